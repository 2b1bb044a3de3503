"""DVL 3-D bottom-track velocity factor (docs/conventions.md, paper eq. 2 and 7 with the lever arm).

    measured d_y = k * d_R_b * ( n_R_b^T * n_v  +  b_omega x b_l ) + noise,   d_R_b = b_R_d^T

d_y in dvl_link (m/s); pose n_T_b (base_link in map), velocity n_v (map), scale k (1-vector), misalignment
b_R_d (dvl_link -> base_link) are the variables; b_omega (body rate relative to map, rad/s, base_link) and
b_l (lever arm IMU -> DVL, m, base_link) are known inputs. Error = h(x) - d_y.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ._common import (
    JacobianSlots,
    Vector3Like,
    as_scale,
    as_vector3,
    check_noise,
    fill_slots,
    lever_velocity,
    predict_dvl_velocity,
)


def dvl_velocity_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    d_y: np.ndarray,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """e = k * b_R_d^T * (n_R_b^T n_v + b_omega x b_l) - d_y, (3,), in dvl_link.

    k may be a float or the 1-vector stored in Values. If H is a list of 4 slots (None or preallocated
    arrays), they receive de/d(n_T_b) 3x6, de/d(n_v) 3x3, de/dk 3x1, de/d(b_R_d) 3x3, with n_T_b and b_R_d
    perturbed on the right (GTSAM retract).
    """
    computed: list[np.ndarray] | None = None if H is None else [np.empty(0)] * 4
    h = predict_dvl_velocity(
        n_T_b.rotation().matrix(),
        np.asarray(n_v, dtype=float),
        as_scale(k),
        b_R_d.matrix().T,
        np.cross(b_omega, b_l),
        computed,
    )
    if H is not None and computed is not None:
        fill_slots(H, computed)
    return h - np.asarray(d_y, dtype=float)


def make_dvl_velocity_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    d_y: Vector3Like,
    b_omega: Vector3Like,
    b_l: Vector3Like,
) -> gtsam.CustomFactor:
    """DvlVelocityFactor on [pose, velocity, scale, b_R_d]: d_y = k * b_R_d^T (n_R_b^T n_v + b_omega x b_l).

    noise: any GTSAM noise model of dimension 3 (e.g. Gaussian.Covariance of the DVL's 3x3 covariance,
    possibly inside a Robust wrapper). Values must hold a Pose3 at pose_key, a 3-vector at vel_key, a
    1-vector at scale_key and a Rot3 at b_R_d_key. Raises ValueError on a non-finite or wrongly shaped
    d_y, b_omega or b_l, or a noise model of the wrong dimension.
    """
    check_noise(noise, 3)
    d_y = as_vector3("d_y", d_y)
    # b_omega and b_l only enter through their cross product: compute it once, not per linearisation.
    b_v_lever = lever_velocity(b_omega, b_l)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        # The factor's own keys, in the order [pose, velocity, scale, b_R_d] given to CustomFactor.
        pose_k, vel_k, scale_k, b_R_d_k = this.keys()
        h = predict_dvl_velocity(
            values.atPose3(pose_k).rotation().matrix(),
            values.atPoint3(vel_k),  # accepts a dynamic Vector or a fixed Vector3/Point3 entry
            values.atVector(scale_k).item(),  # a Python float: cheaper arithmetic than np.float64
            values.atRot3(b_R_d_k).matrix().T,
            b_v_lever,
            H,
        )
        return h - d_y

    return gtsam.CustomFactor(noise, [pose_key, vel_key, scale_key, b_R_d_key], error_func)
