"""A step in the IMU's stamps told apart by the DVL: a clock step (the samples run on, the stamps after it are off by
the step) or a gap (samples missing, the stamps right). The IMU's samples alone tell them apart only where the motion
changes across the step (core/imu_faults.py clock_steps); in steady motion, and wherever else they cannot, the DVL
can: its stamps are on their own clock, which did not jump.

The DVL-IMU time offset dt_d (docs/conventions.md) is estimated on a window of the log before the step and on one
after it, each from the IMU samples and the pings of that window alone: the DVL's velocity, turned into the
window's frame by the attitude the gyros carry from a levelled start (heading arbitrary: it cancels), is matched
against the IMU's integrated velocity, both at the ping's stamp shifted by a candidate dt (the misfit J(dt) on a
grid of GRID_STEP_S, offset_guess.py's idea on the velocity instead of its changes: a turn at constant speed and
depth carries no timing, the body-frame velocity that the DVL measures does not change; speed and depth changes
do, and a velocity shows them over their whole length). The start velocity, a constant tilt, the accelerometer bias
and gravity turning at the Earth's rate in the window's frame add a cubic in time per axis, projected out
(POLY_TERMS). The offset is J's minimum, its sigma from J's curvature there and the residual variance, widened by
RESIDUAL_CORRELATION for the misfit's slow, correlated part (the misalignment and scale left out).

If the IMU clock stepped by s (the later stamps s ahead), a ping matches the IMU samples s later after the step than
before it: the offset after differs from the one before by s. If samples went missing, it does not differ. With
sigma the two offsets' combined standard deviation, the step is a clock step when the difference d agrees with s
(|d - s| < AGREE_SIGMAS sigma) and not with 0 (|d| > REJECT_SIGMAS sigma); a gap when the reverse holds; else
undecided, which stays as it is (a forward step crossed as a gap) and is reported. Each window reaches WINDOW_S
into the log on its side, up to the neighbouring step, so that a step in a straight leg is decided by the speed and
depth changes before and after the leg.

A stamp step is a candidate when it is forward by more than core/imu_faults.py's STEP_FACTOR nominal periods and
MIN_STEP_S, and at most MAX_STEP_S, or back by MIN_STEP_S to MAX_STEP_S; a smaller step forward is a plain gap (a few
samples dropped), and beyond MAX_JUDGED candidates in a log (a driver that drops samples all the time) the DVL is not
asked (each judgement integrates up to two windows of WINDOW_S): they stay as they are, undecided.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from gtsam_dvl.core.imu_faults import STEP_FACTOR
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.offset_guess import attitudes

MIN_STEP_S = 0.1  # smaller stamp steps forward are plain gaps
MAX_STEP_S = 6.0  # larger stamp steps are gaps (or the estimators' max_gap_s error): not tested
MAX_JUDGED = 20
WINDOW_S = 600.0  # s of the log on each side of a step at most
# the window's frame is levelled but not turned with the Earth: gravity turns in it at the Earth's rate, which with
# the unknown start velocity, the accelerometer bias and a constant tilt adds a cubic in time per axis (to 1 cm/s
# over WINDOW_S), projected out of the velocity misfit
POLY_TERMS = 4
MARGIN_S = 1.0  # the offset is searched this far beyond both hypotheses
GRID_STEP_S = 0.02
MIN_PINGS = 30
MIN_EVIDENCE = 25.0  # J must drop this many residual variances from the search's worst to its best
AGREE_SIGMAS = 3.0
REJECT_SIGMAS = 5.0
# the curvature's sigma assumes independent residuals; the misfit's slow part (misalignment, scale) is not: widened by
# this factor (paper-3d-short, seeds 1, 2, 11, windows without a step: offset errors within 2.5 sigma after it)
RESIDUAL_CORRELATION = 1.5
G0 = 9.80665


@dataclass(frozen=True)
class WindowOffset:
    """The time offset found on one window: offset_s (s) and its sigma_s, the pings used (pairs) and the time span
    (s, the IMU's stamps as logged); offset_s NaN where the window gave no evidence (why)."""

    offset_s: float
    sigma_s: float
    pairs: int
    span_s: tuple[float, float]
    why: str = ""


@dataclass(frozen=True)
class StampStep:
    """One step in the IMU's stamps and what the DVL said of it: index is the first sample after it; step_s how
    far the later stamps are ahead if it is a clock step (the jump less one nominal period); decision
    "clock step", "gap" or "undecided"; the offsets before and after it and the difference's sigma."""

    index: int
    t_before: float
    t_after: float
    step_s: float
    decision: str
    before: WindowOffset
    after: WindowOffset
    sigma_s: float
    by_imu: bool = False  # the IMU's samples alone showed it (core/imu_faults.py clock_steps)

    @property
    def difference_s(self) -> float:
        return self.after.offset_s - self.before.offset_s

    def record(self) -> dict[str, object]:
        """The health report's record of it (the reader's clock-step record's names, and the evidence)."""
        return {
            "at_s": self.t_before,
            "jump_s": self.t_after - self.t_before,
            "step_s": self.step_s,
            "decision": self.decision,
            "by_imu": self.by_imu,
            "offset_before_s": self.before.offset_s,
            "offset_before_sigma_s": self.before.sigma_s,
            "offset_after_s": self.after.offset_s,
            "offset_after_sigma_s": self.after.sigma_s,
            "difference_sigma_s": self.sigma_s,
            "why": "; ".join(w for w in (self.before.why, self.after.why) if w),
        }

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def stamp_step_candidates(t: np.ndarray) -> list[int]:
    """The first sample after each candidate step of the stamps t (module doc)."""
    if len(t) < 3:
        return []
    d = np.diff(t)
    period = float(np.median(d))
    jump = np.abs(d - period)
    cand = (
        ((d > STEP_FACTOR * period) | (d < 0))
        & (jump > MIN_STEP_S - 0.5 * period)
        & (jump <= MAX_STEP_S)
    )
    return (np.flatnonzero(cand) + 1).tolist()


def judge_stamp_steps(
    log: LogData, prior_s: float = 0.0, by_imu: tuple[int, ...] = ()
) -> list[StampStep]:
    """Every candidate step of the log's IMU stamps judged by the DVL (module doc); prior_s the time offset's prior
    mean (the before-window's search is centred there); by_imu the indices the IMU's samples showed as clock steps
    (recorded with the decision)."""
    imu, dvl = log.imu, log.dvl
    t = np.asarray(imu.t, dtype=float)
    steps = stamp_step_candidates(t)
    if not steps:
        return []
    period = float(np.median(np.diff(t)))
    R = np.asarray(log.mounting.b_R_imu, dtype=float).T @ np.asarray(
        log.mounting.b_R_d0, dtype=float
    )
    ok = np.asarray(dvl.valid, dtype=bool) & np.isfinite(dvl.d_v).all(axis=1)
    if dvl.water_track is not None:
        ok &= ~np.asarray(dvl.water_track, dtype=bool)
    ping_t = np.asarray(dvl.t, dtype=float)[ok]
    v_imu = np.asarray(dvl.d_v, dtype=float)[ok] @ R.T  # velocity in the IMU's frame
    w = np.asarray(imu.b_omega, dtype=float)
    f = np.asarray(imu.b_f, dtype=float)
    out = []
    if len(steps) > MAX_JUDGED:
        why = f"{len(steps)} stamp steps in the log, more than {MAX_JUDGED}: not judged"
        for k in steps:
            none = WindowOffset(math.nan, math.nan, 0, (float(t[k - 1]), float(t[k])), why)
            out.append(
                StampStep(
                    k,
                    float(t[k - 1]),
                    float(t[k]),
                    float(t[k] - t[k - 1] - period),
                    "undecided",
                    none,
                    replace(none, why=""),
                    math.nan,
                    k in by_imu,
                )
            )
        return out
    for j, k in enumerate(steps):
        lo = steps[j - 1] if j else 0
        hi = steps[j + 1] if j + 1 < len(steps) else len(t)
        step = float(t[k] - t[k - 1] - period)
        a = int(np.searchsorted(t[lo:k], t[k - 1] - WINDOW_S)) + lo
        b = int(np.searchsorted(t[k:hi], t[k] + WINDOW_S)) + k
        before = window_offset(t[a:k], w[a:k], f[a:k], ping_t, v_imu, prior_s - 2.0, prior_s + 2.0)
        if math.isfinite(before.offset_s):
            c = before.offset_s
            after = window_offset(
                t[k:b], w[k:b], f[k:b], ping_t, v_imu,
                c + min(0.0, step) - MARGIN_S, c + max(0.0, step) + MARGIN_S,
            )  # fmt: skip
        else:
            after = WindowOffset(math.nan, math.nan, 0, (float(t[k]), float(t[b - 1])), "")
        sigma = math.hypot(before.sigma_s, after.sigma_s)
        out.append(
            StampStep(
                k,
                float(t[k - 1]),
                float(t[k]),
                step,
                _decide(after.offset_s - before.offset_s, step, sigma),
                before,
                after,
                sigma,
                k in by_imu,
            )  # fmt: skip
        )
    return out


def _decide(d: float, step: float, sigma: float) -> str:
    """'clock step', 'gap' or 'undecided' from the offsets' difference d (s), the step s and its sigma."""
    if not (math.isfinite(d) and math.isfinite(sigma) and sigma > 0):
        return "undecided"
    z_step, z_gap = abs(d - step) / sigma, abs(d) / sigma
    if z_step < AGREE_SIGMAS and z_gap > REJECT_SIGMAS:
        return "clock step"
    if z_gap < AGREE_SIGMAS and z_step > REJECT_SIGMAS:
        return "gap"
    return "undecided"


def _levelled(f: np.ndarray) -> np.ndarray:
    """A rotation n_R_b taking the mean specific force f (N, 3) to +z (heading arbitrary: it cancels)."""
    up = f.mean(axis=0)
    up = up / np.linalg.norm(up)
    ax = np.cross(up, [0.0, 0.0, 1.0])
    s, c = float(np.linalg.norm(ax)), float(up[2])
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = ax / s
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def window_offset(
    t: np.ndarray,
    w: np.ndarray,
    f: np.ndarray,
    ping_t: np.ndarray,
    v_b: np.ndarray,
    lo_s: float,
    hi_s: float,
) -> WindowOffset:
    """The time offset in [lo_s, hi_s] that best matches the pings (stamps ping_t s, velocity v_b m/s in the IMU's
    frame) to the IMU samples of one window (stamps t s as logged, gyro w rad/s, specific force f m/s^2), with its
    sigma (module doc)."""
    span = (float(t[0]), float(t[-1])) if len(t) else (math.nan, math.nan)
    none = WindowOffset(math.nan, math.nan, 0, span, "")
    if len(t) < 100:
        return replace(none, why=f"{span[0]:.0f}-{span[1]:.0f} s: too few IMU samples")
    keep = (ping_t + lo_s >= t[0]) & (ping_t + hi_s <= t[-1])
    pt, pv = ping_t[keep], v_b[keep]
    if len(pt) < MIN_PINGS:
        return replace(none, why=f"{span[0]:.0f}-{span[1]:.0f} s: too few pings")
    n_R_b = attitudes(t, w, _levelled(f), np.zeros(3))
    n_a = np.einsum("kij,kj->ki", n_R_b, f) + np.array([0.0, 0.0, -G0])
    V = np.concatenate(
        [np.zeros((1, 3)), np.cumsum(0.5 * (n_a[1:] + n_a[:-1]) * np.diff(t)[:, None], axis=0)]
    )
    # the start velocity, a constant tilt, the accelerometer bias and the Earth's rotation (a cubic in time per axis:
    # POLY_TERMS) tell nothing of dt: projected out
    tau = (pt - pt.mean()) / max(float(np.ptp(pt)), 1.0)
    A = np.stack([tau**i for i in range(POLY_TERMS)], axis=1)
    P = np.eye(len(pt)) - A @ np.linalg.pinv(A)
    grid = np.arange(lo_s, hi_s + 0.5 * GRID_STEP_S, GRID_STEP_S)
    cost = np.array([_misfit(dt, t, n_R_b, V, pt, pv, P) for dt in grid])
    best = int(np.argmin(cost))
    n_rows = 3 * (len(pt) - A.shape[1])
    var = cost[best] / max(n_rows - 1, 1)
    evidence = float((cost.max() - cost[best]) / var) if var > 0 else 0.0
    where = f"{span[0]:.0f}-{span[1]:.0f} s"
    if best in (0, len(grid) - 1):
        return replace(none, pairs=len(pt), why=f"{where}: best at the search's edge")
    if not evidence > MIN_EVIDENCE:
        return replace(
            none, pairs=len(pt), why=f"{where}: no timing in the motion (evidence {evidence:.0f})"
        )
    # J near its minimum: a parabola through the neighbours gives the curvature and the refined minimum
    j0, j1, j2 = cost[best - 1], cost[best], cost[best + 1]
    curv = (j0 - 2.0 * j1 + j2) / GRID_STEP_S**2
    if not curv > 0:
        return replace(none, pairs=len(pt), why=f"{where}: a flat misfit")
    shift = 0.5 * (j0 - j2) / (j0 - 2.0 * j1 + j2) * GRID_STEP_S
    sigma = RESIDUAL_CORRELATION * math.sqrt(2.0 * var / curv)
    return WindowOffset(float(grid[best] + shift), sigma, len(pt), span)


def _misfit(
    dt: float,
    t: np.ndarray,
    n_R_b: np.ndarray,
    V: np.ndarray,
    pt: np.ndarray,
    pv: np.ndarray,
    P: np.ndarray,
) -> float:
    """J(dt): the DVL's velocity in the window's frame against the IMU's integrated velocity, a cubic per axis
    projected out (module doc)."""
    ts = pt + dt
    k = np.clip(np.searchsorted(t, ts), 1, len(t) - 1)
    k = np.where(np.abs(t[k - 1] - ts) < np.abs(t[k] - ts), k - 1, k)
    n_v = np.einsum("kij,kj->ki", n_R_b[k], pv)
    v = np.stack([np.interp(ts, t, V[:, a]) for a in range(3)], axis=1)
    r = P @ (n_v - v)
    s = float(np.sum(r * r))
    return s if math.isfinite(s) else math.inf


def evidence_words(r: dict[str, Any]) -> str:
    """The DVL's evidence of one stamp step record (clock_evidence.StampStep.record) in words."""
    if not np.isfinite(r["difference_sigma_s"]):
        return f"the DVL cannot time it: {r['why']}"
    return (
        f"DVL time offset {r['offset_before_s']:+.3f} +- {r['offset_before_sigma_s']:.3f} s before, "
        f"{r['offset_after_s']:+.3f} +- {r['offset_after_sigma_s']:.3f} s after"
    )
