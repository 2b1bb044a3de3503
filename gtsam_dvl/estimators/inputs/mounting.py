"""The IMU's mounting from /tf_static, applied once for every estimator: gyro and accelerometer samples are
rotated from imu_link into base_link, b_x = b_R_imu imu_x (docs/conventions.md, Frames).

Only the rotation changes the samples. The IMU's origin is the navigation point: positions are those of the
IMU's origin, attitude is base_link's, and the DVL lever arm b_l = b_p_dvl - b_p_imu runs from the IMU to the
DVL (Mounting.b_l), so the translation of imu_link enters through the lever arm and no specific-force
correction is needed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from gtsam_dvl.core.types import ImuData, LogData, Mounting

# a mounting this close to identity leaves the samples untouched (bit for bit)
_IDENTITY_TOL = 1e-12


def imu_is_rotated(mounting: Mounting) -> bool:
    return not np.allclose(mounting.b_R_imu, np.eye(3), rtol=0.0, atol=_IDENTITY_TOL)


def rotate_imu_samples(
    b_R_imu: np.ndarray, imu_omega: np.ndarray, imu_f: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) gyro (rad/s) and specific force (m/s^2) from imu_link into base_link."""
    return np.asarray(imu_omega @ b_R_imu.T), np.asarray(imu_f @ b_R_imu.T)


def imu_in_base_link(imu: ImuData, mounting: Mounting) -> ImuData:
    """The samples in base_link (the same object when the IMU is mounted with base_link's axes)."""
    # nothing to rotate, or rotated already
    if not imu_is_rotated(mounting) or imu.frame_id == "base_link":
        return imu
    b_omega, b_f = rotate_imu_samples(mounting.b_R_imu, imu.b_omega, imu.b_f)
    return dataclasses.replace(imu, b_omega=b_omega, b_f=b_f, frame_id="base_link")


def log_in_base_link(log: LogData) -> LogData:
    """The log with its IMU samples in base_link (the same object when nothing is rotated)."""
    imu = imu_in_base_link(log.imu, log.mounting)
    return log if imu is log.imu else dataclasses.replace(log, imu=imu)
