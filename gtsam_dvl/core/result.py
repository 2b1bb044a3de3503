"""The typed result every estimator returns, and how its numbers are read (calibration in user units)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core.units import DEG_PER_H, UG


def misalignment_rpy_and_cov(b_R_d: np.ndarray, b_R_d0: np.ndarray, cov_right: np.ndarray) -> tuple[np.ndarray,
                                                                                                        np.ndarray]:
    """[roll, pitch, yaw] (deg) of R_c = b_R_d b_R_d0^T and their covariance (deg^2), from the covariance of
    b_R_d in GTSAM's right tangent (rad^2). R_c's perturbation in body axes is b_R_d times the right one;
    with R_c = Rz(y) Ry(p) Rx(r), a body-axes perturbation Exp(e) R_c moves the angles by E^-1 e,
    E = [Rz Ry x, Rz y, z] (ZYX Euler rates). Closed form: it is called at every epoch by the filters."""
    R_c = b_R_d @ b_R_d0.T
    roll = math.atan2(R_c[2, 1], R_c[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, R_c[2, 0])))
    yaw = math.atan2(R_c[1, 0], R_c[0, 0])
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    E = np.array([[cp * cy, -sy, 0.0], [cp * sy, cy, 0.0], [-sp, 0.0, 1.0]])
    J = np.linalg.inv(E)
    cov_body = b_R_d @ cov_right @ b_R_d.T
    return np.degrees([roll, pitch, yaw]), np.degrees(np.degrees(J @ cov_body @ J.T))


class CalibrationUnits:
    """User-unit views (degrees, deg/h, micro-g) shared by every result type that holds b_R_d, b_R_d0,
    b_R_d_cov, gyro_bias, accel_bias and bias_cov in SI units."""

    b_R_d: np.ndarray
    b_R_d0: np.ndarray
    b_R_d_cov: np.ndarray
    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    bias_cov: np.ndarray

    @property
    def misalignment_deg(self) -> np.ndarray:
        return misalignment_rpy_and_cov(self.b_R_d, self.b_R_d0, self.b_R_d_cov)[0]

    @property
    def misalignment_sigma_deg(self) -> np.ndarray:
        return np.sqrt(np.diag(misalignment_rpy_and_cov(self.b_R_d, self.b_R_d0, self.b_R_d_cov)[1]))

    @property
    def gyro_bias_deg_per_h(self) -> np.ndarray:
        return self.gyro_bias / DEG_PER_H

    @property
    def gyro_bias_sigma_deg_per_h(self) -> np.ndarray:
        return np.sqrt(np.diag(self.bias_cov)[3:]) / DEG_PER_H

    @property
    def accel_bias_ug(self) -> np.ndarray:
        return self.accel_bias / UG

    @property
    def accel_bias_sigma_ug(self) -> np.ndarray:
        return np.sqrt(np.diag(self.bias_cov)[:3]) / UG


@dataclass
class NavResult(CalibrationUnits):
    """Estimates of one estimator on one log. Angles in radians and SI units inside; the accessors and
    the summary give degrees, deg/h and micro-g."""

    estimator: str
    t: np.ndarray  # (N,) s, relative to t0_ns
    n_p: np.ndarray  # (N, 3) m
    n_R_b: np.ndarray  # (N, 3, 3)
    n_v: np.ndarray  # (N, 3) m/s
    pose_cov: np.ndarray  # (N, 6, 6) GTSAM Pose3 tangent [rotation (body), translation (body)]
    vel_cov: np.ndarray  # (N, 3, 3) m^2/s^2, map frame
    accel_bias: np.ndarray  # (3,) m/s^2 (final; or the constant)
    gyro_bias: np.ndarray  # (3,) rad/s
    bias_cov: np.ndarray  # (6, 6) [accel, gyro] SI
    scale: float
    scale_sigma: float
    b_R_d: np.ndarray  # (3, 3)
    b_R_d_cov: np.ndarray  # (3, 3) rad^2, right tangent of b_R_d
    b_R_d0: np.ndarray  # nominal mounting
    t0_ns: int = 0
    # DVL-IMU time offset dt_d, s, and its sigma (nan: not estimated, dt_d taken as time_offset_s)
    time_offset_s: float = 0.0
    time_offset_sigma_s: float = float("nan")
    # DVL lever arm b_l (IMU -> DVL, m, base_link) and its 3x3 marginal covariance (m^2) with [dvl]
    # estimate_lever_arm (None: not estimated, b_l taken from /tf_static)
    lever_arm_m: np.ndarray | None = None
    lever_arm_cov: np.ndarray | None = None
    b_omega: np.ndarray | None = None  # (N, 3) rad/s body rate relative to map at each state (gyro - bias - earth)
    pose_vel_cross: np.ndarray | None = None  # (N, 6, 3) cross-covariance of pose tangent and n_v
    calib_joint_cov: np.ndarray | None = None  # (10, 10): [accel, gyro] bias, scale, b_R_d right tangent
    timeline: Timeline | None = None  # filtering history (online estimators and the EKF)
    timing_s: dict[str, float] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)  # solver report, counters, alignment
    # how the initial attitude was found: "attitude_topic", "configured", "static" or "in_motion" (details,
    # with its sigmas, in info["alignment"])
    alignment_method: str = ""
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def lever_arm_sigma_m(self) -> np.ndarray | None:
        """(3,) marginal sigmas of the estimated lever arm along base_link x, y, z, m (None: not estimated)."""
        return None if self.lever_arm_cov is None else np.sqrt(np.diag(self.lever_arm_cov))

    @property
    def attitude_sigma_deg(self) -> np.ndarray:
        """(N, 3) attitude sigmas about map axes (east, north, up), deg."""
        cov_map = self.n_R_b @ self.pose_cov[:, :3, :3] @ np.transpose(self.n_R_b, (0, 2, 1))
        return np.degrees(np.sqrt(np.einsum("nii->ni", cov_map)))

    @property
    def position_sigma_m(self) -> np.ndarray:
        """(N, 3) position sigmas in map axes, m (GTSAM's translation tangent is in body axes)."""
        cov_map = self.n_R_b @ self.pose_cov[:, 3:, 3:] @ np.transpose(self.n_R_b, (0, 2, 1))
        return np.sqrt(np.einsum("nii->ni", cov_map))

    @property
    def velocity_sigma_m_s(self) -> np.ndarray:
        """(N, 3) velocity sigmas in map axes, m/s."""
        return np.sqrt(np.einsum("nii->ni", self.vel_cov))


@dataclass
class StoredResult:
    """A result as read back from a result log (gtsam_dvl.io.result_reader): the NavResult that was written,
    the summary written with it, and where it came from: the source log's absolute path when smoothed, its path
    relative to the result file's folder, and the options it was read with (imu_topic, dvl_topic, salvage,
    repair; empty for a result written before they were recorded)."""

    result: NavResult
    summary: dict[str, Any]
    path: str = ""
    source_log: str = ""
    source_log_relative: str = ""
    read_options: dict[str, Any] = field(default_factory=dict)


@dataclass
class Timeline:
    """Filtering estimates and marginal sigmas of the calibration, biases and attitude after each epoch:
    the paper's Figures 4-9 and 12. Units as named; misalignment = [roll, pitch, yaw] of R_c in body axes;
    attitude sigmas about map axes (east, north, up)."""

    t: np.ndarray  # (N,) s
    scale: np.ndarray  # (N,)
    scale_sigma: np.ndarray  # (N,)
    misalignment_deg: np.ndarray  # (N, 3)
    misalignment_sigma_deg: np.ndarray  # (N, 3)
    gyro_bias_deg_per_h: np.ndarray  # (N, 3)
    gyro_bias_sigma_deg_per_h: np.ndarray  # (N, 3)
    accel_bias_ug: np.ndarray  # (N, 3)
    accel_bias_sigma_ug: np.ndarray  # (N, 3)
    attitude_sigma_deg: np.ndarray  # (N, 3)
    # when estimated (None otherwise): the DVL time offset (s) and lever arm (m, base_link)
    time_offset_s: np.ndarray | None = None  # (N,)
    time_offset_sigma_s: np.ndarray | None = None  # (N,)
    lever_arm_m: np.ndarray | None = None  # (N, 3)
    lever_arm_sigma_m: np.ndarray | None = None  # (N, 3)

    FIELDS = ("t", "scale", "scale_sigma", "misalignment_deg", "misalignment_sigma_deg", "gyro_bias_deg_per_h",
              "gyro_bias_sigma_deg_per_h", "accel_bias_ug", "accel_bias_sigma_ug", "attitude_sigma_deg")
    OPTIONAL = ("time_offset_s", "time_offset_sigma_s", "lever_arm_m", "lever_arm_sigma_m")

    def as_arrays(self) -> dict[str, np.ndarray]:
        out = {name: np.asarray(getattr(self, name)) for name in self.FIELDS}
        out.update({name: np.asarray(getattr(self, name)) for name in self.OPTIONAL if getattr(self, name) is not None})
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Timeline:
        return cls(**{name: np.asarray(arrays[name]) for name in cls.FIELDS},
                   **{name: np.asarray(arrays[name]) for name in cls.OPTIONAL if name in arrays})
