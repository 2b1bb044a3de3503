"""The DVL velocity factors of a whole log evaluated at once with numpy: errors and Jacobians of N pings.

Why: evaluated one by one through GTSAM's CustomFactor, each DVL factor costs a Python call of 15-60 us per
linearisation or error evaluation, and on a 5 Hz log with 1 s keyframes there are 18,000 of them per hour,
evaluated about ten times per solve. The batch smoother owns its Gauss-Newton loop (estimators/solver.py), so
it can evaluate them all in a few vectorised numpy operations instead (estimators/bulk.py turns the result
into GTSAM Jacobian factors). The model is exactly the per-factor one, written for stacks of pings:

- a ping at a state (factors/dvl_velocity.py, `predict_dvl_velocity`, or with the time offset
  `_offset_prediction`) is the special case of a ping between keyframes (factors/dvl_keyframe.py,
  `ping_state` then the same DVL model) with no IMU motion: dt = 0, dR = I, dv = dp = 0 and zero bias
  Jacobians give the keyframe's own attitude and velocity, the direct factor's Jacobians, and zero bias columns;
- so every ping is evaluated by one formula, with the IMU motion of PingMotion given as arrays.

Keys per ping (the carrier's order in estimators/bulk.py): [pose X_i (rotation, translation), velocity V_i,
bias B ([accelerometer, gyroscope]), scale k, misalignment b_R_d] + [time offset dt_d] with the offset model.
tests/factors/test_dvl_bulk.py checks errors and Jacobians against the per-factor functions to 1e-9 and the
Jacobians against numerical derivatives.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np


def skew_n(a: np.ndarray) -> np.ndarray:
    """[a]_x for a stack of 3-vectors (N, 3) -> (N, 3, 3)."""
    out = np.zeros(a.shape[:-1] + (3, 3))
    x, y, z = a[..., 0], a[..., 1], a[..., 2]
    out[..., 0, 1], out[..., 0, 2] = -z, y
    out[..., 1, 0], out[..., 1, 2] = z, -x
    out[..., 2, 0], out[..., 2, 1] = -y, x
    return out


def so3_exp_n(phi: np.ndarray) -> np.ndarray:
    """Rodrigues' formula for a stack of rotation vectors (N, 3), as factors/dvl_keyframe._so3_exp."""
    theta2 = np.einsum("ni,ni->n", phi, phi)
    theta = np.sqrt(theta2)
    K = skew_n(phi)
    K2 = K @ K
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1.0 - np.cos(safe)) / np.where(small, 1.0, theta2))
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * K2


def so3_right_jacobian_n(phi: np.ndarray) -> np.ndarray:
    """SO(3) right Jacobian of a stack of rotation vectors (N, 3), as factors/dvl_keyframe._right_jacobian."""
    theta2 = np.einsum("ni,ni->n", phi, phi)
    theta = np.sqrt(theta2)
    K = skew_n(phi)
    K2 = K @ K
    small = theta < 1e-6
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 0.5, (1.0 - np.cos(safe)) / safe**2)
    b = np.where(small, 1.0 / 6.0, (safe - np.sin(safe)) / safe**3)
    return np.eye(3) - a[:, None, None] * K + b[:, None, None] * K2


@dataclass
class PingArrays:
    """N pings' measurements and IMU motion from their state (keyframe) to the ping.

    state (N,): index of the ping's state in the state arrays; d_y (N, 3) m/s the velocity in dvl_link;
    b_omega (N, 3) rad/s the body rate relative to map at the ping (with the time offset: the mean over its
    window, FactorMaker.velocity_rate_input); b_v_lever (N, 3) m/s = b_omega x b_l. IMU motion (PingMotion,
    factors/dvl_keyframe.py): dt (N,) s, dR (N, 3, 3), dv (N, 3) m/s, dp (N, 3) m, dR_dbg, dv_dba, dv_dbg
    (N, 3, 3); gravity n_g0 (N, 3) m/s^2 at n_p0 (N, 3) m with gradient n_G (N, 3, 3) 1/s^2. A ping at its
    state has dt = 0, dR = I and zeros. With the time offset: offset_b_a (N, 3) m/s^2 and offset_G (N, 3, 3)
    (FactorMaker.velocity_rate_input), else None."""

    state: np.ndarray
    d_y: np.ndarray
    b_omega: np.ndarray
    b_v_lever: np.ndarray
    dt: np.ndarray
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dR_dbg: np.ndarray
    dv_dba: np.ndarray
    dv_dbg: np.ndarray
    n_g0: np.ndarray
    n_p0: np.ndarray
    n_G: np.ndarray
    offset_b_a: np.ndarray | None = None
    offset_G: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.state)

    def part(self, sl: slice) -> PingArrays:
        """The pings sl (views)."""
        parts: dict[str, Any] = {f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[sl]
                                 for f in dataclasses.fields(self)}
        return PingArrays(**parts)


@dataclass
class PingConstants:
    """What depends on the pings and the Earth rate only, computed once (PingMotion's cached terms)."""

    earth_turn: np.ndarray  # Exp(-[w] dt) (N, 3, 3)
    v_v: np.ndarray  # I - 2 dt [w]_x (N, 3, 3)
    c: np.ndarray  # dt dv + dp (N, 3)
    c_x: np.ndarray  # [c]_x (N, 3, 3)
    trans_G: np.ndarray  # (dt I - dt^2 [w]_x) n_G (N, 3, 3)

    def part(self, sl: slice) -> PingConstants:
        """The pings sl (views)."""
        return PingConstants(**{f.name: getattr(self, f.name)[sl] for f in dataclasses.fields(self)})


