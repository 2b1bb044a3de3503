"""Strapdown mechanisation between two DVL epochs, vectorised over the IMU samples, and the error-state
transition matrix of the same interval for the EKF (gtsam_dvl/ekf.py).

Navigation equations in the Earth-fixed map frame (CONVENTIONS.md; the paper's eq. 3-5 with the map as
reference frame, so there is no transport rate and position is Cartesian):

    d/dt n_R_b = n_R_b [b_omega_ib - b_g]x - [n_omega_ie]x n_R_b
    d/dt n_v   = n_R_b (b_f - b_a) - 2 n_omega_ie x n_v + n_g(n_p)
    d/dt n_p   = n_v

n_g is normal gravity (gravitation and centrifugal) at the vehicle's position (earth.LocalFrame.n_gravity).
Because the Earth rate is constant in the map frame the attitude separates exactly into a left factor and
a body factor: n_R_b(t) = Exp(-n_omega_ie t) n_R_b(0) B(t), with B the ordered product of the body
increments Exp(dtheta_j), computed here as a prefix product of quaternions (log2(m) vectorised steps).

IMU samples are interval averages (types.ImuData): sample j gives dtheta_j = omega_j dt_j and dv_j = f_j dt_j
accumulated while the body turns by dtheta_j, so each delta-v is rotated back to the sample's start,
dv_j + 1/2 dtheta_j x dv_j, as the graph builder does before preintegration (graph.py).

Error state (19), "true = estimate (+) error":
    phi (0:3)   attitude, map axes, left:   n_R_b = Exp(phi) n_R_b_est
    dv  (3:6)   velocity, map             dp (6:9) position, map
    dbg (9:12)  gyro bias                 dba (12:15) accelerometer bias
    dk  (15)    DVL scale                 psi (16:19) b_R_d = b_R_d_est Exp(psi) (right, as GTSAM's Rot3)
with the linearised dynamics
    phi' = -[w_ie]x phi - n_R_b dbg
    dv'  = -[n_R_b f]x phi - 2 [w_ie]x dv + G dp - n_R_b dba        (G = d n_g / d n_p)
    dp'  = dv
integrated in closed form over the interval from the same sample quantities (first order in the Earth
rate and the gravity gradient, exact in the time-varying attitude and specific force).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.rotations import skew

N_ERR = 19
PHI, VEL, POS, BG, BA, SCALE, MIS = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12), slice(12, 15), 15, slice(
    16, 19)


@dataclass
class NavState:
    """Nominal navigation state: base_link attitude, velocity and position in the map frame."""

    n_R_b: np.ndarray
    n_v: np.ndarray
    n_p: np.ndarray


@dataclass
class IntervalResult:
    """The state at the interval's end and the quantities the covariance propagation needs."""

    state: NavState
    Phi: np.ndarray  # (19, 19) error-state transition over the interval
    duration: float


