"""Gaps in the data, crossed the same way by every estimator: IMU gaps and DVL dropouts.

DVL dropouts. Where no usable ping comes for more than 1.5 solver.max_state_spacing_s after a state, a state
without a DVL factor is added max_state_spacing_s after it (and so on), so that no IMU factor spans more than
that: long preintegrations are not where GTSAM's first-order covariance propagation is accurate, and the EKF
propagates in such steps too. The rule is causal, so the online estimator adds the same states: it decides
once the IMU has reached FILLER_MARGIN_S past the point where a ping would have been due.

IMU gaps.
A gap is a spacing of consecutive stamps longer than `imu.gap_samples` nominal periods (the median spacing).
The sample after a gap averages only its own nominal period, never the whole gap (a driver that resumes does
not integrate over the outage). The gap itself, (t[k-1], t[k] - period], is crossed by holding the last sample
before it (constant specific force and rate: a zero-order hold) and the uncertainty of that motion model is
added to the estimator's covariance: the rate may change by imu.gap_rate_sigma_deg_s and the acceleration by
imu.gap_accel_sigma_m_s2 over the gap, and an attitude error tilts gravity into the velocity. The same pieces
(selection-style index and duration arrays) feed the preintegration of the factor-graph estimators and the
EKF's strapdown, so all three cross a gap the same way.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.core.config import ImuConfig, SolverConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.imu_faults import STEP_FACTOR, clock_steps, drop_saturated
from gtsam_dvl.core.types import ImuData, LogData
from gtsam_dvl.estimators.inputs.clock_evidence import (
    evidence_words,
    judge_stamp_steps,
    stamp_step_candidates,
)
from gtsam_dvl.estimators.inputs.selection import imu_pieces

G0 = 9.80665  # m/s^2: how much specific force an attitude error of 1 rad turns into acceleration


@dataclass(frozen=True)
class Gaps:
    """The gaps of an IMU stream: gap j is (start[j], end[j]] with no data, the last sample before it index[j]
    (held across it)."""

    period_s: float  # nominal sample period
    start: np.ndarray  # (G,) s
    end: np.ndarray  # (G,) s
    index: np.ndarray  # (G,) int

    def __len__(self) -> int:
        return int(len(self.start))

    @property
    def total_s(self) -> float:
        return float(np.sum(self.end - self.start))

    def summary(self) -> dict[str, float | int]:
        """Count, total and longest gap (s): what the summary and the health report show."""
        return {
            "count": len(self),
            "total_s": self.total_s,
            "longest_s": float(np.max(self.end - self.start)) if len(self) else 0.0,
        }


def gaps_within(gaps: Gaps, t0: float, t1: float) -> Gaps:
    """The gaps that overlap (t0, t1]: those the states cross."""
    keep = (gaps.end > t0) & (gaps.start < t1)
    return Gaps(gaps.period_s, gaps.start[keep], gaps.end[keep], gaps.index[keep])


def nominal_period(t: np.ndarray) -> float:
    """Median spacing of the stamps, s (0.01 when there are fewer than two)."""
    return float(np.median(np.diff(t))) if len(t) > 1 else 0.01


def find_gaps(t: np.ndarray, gap_samples: float, period_s: float | None = None) -> Gaps:
    """Spacings longer than gap_samples nominal periods (module doc)."""
    period = nominal_period(t) if period_s is None else period_s
    dt = np.diff(t)
    k = np.flatnonzero(dt > gap_samples * period) + 1  # first sample after each gap
    return Gaps(period, t[k - 1].astype(float), (t[k] - period).astype(float), (k - 1).astype(int))


def check_spacing(cfg: SolverConfig) -> None:
    """Keyframe thinning and the maximum state spacing must agree: with keyframes farther apart than 1.5 spacings,
    states without a ping would take the places of the pings skipped (more states, fewer pings)."""
    if cfg.keyframe_interval_s > 1.5 * cfg.max_state_spacing_s:
        raise GtsamDvlError(
            f"solver.keyframe_interval_s = {cfg.keyframe_interval_s:g} s needs "
            f"solver.max_state_spacing_s >= {cfg.keyframe_interval_s / 1.5:g} s: states without a "
            "ping would take the places of the pings skipped"
        )


def check_gaps(gaps: Gaps, cfg: ImuConfig, source: str = "") -> None:
    """GtsamDvlError naming the first gap longer than cfg.max_gap_s (a hold that long is no motion model: over a
    30 s gap in a turn its error is systematic and the white-noise covariance of hold_covariance too small)."""
    long = np.flatnonzero(gaps.end - gaps.start > cfg.max_gap_s)
    if len(long):
        j = int(long[0])
        raise GtsamDvlError(
            f"{source + ': ' if source else ''}IMU gap of {gaps.end[j] - gaps.start[j]:.1f} s at "
            f"{gaps.start[j]:.2f}-{gaps.end[j]:.2f} s ({len(long)} gap(s) longer than imu.max_gap_s = "
            f"{cfg.max_gap_s:g} s): cut the log there and process the pieces, or raise imu.max_gap_s"
        )


def sample_starts_with_gaps(t: np.ndarray, gaps: Gaps) -> np.ndarray:
    """Start of each sample's interval: the previous stamp, or one nominal period before its own stamp after a
    gap (and for the first sample)."""
    if len(t) == 0:
        return np.zeros(0)
    starts = np.concatenate([[t[0] - gaps.period_s], t[:-1]])
    starts[gaps.index + 1] = gaps.end
    return starts


@dataclass(frozen=True)
class Holds:
    """The parts of one interval crossed by holding a sample: for each gap it overlaps, (from_s, to_s) measured
    from the gap's start (so that a gap spanning several intervals adds, interval by interval, the increments
    of one motion-model covariance that grows with the time since the gap began)."""

    spans: tuple[tuple[float, float], ...] = ()

    def __bool__(self) -> bool:
        return bool(self.spans)

    @property
    def total_s(self) -> float:
        return float(sum(b - a for a, b in self.spans))


def pieces_with_holds(
    t: np.ndarray, starts: np.ndarray, gaps: Gaps, a: float, b: float
) -> tuple[np.ndarray, np.ndarray, Holds]:
    """The pieces of (a, b] in time order: (sample index, duration s) of the samples covering it, with each
    gap's overlap as pieces of the sample held across it, one nominal period long (so that preintegration and
    the strapdown turn the attitude through the hold as they do through samples: one piece of several seconds
    would be integrated at the attitude of its start); and what was held."""
    idx, dt = imu_pieces(t, starts, a, b)
    if len(gaps) == 0:
        return idx, dt, Holds()
    lo = np.maximum(gaps.start, a)
    hi = np.minimum(gaps.end, b)
    inside = np.flatnonzero(hi > lo)
    if len(inside) == 0:
        return idx, dt, Holds()
    spans = []
    for g in inside.tolist():
        T = float(hi[g] - lo[g])
        n = max(1, int(np.ceil(T / gaps.period_s - 1e-9)))
        # after its sample, before the next one's
        at = int(np.searchsorted(idx, gaps.index[g], side="right"))
        idx = np.insert(idx, at, np.full(n, gaps.index[g]))
        dt = np.insert(dt, at, np.full(n, T / n))
        spans.append((float(lo[g] - gaps.start[g]), float(hi[g] - gaps.start[g])))
    return idx, dt, Holds(tuple(spans))


@dataclass(frozen=True)
class ImuPieces:
    """IMU samples as the preintegrations take them: sample i covers (starts[i], t[i]] (s,
    sample_starts_with_gaps) with its rotation-compensated specific force b_f[i] (m/s^2) and rate b_omega[i]
    (rad/s), and the IMU gaps held across. The batch graph makes one for the whole log, the online estimator
    one for its buffer; the keyframe snapshots and the IMU factors' intervals are cut from it."""

    t: np.ndarray
    starts: np.ndarray
    b_f: np.ndarray
    b_omega: np.ndarray
    gaps: Gaps

    def pieces(self, a: float, b: float) -> tuple[np.ndarray, np.ndarray, Holds]:
        """The pieces of (a, b] (pieces_with_holds) and what was held."""
        return pieces_with_holds(self.t, self.starts, self.gaps, a, b)


