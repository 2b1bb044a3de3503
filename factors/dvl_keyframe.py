"""DVL factor of a ping between keyframes: the ping seen from the keyframe before it through the IMU motion.

With states only at keyframes (estimators/graph.py, [solver] keyframe_spacing_s), a ping at t_p between
keyframes i and i+1 constrains keyframe i's pose X_i = n_T_b, velocity V_i = n_v and the IMU bias B through
the preintegrated IMU motion over [t_i, t_p] (dt = t_p - t_i; PingMotion, zero-bias deltas dR, dv and their
bias Jacobians, from GTSAM's preintegration):

    n_R_b(t_p) = Exp(-[n_omega_ie] dt) n_R_i dR(b_g),          dR(b_g) = dR Exp(J_R,g b_g)
    n_v(t_p)   = n_v_i + n_g(p_i) dt - 2 n_omega_ie x n_v_i dt + n_R_i dv(b_a, b_g)
                 - n_omega_ie x (n_R_i (dt dv + dp) + n_g dt^2),
                 dv(b_a, b_g) = dv + J_v,a b_a + J_v,g b_g

(Earth rate w = n_omega_ie constant in the Earth-fixed map frame.) The last line is first order in w and
exact there: the Earth's turn of the body acting on the specific force (n_R_b(t) = Exp(-[w] t) n_R_i dR(t), so
the specific force integrated in map is n_R_i dv - w x n_R_i (dt dv - dp)), and the Coriolis term of the
velocity change within the interval (-2 w x (n_R_i dp + n_g dt^2 / 2)); dp is GTSAM's deltaPij. A static vehicle
needs them: without them the velocity predicted after 1 s is off by w x g / 2 = 3.6e-4 m/s, and an accelerating
one by 2 w x dp. They are taken at zero bias (their bias dependence is below 1e-10 m/s). GTSAM's own prediction
agrees to 1e-6 m/s over 0.8 s in a 0.3 rad/s turn at 0.5 m/s^2 (tests/factors/test_dvl_keyframe.py). Normal
gravity n_g at the keyframe's position, to first order about a reference n_p0: n_g0 + G (p_i - n_p0),
G the gravity gradient, 1.5e-6 s^-2: over dt = 1 s its Jacobian is 1.5e-6 (m/s)/m, kept for exactness). The
DVL model of factors/dvl_velocity.py is then applied at that attitude and velocity: the 3-D velocity
(predict_dvl_velocity), with the lever arm as a variable (predict_dvl_velocity_lever), with the time offset
(the first-order model of make_dvl_velocity_offset_factor, with the ping's own IMU constants), both, or one beam
d_u . h. The ping's body rate b_omega (for the lever arm) is the one at t_p.

Keys: [pose X_i, velocity V_i, bias B (ConstantBias, tangent [accelerometer, gyroscope]), scale K (1-vector),
misalignment b_R_d] then [time offset T (1-vector, s)] with the offset, then [lever arm L (3-vector, m)] when
it is a variable. Pose and b_R_d are perturbed on the right (GTSAM retract), pose tangent [rotation,
translation]. The preintegration's noise over [t_i, t_p] belongs in the ping's covariance (the caller adds it:
keyframe_ping_covariance).
"""

from __future__ import annotations

from dataclasses import dataclass
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
    cross3,
    fill_slots,
    lever_jacobian,
    predict_dvl_velocity,
)
from .dvl_bulk import skew_n
from .dvl_velocity import _offset_prediction