def quat_exp(phi: np.ndarray) -> np.ndarray:
    """Unit quaternions (m, 4) [w, x, y, z] of rotation vectors phi (m, 3); exact, small angles included."""
    angle = np.linalg.norm(phi, axis=1)
    half = 0.5 * angle
    # sin(a/2)/a with its Taylor series below 1e-4 rad (exact to 1e-18 there)
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    s = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / safe)
    return np.concatenate([np.cos(half)[:, None], s[:, None] * phi], axis=1)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a (x) b of quaternion arrays (..., 4) [w, x, y, z]."""
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (m, 3, 3) of unit quaternions (m, 4) [w, x, y, z]."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def prefix_rotations(dtheta: np.ndarray) -> np.ndarray:
    """B_j = Exp(dtheta_0) ... Exp(dtheta_{j-1}) for j = 0..m, as (m + 1, 3, 3) matrices (B_0 = I).

    Hillis-Steele scan: after the step with shift s, q[j] holds the product of the 2s factors ending at j.
    """
    q = np.concatenate([np.array([[1.0, 0.0, 0.0, 0.0]]), quat_exp(dtheta)], axis=0)
    shift = 1
    while shift < len(q):
        q = np.concatenate([q[:shift], quat_mul(q[:-shift], q[shift:])], axis=0)
        shift *= 2
    return quat_to_matrix(q)


def small_rotation(phi: np.ndarray) -> np.ndarray:
    """Exp(phi) for |phi| below 1e-3 rad (Earth rate over an interval), second order: error < 1e-10."""
    S = skew(phi)
    return np.eye(3) + S + 0.5 * S @ S


def propagate_interval(state: NavState, b_omega: np.ndarray, b_f: np.ndarray, dt: np.ndarray,
                       n_omega_ie: np.ndarray, n_g: np.ndarray, G: np.ndarray) -> IntervalResult:
    """Integrate bias-corrected IMU pieces (b_omega, b_f (m, 3); durations dt (m,)) from `state`.

    n_g is gravity at the interval's mid position and G its gradient (the interval is short: gravity
    changes by 1.6e-7 rad per metre, about 3e-7 m/s^2 over one interval at 2 m/s).
    """
    T = float(dt.sum())
    dtheta = b_omega * dt[:, None]
    dv = b_f * dt[:, None]
    dv_start = dv + 0.5 * np.cross(dtheta, dv)  # delta-v in the body at the sample's start
    B = prefix_rotations(dtheta)  # (m + 1, 3, 3)
    tau = np.concatenate([[0.0], np.cumsum(dt)])  # piece boundaries relative to the interval start
    # left factor Exp(-w tau) R0 to first order in w tau (7e-5 rad over a second): products below 3e-9
    R0B = state.n_R_b @ B  # (m + 1, 3, 3) = R0 B_j
    W = skew(n_omega_ie)
    R = R0B - tau[:, None, None] * (W @ R0B)
    dv_n = np.einsum("jab,jb->ja", R[:-1], dv_start)  # specific-force velocity increments in map
    sum_dv = np.concatenate([np.zeros((1, 3)), np.cumsum(dv_n, axis=0)])  # (m + 1, 3)
    v_nc = state.n_v + sum_dv + np.outer(tau, n_g)  # velocity without Coriolis at the boundaries
    dp_nc = np.cumsum((v_nc[:-1] + 0.5 * (dv_n + n_g * dt[:, None])) * dt[:, None], axis=0)
    dp_nc = np.concatenate([np.zeros((1, 3)), dp_nc])  # position change without Coriolis
    # Coriolis -2 w x v integrates to -2 w x dp (exact up to w^2 terms: 5e-9 m/s^2)
    dv_cor = -2.0 * np.cross(n_omega_ie, dp_nc[-1])
    dp_cor = -2.0 * np.cross(n_omega_ie, np.sum(0.5 * (dp_nc[:-1] + dp_nc[1:]) * dt[:, None], axis=0))
    n_R_b = small_rotation(-n_omega_ie * T) @ R0B[-1]
    new = NavState(n_R_b, v_nc[-1] + dv_cor, state.n_p + dp_nc[-1] + dp_cor)

    # ----- transition matrix: closed-form integrals of the linearised dynamics over the interval
    R_mid = 0.5 * (R[:-1] + R[1:])  # attitude over each piece
    R_dt = R_mid * dt[:, None, None]
    S_R = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(R_dt, axis=0)])  # int_0^tau n_R_b
    S_R_mid = S_R[:-1] + 0.5 * R_dt
    dv_skew = _skew_rows(dv_n)  # [a dt]x per piece
    vbg_inc = dv_skew @ S_R_mid  # [a]x int n_R_b, per piece
    Phi_v_bg = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(vbg_inc, axis=0)])
    Phi = np.eye(N_ERR)
    Phi[PHI, PHI] = small_rotation(-n_omega_ie * T)
    Phi[PHI, BG] = -S_R[-1]
    Phi[VEL, PHI] = -skew(sum_dv[-1])
    Phi[VEL, VEL] = np.eye(3) - 2.0 * W * T
    Phi[VEL, POS] = G * T
    Phi[VEL, BG] = Phi_v_bg[-1]
    Phi[VEL, BA] = -S_R[-1]
    Phi[POS, PHI] = -skew(np.sum((sum_dv[:-1] + 0.5 * dv_n) * dt[:, None], axis=0))
    Phi[POS, VEL] = np.eye(3) * T - W * T**2
    Phi[POS, POS] = np.eye(3) + 0.5 * G * T**2
    Phi[POS, BG] = np.sum((Phi_v_bg[:-1] + 0.5 * vbg_inc) * dt[:, None, None], axis=0)
    Phi[POS, BA] = -np.sum(S_R_mid * dt[:, None, None], axis=0)
    return IntervalResult(new, Phi, T)


def _skew_rows(v: np.ndarray) -> np.ndarray:
    """[v_j]x for each row of v (m, 3) -> (m, 3, 3)."""
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S
