"""Initialisation without the truth: the map frame, static-segment detection and the initial attitude.

align() takes the initial attitude (AlignmentConfig.method "auto": the first that applies) from
1. an attitude sensor in the log (LogData.attitude: an IMU's own orientation, an AHRS, an INS; io/attitude.py
   turns it into base_link in map), its first sample, with the sensor's covariance (or
   alignment.attitude_sigma_deg when it gives none);
2. the configuration (alignment.initial_attitude_deg);
3. coarse alignment on an initial static segment of at least alignment.min_static_s: roll and pitch from the
   mean specific force (it points up in a static body), heading from gyrocompassing (the horizontal part of
   the measured Earth rate points north);
4. in-motion alignment with DVL aiding over the first alignment.in_motion_window_s (in_motion_alignment).

In-motion alignment (optimisation-based alignment in inertial frames, Li et al. 2013 / Wu & Pan's velocity
integration formula, with the DVL giving the velocity). Frames: n0 and b0 are the inertial frames that
coincide with map and base_link at t_ref, the first IMU sample. The map frame is Earth-fixed, so
n0_R_n(t) = Exp(n_omega_ie t) exactly, and the gyros give b0_R_b(t) (they measure the inertial rate). The
unknown is the constant C = n0_R_b0 = n_R_b(t_ref). In the Earth-fixed map frame
    d/dt n_v = n_R_b b_f - 2 n_omega_ie x n_v + n_g(n_p)
(n_g normal gravity, with the centrifugal part). With n0_R_n n_v = C b0_R_b b_v and n0_R_n n_omega_ie x n_v =
n_omega_ie x (C b0_R_b b_v), integrating from t_ref to t gives
    C alpha(t) = beta(t) + c,
    alpha(t) = int b0_R_b b_f dt - b0_R_b(t) b_v(t),
    beta(t)  = -int n0_R_n n_g dt + n_omega_ie x (C int b0_R_b b_v dt),
    c        = -C b_v(t_ref)  (a constant; taken as unknown, so that no single ping sets it)
with b_v = b_R_d0 d_y - b_omega x b_l the DVL velocity at the IMU (nominal scale 1 and mounting: the
calibration is not known yet; its errors, 1e-4 and 0.5 deg, act like a DVL noise of 1-2 cm/s). alpha and beta
are formed at every valid ping of the window; eliminating c by centring both sets leaves a Wahba problem
solved in closed form by SVD. The gravity direction turning with the Earth (4.5 m/s over 120 s at latitude
30 deg, against a DVL noise of 2 cm/s) gives the heading, the gravity integral roll and pitch. The terms with C
(Coriolis and the position of gravity along the track) are evaluated with the previous solution: three passes,
pings with residuals beyond IN_MOTION_OUTLIER_SIGMAS dropped after the first.
Accuracy: sigma^2 (sum |beta~|^2 I - beta~ beta~^T)^-1 about map axes, sigma^2 from the residuals, plus the
bias floors: roll/pitch accel_bias / g; heading gyro_bias / (omega_ie cos lat) and accel_bias tan(lat) / g
(the errors of gyrocompassing). Measured on a simulated navigation-grade run starting at 2 m/s with turns
(0.01 deg/h, 50 micro-g, 2 cm/s DVL; tests/estimators/test_alignment_motion.py): see that test's numbers.

The given initial state means the log's first IMU stamp: the configured attitude, the in-motion alignment's
and the map origin (the vehicle's position then). first_state carries them to the first state, the first
usable ping, which may come later (a log that starts underway, DVL stamps offset, unusable first pings):
n_R_b(t1) = Exp(-n_omega_ie (t1 - t0)) n_R_b(t0) prod_k Exp(b_omega_k dt_k) (Alignment.at) and the position
by the first ping's body velocity turned with that attitude; the prior covariance grows by the gyro noise
and bias over the interval and by the velocity error times it, and the attitude error turns the distance
travelled (tests/estimators/test_initial_state.py). The batch smoother, the online estimator and the EKF all
start from it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from gtsam_dvl.core.config import AlignmentConfig, EstimatorConfig, ImuConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import (
    quat_xyzw_to_matrix,
    rpy_deg_to_matrix,
    rpy_to_matrix,
    skew,
    so3_exp,
    so3_log,
)
from gtsam_dvl.core.types import AttitudeData, DvlData, ImuData, LogData, Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG

METHODS = ("attitude_topic", "configured", "static", "in_motion")
ATTITUDE_SOURCES = (
    "an attitude topic (--attitude-topic: sensor_msgs/msg/Imu, nav_msgs/msg/Odometry or "
    "geometry_msgs/msg/PoseWithCovarianceStamped; or the IMU's own orientation), "
    "alignment.initial_attitude_deg, or a static start"
)


@dataclass
class Alignment:
    """Initial attitude of base_link in map. Static and configured: the attitude of the whole static segment
    (up to t_static_end) or at the log's first IMU stamp. Attitude sensor and in motion: the attitude at t_ref,
    which at() carries to another time with the gyros (first_state: to the first state, with its sigmas)."""

    n_R_b: np.ndarray
    t_static_end: float  # end of the detected static segment, s (0 when none was used)
    method: str  # one of METHODS
    b_f_mean: np.ndarray | None = None  # mean specific force on the static segment, m/s^2
    b_omega_mean: np.ndarray | None = None  # mean gyro on the static segment, rad/s
    # 1-sigma attitude accuracy about map axes [east (roll-like), north (pitch-like), up (yaw)], deg; None:
    # the prior sigmas of [priors] (static and configured)
    sigma_rpy_deg: np.ndarray | None = None
    t_ref: float | None = None  # time n_R_b refers to, s; None: constant (static, configured)
    window_s: float = 0.0  # in motion: the window used, s

    def info(self) -> dict[str, Any]:
        """What the results report (NavResult.info["alignment"], the summary)."""
        return {
            "method": self.method,
            "t_static_end": self.t_static_end,
            "sigma_rpy_deg": None
            if self.sigma_rpy_deg is None
            else [float(v) for v in self.sigma_rpy_deg],
            "t_ref": self.t_ref,
            "window_s": self.window_s,
        }

    def at(self, t: float, imu: ImuData, frame: LocalFrame) -> Alignment:
        """This alignment carried to time t (s) with the gyros (imu in base_link); itself when it has no
        t_ref. In the Earth-fixed map frame n_R_b(t) = Exp(-n_omega_ie (t - t_ref)) n_R_b(t_ref) b_ref_R_b(t),
        exactly (no transport rate)."""
        if self.t_ref is None or t == self.t_ref:
            return self
        a, b = sorted((self.t_ref, t))
        R = body_rotation(imu, a, b)
        if t < self.t_ref:
            R = R.T
        E = so3_exp(-frame.n_omega_ie * (t - self.t_ref))
        return replace(self, n_R_b=E @ self.n_R_b @ R, t_ref=float(t))


def map_frame_of(log: LogData, config: EstimatorConfig) -> LocalFrame:
    """The map origin: from the configuration if given, else the log's (LogData.origin)."""
    a = config.alignment
    if a.origin_lat_deg is not None:
        return LocalFrame(a.origin_lat_deg, a.origin_lon_deg or 0.0, a.origin_height_m or 0.0)
    if log.origin is None:
        raise GtsamDvlError(
            f"{log.source or 'log'}: no map origin in the log; set alignment.origin_lat_deg "
            "(and lon, height) in the configuration: Earth rate and gravity need the latitude"
        )
    return LocalFrame(log.origin.lat_deg, log.origin.lon_deg, log.origin.height_m)


