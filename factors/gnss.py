"""GNSS position factor: a state's antenna position against a fix, with the antenna's lever arm.

    n_p_antenna = n_p + n_R_b b_p_a + dt * n_v

n_p the state's position in map (ENU at the map origin), n_R_b its attitude, b_p_a the antenna in base_link
(/tf_static base_link -> gnss_link), dt the time from the state to the fix (bridged by the state's velocity
when a velocity key is given). The measurement z is the fix converted into map (estimators/inputs/gnss.py);
error = n_p_antenna - z, (3,) in metres, map axes. gtsam.GPSFactor has no lever arm, hence this factor.

Jacobians, pose n_T_b perturbed on the right (GTSAM retract, tangent [rotation, translation], translation in
body axes): d n_p = n_R_b dt_b, d(n_R_b b_p) = -n_R_b [b_p]_x dth; velocity: dt I.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ._common import (
    JacobianSlots,
    Vector3Like,
    as_finite_float,
    as_vector3,
    check_noise,
    fill_slots,
)
from .so3 import skew


def predict_antenna(
    n_R_b: np.ndarray, n_p: np.ndarray, b_p_a: np.ndarray, H: list[np.ndarray] | None = None
) -> np.ndarray:
    """Antenna position in map (3,), and with H its Jacobian w.r.t. the pose (3x6, right perturbation) in H[0]."""
    p = np.asarray(n_p, dtype=float) + n_R_b @ b_p_a
    if H is not None:
        H[0] = np.hstack((-n_R_b @ skew(b_p_a), n_R_b))
    return np.asarray(p)


def gnss_error(
    n_T_b: gtsam.Pose3,
    z: np.ndarray,
    b_p_a: np.ndarray,
    n_v: np.ndarray | None = None,
    dt: float = 0.0,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """e = n_p + n_R_b b_p_a + dt n_v - z (3,), see the module doc. H: one slot (pose, 3x6), or two with n_v
    (velocity, 3x3)."""
    computed: list[np.ndarray] = [np.empty(0)]
    p = predict_antenna(
        n_T_b.rotation().matrix(),
        n_T_b.translation(),
        np.asarray(b_p_a, dtype=float),
        computed if H is not None else None,
    )
    if n_v is not None:
        p = p + dt * np.asarray(n_v, dtype=float)
        computed.append(dt * np.eye(3))
    if H is not None:
        fill_slots(H, computed)
    return np.asarray(p - np.asarray(z, dtype=float))


def make_gnss_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    z: Vector3Like,
    b_p_a: Vector3Like,
    vel_key: int | None = None,
    dt: float = 0.0,
) -> gtsam.CustomFactor:
    """GnssFactor on [pose] (or [pose, velocity] with vel_key, the fix dt seconds after the state): the
    antenna's position in map against the fix z (m, map ENU). noise: a GTSAM noise model of dimension 3 (the
    fix's covariance in map axes). Raises ValueError on a non-finite z, b_p_a or dt."""
    check_noise(noise, 3)
    z_m = as_vector3("z", z)
    b_p = as_vector3("b_p_a", b_p_a)
    dt_f = as_finite_float("dt", dt)
    J_v = dt_f * np.eye(3)
    S = skew(b_p)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        keys = this.keys()
        pose = values.atPose3(keys[0])
        R = pose.rotation().matrix()
        p = pose.translation() + R @ b_p
        if len(keys) > 1:
            p = p + dt_f * values.atPoint3(keys[1])
        if H is not None:
            fill_slots(H, [np.hstack((-R @ S, R))] + [J_v] * (len(keys) - 1))
        return np.asarray(p - z_m)

    keys = [pose_key] if vel_key is None else [pose_key, vel_key]
    return gtsam.CustomFactor(noise, keys, error_func)
