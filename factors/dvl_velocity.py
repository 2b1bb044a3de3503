"""DVL 3-D bottom-track velocity factor (docs/conventions.md, paper eq. 2 and 7 with the lever arm).

    measured d_y = k * d_R_b * ( n_R_b^T * n_v  +  b_omega x b_l ) + noise,   d_R_b = b_R_d^T

d_y in dvl_link (m/s); pose n_T_b (base_link in map), velocity n_v (map), scale k (1-vector), misalignment
b_R_d (dvl_link -> base_link) are the variables; b_omega (body rate relative to map, rad/s, base_link) and
b_l (lever arm IMU -> DVL, m, base_link) are known inputs. Error = h(x) - d_y.

The *_lever variants take the lever arm b_l as a variable too (a 3-vector key after the others, [dvl]
estimate_lever_arm): h is linear in b_l, de/d(b_l) = k d_R_b [b_omega]_x exactly, so a lever arm is
observable only from rotation, and a lever arm along the axis of every rotation of a log is not.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ._common import (
    JacobianSlots,
    Vector3Like,
    _skew,
    as_scale,
    as_vector3,
    check_noise,
    cross3,
    fill_slots,
    lever_jacobian,
    lever_velocity,
    predict_dvl_velocity,
    predict_dvl_velocity_lever,
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
        cross3(b_omega, b_l),
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


def dvl_velocity_lever_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    b_l: np.ndarray,
    d_y: np.ndarray,
    b_omega: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """dvl_velocity_error with the lever arm b_l (m, base_link) a variable: the same e, and with H a list of 5
    slots the 4 Jacobians of dvl_velocity_error plus de/d(b_l) = k b_R_d^T [b_omega]_x, 3x3."""
    computed: list[np.ndarray] | None = None if H is None else [np.empty(0)] * 5
    h = predict_dvl_velocity_lever(
        n_T_b.rotation().matrix(),
        np.asarray(n_v, dtype=float),
        as_scale(k),
        b_R_d.matrix().T,
        np.asarray(b_omega, dtype=float),
        np.asarray(b_l, dtype=float).reshape(3),
        computed,
    )
    if H is not None and computed is not None:
        fill_slots(H, computed)
    return h - np.asarray(d_y, dtype=float)


def make_dvl_velocity_lever_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    lever_key: int,
    d_y: Vector3Like,
    b_omega: Vector3Like,
) -> gtsam.CustomFactor:
    """DvlVelocityLeverFactor on [pose, velocity, scale, b_R_d, lever arm b_l (3-vector, m, base_link)]:
    d_y = k * b_R_d^T (n_R_b^T n_v + b_omega x b_l), as make_dvl_velocity_factor with b_l estimated.
    Raises ValueError on a non-finite or wrongly shaped d_y or b_omega, or a noise model of the wrong
    dimension."""
    check_noise(noise, 3)
    d_y = as_vector3("d_y", d_y)
    b_om = as_vector3("b_omega", b_omega)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose_k, vel_k, scale_k, b_R_d_k, lever_k = this.keys()
        h = predict_dvl_velocity_lever(
            values.atPose3(pose_k).rotation().matrix(),
            values.atPoint3(vel_k),
            values.atVector(scale_k).item(),
            values.atRot3(b_R_d_k).matrix().T,
            b_om,
            values.atPoint3(lever_k),
            H,
        )
        return h - d_y

    return gtsam.CustomFactor(noise, [pose_key, vel_key, scale_key, b_R_d_key, lever_key], error_func)


def _offset_prediction(n_R_b: np.ndarray, n_v: np.ndarray, k: float, d_R_b: np.ndarray, dt: float,
                       b_omega: np.ndarray, b_v_lever: np.ndarray, b_a: np.ndarray, n_g: np.ndarray,
                       G: np.ndarray, H: JacobianSlots | None) -> np.ndarray:
    """h = k d_R_b (b_v + dt * b_vdot + b_v_lever), b_v = n_R_b^T n_v,
    b_vdot = b_a + G n_R_b^T n_g - b_omega x b_v (the body-frame velocity rate, first order in dt; G the
    mean body rotation since the stamp, transposed, over the IMU window that b_a averages).

    Jacobians (pose and b_R_d on the right, as in _common.predict_dvl_velocity), M = I - dt [b_omega]_x:
        pose rotation: k d_R_b (M [b_v]_x + dt G [n_R_b^T n_g]_x), translation 0
        n_v:           k d_R_b M n_R_b^T
        k:             d_R_b b_v_eff
        b_R_d:         k [d_R_b b_v_eff]_x
        dt:            k d_R_b b_vdot
    """
    b_v = n_v @ n_R_b
    b_g0 = n_g @ n_R_b
    b_g = G @ b_g0
    b_vdot = b_a + b_g - cross3(b_omega, b_v)
    b_v_eff = b_v + dt * b_vdot + b_v_lever
    d_v = d_R_b @ b_v_eff
    if H is not None:
        k_d_R_b = k * d_R_b
        M = np.eye(3) - dt * _skew(*b_omega.tolist())
        H[0] = np.concatenate((k_d_R_b @ (M @ _skew(*b_v.tolist()) + dt * G @ _skew(*b_g0.tolist())),
                               np.zeros((3, 3))), axis=1)
        H[1] = k_d_R_b @ M @ n_R_b.T
        H[2] = d_v.reshape(3, 1)
        H[3] = _skew(*(k * d_v).tolist())
        H[4] = (k_d_R_b @ b_vdot).reshape(3, 1)
    return k * d_v


def dvl_velocity_offset_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    dt: float | np.ndarray,
    d_y: np.ndarray,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    b_a: np.ndarray,
    n_g: np.ndarray,
    G: np.ndarray | None = None,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """The DVL velocity with a DVL-IMU time offset dt (s, docs/conventions.md: the ping stamped t measures
    the velocity at t + dt), to first order in dt:

        e = k b_R_d^T (b_v + dt (b_a + G n_R_b^T n_g - b_omega x b_v) + b_omega x b_l) - d_y,  b_v = n_R_b^T n_v

    b_a: the specific force from the IMU (mean over a window around the stamp, base_link, m/s^2; the
    Coriolis acceleration is left out), b_omega the body rate relative to map, n_g the gravity in map (all
    known inputs of the epoch); G (3x3, identity if None) the mean over the IMU window of the body rotation
    since the stamp, transposed (gravity seen in the body while b_a was measured). H: 5 slots,
    de/d(n_T_b) 3x6, de/d(n_v) 3x3, de/dk 3x1, de/d(b_R_d) 3x3, de/d(dt) 3x1.
    """
    computed: list[np.ndarray] | None = None if H is None else [np.empty(0)] * 5
    h = _offset_prediction(n_T_b.rotation().matrix(), np.asarray(n_v, dtype=float), as_scale(k),
                           b_R_d.matrix().T, as_scale(dt), np.asarray(b_omega, dtype=float),
                           cross3(b_omega, b_l), np.asarray(b_a, dtype=float), np.asarray(n_g, dtype=float),
                           np.eye(3) if G is None else np.asarray(G, dtype=float), computed)
    if H is not None and computed is not None:
        fill_slots(H, computed)
    return h - np.asarray(d_y, dtype=float)


def make_dvl_velocity_offset_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    offset_key: int,
    d_y: Vector3Like,
    b_omega: Vector3Like,
    b_l: Vector3Like,
    b_a: Vector3Like,
    n_g: Vector3Like,
    G: np.ndarray | None = None,
) -> gtsam.CustomFactor:
    """DvlVelocityOffsetFactor on [pose, velocity, scale, b_R_d, time offset (1-vector, s)]: the 3-D
    velocity factor with the ping's velocity taken at its stamp + dt, first order in dt
    (dvl_velocity_offset_error). b_a, n_g, b_omega, G are the epoch's IMU-derived constants."""
    check_noise(noise, 3)
    d_y = as_vector3("d_y", d_y)
    b_om = as_vector3("b_omega", b_omega)
    b_v_lever = lever_velocity(b_omega, b_l)
    b_a_c = as_vector3("b_a", b_a)
    n_g_c = as_vector3("n_g", n_g)
    G_c = np.eye(3) if G is None else np.array(G, dtype=float)
    if G_c.shape != (3, 3) or not np.all(np.isfinite(G_c)):
        raise ValueError(f"G must be a finite 3x3 matrix, got {G_c}")

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose_k, vel_k, scale_k, b_R_d_k, dt_k = this.keys()
        h = _offset_prediction(
            values.atPose3(pose_k).rotation().matrix(),
            values.atPoint3(vel_k),
            values.atVector(scale_k).item(),
            values.atRot3(b_R_d_k).matrix().T,
            values.atVector(dt_k).item(),
            b_om, b_v_lever, b_a_c, n_g_c, G_c, H,
        )
        return h - d_y

    return gtsam.CustomFactor(noise, [pose_key, vel_key, scale_key, b_R_d_key, offset_key], error_func)


