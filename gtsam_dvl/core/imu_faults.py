"""IMU faults found from the samples alone, before any estimator sees them: saturation and clock steps. The
log reader (io/reader.py) applies them to every log it reads and records what it found in
metadata["reader_losses"] ("saturation", "clock_steps"), which the health report states (analysis/health_losses.py).

Saturation. A gyro or accelerometer driven past its range reports the range's limit: a run of samples all
equal to the axis's largest (or most negative) value in the log. A real sensor's noise makes equal consecutive
samples rare, so a long run of them at the extreme is no chance: per axis, the share p of equal consecutive
samples elsewhere (away from the extreme) gives the chance of a run of n equal samples anywhere among the N
samples, about N p^(n - 1); a run of at least SATURATION_MIN_RUN samples at the extreme, at a value above
the axis's floor (SATURATION_FLOOR: not a dead axis or the Earth rate), whose chance is below
SATURATION_CHANCE, is saturation. A quantised or noise-free stream, which repeats its values everywhere, shows
no saturation this way (its runs are its own); neither does a steady turn on a noisy gyro. The saturated
samples are dropped, so that every estimator crosses them as an IMU gap (estimators/inputs/gaps.py: the last sample
before is held, the motion model's uncertainty added; longer than imu.max_gap_s the run stops naming it).

Clock steps. A stamp step of more than STEP_FACTOR nominal periods is either missing data (a gap; back in
time: older samples logged late) or the IMU's clock jumping while the samples run on (a clock step). The
samples tell which where the motion changes (a turn, an acceleration): fitting a line to the WINDOW samples on
each side (per gyro and accelerometer axis), continuous data joins up at the next sample (the two lines agree
one period after the last sample before the step, within STEP_JOIN_SIGMAS of their standard errors on every
axis), while a gap of n missing samples would have moved the signal by about its slope times n
(GAP_SHOW_SIGMAS or more on some axis). Both must hold to call it a clock step; in steady motion (no slope) the
two cannot be told apart from the samples and the step stays a gap here (the estimators' screen then asks the
DVL's timing across it: estimators/inputs/clock_evidence.py). After a clock step the samples continue one period
after the last one before it: the later stamps are ahead by the step less one period, and shifting them back by that
restores the IMU's timeline against the other sensors' clocks (the DVL's stamps, on their own clock, did not
jump); a step back is undone forward the same way, where the stamps' rule would otherwise drop the samples
until they pass the newest one. The reader does so with --repair, before its stamp checks, and otherwise stops
with an error naming the step.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import ImuData

SATURATION_MIN_RUN = 5  # samples at the extreme in a row
SATURATION_CHANCE = 1e-3  # a run less likely than this over the whole log is no chance
SATURATION_FLOOR = (
    1e-3,
    0.5,
)  # rad/s (14x the Earth rate), m/s^2: smaller extremes are not a range limit
STEP_FACTOR = 5.0  # a stamp step this many nominal periods long is a gap or a clock step (io/stamps.py's gaps)
WINDOW = 50  # samples on each side of a step
MIN_WINDOW = 10  # fewer on a side: undecided (a gap)
STEP_JOIN_SIGMAS = 5.0
GAP_SHOW_SIGMAS = 10.0


@dataclass(frozen=True)
class SaturatedRun:
    """Samples start..stop-1 of one axis at its range limit."""

    sensor: str  # "gyro" or "accel"
    axis: int  # 0, 1, 2: x, y, z of the IMU's frame
    value: float  # the limit, rad/s or m/s^2
    start: int
    stop: int


def saturated_runs(b_omega: np.ndarray, b_f: np.ndarray) -> list[SaturatedRun]:
    """The saturated runs of an IMU stream (module doc), per sensor and axis, in sample order."""
    runs: list[SaturatedRun] = []
    for sensor, data, floor in (
        ("gyro", b_omega, SATURATION_FLOOR[0]),
        ("accel", b_f, SATURATION_FLOOR[1]),
    ):
        x = np.asarray(data, dtype=float)
        for axis in range(3):
            runs += _axis_runs(sensor, axis, x[:, axis], floor)
    return sorted(runs, key=lambda r: r.start)


def _axis_runs(sensor: str, axis: int, x: np.ndarray, floor: float) -> list[SaturatedRun]:
    finite = np.isfinite(x)
    if len(x) < SATURATION_MIN_RUN or not finite.any():
        return []
    out: list[SaturatedRun] = []
    same = x[1:] == x[:-1]
    for limit in (float(np.max(x[finite])), float(np.min(x[finite]))):
        if abs(limit) <= floor or (out and limit == out[0].value):
            continue
        at = x == limit
        edges = np.flatnonzero(np.diff(np.r_[0, at.astype(np.int8), 0]))
        starts, stops = edges[::2], edges[1::2]
        long = stops - starts >= SATURATION_MIN_RUN
        if not long.any():
            continue
        # the share of equal neighbours away from this extreme: how often the axis repeats a value by itself
        away = ~(at[1:] & at[:-1])
        p = (int((same & away).sum()) + 1) / (int(away.sum()) + 1)
        n = stops - starts
        chance = len(x) * np.exp((n - 1) * np.log(p))
        for a, b in zip(
            starts[long & (chance < SATURATION_CHANCE)].tolist(),
            stops[long & (chance < SATURATION_CHANCE)].tolist(),
            strict=True,
        ):
            out.append(SaturatedRun(sensor, axis, limit, int(a), int(b)))
    return out


def saturation_report(t: np.ndarray, runs: list[SaturatedRun]) -> dict[str, Any]:
    """What the reader records of the saturated runs (t: the stamps, s): samples dropped, the runs, the axes
    and limits, the longest stretch and the first spans (s)."""
    mask = saturated_mask(len(t), runs)
    axes = sorted({(r.sensor, "xyz"[r.axis], r.value) for r in runs})
    spans = _spans(t, mask)
    return {
        "samples": int(mask.sum()),
        "stretches": len(spans),
        "axes": [{"sensor": s, "axis": a, "limit": v} for s, a, v in axes],
        "longest_s": max((b - a for a, b in spans), default=0.0),
        "spans_s": [list(s) for s in spans[:20]],
    }


def saturated_mask(n: int, runs: list[SaturatedRun]) -> np.ndarray:
    """(n,) True for the samples of any saturated run (on any axis): those dropped."""
    mask = np.zeros(n, dtype=bool)
    for r in runs:
        mask[r.start : r.stop] = True
    return mask


def _spans(t: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """(first, last) stamps of each stretch of consecutive True in mask."""
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    return [(float(t[a]), float(t[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]


@dataclass(frozen=True)
class ClockStep:
    """A jump of the stamps with the samples running on: sample index is the first after it."""

    index: int
    t_before: float  # the stamp before the jump, s
    t_after: float  # the stamp after it, s
    step_s: float  # how far the later stamps are ahead: the jump less one nominal period

    def words(self) -> str:
        jump = self.t_after - self.t_before
        return (
            f"clock step at {self.t_before:.3f} s: the stamps jump {'back ' if jump < 0 else ''}by "
            f"{abs(jump):.3f} s while the samples run on without a break"
        )

    def shift_words(self) -> str:
        """How the later stamps are corrected."""
        return f"{'back' if self.step_s > 0 else 'forward'} by {abs(self.step_s):.3f} s"


def clock_steps(t: np.ndarray, b_omega: np.ndarray, b_f: np.ndarray) -> list[ClockStep]:
    """The stamp steps of an IMU stream (t in s, as logged) that are clock steps (module doc): forward, not a
    gap, or back, not older samples logged late (the alternative's samples then belong |jump| earlier)."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2 * MIN_WINDOW:
        return []
    d = np.diff(t)
    period = float(np.median(d))
    steps = (np.flatnonzero(np.abs(d) > STEP_FACTOR * period) + 1).tolist()
    del d  # the windows below are small: no other array over the whole log (the reader's memory)
    out = []
    for j, k in enumerate(steps):  # the windows stop at the neighbouring steps
        lo = max(k - WINDOW, steps[j - 1] if j else 0)
        hi = min(k + WINDOW, steps[j + 1] if j + 1 < len(steps) else len(t))
        x = np.concatenate(
            [np.asarray(b_omega[lo:hi], dtype=float), np.asarray(b_f[lo:hi], dtype=float)], axis=1
        )
        if _continuous(x[: k - lo], x[k - lo :], (t[k] - t[k - 1]) / period - 1.0):
            out.append(ClockStep(k, float(t[k - 1]), float(t[k]), float(t[k] - t[k - 1] - period)))
    return out


def _line(
    y: np.ndarray, i: np.ndarray, at: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares lines y = a + b i per column: (value at `at`, its variance, slope, slope variance)."""
    n = len(i)
    ibar = float(i.mean())
    sxx = float(((i - ibar) ** 2).sum())
    b = ((i - ibar)[:, None] * (y - y.mean(axis=0))).sum(axis=0) / sxx
    a = y.mean(axis=0) - b * ibar
    resid = y - (a + b * i[:, None])
    s2 = (resid**2).sum(axis=0) / max(n - 2, 1)
    s2 = np.maximum(s2, (1e-12 * (1.0 + np.abs(y).max(axis=0))) ** 2)  # noise-free data: a floor
    return a + b * at, s2 * (1.0 / n + (at - ibar) ** 2 / sxx), b, s2 / sxx


def _continuous(before: np.ndarray, after: np.ndarray, n_missing: float) -> bool:
    """Whether the samples after a stamp step continue those before it one period on (they join within
    STEP_JOIN_SIGMAS on every axis) while n_missing samples missing would have shown (GAP_SHOW_SIGMAS on some
    axis). Sample indices: before at -len(before)..-1, after at 0.. under continuity."""
    if len(before) < MIN_WINDOW or len(after) < MIN_WINDOW:
        return False
    y_b, var_b, slope_b, svar_b = _line(before, np.arange(-len(before), 0, dtype=float), 0.0)
    y_a, var_a, slope_a, svar_a = _line(after, np.arange(len(after), dtype=float), 0.0)
    join = np.abs(y_a - y_b) / np.sqrt(var_a + var_b)
    slope = 0.5 * (slope_a + slope_b)
    shown = np.abs(y_a - y_b - slope * n_missing) / np.sqrt(
        var_a + var_b + 0.25 * (svar_a + svar_b) * n_missing**2
    )
    return bool(np.all(join < STEP_JOIN_SIGMAS) and np.any(shown > GAP_SHOW_SIGMAS))


def undo_clock_steps(
    ns: np.ndarray,
    t0_ns: int,
    b_omega: np.ndarray,
    b_f: np.ndarray,
    topic: str,
    repair: bool,
    warnings: list[str],
) -> tuple[np.ndarray, list[dict[str, float]]]:
    """The IMU's stamps (ns, as logged; t0_ns the log's time base) with its clock steps undone (module doc;
    samples with a non-finite value are left out of the test and shifted with their neighbours), and the steps
    found ([{"at_s", "jump_s", "step_s"}], one warning each). Without repair a clock step is a GtsamDvlError
    naming it."""
    finite = np.isfinite(b_omega).all(axis=1) & np.isfinite(b_f).all(axis=1)
    if finite.all():  # no copies of the samples
        rows = None
        steps = clock_steps((np.asarray(ns, dtype=np.int64) - t0_ns) / 1e9, b_omega, b_f)
    else:
        rows = np.flatnonzero(finite)
        steps = clock_steps(
            (np.asarray(ns, dtype=np.int64)[rows] - t0_ns) / 1e9, b_omega[rows], b_f[rows]
        )
    if steps and not repair:
        s = steps[0]
        raise GtsamDvlError(
            f"{topic}: {s.words()}{f' (and {len(steps) - 1} more)' if len(steps) > 1 else ''}; "
            f"rerun with --repair to shift the later stamps {s.shift_words()}"
        )
    if not steps:
        return ns, []
    out = np.array(ns, dtype=np.int64)
    for s in steps:
        out[s.index if rows is None else rows[s.index] :] -= int(round(s.step_s * 1e9))
    warnings.extend(
        f"{topic}: {s.words()}; the later stamps shifted {s.shift_words()}" for s in steps
    )
    return out, [
        {"at_s": s.t_before, "jump_s": s.t_after - s.t_before, "step_s": s.step_s} for s in steps
    ]


def drop_saturated(
    imu: ImuData, topic: str, warnings: list[str]
) -> tuple[ImuData, dict[str, Any] | None]:
    """The IMU stream without its saturated samples (module doc) and their saturation_report (None: none), with
    a warning."""
    runs = saturated_runs(imu.b_omega, imu.b_f)
    if not runs:
        return imu, None
    report = saturation_report(imu.t, runs)
    keep = ~saturated_mask(len(imu), runs)
    warnings.append(f"{topic}: {saturation_words(report)}: dropped, crossed as IMU gaps")
    return dataclasses.replace(
        imu, t=imu.t[keep], b_omega=imu.b_omega[keep], b_f=imu.b_f[keep]
    ), report


def saturation_words(report: dict[str, Any]) -> str:
    """The saturation of saturation_report in words: which axes at which limits, how many samples, where."""
    axes = ", ".join(
        f"{a['sensor']} {a['axis']} at {a['limit']:+.4g} {'rad/s' if a['sensor'] == 'gyro' else 'm/s^2'}"
        for a in report["axes"]
    )
    a, b = (
        max(report["spans_s"], key=lambda s: s[1] - s[0])
        if report["spans_s"]
        else (float("nan"),) * 2
    )
    return (
        f"the IMU saturated ({axes}): {report['samples']} samples at the range limit in {report['stretches']} "
        f"stretch(es), the longest {a:.2f} to {b:.2f} s"
    )
