"""The EKF's record of its states after each update, and the NavResult made of it (estimators/ekf/filter.py)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.core.rotations import matrix_to_rpy, so3_exp
from gtsam_dvl.core.states import Estimate, block_states, ekf_layout, joint_states
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.ekf.strapdown import BA, BG, MIS, N_NAV, PHI, SCALE

if TYPE_CHECKING:
    from gtsam_dvl.estimators.ekf.strapdown import FilterState

__all__ = ["N_NAV", "History", "history_result"]  # (N_NAV: strapdown.py's, read from here too)


@dataclass
class History:
    """What is recorded after each update."""

    t: list[float] = field(default_factory=list)
    n_p: list[np.ndarray] = field(default_factory=list)
    n_R_b: list[np.ndarray] = field(default_factory=list)
    n_v: list[np.ndarray] = field(default_factory=list)
    P: list[np.ndarray] = field(default_factory=list)
    b_omega: list[np.ndarray] = field(default_factory=list)
    gyro_bias: list[np.ndarray] = field(default_factory=list)
    accel_bias: list[np.ndarray] = field(default_factory=list)
    scale: list[float] = field(default_factory=list)
    b_R_d: list[np.ndarray] = field(default_factory=list)
    time_offset: list[float] = field(default_factory=list)

    def record(self, fs: FilterState, t: float, b_omega: np.ndarray) -> None:
        """Append the filter's state after an update (or a propagation) at t."""
        self.t.append(t)
        self.n_p.append(fs.nav.n_p.copy())
        self.n_R_b.append(fs.nav.n_R_b.copy())
        self.n_v.append(fs.nav.n_v.copy())
        # the navigation, calibration and time offset block (the results read
        m = len(fs.P) - fs.extra_states()
        # only these; the current's layer boundaries grow the rest)
        self.P.append(fs.P[:m, :m].copy())
        self.b_omega.append(b_omega)
        self.gyro_bias.append(fs.gyro_bias.copy())
        self.accel_bias.append(fs.accel_bias.copy())
        self.scale.append(fs.scale)
        self.b_R_d.append(fs.b_R_d.copy())
        self.time_offset.append(fs.time_offset)


def misalignment_timeline(
    b_R_d: np.ndarray, b_R_d0: np.ndarray, cov_right: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """result.misalignment_rpy_and_cov over (N, 3, 3) stacks, vectorised: [roll, pitch, yaw] of
    R_c = b_R_d b_R_d0^T (deg) and their covariance (deg^2), from the covariance in b_R_d's right tangent."""
    R_c = b_R_d @ b_R_d0.T
    cov_body = b_R_d @ cov_right @ np.transpose(b_R_d, (0, 2, 1))
    rpy = matrix_to_rpy(R_c)
    J = np.zeros(R_c.shape)
    h = 1e-7
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        J[:, :, j] = (matrix_to_rpy(so3_exp(e) @ R_c) - matrix_to_rpy(so3_exp(-e) @ R_c)) / (2 * h)
    cov = J @ cov_body @ np.transpose(J, (0, 2, 1))
    return np.degrees(rpy), np.degrees(np.degrees(cov))


def history_result(hist: History, log: LogData, config: EstimatorConfig) -> NavResult:
    """NavResult and Timeline from the history. GTSAM's Pose3 tangent is [rotation, translation] in body
    axes: n_R_b Exp(w) = Exp(n_R_b w) n_R_b gives w = n_R_b^T phi, and Pose3's translation perturbation
    t + n_R_b v gives v = n_R_b^T dp; so pose_cov = J P[phi, p] J^T with J = diag(n_R_b^T, n_R_b^T)."""
    P = np.array(hist.P)
    n_R_b = np.array(hist.n_R_b)
    n = len(hist.t)
    J = np.zeros((n, 6, 6))
    J[:, :3, :3] = np.transpose(n_R_b, (0, 2, 1))
    J[:, 3:, 3:] = J[:, :3, :3]
    pose_idx = np.r_[0:3, 6:9]
    P_pose = P[:, pose_idx][:, :, pose_idx]
    pose_cov = J @ P_pose @ np.transpose(J, (0, 2, 1))
    pose_vel_cross = J @ P[:, pose_idx, 3:6]
    layout = ekf_layout(config, N_NAV)
    calib_idx = np.r_[
        tuple(layout[s.name] for s in block_states())
    ]  # [accel, gyro] bias, scale, b_R_d tangent
    calib = P[-1][np.ix_(calib_idx, calib_idx)]
    shared_idx = np.r_[
        tuple(layout[s.name] for s in joint_states(config, ekf=True))
    ]  # NavResult.shared_joint_cov
    shared = P[-1][np.ix_(shared_idx, shared_idx)]
    b_R_d0 = log.mounting.b_R_d0
    mis_deg, mis_cov = misalignment_timeline(np.array(hist.b_R_d), b_R_d0, P[:, MIS, MIS])
    diag = np.einsum("nii->ni", P)
    timeline = Timeline(
        t=np.array(hist.t),
        scale=np.array(hist.scale),
        scale_sigma=np.sqrt(diag[:, SCALE]),
        misalignment_deg=mis_deg,
        misalignment_sigma_deg=np.sqrt(np.einsum("nii->ni", mis_cov)),
        gyro_bias_deg_per_h=np.array(hist.gyro_bias) / DEG_PER_H,
        gyro_bias_sigma_deg_per_h=np.sqrt(diag[:, BG]) / DEG_PER_H,
        accel_bias_ug=np.array(hist.accel_bias) / UG,
        accel_bias_sigma_ug=np.sqrt(diag[:, BA]) / UG,
        attitude_sigma_deg=np.degrees(np.sqrt(diag[:, PHI])),
    )
    final = {
        "gyro_bias": hist.gyro_bias[-1],
        "accel_bias": hist.accel_bias[-1],
        "scale": [hist.scale[-1]],
        "misalignment": hist.b_R_d[-1],
        "time_offset": [hist.time_offset[-1]],
    }
    return NavResult(
        estimator="ekf",
        t=np.array(hist.t),
        n_p=np.array(hist.n_p),
        n_R_b=n_R_b,
        n_v=np.array(hist.n_v),
        pose_cov=pose_cov,
        vel_cov=P[:, 3:6, 3:6].copy(),
        calibration={
            name: Estimate(np.asarray(final[name], dtype=float), P[-1][sl, sl].copy())
            for name, sl in layout.items()
        },
        b_R_d0=b_R_d0,
        t0_ns=log.t0_ns,
        b_omega=np.array(hist.b_omega),
        pose_vel_cross=pose_vel_cross,
        calib_joint_cov=calib,
        shared_joint_cov=shared,
        timeline=timeline,
        config=config.to_dict(),
    )