@dataclass(frozen=True)
class PingMotion:
    """The IMU motion from a keyframe at t_i to a ping at t_i + dt, and the Earth model there.

    dR (3x3): body at the ping in the body at the keyframe, from the gyros with zero bias; dv (3,) m/s: the
    specific force integrated in the keyframe's body axes with zero bias; dp (3,) m: dv integrated once more
    (GTSAM's deltaPij); dR_dbg: dR's right tangent per gyro
    bias (s); dv_dba (s), dv_dbg (m/s per rad/s): dv per accelerometer and gyro bias. n_omega_ie
    (rad/s) Earth rate in map (zero in the flat model); n_g0 (m/s^2) gravity in map at n_p0 (m, map), n_G
    (1/s^2) its gradient there (zero in the flat model)."""

    dt: float
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dR_dbg: np.ndarray
    dv_dba: np.ndarray
    dv_dbg: np.ndarray
    n_omega_ie: np.ndarray
    n_g0: np.ndarray
    n_p0: np.ndarray
    n_G: np.ndarray

    def __post_init__(self) -> None:
        as_finite_float("dt", self.dt)
        for name, shape in (("dR", (3, 3)), ("dv", (3,)), ("dp", (3,)), ("dR_dbg", (3, 3)), ("dv_dba", (3, 3)),
                            ("dv_dbg", (3, 3)), ("n_omega_ie", (3,)), ("n_g0", (3,)), ("n_p0", (3,)),
                            ("n_G", (3, 3))):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise ValueError(f"PingMotion.{name} must be a finite array of shape {shape}, got {arr!r}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "_earth_turn", _so3_exp(-self.n_omega_ie * self.dt))
        object.__setattr__(self, "_v_v", np.eye(3) - 2.0 * self.dt * _skew(self.n_omega_ie))
        object.__setattr__(self, "_w_x", _skew(self.n_omega_ie))
        object.__setattr__(self, "_c", self.dt * self.dv + self.dp)
        object.__setattr__(self, "_c_x", _skew(self.dt * self.dv + self.dp))


def _skew(a: np.ndarray) -> np.ndarray:
    x, y, z = np.asarray(a, dtype=float).tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _so3_exp(phi: np.ndarray) -> np.ndarray:
    """Rodrigues' formula (factors/ imports nothing of gtsam_dvl.core)."""
    theta = float(np.sqrt(phi @ phi))
    K = _skew(phi)
    if theta < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * K @ K


def _right_jacobian(phi: np.ndarray) -> np.ndarray:
    """SO(3) right Jacobian: Exp(phi + d) = Exp(phi) Exp(Jr(phi) d) to first order."""
    theta = float(np.sqrt(phi @ phi))
    K = _skew(phi)
    if theta < 1e-6:
        return np.eye(3) - 0.5 * K + K @ K / 6.0
    return (np.eye(3) - (1.0 - np.cos(theta)) / theta**2 * K
            + (theta - np.sin(theta)) / theta**3 * K @ K)


def ping_state(n_R_i: np.ndarray, n_p_i: np.ndarray, n_v_i: np.ndarray, b_a: np.ndarray, b_g: np.ndarray,
               m: PingMotion, with_jacobians: bool = True) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """(n_R_b at the ping, n_v at the ping, Jacobians) from keyframe i's attitude, position, velocity and the
    bias (module doc). Jacobians [A_R_pose (3x6), A_R_bias (3x6), A_v_pose (3x6), A_v_vel (3x3), A_v_bias
    (3x6)]: A_R_* the right tangent of the ping's attitude, A_v_* its velocity, per the pose's right tangent
    [rotation, translation], the velocity and the bias tangent [accelerometer, gyroscope]."""
    phi = m.dR_dbg @ b_g
    dR_c = m.dR @ _so3_exp(phi)
    dv_c = m.dv + m.dv_dba @ b_a + m.dv_dbg @ b_g
    n_g = m.n_g0 + m.n_G @ (n_p_i - m.n_p0)
    earth_turn: np.ndarray = m._earth_turn  # type: ignore[attr-defined]
    v_v: np.ndarray = m._v_v  # type: ignore[attr-defined]
    w_x: np.ndarray = m._w_x  # type: ignore[attr-defined]
    n_R_p = earth_turn @ n_R_i @ dR_c
    c: np.ndarray = m._c  # type: ignore[attr-defined]
    n_v_p = v_v @ n_v_i + n_g * m.dt + n_R_i @ dv_c - w_x @ (n_R_i @ c + n_g * m.dt**2)
    if not with_jacobians:
        return n_R_p, n_v_p, []
    z33 = np.zeros((3, 3))
    A_R_pose = np.concatenate((dR_c.T, z33), axis=1)
    A_R_bias = np.concatenate((z33, _right_jacobian(phi) @ m.dR_dbg), axis=1)
    c_x: np.ndarray = m._c_x  # type: ignore[attr-defined]
    A_v_pose = np.concatenate((-n_R_i @ _skew(dv_c) + w_x @ n_R_i @ c_x,
                               (m.dt * np.eye(3) - m.dt**2 * w_x) @ m.n_G @ n_R_i), axis=1)
    A_v_bias = np.concatenate((n_R_i @ m.dv_dba, n_R_i @ m.dv_dbg), axis=1)
    return n_R_p, n_v_p, [A_R_pose, A_R_bias, A_v_pose, v_v, A_v_bias]


def _keyframe_prediction(n_R_i: np.ndarray, n_p_i: np.ndarray, n_v_i: np.ndarray, b_a: np.ndarray,
                         b_g: np.ndarray, k: float, d_R_b: np.ndarray, m: PingMotion, b_omega: np.ndarray,
                         b_l: np.ndarray, lever_variable: bool, dt_d: float | None,
                         offset_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
                         H: JacobianSlots | None) -> np.ndarray:
    """h (3,) in dvl_link; H: [pose, vel, bias, k, b_R_d] + [dt_d] + [b_l] as the keys (module doc)."""
    n_R_p, n_v_p, A = ping_state(n_R_i, n_p_i, n_v_i, b_a, b_g, m, H is not None)
    n_model = 4 + (dt_d is not None)
    Hd: list[np.ndarray] | None = None if H is None else [np.empty(0)] * n_model
    if dt_d is not None:
        assert offset_input is not None
        o_b_a, o_n_g, o_G = offset_input
        h = _offset_prediction(n_R_p, n_v_p, k, d_R_b, dt_d, b_omega, cross3(b_omega, b_l), o_b_a, o_n_g, o_G, Hd)
    else:
        h = predict_dvl_velocity(n_R_p, n_v_p, k, d_R_b, cross3(b_omega, b_l), Hd)
    if H is not None and Hd is not None:
        A_R_pose, A_R_bias, A_v_pose, A_v_vel, A_v_bias = A
        h_R, h_v = Hd[0][:, :3], Hd[1]
        H[0] = h_R @ A_R_pose + h_v @ A_v_pose
        H[1] = h_v @ A_v_vel
        H[2] = h_R @ A_R_bias + h_v @ A_v_bias
        H[3] = Hd[2]
        H[4] = Hd[3]
        if dt_d is not None:
            H[5] = Hd[4]
        if lever_variable:
            H[n_model + 1] = lever_jacobian(k, d_R_b, b_omega)
    return h


def dvl_keyframe_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    bias: gtsam.imuBias.ConstantBias,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    d_y: np.ndarray | float,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    motion: PingMotion,
    dt_d: float | np.ndarray | None = None,
    offset_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    lever_variable: bool = False,
    d_u: np.ndarray | None = None,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """e = h(ping state) - d_y (3,), or with a beam unit vector d_u (dvl_link) e = d_u . h - d_y (1,).

    n_T_b, n_v, bias: keyframe i's pose, velocity and the IMU bias; k, b_R_d the calibration; d_y the ping's
    velocity (m/s, dvl_link) or beam velocity; b_omega (rad/s) the body rate relative to map at the ping, b_l
    (m, base_link) the lever arm; motion the IMU motion keyframe -> ping. dt_d (s) with offset_input = (b_a,
    n_g, G) of the ping (FactorMaker.velocity_rate_input, offset gravity): the time-offset model.
    lever_variable: b_l is a variable (one more Jacobian slot). H: slots for [pose 6, velocity 3, bias 6,
    k 1, b_R_d 3] + [dt_d 1] + [b_l 3]."""
    n_slots = 5 + (dt_d is not None) + lever_variable
    computed: list[np.ndarray] | None = None if H is None else [np.empty(0)] * n_slots
    h = _keyframe_prediction(n_T_b.rotation().matrix(), np.asarray(n_T_b.translation(), dtype=float),
                             np.asarray(n_v, dtype=float), np.asarray(bias.accelerometer(), dtype=float),
                             np.asarray(bias.gyroscope(), dtype=float), as_scale(k), b_R_d.matrix().T, motion,
                             np.asarray(b_omega, dtype=float), np.asarray(b_l, dtype=float).reshape(3),
                             lever_variable, None if dt_d is None else as_scale(dt_d), offset_input, computed)
    if d_u is not None:
        u = np.asarray(d_u, dtype=float).reshape(1, 3)
        if H is not None and computed is not None:
            fill_slots(H, [u @ J for J in computed])
        return np.array([float(u[0] @ h) - float(np.asarray(d_y, dtype=float).reshape(()))])
    if H is not None and computed is not None:
        fill_slots(H, computed)
    return h - np.asarray(d_y, dtype=float)


def make_dvl_keyframe_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    bias_key: int,
    scale_key: int,
    b_R_d_key: int,
    d_y: Vector3Like | float,
    b_omega: Vector3Like,
    b_l: Vector3Like,
    motion: PingMotion,
    offset_key: int | None = None,
    offset_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    lever_key: int | None = None,
    d_u: Vector3Like | None = None,
) -> gtsam.CustomFactor:
    """DvlKeyframeFactor on [pose X_i, velocity V_i, bias B, scale, b_R_d] (+ [time offset] with offset_key and
    offset_input = (b_a, n_g, G), + [lever arm] with lever_key, b_l then only its initial value is unused):
    a ping between keyframes through the IMU motion from keyframe i (module doc, dvl_keyframe_error). With a
    beam unit vector d_u, d_y is the beam's velocity and the factor 1-dimensional. noise: a GTSAM noise model of
    the factor's dimension (the ping's covariance plus keyframe_ping_covariance, possibly robust). Raises
    ValueError on non-finite or wrongly shaped inputs or a noise model of the wrong dimension."""
    beam = d_u is not None
    check_noise(noise, 1 if beam else 3)
    u = as_unit_vector3("d_u", d_u) if beam else None
    y: np.ndarray | float = as_finite_float("d_y", d_y) if beam else as_vector3("d_y", d_y)
    b_om = as_vector3("b_omega", b_omega)
    b_l_c = as_vector3("b_l", b_l)
    if (offset_key is None) != (offset_input is None):
        raise ValueError("offset_key and offset_input go together")
    if beam and offset_key is not None:
        raise ValueError("the time offset works with the 3-D velocity only, not with a beam")
    o_in: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    if offset_input is not None:
        G = np.array(offset_input[2], dtype=float)
        if G.shape != (3, 3) or not np.all(np.isfinite(G)):
            raise ValueError(f"G must be a finite 3x3 matrix, got {G}")
        o_in = (as_vector3("b_a", offset_input[0]), as_vector3("n_g", offset_input[1]), G)
    offset, lever = offset_key is not None, lever_key is not None
    keys = [pose_key, vel_key, bias_key, scale_key, b_R_d_key] + ([] if offset_key is None else [offset_key]) \
        + ([] if lever_key is None else [lever_key])
    n_slots = len(keys)
    u_row = None if u is None else u.reshape(1, 3)

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        ks = this.keys()
        pose = values.atPose3(ks[0])
        bias = values.atConstantBias(ks[2])
        computed: list[np.ndarray] | None = None if H is None else [np.empty(0)] * n_slots
        h = _keyframe_prediction(
            pose.rotation().matrix(), pose.translation(), values.atPoint3(ks[1]), bias.accelerometer(),
            bias.gyroscope(), values.atVector(ks[3]).item(), values.atRot3(ks[4]).matrix().T, motion, b_om,
            values.atPoint3(ks[-1]) if lever else b_l_c, lever,
            values.atVector(ks[5]).item() if offset else None, o_in, computed)
        if u_row is not None:
            if H is not None and computed is not None:
                for n, J in enumerate(computed):
                    H[n] = u_row @ J
            return np.array([float(u_row[0] @ h) - float(y)])
        if H is not None and computed is not None:
            for n, J in enumerate(computed):
                H[n] = J
        return h - y

    return gtsam.CustomFactor(noise, keys, error_func)