def ping_constants(p: PingArrays, n_omega_ie: np.ndarray) -> PingConstants:
    w = np.asarray(n_omega_ie, dtype=float)
    w_x = skew_n(w[None])[0]
    dt = p.dt[:, None, None]
    return PingConstants(
        earth_turn=so3_exp_n(-w[None] * p.dt[:, None]),
        v_v=np.eye(3) - 2.0 * dt * w_x,
        c=p.dt[:, None] * p.dv + p.dp,
        c_x=skew_n(p.dt[:, None] * p.dv + p.dp),
        trans_G=(dt * np.eye(3) - dt**2 * w_x) @ p.n_G,
    )


@dataclass
class PingJacobians:
    """Jacobians of the N errors (N, 3, d) per key: pose (6), velocity (3), bias (6), scale (1), b_R_d (3),
    time offset (1, or None without the offset model)."""

    pose: np.ndarray
    vel: np.ndarray
    bias: np.ndarray
    scale: np.ndarray
    b_R_d: np.ndarray
    offset: np.ndarray | None


def dvl_ping_errors(p: PingArrays, const: PingConstants, n_omega_ie: np.ndarray, n_R_i: np.ndarray,
                    n_p_i: np.ndarray, n_v_i: np.ndarray, b_a: np.ndarray, b_g: np.ndarray, k: float,
                    b_R_d: np.ndarray, dt_d: float | None = None, offset_n_g: np.ndarray | None = None,
                    jacobians: bool = True) -> tuple[np.ndarray, PingJacobians | None]:
    """Errors e = h - d_y (N, 3) of the pings (module doc) and, with jacobians, their Jacobians.

    n_R_i (N, 3, 3), n_p_i (N, 3) m, n_v_i (N, 3) m/s: each ping's state (keyframe) attitude, position and
    velocity; b_a, b_g (N, 3): the bias at that state (m/s^2, rad/s); k the scale, b_R_d (3, 3) the
    misalignment; dt_d (s) the time offset with offset_n_g (3,) the offset model's gravity in map
    (FactorMaker.offset_gravity), or None for the model without offset."""
    w = np.asarray(n_omega_ie, dtype=float)
    w_x = skew_n(w[None])[0]
    # ----- the state at the ping (factors/dvl_keyframe.ping_state) -----
    phi = np.einsum("nij,nj->ni", p.dR_dbg, b_g)
    dR_c = p.dR @ so3_exp_n(phi)
    dv_c = p.dv + np.einsum("nij,nj->ni", p.dv_dba, b_a) + np.einsum("nij,nj->ni", p.dv_dbg, b_g)
    n_g = p.n_g0 + np.einsum("nij,nj->ni", p.n_G, n_p_i - p.n_p0)
    n_R_p = const.earth_turn @ n_R_i @ dR_c
    R_c = np.einsum("nij,nj->ni", n_R_i, const.c)
    dt = p.dt[:, None]
    n_v_p = (np.einsum("nij,nj->ni", const.v_v, n_v_i) + n_g * dt + np.einsum("nij,nj->ni", n_R_i, dv_c)
             - (R_c + n_g * dt**2) @ w_x.T)
    # ----- the DVL model at that state (factors/_common.predict_dvl_velocity, dvl_velocity._offset_prediction)
    d_R_b = np.asarray(b_R_d, dtype=float).T
    b_v = np.einsum("nji,nj->ni", n_R_p, n_v_p)  # n_R_p^T n_v_p
    if dt_d is None:
        b_v_eff = b_v + p.b_v_lever
        b_vdot = None
    else:
        assert p.offset_b_a is not None and p.offset_G is not None and offset_n_g is not None
        b_g0 = np.einsum("nji,j->ni", n_R_p, np.asarray(offset_n_g, dtype=float))
        b_grav = np.einsum("nij,nj->ni", p.offset_G, b_g0)
        b_vdot = p.offset_b_a + b_grav - np.cross(p.b_omega, b_v)
        b_v_eff = b_v + dt_d * b_vdot + p.b_v_lever
    d_v = b_v_eff @ d_R_b.T
    e = k * d_v - p.d_y
    if not jacobians:
        return e, None
    k_d_R_b = k * d_R_b
    if dt_d is None:
        h_R = k_d_R_b @ skew_n(b_v)  # (N, 3, 3): per the ping attitude's right tangent
        h_v = k_d_R_b @ np.transpose(n_R_p, (0, 2, 1))
        h_T = None
    else:
        assert p.offset_G is not None and b_vdot is not None
        M = np.eye(3) - dt_d * skew_n(p.b_omega)
        h_R = k_d_R_b @ (M @ skew_n(b_v) + dt_d * p.offset_G @ skew_n(b_g0))
        h_v = k_d_R_b @ M @ np.transpose(n_R_p, (0, 2, 1))
        h_T = (b_vdot @ k_d_R_b.T)[:, :, None]
    n = len(p)
    # ----- chain through the ping state (dvl_keyframe._keyframe_prediction) -----
    A_v_rot = -n_R_i @ skew_n(dv_c) + w_x @ n_R_i @ const.c_x
    A_v_trans = const.trans_G @ n_R_i
    pose = np.empty((n, 3, 6))
    pose[:, :, :3] = h_R @ np.transpose(dR_c, (0, 2, 1)) + h_v @ A_v_rot
    pose[:, :, 3:] = h_v @ A_v_trans
    bias = np.empty((n, 3, 6))
    bias[:, :, :3] = h_v @ n_R_i @ p.dv_dba
    bias[:, :, 3:] = h_R @ so3_right_jacobian_n(phi) @ p.dR_dbg + h_v @ n_R_i @ p.dv_dbg
    J = PingJacobians(pose=pose, vel=h_v @ const.v_v, bias=bias, scale=d_v[:, :, None],
                      b_R_d=skew_n(k * d_v), offset=h_T)
    return e, J
