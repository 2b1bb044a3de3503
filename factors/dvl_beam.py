"""DVL single-beam velocity factor: one scalar measurement per valid beam.

    measured y_j = d_u_j . ( k * d_R_b * ( n_R_b^T * n_v  +  b_omega x b_l ) ) + noise,   d_R_b = b_R_d^T

d_u_j is the unit vector of beam j in dvl_link, y_j its velocity (m/s). The model is the 3-D one of
dvl_velocity.py projected on the beam, so a DVL with one, two or three good beams still contributes; the
Jacobians are d_u_j^T times the 3-D ones. Error = h_j(x) - y_j, shape (1,).
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
    check_noise,
    cross3,
    fill_slots,
    lever_velocity,
    predict_dvl_velocity,
)

_EMPTY = np.empty(0)  # placeholder for a Jacobian slot before predict_dvl_velocity fills it
_EMPTY.setflags(write=False)


def _project(
    d_u_row: np.ndarray, h: np.ndarray, y_j: float, H3: list[np.ndarray] | None, H: Any
) -> np.ndarray:
    """e_j = d_u^T h - y_j (1,); H[i] = d_u^T H3[i] (1 x dim) when H3 holds the 3-D Jacobians."""
    if H3 is not None:
        for i, J in enumerate(H3):
            H[i] = d_u_row @ J
    return d_u_row @ h - y_j


def dvl_beam_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    d_u: np.ndarray,
    y_j: float,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """e_j = d_u . (k * b_R_d^T (n_R_b^T n_v + b_omega x b_l)) - y_j, shape (1,).

    If H is a list of 4 slots (None or preallocated arrays), they receive the 1x6, 1x3, 1x1, 1x3 Jacobians
    for [n_T_b, n_v, k, b_R_d], poses and rotations perturbed on the right.
    """
    H3: list[np.ndarray] | None = None if H is None else [_EMPTY] * 4
    h = predict_dvl_velocity(
        n_T_b.rotation().matrix(),
        np.asarray(n_v, dtype=float),
        as_scale(k),
        b_R_d.matrix().T,
        cross3(b_omega, b_l),
        H3,
    )
    computed: list[np.ndarray] = [_EMPTY] * 4
    e = _project(np.asarray(d_u, dtype=float).reshape(1, 3), h, float(y_j), H3, computed)
    if H is not None:
        fill_slots(H, computed)
    return e


def make_dvl_beam_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    d_u: Vector3Like,
    y_j: float,
    b_omega: Vector3Like,
    b_l: Vector3Like,
) -> gtsam.CustomFactor:
    """DvlBeamFactor on [pose, velocity, scale, b_R_d]: y_j = d_u . (k b_R_d^T (n_R_b^T n_v + b_omega x b_l)).

    noise: any GTSAM noise model of dimension 1 (the beam's velocity sigma, possibly robust). Values hold
    the same types as for make_dvl_velocity_factor. Raises ValueError on a d_u that is not a finite unit
    3-vector, a non-finite y_j, b_omega or b_l, or a noise model of the wrong dimension.
    """
    check_noise(noise, 1)
    d_u_row = as_unit_vector3("d_u", d_u).reshape(1, 3)
    y = as_finite_float("y_j", y_j)
    b_v_lever = lever_velocity(b_omega, b_l)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose_k, vel_k, scale_k, b_R_d_k = this.keys()
        # The 3-D Jacobians go to a local list first: GTSAM's slots only receive the projected rows.
        H3: list[np.ndarray] | None = None if H is None else [_EMPTY] * 4
        h = predict_dvl_velocity(
            values.atPose3(pose_k).rotation().matrix(),
            values.atPoint3(vel_k),
            values.atVector(scale_k).item(),
            values.atRot3(b_R_d_k).matrix().T,
            b_v_lever,
            H3,
        )
        return _project(d_u_row, h, y, H3, H)

    return gtsam.CustomFactor(noise, [pose_key, vel_key, scale_key, b_R_d_key], error_func)