def keyframe_ping_covariance(cov_pim: np.ndarray, dR: np.ndarray, d_R_b: np.ndarray, b_v: np.ndarray,
                             k: float = 1.0) -> np.ndarray:
    """The preintegration noise over [t_i, t_p] mapped into the ping's 3-D velocity (3x3, m^2/s^2):
    J cov_pim J^T with J = k d_R_b [[b_v]_x, 0, dR^T] over GTSAM's preintegration error [rotation, position,
    velocity] (cov_pim 9x9): a right rotation of the ping's attitude and a velocity increment in the keyframe's
    body axes. b_v (m/s, base_link) the body velocity at the ping (e.g. from the ping at the prior calibration),
    d_R_b = b_R_d^T. With navigation-grade noise (10 micro-g/sqrt(Hz)) it is 1e-4 m/s over 1 s."""
    return keyframe_ping_covariances(np.asarray(cov_pim, dtype=float)[None], np.asarray(dR, dtype=float)[None],
                                     d_R_b, np.asarray(b_v, dtype=float).reshape(1, 3), k)[0]


def keyframe_ping_covariances(cov_pim: np.ndarray, dR: np.ndarray, d_R_b: np.ndarray, b_v: np.ndarray,
                              k: float = 1.0) -> np.ndarray:
    """keyframe_ping_covariance of N pings at once: cov_pim (N, 9, 9), dR (N, 3, 3), b_v (N, 3) -> (N, 3, 3)."""
    n = len(b_v)
    J = np.zeros((n, 3, 9))
    J[:, :, :3] = skew_n(np.asarray(b_v, dtype=float))
    J[:, :, 6:] = np.transpose(dR, (0, 2, 1))
    J = k * np.asarray(d_R_b, dtype=float) @ J
    return np.asarray(J @ cov_pim @ np.transpose(J, (0, 2, 1)))