def _offset_lever_prediction(n_R_b: np.ndarray, n_v: np.ndarray, k: float, d_R_b: np.ndarray, dt: float,
                             b_omega: np.ndarray, b_l: np.ndarray, b_a: np.ndarray, n_g: np.ndarray,
                             G: np.ndarray, H: JacobianSlots | None) -> np.ndarray:
    """_offset_prediction with the lever arm a variable: the lever term b_omega x b_l does not depend on dt
    (first order), so H[0..4] are _offset_prediction's and H[5] = de/d(b_l) = k d_R_b [b_omega]_x."""
    h = _offset_prediction(n_R_b, n_v, k, d_R_b, dt, b_omega, cross3(b_omega, b_l), b_a, n_g, G, H)
    if H is not None:
        H[5] = lever_jacobian(k, d_R_b, b_omega)
    return h


def dvl_velocity_offset_lever_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    dt: float | np.ndarray,
    b_l: np.ndarray,
    d_y: np.ndarray,
    b_omega: np.ndarray,
    b_a: np.ndarray,
    n_g: np.ndarray,
    G: np.ndarray | None = None,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """dvl_velocity_offset_error with the lever arm b_l (m, base_link) a variable. H: 6 slots, those of
    dvl_velocity_offset_error and de/d(b_l) 3x3."""
    computed: list[np.ndarray] | None = None if H is None else [np.empty(0)] * 6
    h = _offset_lever_prediction(n_T_b.rotation().matrix(), np.asarray(n_v, dtype=float), as_scale(k),
                                 b_R_d.matrix().T, as_scale(dt), np.asarray(b_omega, dtype=float),
                                 np.asarray(b_l, dtype=float).reshape(3), np.asarray(b_a, dtype=float),
                                 np.asarray(n_g, dtype=float), np.eye(3) if G is None else np.asarray(G, dtype=float),
                                 computed)
    if H is not None and computed is not None:
        fill_slots(H, computed)
    return h - np.asarray(d_y, dtype=float)