def _hold_sigmas(cfg: ImuConfig, T: float) -> np.ndarray:
    """[rotation, position, velocity] sigmas after holding for T seconds: w T, a T^2 / 2 + g w T^3 / 6,
    a T + g w T^2 / 2 (the rate may drift by w, the acceleration by a; an attitude error tilts gravity)."""
    w = np.radians(cfg.gap_rate_sigma_deg_s)
    a = cfg.gap_accel_sigma_m_s2
    return np.array([w * T, a * T**2 / 2.0 + G0 * w * T**3 / 6.0, a * T + G0 * w * T**2 / 2.0])


def hold_covariance(cfg: ImuConfig, holds: Holds, interval_s: float) -> np.ndarray:
    """(9, 9) covariance added to an interval for what it held, in the order of GTSAM's preintegration error
    [rotation, position, velocity] (also the EKF's blocks): for each span (T0, T1) from its gap's start, the
    increment of the variances from T0 to T1 (the intervals of one gap then add up to the covariance of the
    whole hold), and the velocity error carried over the rest of the interval into the position."""
    var = np.zeros(3)
    for t0, t1 in holds.spans:
        s0, s1 = _hold_sigmas(cfg, t0), _hold_sigmas(cfg, t1)
        inc = s1**2 - s0**2
        rest = max(interval_s - (t1 - t0), 0.0)
        inc[1] += (s1[2] * rest) ** 2
        var += inc
    return np.diag(np.repeat(var, 3)) if holds else np.zeros((9, 9))


