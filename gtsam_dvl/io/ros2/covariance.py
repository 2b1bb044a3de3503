"""ROS conventions of a navigation state's covariances, from GTSAM's tangent spaces.

GTSAM's Pose3 covariance is over [rot_body, trans_body] (base_link axes); a ROS nav_msgs/msg/Odometry holds
the pose covariance over (x, y, z, rot_x, rot_y, rot_z) in the parent frame's axes (map) and the twist
covariance over (v_x, v_y, v_z, omega_x, omega_y, omega_z) in the child frame (base_link). The result MCAP
(io/result_writer.py) and the live view (app/live) both convert with these functions; each broadcasts over
leading axes (one state or N).
"""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.state_covariance import pose_velocity_covariance


def ros_pose_covariance(n_R_b: np.ndarray, pose_cov: np.ndarray) -> np.ndarray:
    """(..., 6, 6) pose covariance in ROS order [trans_map, rot_map] from n_R_b (..., 3, 3) and GTSAM's Pose3
    covariance pose_cov (..., 6, 6) over [rot_body, trans_body]: both blocks turn by n_R_b (a body tangent
    d maps to n_R_b d in map axes), and the two halves swap."""
    n_R_b = np.asarray(n_R_b, dtype=float)
    P = np.zeros((*n_R_b.shape[:-2], 6, 6))
    P[..., :3, 3:] = n_R_b  # translation in map = R * body translation tangent
    P[..., 3:, :3] = n_R_b  # rotation about map axes = R * body rotation tangent
    return P @ pose_cov @ np.swapaxes(P, -1, -2)


def ros_twist_covariance(
    n_R_b: np.ndarray,
    n_v: np.ndarray,
    pose_cov: np.ndarray,
    vel_cov: np.ndarray,
    pose_vel_cross: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(b_v (..., 3) m/s, twist covariance (..., 6, 6) of (b_v, b_omega) in base_link) from the state's n_R_b
    (..., 3, 3), n_v (..., 3) and its covariance blocks (core/state_covariance.py). The angular block is left
    zero: the estimators do not estimate b_omega (ROS: unknown).

    b_v = n_R_b^T n_v, so d b_v = [b_v]x d rot_body + n_R_b^T d n_v (the translation does not enter)."""
    n_R_b = np.asarray(n_R_b, dtype=float)
    R_T = np.swapaxes(n_R_b, -1, -2)
    b_v = (R_T @ np.asarray(n_v, dtype=float)[..., None])[..., 0]
    # column j: b_v x e_j, i.e. [b_v]x
    skew_b_v = np.swapaxes(np.cross(b_v[..., None, :], np.eye(3)), -1, -2)
    J = np.concatenate([skew_b_v, np.zeros_like(R_T), R_T], axis=-1)  # (..., 3, 9)
    joint = pose_velocity_covariance(pose_cov, vel_cov, pose_vel_cross)
    twist = np.zeros((*b_v.shape[:-1], 6, 6))
    twist[..., :3, :3] = J @ joint @ np.swapaxes(J, -1, -2)
    return b_v, twist
