"""A first guess of the DVL-IMU time offset dt_d from the data alone, before any solve (docs/conventions.md: the ping
stamped t measures the velocity at t + dt_d).

The DVL's velocity changes between consecutive pings are matched against the IMU's integrated acceleration over the
same stretch of time shifted by a candidate dt, for every dt on a grid of GRID_STEP_S within +- SEARCH_S of the
prior's mean; the dt of the least squared misfit wins (a cross-correlation of the two velocity-change series):

    n_v_dvl(t_k; dt) = n_R_b(t_k + dt) b_R_d0 y_k                     (scale 1, the nominal mounting)
    dv_imu(t_k; dt)  = integral over [t_k + dt, t_k+1 + dt] of (n_R_b b_f + n_g) ds
    J(dt) = sum_k | n_v_dvl(t_k+1; dt) - n_v_dvl(t_k; dt) - dv_imu(t_k; dt) |^2

n_R_b from the alignment carried with the gyros (Earth rate removed, as Alignment.at), n_g gravity at the map origin.
What the guess cannot see cancels in the difference or is constant in dt: the velocity's unknown start, the
accelerometer bias and the gravity leak of a small attitude error (a constant shift of every difference), the scale
and misalignment (a few tenths of a percent of each change); the Coriolis term (3e-4 m/s^2) is left out. The
vehicle's own accelerations (turns, speed changes, heave and the hull's slow motions) carry the timing.

Why by hand: the objective is the estimators' own velocity model evaluated at a few hundred shifts, a few numpy
array operations; no library function computes a lag between a velocity and an integrated specific force in a
rotating frame. The guess is used only where the data support it (a drop of J by more than MIN_EVIDENCE times the
residual variance from the prior's mean, and not at the grid's edge); else the prior's mean stands. It sets the
offset's initial value and the first centre of its IMU windows, never its prior.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from gtsam_dvl.factors.so3 import exp as so3_exp

SEARCH_S = 2.0  # the guess is searched within +- this of the prior's mean (DVL clocks seen 1 s off, ROS stamps 0.3 s)
GRID_STEP_S = 0.02  # one IMU sample at 50 Hz; the solve refines it
# the first minutes of the log: enough pairs, and the attitude integration stays cheap
MAX_SPAN_S = 600.0
# J must drop by this many residual variances from the prior's mean to the best dt (a 3-sigma likelihood ratio)
MIN_EVIDENCE = 9.0
MIN_PAIRS = 30


@dataclass(frozen=True)
class OffsetGuess:
    """The first guess guess_s (s) of the DVL time offset, whether the data supported it (used: else guess_s is the
    prior's mean), the misfit's drop in residual variances (evidence), the pairs of pings used and the reason in
    words (as_dict: info["time_offset_centring"]["guess"], the same names)."""

    guess_s: float
    used: bool
    evidence: float
    pairs: int
    why: str

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def attitudes(
    t: np.ndarray, b_omega: np.ndarray, n_R_b0: np.ndarray, n_omega_ie: np.ndarray
) -> np.ndarray:
    """n_R_b (K, 3, 3) at the samples t (K,) by the gyros b_omega (K, 3) rad/s from n_R_b0 at t[0], in the
    Earth-fixed map frame (n_R_b(t + h) = Exp(-n_omega_ie h) n_R_b(t) Exp(b_omega h))."""
    h = np.diff(t, prepend=t[0])
    body = so3_exp(b_omega * h[:, None])  # (K, 3, 3); the first is the identity
    earth = so3_exp(-np.outer(h, n_omega_ie))
    out = np.empty((len(t), 3, 3))
    R = np.asarray(n_R_b0, dtype=float)
    for k in range(len(t)):  # sequential by nature; K <= MAX_SPAN_S x the IMU rate
        R = earth[k] @ R @ body[k]
        out[k] = R
    return out


def guess_offset(
    imu_t: np.ndarray,
    b_omega: np.ndarray,
    b_f: np.ndarray,
    n_R_b0: np.ndarray,
    t_ref: float,
    dvl_t: np.ndarray,
    d_v: np.ndarray,
    b_R_d0: np.ndarray,
    n_g: np.ndarray,
    n_omega_ie: np.ndarray,
    prior_s: float,
) -> OffsetGuess:
    """The first guess of dt_d (module doc) from IMU samples (base_link: stamps s, gyro rad/s, specific force
    m/s^2), the attitude n_R_b0 at t_ref (s), bottom-track pings (stamps s, velocity in dvl_link m/s; usable ones
    only), the nominal mounting b_R_d0, gravity n_g (m/s^2, map) and Earth rate (rad/s, map); prior_s the offset
    prior's mean."""
    lo_t = max(float(imu_t[0]), float(t_ref))
    sel = (imu_t >= lo_t) & (imu_t <= lo_t + MAX_SPAN_S + 2.0 * SEARCH_S)
    t, w, f = imu_t[sel], b_omega[sel], b_f[sel]
    if len(t) < 10:
        return OffsetGuess(prior_s, False, 0.0, 0, "too few IMU samples for a first guess")
    reach = SEARCH_S + abs(prior_s)  # every shifted stamp inside the IMU's samples
    keep = (dvl_t >= t[0] + reach) & (dvl_t <= t[-1] - reach)
    dvl_t, d_v = dvl_t[keep], d_v[keep]
    if len(dvl_t) < MIN_PAIRS + 1:
        return OffsetGuess(prior_s, False, 0.0, 0, "too few pings for a first guess")
    n_R_b = attitudes(t, w, n_R_b0, n_omega_ie)
    n_a = np.einsum("kij,kj->ki", n_R_b, f) + n_g
    # the velocity change from t[0] at every sample (trapezoid), interpolated at any time
    V = np.concatenate(
        [np.zeros((1, 3)), np.cumsum(0.5 * (n_a[1:] + n_a[:-1]) * np.diff(t)[:, None], axis=0)]
    )
    gap = np.diff(dvl_t)
    pair = gap < 1.5 * float(np.median(gap))  # consecutive pings only
    if pair.sum() < MIN_PAIRS:
        return OffsetGuess(
            prior_s, False, 0.0, int(pair.sum()), "too few consecutive pings for a first guess"
        )
    b_v = d_v @ np.asarray(b_R_d0, dtype=float).T
    grid = prior_s + np.arange(-SEARCH_S, SEARCH_S + 0.5 * GRID_STEP_S, GRID_STEP_S)
    cost = np.array([_misfit(dt, t, n_R_b, V, dvl_t, b_v, pair) for dt in grid])
    best = int(np.argmin(cost))
    at_prior = int(np.argmin(np.abs(grid - prior_s)))
    n_rows = 3 * int(pair.sum())
    var = cost[best] / max(n_rows - 1, 1)
    evidence = float((cost[at_prior] - cost[best]) / var) if var > 0 else 0.0
    dt = float(grid[best])
    if best in (0, len(grid) - 1):
        return OffsetGuess(
            prior_s,
            False,
            evidence,
            int(pair.sum()),
            f"the misfit is least at the search's edge ({dt:+.2f} s): the prior's mean stands",
        )
    if not evidence > MIN_EVIDENCE:
        return OffsetGuess(
            prior_s,
            False,
            evidence,
            int(pair.sum()),
            f"the data barely prefer {dt:+.2f} s (evidence {evidence:.1f} < {MIN_EVIDENCE:g}): "
            "the prior's mean stands",
        )
    return OffsetGuess(
        dt,
        True,
        evidence,
        int(pair.sum()),
        f"DVL velocity changes match the IMU's best {dt:+.2f} s later (evidence {evidence:.0f})",
    )


def _misfit(
    dt: float,
    t: np.ndarray,
    n_R_b: np.ndarray,
    V: np.ndarray,
    dvl_t: np.ndarray,
    b_v: np.ndarray,
    pair: np.ndarray,
) -> float:
    """J(dt) of the module doc."""
    ts = dvl_t + dt
    k = np.clip(np.searchsorted(t, ts), 1, len(t) - 1)
    # the nearest sample's attitude
    k = np.where(np.abs(t[k - 1] - ts) < np.abs(t[k] - ts), k - 1, k)
    n_v = np.einsum("kij,kj->ki", n_R_b[k], b_v)
    v_imu = np.stack([np.interp(ts, t, V[:, a]) for a in range(3)], axis=1)
    r = (n_v[1:] - n_v[:-1]) - (v_imu[1:] - v_imu[:-1])
    r = r[pair]
    # a constant shift (bias, gravity leak of the attitude error) tells nothing of dt
    r = r - r.mean(axis=0)
    return float(np.sum(r * r)) if math.isfinite(float(np.sum(r * r))) else math.inf
