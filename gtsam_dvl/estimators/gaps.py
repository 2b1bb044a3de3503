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

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.estimators.selection import imu_pieces

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
        return {"count": len(self), "total_s": self.total_s,
                "longest_s": float(np.max(self.end - self.start)) if len(self) else 0.0}


def nominal_period(t: np.ndarray) -> float:
    """Median spacing of the stamps, s (0.01 when there are fewer than two)."""
    return float(np.median(np.diff(t))) if len(t) > 1 else 0.01


def find_gaps(t: np.ndarray, gap_samples: float, period_s: float | None = None) -> Gaps:
    """Spacings longer than gap_samples nominal periods (module doc)."""
    period = nominal_period(t) if period_s is None else period_s
    dt = np.diff(t)
    k = np.flatnonzero(dt > gap_samples * period) + 1  # first sample after each gap
    return Gaps(period, t[k - 1].astype(float), (t[k] - period).astype(float), (k - 1).astype(int))


def check_gaps(gaps: Gaps, cfg: ImuConfig, source: str = "") -> None:
    """GtsamDvlError naming the first gap longer than cfg.max_gap_s (a hold that long is no motion model: over a
    30 s gap in a turn its error is systematic and the white-noise covariance of hold_covariance too small)."""
    long = np.flatnonzero(gaps.end - gaps.start > cfg.max_gap_s)
    if len(long):
        j = int(long[0])
        raise GtsamDvlError(
            f"{source + ': ' if source else ''}IMU gap of {gaps.end[j] - gaps.start[j]:.1f} s at "
            f"{gaps.start[j]:.2f}-{gaps.end[j]:.2f} s ({len(long)} gap(s) longer than imu.max_gap_s = "
            f"{cfg.max_gap_s:g} s): cut the log there and process the pieces, or raise imu.max_gap_s")


def sample_starts_with_gaps(t: np.ndarray, gaps: Gaps) -> np.ndarray:
    """Start of each sample's interval: the previous stamp, or one nominal period before its own stamp after a
    gap (and for the first sample)."""
    if len(t) == 0:
        return np.zeros(0)
    starts = np.concatenate([[t[0] - gaps.period_s], t[:-1]])
    starts[gaps.index + 1] = gaps.end
    return starts


def pieces_with_holds(t: np.ndarray, starts: np.ndarray, gaps: Gaps, a: float,
                      b: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The pieces of (a, b] in time order: (sample index, duration s) of the samples covering it, with each
    gap's overlap as a piece of the sample held across it; and the held time, s."""
    idx, dt = imu_pieces(t, starts, a, b)
    if len(gaps) == 0:
        return idx, dt, 0.0
    lo = np.maximum(gaps.start, a)
    hi = np.minimum(gaps.end, b)
    inside = np.flatnonzero(hi > lo)
    if len(inside) == 0:
        return idx, dt, 0.0
    hold_idx = gaps.index[inside]
    hold_dt = (hi - lo)[inside]
    # a held piece goes after every piece of its sample and before the next sample's
    at = np.searchsorted(idx, hold_idx, side="right")
    return np.insert(idx, at, hold_idx), np.insert(dt, at, hold_dt), float(hold_dt.sum())


def hold_covariance(cfg: ImuConfig, held_s: float, interval_s: float) -> np.ndarray:
    """(9, 9) covariance added to an interval whose motion was held for held_s of its interval_s seconds,
    in the order of GTSAM's preintegration error [rotation, position, velocity] (also the EKF's blocks):
    rotation sigma w T, velocity a T + g w T^2 / 2, position a T^2 / 2 + g w T^3 / 6 (T = held_s), and the
    velocity error carried over the rest of the interval into the position."""
    if held_s <= 0:
        return np.zeros((9, 9))
    w = np.radians(cfg.gap_rate_sigma_deg_s)
    a = cfg.gap_accel_sigma_m_s2
    T = held_s
    rest = max(interval_s - held_s, 0.0)
    sig_rot = w * T
    sig_vel = a * T + G0 * w * T**2 / 2.0
    sig_pos = a * T**2 / 2.0 + G0 * w * T**3 / 6.0 + sig_vel * rest
    return np.diag(np.repeat([sig_rot**2, sig_pos**2, sig_vel**2], 3))


FILLER_MARGIN_S = 2.0  # the online estimator waits this long for a late ping before adding a state without one


def filler_due(t_last: float, t_next_ping: float | None, t_imu_end: float, max_spacing_s: float) -> float | None:
    """The time of the state to add after the state at t_last (None: none), given the next usable ping known
    (None: none known yet) and how far the IMU reaches: due when the next ping is later than 1.5 max_spacing_s
    after t_last, or, with no next ping known, when the IMU reaches FILLER_MARGIN_S past that."""
    limit = t_last + 1.5 * max_spacing_s
    t_filler = t_last + max_spacing_s
    if t_next_ping is not None:
        return t_filler if t_next_ping > limit and t_imu_end >= t_filler else None
    return t_filler if t_imu_end >= limit + FILLER_MARGIN_S else None


def with_fillers(ping_t: np.ndarray, t_imu_end: float, max_spacing_s: float) -> tuple[np.ndarray, np.ndarray]:
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
