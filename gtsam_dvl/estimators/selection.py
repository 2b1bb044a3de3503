"""Which measurements an estimator uses, and how IMU samples are split between epochs: the one copy of these
rules, shared by the batch smoother (estimators/graph.py), the online estimator (estimators/online/) and the
EKF (estimators/ekf/), so that all three see the same epochs on the same log.

Pings. A DVL ping is usable when it has a valid velocity (or, with `dvl.use_beams`, at least one valid beam
with finite values), it is not faster than `dvl.max_speed_m_s` (a bottom-track outlier) and it lies after the
first IMU sample (nothing before it can be propagated) and not after the last one. Every rejection is counted
by reason. Keyframe thinning (`solver.keyframe_interval_s`) then keeps pings at least that far apart.

IMU samples. Sample i is the average over (starts[i], t[i]] (ImuData's convention); an interval (a, b] between
two epochs takes each sample's overlap with it, so a sample straddling a ping is split exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.types import DvlData

# Rejection reasons, in the counters every estimator reports.
USABLE = 0
UNUSABLE = 1  # no valid velocity or beam, or outside the IMU's time span
TOO_FAST = 2  # faster than dvl.max_speed_m_s
REASONS = {UNUSABLE: "dvl_unusable", TOO_FAST: "dvl_too_fast"}


def classify_pings(t: np.ndarray, d_v: np.ndarray, valid: np.ndarray, beam_valid: np.ndarray | None,
                   beam_finite: np.ndarray | None, cfg: DvlConfig, t_imu_first: float,
                   t_imu_last: float = np.inf) -> np.ndarray:
    """Reason code per ping (USABLE, UNUSABLE, TOO_FAST), vectorised over M pings.

    t (M,) s; d_v (M, 3) m/s in dvl_link; valid (M,) the 3-D velocity's flag; beam_valid (M, B) and
    beam_finite (M,) (all valid beams finite) when the log has beams. t_imu_last: inf for an online
    estimator, which waits for the IMU samples that reach a ping.
    """
    t = np.asarray(t, dtype=float)
    if cfg.use_beams and beam_valid is not None:
        usable = np.asarray(beam_valid).any(axis=1)
        if beam_finite is not None:
            usable &= np.asarray(beam_finite, dtype=bool)
        too_fast = np.zeros(len(t), dtype=bool)  # a beam sees one component: no 3-D speed check
    else:
        finite = np.isfinite(d_v).all(axis=1)
        usable = np.asarray(valid, dtype=bool) & finite
        speed = np.linalg.norm(np.where(finite[:, None], d_v, 0.0), axis=1)
        too_fast = usable & (speed > cfg.max_speed_m_s)
    in_span = (t > t_imu_first) & (t <= t_imu_last)
    code = np.full(len(t), UNUSABLE, dtype=np.int8)
    code[usable & in_span] = USABLE
    code[too_fast & in_span] = TOO_FAST
    return code


def count_reasons(code: np.ndarray, counters: dict[str, int], keep_zero: bool = True) -> None:
    """Add the rejections of classify_pings to counters (by reason name); keep_zero: also create the
    counters of reasons that did not occur."""
    for reason, name in REASONS.items():
        n = int((code == reason).sum())
        if n or keep_zero:
            counters[name] = counters.get(name, 0) + n


def beam_arrays(dvl: DvlData) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(beam_valid (M, B), beam_finite (M,)) of a log's DVL data, or (None, None) without beams."""
    if dvl.beams is None:
        return None, None
    b = dvl.beams
    ok = b.valid
    finite = np.where(ok, np.isfinite(b.v), True).all(axis=1) & np.where(ok[..., None], np.isfinite(b.d_u),
                                                                        True).all(axis=(1, 2))
    return np.asarray(ok), np.asarray(finite)


def usable_pings(dvl: DvlData, imu_t: np.ndarray, cfg: DvlConfig, counters: dict[str, int]) -> np.ndarray:
    """Indices of the usable pings of a whole log (module doc), counting the others."""
    beam_valid, beam_finite = beam_arrays(dvl)
    t_first = float(imu_t[0]) if len(imu_t) else np.inf
    t_last = float(imu_t[-1]) if len(imu_t) else -np.inf
    code = classify_pings(dvl.t, dvl.d_v, dvl.valid, beam_valid, beam_finite, cfg, t_first, t_last)
    count_reasons(code, counters)
    return np.flatnonzero(code == USABLE)


@dataclass
class KeyframeThinning:
    """Keeps pings at least interval_s apart (0 keeps every one); stateful so an online estimator can feed
    pings one at a time and get the batch smoother's choice."""

    interval_s: float
    last_t: float = -np.inf

    def keep(self, t: float) -> bool:
        if t - self.last_t < self.interval_s:
            return False
        self.last_t = t
        return True


def select_epochs(dvl: DvlData, imu_t: np.ndarray, cfg: DvlConfig, keyframe_interval_s: float,
                  counters: dict[str, int]) -> np.ndarray:
    """Indices of the pings that become epochs: usable, then thinned to keyframes (module doc)."""
    idx = usable_pings(dvl, imu_t, cfg, counters)
    if keyframe_interval_s <= 0:
        return idx
    thin = KeyframeThinning(keyframe_interval_s)
    keep = np.array([thin.keep(float(dvl.t[j])) for j in idx], dtype=bool)
    counters["dvl_not_keyframe"] = counters.get("dvl_not_keyframe", 0) + int((~keep).sum())
    return idx[keep]


def sample_starts(t: np.ndarray) -> np.ndarray:
    """Start of each IMU sample's interval: the previous stamp (the first sample gets the median spacing)."""
    if len(t) == 0:
        return np.zeros(0)
    first_dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
    return np.concatenate([[t[0] - first_dt], t[:-1]])


def imu_pieces(t: np.ndarray, starts: np.ndarray, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples covering (a, b] and the part of each inside it (s): interval averages are split exactly."""
    lo = int(np.searchsorted(t, a, side="right"))  # first sample ending after a
    hi = min(int(np.searchsorted(t, b, side="left")), len(t) - 1)  # last sample that reaches b
    idx = np.arange(lo, hi + 1)
    dt = np.minimum(t[idx], b) - np.maximum(starts[idx], a)
    keep = dt > 0.0
    return idx[keep], dt[keep]


def covering_sample(t: np.ndarray, t_ping: float | np.ndarray) -> np.ndarray:
    """Index of the IMU sample whose interval contains each ping time (the last one past the end)."""
    return np.minimum(np.searchsorted(t, t_ping, side="left"), len(t) - 1)