def make_dvl_velocity_offset_lever_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    offset_key: int,
    lever_key: int,
    d_y: Vector3Like,
    b_omega: Vector3Like,
    b_a: Vector3Like,
    n_g: Vector3Like,
    G: np.ndarray | None = None,
) -> gtsam.CustomFactor:
    """DvlVelocityOffsetLeverFactor on [pose, velocity, scale, b_R_d, time offset (1-vector, s), lever arm
    (3-vector, m, base_link)]: make_dvl_velocity_offset_factor with b_l estimated."""
    check_noise(noise, 3)
    d_y = as_vector3("d_y", d_y)
    b_om = as_vector3("b_omega", b_omega)
    b_a_c = as_vector3("b_a", b_a)
    n_g_c = as_vector3("n_g", n_g)
    G_c = np.eye(3) if G is None else np.array(G, dtype=float)
    if G_c.shape != (3, 3) or not np.all(np.isfinite(G_c)):
        raise ValueError(f"G must be a finite 3x3 matrix, got {G_c}")

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose_k, vel_k, scale_k, b_R_d_k, dt_k, lever_k = this.keys()
        h = _offset_lever_prediction(
            values.atPose3(pose_k).rotation().matrix(),
            values.atPoint3(vel_k),
            values.atVector(scale_k).item(),
            values.atRot3(b_R_d_k).matrix().T,
            values.atVector(dt_k).item(),
            b_om, values.atPoint3(lever_k), b_a_c, n_g_c, G_c, H,
        )
        return h - d_y

    return gtsam.CustomFactor(noise, [pose_key, vel_key, scale_key, b_R_d_key, offset_key, lever_key], error_func)
