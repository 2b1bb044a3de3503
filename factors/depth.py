"""Depth factor: the vertical position of a state against a depth sensor's measurement.

    height of the sensor  h_s = h0 + z + (x^2 + y^2) / (2 R) + (n_R_b b_p_s)_z + dt * n_v_z

(x, y, z) = n_p the state's position in map (ENU at the origin of ellipsoidal height h0), R the Gaussian
radius of the Earth at the origin (the map's z axis leaves the ellipsoid by (x^2 + y^2) / (2 R): 0.3 m at
2 km; radius_m = inf drops the term), b_p_s the sensor's position in base_link, dt the time from the state to
the sample (bridged by the state's velocity when a velocity key is given). The measurement is the map
height z_meas = -depth - h0 of the surface at h = 0; error = h_s - h0 - z_meas, in metres (up).

Jacobians, pose n_T_b perturbed on the right (GTSAM retract, tangent [rotation, translation], translation in
body axes): d n_p = n_R_b dt_b, d(n_R_b b_p) = -n_R_b [b_p]_x dth.
"""

from __future__ import annotations

import math
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

_E3 = np.array([0.0, 0.0, 1.0])


def predict_height(
    n_R_b: np.ndarray,
    n_p: np.ndarray,
    b_p_s: np.ndarray,
    radius_m: float,
    H: list[np.ndarray] | None = None,
) -> float:
    """Height of the sensor above the map origin's height (m), and with H its Jacobian w.r.t. the pose
    (1x6, right perturbation) in H[0]."""
    inv_r = 0.0 if math.isinf(radius_m) else 1.0 / radius_m
    x, y = float(n_p[0]), float(n_p[1])
    lever = n_R_b @ b_p_s
    h = float(n_p[2]) + 0.5 * (x * x + y * y) * inv_r + float(lever[2])
    if H is not None:
        grad = np.array([x * inv_r, y * inv_r, 1.0])  # d h / d n_p
        d_rot = -(n_R_b[2] @ skew(b_p_s))  # d (n_R_b Exp(th) b_p)_z / d th
        H[0] = np.concatenate((d_rot, grad @ n_R_b)).reshape(1, 6)
    return h


def depth_error(
    n_T_b: gtsam.Pose3,
    z_meas: float,
    b_p_s: np.ndarray,
    radius_m: float = math.inf,
    n_v: np.ndarray | None = None,
    dt: float = 0.0,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """e = h_s - z_meas (1,), see the module doc. H: one slot (pose, 1x6), or two with n_v (velocity, 1x3)."""
    computed: list[np.ndarray] = [np.empty(0)]
    h = predict_height(
        n_T_b.rotation().matrix(),
        n_T_b.translation(),
        np.asarray(b_p_s, dtype=float),
        radius_m,
        computed if H is not None else None,
    )
    if n_v is not None:
        h += dt * float(np.asarray(n_v)[2])
        computed.append((dt * _E3).reshape(1, 3))
    if H is not None:
        fill_slots(H, computed)
    return np.array([h - z_meas])


def make_depth_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    z_meas: float,
    b_p_s: Vector3Like,
    radius_m: float = math.inf,
    vel_key: int | None = None,
    dt: float = 0.0,
) -> gtsam.CustomFactor:
    """DepthFactor on [pose] (or [pose, velocity] with vel_key, the sample dt seconds after the state):
    the sensor's height above the map origin's height against z_meas = -depth - h0 (m, up). noise: a GTSAM
    noise model of dimension 1. Raises ValueError on a non-finite z_meas, dt, b_p_s or a bad radius."""
    check_noise(noise, 1)
    z = as_finite_float("z_meas", z_meas)
    b_p = as_vector3("b_p_s", b_p_s)
    dt_f = as_finite_float("dt", dt)
    radius = float(radius_m)
    if not radius > 0:
        raise ValueError(f"radius_m must be positive (inf: no curvature term), got {radius_m}")
    J_v = (dt_f * _E3).reshape(1, 3)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        keys = this.keys()
        pose = values.atPose3(keys[0])
        slot: list[np.ndarray] | None = [np.empty(0)] if H is not None else None
        h = predict_height(pose.rotation().matrix(), pose.translation(), b_p, radius, slot)
        if len(keys) > 1:
            h += dt_f * float(values.atPoint3(keys[1])[2])
        if H is not None and slot is not None:
            fill_slots(H, slot + [J_v] * (len(keys) - 1))
        return np.array([h - z])

    keys = [pose_key] if vel_key is None else [pose_key, vel_key]
    return gtsam.CustomFactor(noise, keys, error_func)
