"""The joint covariance of a navigation state's pose and velocity, as the estimators give its blocks.

The state tangent is [rot_body (3, rad), trans_body (3, m), n_v (3, m/s)]: GTSAM's Pose3 tangent (rotation and
translation in base_link axes) followed by the velocity in map axes. NavResult and OnlineEstimate hold its
blocks apart (pose_cov (6, 6), vel_cov (3, 3), pose_vel_cross (6, 3)); the result MCAP's twist covariance and
the surfacing check propagate the joint one.
"""

from __future__ import annotations

import numpy as np


def pose_velocity_covariance(
    pose_cov: np.ndarray, vel_cov: np.ndarray, pose_vel_cross: np.ndarray | None = None
) -> np.ndarray:
    """(..., 9, 9) covariance of [rot_body, trans_body, n_v] from pose_cov (..., 6, 6), vel_cov (..., 3, 3) and
    pose_vel_cross (..., 6, 3) (None: zero, pose and velocity taken as uncorrelated)."""
    pose_cov, vel_cov = np.asarray(pose_cov, dtype=float), np.asarray(vel_cov, dtype=float)
    joint = np.zeros((*pose_cov.shape[:-2], 9, 9))
    joint[..., :6, :6] = pose_cov
    joint[..., 6:, 6:] = vel_cov
    if pose_vel_cross is not None:
        joint[..., :6, 6:] = pose_vel_cross
        joint[..., 6:, :6] = np.swapaxes(pose_vel_cross, -1, -2)
    return joint