STATIC_MARGIN_S = 5.0  # the static segment ends this long before motion is first detected
# The DVL shows motion from the first valid ping faster than alignment.dvl_speed_threshold_m_s that starts a
# run of DVL_MOTION_PINGS valid pings (fewer at the end of the data, but at least DVL_MOTION_MIN_PINGS) of
# which at least DVL_MOTION_FRACTION are that fast: a vehicle that moves keeps moving, an outlier does not
# repeat. 1 % of gross outliers put 8 of 10 in a row with probability 5e-15 per ping, 5 % with 2e-9.
DVL_MOTION_PINGS = 10
DVL_MOTION_FRACTION = 0.8
DVL_MOTION_MIN_PINGS = 3


def window_means(
    t: np.ndarray, x: np.ndarray, window_s: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Means of x over consecutive windows of window_s seconds; returns (window end times, means). A window's
    end is its nominal end, or the last sample's time for the last window (the data end there)."""
    idx = np.floor((t - t[0]) / window_s).astype(int)
    n = int(idx[-1]) + 1
    sums = np.zeros((n, x.shape[1]))
    np.add.at(sums, idx, x)
    counts = np.bincount(idx, minlength=n)[:, None]
    ok = counts[:, 0] > 0
    ends = np.minimum(t[0] + (np.arange(n) + 1) * window_s, t[-1])
    return ends[ok], sums[ok] / counts[ok]


def dvl_motion_start(dvl: DvlData, speed_threshold_m_s: float) -> float | None:
    """Stamp of the first valid ping from which the DVL shows motion (DVL_MOTION_PINGS: a run of pings
    mostly faster than speed_threshold_m_s, so that single outliers do not count), None if it never does."""
    ok = dvl.valid & np.isfinite(dvl.d_v).all(axis=1)
    t = dvl.t[ok]
    fast = np.linalg.norm(dvl.d_v[ok], axis=1) > speed_threshold_m_s
    n = len(t)
    if n == 0 or not fast.any():
        return None
    counts = np.concatenate([[0], np.cumsum(fast)])
    start = np.arange(n)
    stop = np.minimum(start + DVL_MOTION_PINGS, n)
    size = stop - start
    moving = (
        fast
        & (size >= DVL_MOTION_MIN_PINGS)
        & (counts[stop] - counts[start] >= DVL_MOTION_FRACTION * size)
    )
    return float(t[np.argmax(moving)]) if moving.any() else None


def detect_static_end(imu: ImuData, dvl: DvlData, cfg: AlignmentConfig) -> float:
    """End time (s) of the static segment at the start of the log; 0 when the log starts moving. Motion is
    the IMU's 1 s means leaving the first 10 s's by the thresholds, or the DVL showing motion
    (dvl_motion_start: a single fast ping, a gross outlier, neither ends nor aborts the segment); the
    segment ends STATIC_MARGIN_S before the earlier of the two."""
    ends, f_means = window_means(imu.t, imu.b_f)
    _, w_means = window_means(imu.t, imu.b_omega)
    n_ref = max(1, min(10, len(ends)))
    f_ref, w_ref = f_means[:n_ref].mean(axis=0), w_means[:n_ref].mean(axis=0)
    moving = (np.linalg.norm(f_means - f_ref, axis=1) > cfg.accel_threshold_m_s2) | (
        np.degrees(np.linalg.norm(w_means - w_ref, axis=1)) > cfg.gyro_threshold_deg_s
    )
    t_end = float(ends[np.argmax(moving)] - STATIC_MARGIN_S) if moving.any() else float(ends[-1])
    t_dvl = dvl_motion_start(dvl, cfg.dvl_speed_threshold_m_s)
    if t_dvl is not None:
        t_end = min(t_end, t_dvl - STATIC_MARGIN_S)
    if cfg.max_static_s > 0:
        t_end = min(t_end, float(imu.t[0]) + cfg.max_static_s)
    return t_end if t_end > imu.t[0] else float(imu.t[0])


# Gyrocompassing needs the horizontal Earth rate well above the gyro bias: the heading error is about
# bias / horizontal rate (rad). Below 0.1 deg/h (latitudes beyond 89.6 deg) even a navigation-grade 0.01 deg/h
# bias turns the heading by more than 0.1 rad, so there the heading must be given.
GYROCOMPASS_MIN_HORIZONTAL_RATE_RAD_S = 0.1 * DEG_PER_H


def coarse_alignment(b_f: np.ndarray, b_omega: np.ndarray, frame: LocalFrame) -> np.ndarray:
    """n_R_b from mean static specific force b_f (m/s^2) and gyro b_omega (rad/s), at the map origin."""
    roll = np.arctan2(b_f[1], b_f[2])
    pitch = np.arctan2(-b_f[0], np.hypot(b_f[1], b_f[2]))
    l_R_b_level = rpy_to_matrix(float(roll), float(pitch), 0.0)  # heading still unknown
    w_level = l_R_b_level @ b_omega  # = Rz(yaw)^T n_omega_ie
    yaw = np.arctan2(w_level[0], w_level[1])
    horizontal_rate = float(np.linalg.norm(frame.n_omega_ie[:2]))
    if (
        np.hypot(w_level[0], w_level[1]) < 0.2 * horizontal_rate
        or horizontal_rate < GYROCOMPASS_MIN_HORIZONTAL_RATE_RAD_S
    ):
        raise GtsamDvlError(
            "gyrocompassing failed: the horizontal Earth rate is not visible in the gyros "
            "(IMU too noisy, or latitude near a pole); give alignment.initial_attitude_deg"
        )
    return rpy_to_matrix(float(roll), float(pitch), float(yaw))


def _pieces(imu: ImuData, a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """IMU samples covering (a, b] and the seconds of each inside it (sample k covers (t[k-1], t[k]])."""
    from gtsam_dvl.estimators.inputs.selection import imu_pieces, sample_starts

    return imu_pieces(imu.t, sample_starts(imu.t), a, b)


def body_rotation(imu: ImuData, a: float, b: float) -> np.ndarray:
    """b(a)_R_b(b): the body's rotation from time a to b >= a (s) relative to inertial space, from the gyros."""
    idx, dt = _pieces(imu, a, b)
    R = np.eye(3)
    for D in so3_exp(imu.b_omega[idx] * dt[:, None]):
        R = R @ D
    return R


def _attitude_alignment(att: AttitudeData, imu: ImuData, cfg: AlignmentConfig) -> Alignment:
    """The first sample of the attitude sensor at or after the first IMU sample (the last one before it if
    none), with its covariance turned into map axes (or alignment.attitude_sigma_deg if it has none)."""
    ok = np.isfinite(att.n_q_b).all(axis=1) & (np.linalg.norm(att.n_q_b, axis=1) > 0.5)
    if not ok.any():
        raise GtsamDvlError(f"attitude source {att.source or '?'} has no valid orientation")
    idx = np.flatnonzero(ok)
    after = idx[att.t[idx] >= imu.t[0]]
    k = int(after[0]) if len(after) else int(idx[-1])
    n_R_b = quat_xyzw_to_matrix(att.n_q_b[k] / np.linalg.norm(att.n_q_b[k]))
    cov = att.cov_rad2[k]
    if np.isfinite(cov).all() and np.all(np.linalg.eigvalsh(0.5 * (cov + cov.T)) > 0):
        sigma = np.degrees(np.sqrt(np.diag(n_R_b @ cov @ n_R_b.T)))  # body axes -> map axes
    else:
        rp, yaw = cfg.attitude_sigma_deg
        sigma = np.array([rp, rp, yaw], dtype=float)
    return Alignment(n_R_b, 0.0, "attitude_topic", sigma_rpy_deg=sigma, t_ref=float(att.t[k]))


# In-motion alignment (module doc): pings whose Wahba residual exceeds this many sigmas are dropped after the
# first pass; at least IN_MOTION_MIN_PINGS valid pings are needed; a heading sigma beyond
# IN_MOTION_MAX_YAW_SIGMA_DEG (the default yaw prior of the graph, [priors] yaw_sigma_deg) is refused: the
# heading is then not known well enough for a linearisation point.
IN_MOTION_OUTLIER_SIGMAS = 5.0
IN_MOTION_MIN_PINGS = 10
IN_MOTION_MAX_YAW_SIGMA_DEG = 5.0
IN_MOTION_PASSES = 3


def _body_integrals(
    imu: ImuData,
    sel: np.ndarray,
    tk: np.ndarray,
    j: np.ndarray,
    s: np.ndarray,
    d_omega: np.ndarray,
    d_f: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """b0_R_b on the grid tk, and b0_R_b and int b0_R_b b_f dt at the pings (in grid step j, s seconds into
    it), from the samples sel with the gyro and the accelerometer offset by d_omega (rad/s) and d_f (m/s^2)
    (zero, or a bias to see what it does)."""
    dt = np.diff(tk)
    w, f = imu.b_omega[sel] + d_omega, imu.b_f[sel] + d_f
    D, half = so3_exp(w * dt[:, None]), so3_exp(w * (0.5 * dt)[:, None])
    R = np.empty((len(tk), 3, 3))
    R[0] = np.eye(3)
    for i in range(len(sel)):
        R[i + 1] = R[i] @ D[i]
    V = np.vstack(
        [np.zeros(3), np.cumsum(np.einsum("kij,kjl,kl->ki", R[:-1], half, f) * dt[:, None], axis=0)]
    )
    Rp = R[j - 1] @ so3_exp(w[j - 1] * s[:, None])
    Vp = V[j - 1] + (V[j] - V[j - 1]) * (s / dt[j - 1])[:, None]
    return R, Rp, Vp


def in_motion_alignment(
    imu: ImuData,
    dvl: DvlData,
    frame: LocalFrame,
    mounting: Mounting,
    window_s: float,
    imu_cfg: ImuConfig | None = None,
) -> Alignment:
    """n_R_b at the first IMU sample from the IMU (in base_link) and the DVL over the first window_s seconds
    while moving (module doc: velocity integration in inertial frames, a centred Wahba problem solved by
    SVD). Accuracy in Alignment.sigma_rpy_deg: the fit's covariance plus what a 1-sigma bias of imu_cfg
    (defaults if None) on each gyro and accelerometer axis does to the solution."""
    imu_cfg = imu_cfg or ImuConfig()
    t_ref, t_end, sel, pings = _alignment_window(imu, dvl, window_s)
    tk = np.concatenate([[t_ref], imu.t[sel]])  # grid: the first sample, then each sample's end
    tp = dvl.t[pings]
    # grid step (tk[j-1], tk[j]] holding tp
    j = np.clip(np.searchsorted(tk, tp, side="left"), 1, len(tk) - 1)
    s = tp - tk[j - 1]
    zero = np.zeros(3)
    _, Rp, Vp = _body_integrals(imu, sel, tk, j, s, zero, zero)
    w = imu.b_omega[sel[j - 1]]
    # at the IMU (w ~ rate vs map)
    b_v = dvl.d_v[pings] @ mounting.b_R_d0.T - np.cross(w, mounting.b_l)
    q = np.einsum("kij,kj->ki", Rp, b_v)  # body velocity in b0 at the pings
    alpha = Vp - q
    # body velocity in b0 on the grid (linear between pings, held outside) and its integral
    q_grid = np.column_stack([np.interp(tk, tp, q[:, a]) for a in range(3)])
    P = np.vstack(
        [np.zeros(3), np.cumsum(0.5 * (q_grid[1:] + q_grid[:-1]) * np.diff(tk)[:, None], axis=0)]
    )
    beta, use = _gravity_passes(frame, tk, tp, P, alpha)
    C, sigma2 = _centred_wahba(alpha[use], beta[use])
    cov = _alignment_covariance(
        imu, imu_cfg, _BiasedIntegrals(sel, tk, j, s, b_v), beta[use], use, C, sigma2
    )
    sigma = np.degrees(np.sqrt(np.diag(cov)))
    if not sigma[2] <= IN_MOTION_MAX_YAW_SIGMA_DEG:
        raise GtsamDvlError(
            f"in-motion alignment over {t_end - t_ref:.0f} s gives the heading only to "
            f"{sigma[2]:.1f} deg (1 sigma; gyrocompassing needs the Earth rate well above the gyro "
            f"bias and the DVL noise); give {ATTITUDE_SOURCES}"
        )
    return Alignment(C, 0.0, "in_motion", sigma_rpy_deg=sigma, t_ref=t_ref, window_s=t_end - t_ref)


def _alignment_window(
    imu: ImuData, dvl: DvlData, window_s: float
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """The in-motion alignment's window from the first IMU sample: its start and end (s), the IMU samples after
    the start and the valid DVL pings in it; a GtsamDvlError when either is too few."""
    t_ref = float(imu.t[0])
    t_end = min(t_ref + window_s, float(imu.t[-1]))
    sel = np.flatnonzero((imu.t > t_ref) & (imu.t <= t_end))
    if len(sel) < 2 or np.any(np.diff(imu.t[sel]) <= 0):
        raise GtsamDvlError("in-motion alignment: too few IMU samples, or stamps not increasing")
    ok = dvl.valid & np.isfinite(dvl.d_v).all(axis=1) & (dvl.t >= t_ref) & (dvl.t <= t_end)
    pings = np.flatnonzero(ok)
    if len(pings) < IN_MOTION_MIN_PINGS:
        raise GtsamDvlError(
            f"in-motion alignment: only {len(pings)} valid DVL pings in the first "
            f"{t_end - t_ref:.0f} s (needs {IN_MOTION_MIN_PINGS}); give {ATTITUDE_SOURCES}"
        )
    return t_ref, t_end, sel, pings


def _gravity_passes(
    frame: LocalFrame, tk: np.ndarray, tp: np.ndarray, P: np.ndarray, alpha: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The inertial-frame vectors beta (gravity's integral, and the Earth rate's effect on the track) at the
    pings' times tp, refined over IN_MOTION_PASSES passes as the attitude places the track (gravity along it),
    and the pings kept (outliers of the fit dropped). tk: the IMU grid, P: the track's integral in b0 on it."""
    t_ref = tk[0]
    Pp = np.column_stack([np.interp(tp, tk, P[:, a]) for a in range(3)])
    w_ie = frame.n_omega_ie
    n0_R_n = so3_exp(w_ie[None, :] * (tk - t_ref)[:, None])
    # gravity along the track, on a coarser grid (it changes by 1e-4 per km)
    step = max(1, len(tk) // 2000)
    coarse = np.r_[np.arange(0, len(tk), step), len(tk) - 1]
    C = np.eye(3)
    use = np.ones(len(tp), bool)
    for n_pass in range(IN_MOTION_PASSES):
        # map position (n_R_n0 ~ I: 2e-2 rad)
        n_p = P[coarse] @ C.T if n_pass else np.zeros((len(coarse), 3))
        g_c = frame.n_gravity(n_p)
        n_g = np.column_stack([np.interp(tk, tk[coarse], g_c[:, a]) for a in range(3)])
        g0 = np.einsum("kij,kj->ki", n0_R_n, n_g)
        G = np.vstack(
            [np.zeros(3), np.cumsum(0.5 * (g0[1:] + g0[:-1]) * np.diff(tk)[:, None], axis=0)]
        )
        Gp = np.column_stack([np.interp(tp, tk, G[:, a]) for a in range(3)])
        beta = -Gp + (np.cross(w_ie, Pp @ C.T) if n_pass else 0.0)
        C, sigma2 = _centred_wahba(alpha[use], beta[use])
        full = beta - (alpha - alpha[use].mean(axis=0)) @ C.T - beta[use].mean(axis=0)
        use = np.linalg.norm(full, axis=1) <= IN_MOTION_OUTLIER_SIGMAS * np.sqrt(3.0 * sigma2)
        if use.sum() < IN_MOTION_MIN_PINGS:
            raise GtsamDvlError(
                "in-motion alignment: the DVL and the IMU disagree (most pings are outliers); "
                f"give {ATTITUDE_SOURCES}"
            )
    return beta, use


@dataclass
class _BiasedIntegrals:
    """What _body_integrals needs to integrate the IMU again with a bias: the samples, the grid, each ping's
    grid step and time into it, and the pings' body velocities b_v (m/s, base_link)."""

    sel: np.ndarray
    tk: np.ndarray
    j: np.ndarray
    s: np.ndarray
    b_v: np.ndarray


def _alignment_covariance(
    imu: ImuData,
    imu_cfg: ImuConfig,
    grid: _BiasedIntegrals,
    beta_used: np.ndarray,
    use: np.ndarray,
    C: np.ndarray,
    sigma2: float,
) -> np.ndarray:
    """The attitude's covariance (rad^2, map axes n0 at t_ref): the Wahba fit's, plus the rotation a 1-sigma
    bias of imu_cfg on each gyro and accelerometer axis gives the solution."""
    bt = beta_used - beta_used.mean(axis=0)
    # map axes (n0 at t_ref)
    cov = np.linalg.inv((np.einsum("ki,ki->", bt, bt) * np.eye(3) - bt.T @ bt) / sigma2)
    # what a 1-sigma bias on each axis does (the biases are unknown constants, not noise: they add in full)
    for k, sig in [(k, imu_cfg.gyro_bias_sigma_deg_per_h * DEG_PER_H) for k in range(3)] + [
        (k + 3, imu_cfg.accel_bias_sigma_ug * UG) for k in range(3)
    ]:
        d = np.zeros(6)
        d[k] = sig
        _, Rp_b, Vp_b = _body_integrals(imu, grid.sel, grid.tk, grid.j, grid.s, d[:3], d[3:])
        alpha_b = Vp_b - np.einsum("kij,kj->ki", Rp_b, grid.b_v)
        C_b, _ = _centred_wahba(alpha_b[use], beta_used)
        dth = so3_log(C_b @ C.T)
        cov = cov + np.outer(dth, dth)
    return cov


def _centred_wahba(alpha: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, float]:
    """The rotation C minimising sum |beta~ - C alpha~|^2 over the centred vectors (SVD, Kabsch) and the
    residuals' variance per component (3 rotation and 3 offset parameters taken off)."""
    a, b = alpha - alpha.mean(axis=0), beta - beta.mean(axis=0)
    U, _, Vt = np.linalg.svd(b.T @ a)
    C = U @ np.diag([1.0, 1.0, float(np.linalg.det(U @ Vt))]) @ Vt
    r = b - a @ C.T
    return C, float(np.einsum("ki,ki->", r, r) / max(3 * len(a) - 6, 1))


def align(
    imu: ImuData,
    dvl: DvlData,
    frame: LocalFrame,
    cfg: AlignmentConfig,
    *,
    attitude: AttitudeData | None = None,
    mounting: Mounting | None = None,
    imu_cfg: ImuConfig | None = None,
) -> Alignment:
    """Initial attitude by cfg.method (module doc). "auto": the attitude sensor (attitude), else the
    configured attitude, else coarse alignment on the initial static segment (heading by gyrocompassing,
    refused when the gyro bias would set it: see coarse_alignment), else in-motion alignment with the DVL
    (mounting: the DVL's nominal mounting, identity if None). A forced method that cannot be done is an error.
    imu is in base_link (estimators/inputs/mounting.py)."""
    method = cfg.method
    if method in ("auto", "attitude_topic") and attitude is not None and len(attitude):
        return _attitude_alignment(attitude, imu, cfg)
    if method == "attitude_topic":
        raise GtsamDvlError(
            'alignment.method = "attitude_topic" but the log has no attitude: name one with '
            "--attitude-topic (sensor_msgs/msg/Imu, nav_msgs/msg/Odometry or "
            "geometry_msgs/msg/PoseWithCovarianceStamped), or give the IMU messages an orientation"
        )
    if method == "auto" and cfg.initial_attitude_deg is not None:
        return Alignment(rpy_deg_to_matrix(cfg.initial_attitude_deg), 0.0, "configured")
    if method == "in_motion":
        return in_motion_alignment(
            imu, dvl, frame, mounting or Mounting(), cfg.in_motion_window_s, imu_cfg
        )
    t_end = detect_static_end(imu, dvl, cfg)
    if t_end - imu.t[0] < cfg.min_static_s:
        if method == "auto":
            return in_motion_alignment(
                imu, dvl, frame, mounting or Mounting(), cfg.in_motion_window_s, imu_cfg
            )
        raise GtsamDvlError(
            f"no static segment of at least {cfg.min_static_s:.0f} s at the start of the log (found "
            f'{max(t_end - imu.t[0], 0.0):.0f} s); set alignment.method = "auto" or "in_motion", or give '
            f"{ATTITUDE_SOURCES}"
        )
    sel = imu.t <= t_end
    b_f, b_omega = imu.b_f[sel].mean(axis=0), imu.b_omega[sel].mean(axis=0)
    return Alignment(coarse_alignment(b_f, b_omega, frame), t_end, "static", b_f, b_omega)


@dataclass
class FirstState:
    """The given initial state carried to the first state's time t1 (first_state): attitude n_R_b (base_link in
    map) and position n_p (m, map) at t1, and their prior covariance cov (6x6, map axes: attitude error about map
    axes in rad, then position in m). carried False: nothing was carried (t1 at or before the time they refer
    to); n_p is then the map origin and cov the covariance given."""

    alignment: Alignment  # the alignment at t1 (n_R_b)
    n_p: np.ndarray
    cov: np.ndarray
    carried: bool
    t_from: float  # the time the given attitude / origin referred to, s
    t1: float

    def info(self) -> dict[str, Any]:
        """What the results report (NavResult.info["alignment"]["first_state"])."""
        sig = np.sqrt(np.diag(self.cov))
        return {
            "carried": self.carried,
            "t_from": self.t_from,
            "t1": self.t1,
            "n_p": [float(v) for v in self.n_p],
            "sigma_rpy_deg": [float(v) for v in np.degrees(sig[:3])],
            "position_sigma_m": [float(v) for v in sig[3:]],
        }


def align_log(log: LogData, config: EstimatorConfig) -> tuple[LocalFrame, Alignment]:
    """The map frame of a log in base_link (map_frame_of) and its first state's alignment (align with the log's
    attitude sensor, mounting and the configured IMU)."""
    frame = map_frame_of(log, config)
    alignment = align(
        log.imu,
        log.dvl,
        frame,
        config.alignment,
        attitude=log.attitude,
        mounting=log.mounting,
        imu_cfg=config.imu,
    )
    return frame, alignment


def given_covariance(
    alignment: Alignment, config: EstimatorConfig, *, alignment_sigmas: bool = True
) -> np.ndarray:
    """The prior covariance (6x6, map axes: attitude rad, position m) of the given initial state at its own time:
    the alignment's attitude sigmas when it has them (alignment_sigmas; the EKF keeps [priors]'), else [priors]
    roll_pitch_sigma_deg / yaw_sigma_deg, and [priors] position_sigma_m about the map origin."""
    pri = config.priors
    if alignment_sigmas and alignment.sigma_rpy_deg is not None:
        sig_att = np.radians(np.asarray(alignment.sigma_rpy_deg, dtype=float))
    else:
        sig_att = np.radians(
            [pri.roll_pitch_sigma_deg, pri.roll_pitch_sigma_deg, pri.yaw_sigma_deg]
        )
    return np.diag(np.concatenate([sig_att**2, np.full(3, pri.position_sigma_m**2)]))


def first_state(
    alignment: Alignment,
    imu: ImuData,
    frame: LocalFrame,
    t1: float,
    b_v: np.ndarray | None,
    config: EstimatorConfig,
    velocity_sigma_m_s: float,
    cov0: np.ndarray | None = None,
    t_origin: float | None = None,
) -> FirstState:
    """The given initial attitude and map origin carried to the first state's time t1 (s). They refer to the
    log's first IMU stamp (configured attitude, in-motion alignment; the map origin is where the vehicle is
    then, or at t_origin when given: the first GNSS fix's time when the origin is that fix), to the attitude
    sensor's first sample (its t_ref), or for a static alignment to the end of the static segment (nothing moves
    before it). The attitude is carried with the gyros and the Earth rate (Alignment.at); the position by the
    first ping's body velocity b_v (m/s, base_link: held constant in the body, turned with the carried attitude;
    None: no displacement). The covariance cov0 (given_covariance when None) grows by
    - the gyro white noise over |t1 - t_ref| (gyro_noise * sqrt(dt)) and the bias (gyro_bias_sigma * dt), per
      axis about map axes;
    - the attitude error at the start turning the displacement d (delta_p = delta_theta x d, correlated with the
      attitude);
    - the velocity error: velocity_sigma_m_s (the ping's sigma, with the scale and misalignment priors times the
      speed, added here) times the interval.
    A vehicle that changes speed between the first IMU stamp and the first state breaks the constant body
    velocity; the sigma does not cover that."""
    cov0 = given_covariance(alignment, config) if cov0 is None else cov0
    t_imu0 = float(imu.t[0]) if len(imu) else t1
    static = alignment.method == "static" and alignment.t_ref is None
    if alignment.t_ref is not None:
        t_att = alignment.t_ref
    elif static:
        t_att = max(alignment.t_static_end, t_imu0)
    else:  # configured: the first IMU stamp
        t_att = t_imu0
    t_pos = t_imu0 if t_origin is None else float(t_origin)
    if static:  # nothing moves before the end of the static segment
        t_pos = max(t_pos, t_att)
        att_moves, pos_moves = t1 > t_att, t1 > t_pos
    else:
        att_moves, pos_moves = t1 != t_att, t1 != t_pos
    if not (att_moves or pos_moves):
        return FirstState(alignment, np.zeros(3), cov0, False, min(t_att, t_pos), t1)
    at1 = (
        replace(alignment, t_ref=t_att).at(t1, imu, frame)
        if att_moves
        else replace(alignment, t_ref=t1)
    )
    imu_cfg, pri = config.imu, config.priors
    dt_att = abs(t1 - t_att) if att_moves else 0.0
    dt_pos = abs(t1 - t_pos) if pos_moves else 0.0
    var_gyro = (imu_cfg.gyro_noise_deg_per_h_rthz * DEG_PER_H) ** 2 * dt_att + (
        imu_cfg.gyro_bias_sigma_deg_per_h * DEG_PER_H * dt_att
    ) ** 2
    d = np.zeros(3)
    speed = 0.0
    if b_v is not None and np.all(np.isfinite(b_v)) and dt_pos > 0:
        b_v = np.asarray(b_v, dtype=float)
        if t1 > t_pos:
            d = _displacement(at1.n_R_b, imu, frame, t_pos, t1, b_v)
        else:  # the origin refers to a later time (a GNSS fix after the first ping): back from it
            d = -_displacement(at1.at(t_pos, imu, frame).n_R_b, imu, frame, t1, t_pos, b_v)
        speed = float(np.linalg.norm(b_v))
    sig_v = float(
        np.sqrt(
            velocity_sigma_m_s**2
            + (pri.scale_sigma * speed) ** 2
            + (np.radians(max(pri.misalignment_sigma_deg)) * speed) ** 2
        )
    )
    J = np.eye(6)
    J[3:, :3] = -skew(d)
    cov = J @ cov0 @ J.T
    cov[:3, :3] += np.eye(3) * var_gyro
    cov[3:, 3:] += np.eye(3) * (sig_v * dt_pos) ** 2
    return FirstState(at1, d, 0.5 * (cov + cov.T), True, min(t_att, t_pos), t1)


def _displacement(
    n_R_b1: np.ndarray, imu: ImuData, frame: LocalFrame, a: float, b: float, b_v: np.ndarray
) -> np.ndarray:
    """Map displacement (m) from a to b (s) at the constant body velocity b_v (m/s), the attitude n_R_b1 at b
    carried back with the gyros and the Earth rate: n_R_b(t) = Exp(-n_omega_ie (t - b)) n_R_b1 b(a)_R_b(b)^T
    b(a)_R_b(t); each sample's piece at the mean of its ends' attitudes' velocities."""
    idx, dt = _pieces(imu, a, b)
    if not len(idx):
        return np.asarray(n_R_b1 @ b_v * (b - a), dtype=float)
    D = so3_exp(imu.b_omega[idx] * dt[:, None])
    R = np.empty((len(idx) + 1, 3, 3))
    R[0] = np.eye(3)
    for k in range(len(idx)):
        R[k + 1] = R[k] @ D[k]
    tk = a + np.concatenate([[0.0], np.cumsum(dt)])
    E = so3_exp(-frame.n_omega_ie[None, :] * (tk - b)[:, None])
    n_v = np.einsum("kij,kj->ki", E, (R @ b_v) @ (n_R_b1 @ R[-1].T).T)
    return np.asarray(np.sum(0.5 * (n_v[1:] + n_v[:-1]) * dt[:, None], axis=0), dtype=float)