# the online estimator waits this long for a late ping before adding a state without one
FILLER_MARGIN_S = 2.0


def filler_due(
    t_last: float, t_next_ping: float | None, t_imu_end: float, max_spacing_s: float
) -> float | None:
    """The time of the state to add after the state at t_last (None: none), given the next usable ping known
    (None: none known yet) and how far the IMU reaches: due when the next ping is later than 1.5 max_spacing_s
    after t_last, or, with no next ping known, when the IMU reaches FILLER_MARGIN_S past that."""
    limit = t_last + 1.5 * max_spacing_s
    t_filler = t_last + max_spacing_s
    if t_next_ping is not None:
        return t_filler if t_next_ping > limit and t_imu_end >= t_filler else None
    return t_filler if t_imu_end >= limit + FILLER_MARGIN_S else None


def with_fillers(
    ping_t: np.ndarray, t_imu_end: float, max_spacing_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """State times: the ping epochs ping_t (sorted) with the fillers of filler_due between and after them;
    returns (times, is_filler)."""
    times: list[float] = []
    filler: list[bool] = []
    for j, t in enumerate(ping_t.tolist()):
        times.append(t)
        filler.append(False)
        nxt = float(ping_t[j + 1]) if j + 1 < len(ping_t) else None
        while (f := filler_due(times[-1], nxt, t_imu_end, max_spacing_s)) is not None:
            times.append(f)
            filler.append(True)
    return np.array(times), np.array(filler, dtype=bool)


def screened_in_memory(log: LogData, prior_s: float = 0.0) -> LogData:
    """A log that did not come through the reader (no metadata["reader_losses"]: built in memory, e.g. simulated
    and handed to an estimator) screened as the reader screens one (core/imu_faults.py), and its IMU stamp steps
    judged by the DVL (estimators/inputs/clock_evidence.py; prior_s the time offset prior's mean): a clock step
    (the DVL's timing says so, or the IMU's samples do and the DVL does not say gap) is undone, the later stamps
    shifted by it, and recorded in metadata["reader_losses"]["clock_steps"] with the evidence; a step the DVL says
    is a gap, or cannot decide, stays as it is (a forward one crossed as a gap) and is recorded in
    ["imu_stamp_steps"]; the IMU's samples showing a clock step that the DVL says is a gap is an error naming it.
    Saturated IMU samples are dropped and crossed as IMU gaps, recorded in ["saturation"]. The estimators copy the
    record to their result's info["screened_losses"] (screened_losses) for the health report. A noise-free
    simulation (DvlData.noise_free), whose values repeat by design, is left as it is. A log that came through the
    reader has its remaining stamp steps judged the same way (_read_log_steps)."""
    if log.dvl.noise_free or not len(log.imu):
        return log
    if "reader_losses" in log.metadata:
        return _read_log_steps(log, prior_s)
    losses: dict[str, Any] = {}
    warnings: list[str] = []
    imu = log.imu
    if stamp_step_candidates(np.asarray(imu.t, dtype=float)):
        imu, stepped, other = _judged_steps(log, prior_s)
        if stepped:
            losses["clock_steps"] = {"IMU": stepped}
        if other:
            losses["imu_stamp_steps"] = {"IMU": other}
    imu, report = drop_saturated(imu, "IMU", warnings)
    if report is not None:
        losses["saturation"] = {"IMU": report}
    if not losses:
        return log
    meta = {
        **log.metadata,
        "reader_losses": losses,
        "screened_in_memory": True,
        "reader_warnings": [*log.metadata.get("reader_warnings", []), *warnings],
    }
    return dataclasses.replace(log, imu=imu, metadata=meta)


def _read_log_steps(log: LogData, prior_s: float) -> LogData:
    """A log the reader screened, with the stamp steps it left (forward ones, crossed as gaps: in steady motion its
    rule from the IMU's samples cannot tell; a step back it undid, dropped with --repair or refused) judged by the
    DVL as screened_in_memory does: a clock step undone and added to the reader's record ["clock_steps"], the IMU's
    gap record ["gaps"] recounted without it; the others in ["imu_stamp_steps"]. Left as it is when there are none
    (no "screened_in_memory": the reader's record stands)."""
    t = np.asarray(log.imu.t, dtype=float)
    if not stamp_step_candidates(t):
        return log
    imu, stepped, other = _judged_steps(log, prior_s)
    losses = dict(log.metadata["reader_losses"])
    gaps = dict(losses.get("gaps") or {})
    # the IMU's topic: the one whose gaps start where the steps do (the reader's stamps, as log.imu.t)
    at = {round(float(r["at_s"]), 6) for r in stepped + other}
    topic = next(
        (k for k, g in gaps.items() if at & {round(float(a), 6) for a, _ in g.get("spans_s", [])}),
        "IMU",
    )
    if stepped:
        clock = dict(losses.get("clock_steps") or {})
        clock[topic] = [*clock.get(topic, []), *stepped]
        losses["clock_steps"] = clock
        if topic in gaps:
            if (recount := _stamp_gaps(np.asarray(imu.t, dtype=float))) is None:
                del gaps[topic]
            else:
                gaps[topic] = recount
            losses["gaps"] = gaps
    if other:
        losses["imu_stamp_steps"] = {topic: other}
    meta = {**log.metadata, "reader_losses": losses, "screened_in_memory": True}
    return dataclasses.replace(log, imu=imu, metadata=meta)


def _stamp_gaps(t: np.ndarray) -> dict[str, Any] | None:
    """The reader's gap record of one topic's stamps (io/stamps.py stamp_gaps: steps beyond STEP_FACTOR periods)."""
    d = np.diff(t)
    period = float(np.median(d))
    big = np.flatnonzero(d > STEP_FACTOR * period)
    if not len(big):
        return None
    return {
        "count": len(big),
        "seconds": float((d[big] - period).sum()),
        "period_s": period,
        "longest_s": float(d[big].max()),
        "spans_s": [[float(t[i]), float(t[i + 1])] for i in big[:20].tolist()],
    }


def _judged_steps(
    log: LogData, prior_s: float
) -> tuple[ImuData, list[dict[str, Any]], list[dict[str, Any]]]:
    """The IMU with its clock steps undone, and the records of those and of the other stamp steps
    (screened_in_memory)."""
    t = np.asarray(log.imu.t, dtype=float)
    by_imu = {s.index: s for s in clock_steps(t, log.imu.b_omega, log.imu.b_f)}
    judged = judge_stamp_steps(log, prior_s, tuple(by_imu))
    for s in judged:
        if s.by_imu and s.decision == "gap":
            raise GtsamDvlError(
                f"{log.source or 'log'}: IMU {by_imu[s.index].words()}, but the DVL's timing across it says "
                f"samples are missing ({evidence_words(s.record())}); check the IMU's stamps"
            )
    fixed = t.copy()
    stepped, other = [], []
    for s in judged:
        if s.decision == "clock step" or s.by_imu:
            fixed[s.index :] -= s.step_s
            stepped.append(s.record())
        else:
            other.append(s.record())
    return dataclasses.replace(log.imu, t=fixed), stepped, other


def screened_losses(log: LogData) -> dict[str, Any] | None:
    """What screened_in_memory found on log (the reader's record's shape), None for a log it left as it was."""
    return log.metadata.get("reader_losses") if log.metadata.get("screened_in_memory") else None
