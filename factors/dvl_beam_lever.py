"""DVL single-beam factor with the lever arm a variable ([dvl] use_beams with estimate_lever_arm).

    measured y_j = d_u_j . ( k * d_R_b * ( n_R_b^T * n_v  +  b_omega x b_l ) ) + noise,   d_R_b = b_R_d^T

The model of factors/dvl_beam.py on the keys [pose, velocity, scale, b_R_d, lever arm b_l (3-vector, m,
base_link)]: every Jacobian is d_u_j^T times the 3-D one (factors/_common.py predict_dvl_velocity_lever), the
lever arm's d_u_j^T k d_R_b [b_omega]_x. Error = h_j(x) - y_j, shape (1,).
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ._common import (
    JacobianSlots,
    Vector3Like,
    as_finite_float,
    as_scale,
    as_unit_vector3,
    as_vector3,
    check_noise,
    fill_slots,
    predict_dvl_velocity_lever,
)

_EMPTY = np.empty(0)  # placeholder for a Jacobian slot before predict_dvl_velocity_lever fills it
_EMPTY.setflags(write=False)


def dvl_beam_lever_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    b_l: np.ndarray,
    d_u: np.ndarray,
    y_j: float,
    b_omega: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """e_j = d_u . (k * b_R_d^T (n_R_b^T n_v + b_omega x b_l)) - y_j, shape (1,). If H is a list of 5 slots,
    they receive the 1x6, 1x3, 1x1, 1x3, 1x3 Jacobians for [n_T_b, n_v, k, b_R_d, b_l]."""
    H3: list[np.ndarray] | None = None if H is None else [_EMPTY] * 5
    h = predict_dvl_velocity_lever(n_T_b.rotation().matrix(), np.asarray(n_v, dtype=float), as_scale(k),
                                   b_R_d.matrix().T, np.asarray(b_omega, dtype=float),
                                   np.asarray(b_l, dtype=float).reshape(3), H3)
    d_u_row = np.asarray(d_u, dtype=float).reshape(1, 3)
    if H is not None and H3 is not None:
        fill_slots(H, [d_u_row @ J for J in H3])
    return np.asarray(d_u_row @ h - float(y_j))


def make_dvl_beam_lever_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    lever_key: int,
    d_u: Vector3Like,
    y_j: float,
    b_omega: Vector3Like,
) -> gtsam.CustomFactor:
    """DvlBeamLeverFactor on [pose, velocity, scale, b_R_d, lever arm]: make_dvl_beam_factor with b_l estimated.
    Raises ValueError on a d_u that is not a finite unit 3-vector, a non-finite y_j or b_omega, or a noise
    model of the wrong dimension."""
    check_noise(noise, 1)
    d_u_row = as_unit_vector3("d_u", d_u).reshape(1, 3)
    y = as_finite_float("y_j", y_j)
    b_om = as_vector3("b_omega", b_omega)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose_k, vel_k, scale_k, b_R_d_k, lever_k = this.keys()
        H3: list[np.ndarray] | None = None if H is None else [_EMPTY] * 5
        h = predict_dvl_velocity_lever(
            values.atPose3(pose_k).rotation().matrix(),
            values.atPoint3(vel_k),
            values.atVector(scale_k).item(),
            values.atRot3(b_R_d_k).matrix().T,
            b_om,
            values.atPoint3(lever_k),
            H3,
        )
        if H is not None and H3 is not None:
            for i, J in enumerate(H3):
                H[i] = d_u_row @ J
        return np.asarray(d_u_row @ h - y)

    return gtsam.CustomFactor(noise, [pose_key, vel_key, scale_key, b_R_d_key, lever_key], error_func)
