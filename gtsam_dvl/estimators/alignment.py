"""Initialisation without the truth: the map frame, static-segment detection and coarse alignment.

Roll and pitch come from the mean specific force (it points up in a static body), heading from
gyrocompassing: the horizontal part of the measured Earth rate points north.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import AlignmentConfig, EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, rpy_to_matrix
from gtsam_dvl.core.types import DvlData, ImuData, LogData
from gtsam_dvl.core.units import DEG_PER_H


@dataclass
class Alignment:
    """Initial attitude of base_link in map at t_end of the static segment (or at the first IMU sample)."""

    n_R_b: np.ndarray
    t_static_end: float  # end of the detected static segment, s (0 when none was used)
    method: str  # "static" or "configured"
    b_f_mean: np.ndarray | None = None  # mean specific force on the static segment, m/s^2
    b_omega_mean: np.ndarray | None = None  # mean gyro on the static segment, rad/s


def map_frame_of(log: LogData, config: EstimatorConfig) -> LocalFrame:
    """The map origin: from the configuration if given, else the log's (LogData.origin)."""
    a = config.alignment
    if a.origin_lat_deg is not None:
        return LocalFrame(a.origin_lat_deg, a.origin_lon_deg or 0.0, a.origin_height_m or 0.0)
    if log.origin is None:
        raise GtsamDvlError(f"{log.source or 'log'}: no map origin in the log; set alignment.origin_lat_deg "
                            "(and lon, height) in the configuration: Earth rate and gravity need the latitude")
    return LocalFrame(log.origin.lat_deg, log.origin.lon_deg, log.origin.height_m)


STATIC_MARGIN_S = 5.0  # the static segment ends this long before motion is first detected
# The DVL shows motion from the first valid ping faster than alignment.dvl_speed_threshold_m_s that starts a
# run of DVL_MOTION_PINGS valid pings (fewer at the end of the data, but at least DVL_MOTION_MIN_PINGS) of
# which at least DVL_MOTION_FRACTION are that fast: a vehicle that moves keeps moving, an outlier does not
# repeat. 1 % of gross outliers put 8 of 10 in a row with probability 5e-15 per ping, 5 % with 2e-9.
DVL_MOTION_PINGS = 10
DVL_MOTION_FRACTION = 0.8
DVL_MOTION_MIN_PINGS = 3


def window_means(t: np.ndarray, x: np.ndarray, window_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
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
    moving = fast & (size >= DVL_MOTION_MIN_PINGS) & (counts[stop] - counts[start] >= DVL_MOTION_FRACTION * size)
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
        np.degrees(np.linalg.norm(w_means - w_ref, axis=1)) > cfg.gyro_threshold_deg_s)
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
    if (np.hypot(w_level[0], w_level[1]) < 0.2 * horizontal_rate
            or horizontal_rate < GYROCOMPASS_MIN_HORIZONTAL_RATE_RAD_S):
        raise GtsamDvlError("gyrocompassing failed: the horizontal Earth rate is not visible in the gyros "
                            "(IMU too noisy, or latitude near a pole); give alignment.initial_attitude_deg")
    return rpy_to_matrix(float(roll), float(pitch), float(yaw))


def align(imu: ImuData, dvl: DvlData, frame: LocalFrame, cfg: AlignmentConfig) -> Alignment:
    """Initial attitude: the configured one, else coarse alignment on the initial static segment (heading by
    gyrocompassing, refused when the gyro bias would set it: see coarse_alignment)."""
    if cfg.initial_attitude_deg is not None:
        return Alignment(rpy_deg_to_matrix(cfg.initial_attitude_deg), 0.0, "configured")
    t_end = detect_static_end(imu, dvl, cfg)
    if t_end - imu.t[0] < cfg.min_static_s:
        raise GtsamDvlError(
            f"no static segment of at least {cfg.min_static_s:.0f} s at the start of the log (found "
            f"{max(t_end - imu.t[0], 0.0):.0f} s); set alignment.initial_attitude_deg in the configuration")
    sel = imu.t <= t_end
    b_f, b_omega = imu.b_f[sel].mean(axis=0), imu.b_omega[sel].mean(axis=0)
    return Alignment(coarse_alignment(b_f, b_omega, frame), t_end, "static", b_f, b_omega)
