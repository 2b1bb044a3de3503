"""Strapdown mechanisation between two DVL epochs, vectorised over the IMU samples, and the error-state
transition matrix of the same interval for the EKF (gtsam_dvl/estimators/ekf/filter.py).

Navigation equations in the Earth-fixed map frame (docs/conventions.md; the paper's eq. 3-5 with the map as
reference frame, so there is no transport rate and position is Cartesian):

    d/dt n_R_b = n_R_b [b_omega_ib - b_g]x - [n_omega_ie]x n_R_b
    d/dt n_v   = n_R_b (b_f - b_a) - 2 n_omega_ie x n_v + n_g(n_p)
    d/dt n_p   = n_v

n_g is normal gravity (gravitation and centrifugal) at the vehicle's position (earth.LocalFrame.n_gravity).
Because the Earth rate is constant in the map frame the attitude separates exactly into a left factor and
a body factor: n_R_b(t) = Exp(-n_omega_ie t) n_R_b(0) B(t), with B the ordered product of the body
increments Exp(dtheta_j), computed here as a prefix product of quaternions (log2(m) vectorised steps).

IMU samples are interval averages (types.ImuData): sample j gives dtheta_j = omega_j dt_j and dv_j = f_j dt_j
accumulated while the body turns, so each delta-v is rotated back to the sample's start, dv_j + 1/2
dtheta_j x dv_j, as the graph builder does before preintegration (graph/log_graph.py). The velocity is integrated
in the map frame, so the turn that matters is the one relative to the map: the gyro's increment minus
the Earth rate, dtheta_j - n_R_b^T w_ie dt_j (with the raw increment a static IMU would see a spurious
0.4 micro-g, 2 mm/s after ten minutes; GTSAM's preintegration works in a non-rotating frame, where the
raw increment is the right one).

Error state, "true = estimate (+) error": the navigation error (N_NAV = 9)
    phi (0:3)   attitude, map axes, left:   n_R_b = Exp(phi) n_R_b_est
    dv  (3:6)   velocity, map             dp (6:9) position, map
then the shared states the EKF carries, in the columns of core/states.py ekf_layout (the one source of BG, BA,
SCALE, MIS and the time offset's column): dbg (9:12) gyro bias, dba (12:15) accelerometer bias, dk (15) DVL
scale, psi (16:19) b_R_d = b_R_d_est Exp(psi) (right, as GTSAM's Rot3), the time offset (19) when estimated; the
transition below covers the first N_ERR = 19. After them the water current's layer boundaries, then the blocks of
the per-epoch states the configuration carries (estimators/models/epoch_states.py, in registry order: the DVL's
correlated error, the water current; FilterState.epoch_slices). With the linearised dynamics
    phi' = -[w_ie]x phi - n_R_b dbg
    dv'  = -[n_R_b f]x phi - 2 [w_ie]x dv + G dp - n_R_b dba        (G = d n_g / d n_p)
    dp'  = dv
integrated in closed form over the interval from the same sample quantities: exact in the time-varying
attitude and specific force, first order in the Earth rate and the gravity gradient (the terms dropped
are below 1e-4 of the ones kept over a one-second interval; tests/estimators/test_ekf.py checks it numerically).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.rotations import skew, so3_exp
from gtsam_dvl.core.states import ekf_layout

N_NAV = 9  # attitude, velocity, position: the error state's navigation part
PHI, VEL, POS = slice(0, 3), slice(3, 6), slice(6, 9)
LAYOUT = ekf_layout(None, N_NAV)  # the shared states' columns, with every state the EKF can carry
BG, BA, MIS = LAYOUT["gyro_bias"], LAYOUT["accel_bias"], LAYOUT["misalignment"]
SCALE = LAYOUT["scale"].start  # (a scalar's column)
N_ERR = MIS.stop  # the navigation error and the shared states the strapdown's transition covers
OFFSET = LAYOUT["time_offset"].start  # error-state index of the DVL time offset dt_d (s)
CALIBRATION = np.r_[
    LAYOUT["scale"], LAYOUT["misalignment"]
]  # error-state indices of the DVL scale, misalignment


@dataclass
class NavState:
    """Nominal navigation state: base_link attitude, velocity and position in the map frame."""

    n_R_b: np.ndarray
    n_v: np.ndarray
    n_p: np.ndarray


class FilterState:
    """Nominal state and error-state covariance of the filter (module doc: the error state's layout)."""

    def __init__(
        self,
        nav: NavState,
        gyro_bias: np.ndarray,
        accel_bias: np.ndarray,
        scale: float,
        b_R_d: np.ndarray,
        P: np.ndarray,
        time_offset: float = 0.0,
        dvl_error: np.ndarray | None = None,
        current: np.ndarray | None = None,
        epoch: dict[str, np.ndarray] | None = None,
    ) -> None:
        self.nav, self.gyro_bias, self.accel_bias = nav, gyro_bias, accel_bias
        self.scale, self.b_R_d = scale, b_R_d
        self.P = P  # (19, 19), or (20, 20) with the time offset, then the blocks below
        self.time_offset = time_offset  # dt_d, s (with [dvl] estimate_time_offset)
        # the per-epoch states' estimates (estimators/models/epoch_states.py), by name in the order of their blocks,
        # the last components of the error state: the DVL's correlated error "dvl_error" (3,) m/s in dvl_link
        # (estimators/models/correlated.py), the water current "water_current" [c_east, c_north] (2,) m/s in map
        # (estimators/models/current.py), ...
        self.epoch: dict[str, np.ndarray] = {} if epoch is None else dict(epoch)
        if dvl_error is not None:
            self.epoch["dvl_error"] = dvl_error
        if current is not None:
            self.epoch["water_current"] = current
        # with [current] layer_thickness_m > 0: the current's change across each layer boundary crossed so far
        # (estimators/models/current.py, "Layers"), (n, 2) m/s in map, boundary shear_ids[r] in row r; their
        # error-state components sit before the per-epoch states' blocks, two per boundary
        self.shear: np.ndarray | None = None
        self.shear_ids: list[int] = []
        self.layer = 0  # the depth layer of the nominal state (with layers)

    @property
    def dvl_error(self) -> np.ndarray | None:
        """The DVL's correlated error's estimate (None when not modelled)."""
        return self.epoch.get("dvl_error")

    @property
    def current(self) -> np.ndarray | None:
        """The water current's estimate (None when not modelled)."""
        return self.epoch.get("water_current")

    def epoch_dims(self) -> int:
        """The error-state components of the per-epoch states' blocks (the last ones)."""
        return sum(len(v) for v in self.epoch.values())

    def epoch_slices(self) -> dict[str, slice]:
        """Each per-epoch state's error-state columns: its block, in the order of `epoch`, at the end."""
        out: dict[str, slice] = {}
        start = len(self.P) - self.epoch_dims()
        for name, value in self.epoch.items():
            out[name] = slice(start, start + len(value))
            start += len(value)
        return out

    def error_slice(self) -> slice | None:
        """The correlated DVL error's error-state columns, None when not modelled."""
        return self.epoch_slices().get("dvl_error")

    def current_slice(self) -> slice | None:
        """The water current's error-state columns, None when not modelled."""
        return self.epoch_slices().get("water_current")

    def shear_slice(self) -> slice | None:
        """The layer boundaries' error-state columns (before the per-epoch states' blocks), None without layers."""
        if self.shear is None:
            return None
        end = len(self.P) - self.epoch_dims()
        return slice(end - 2 * len(self.shear_ids), end)

    def extra_states(self) -> int:
        """How many error-state components follow the time offset's place: the layer boundaries' and the per-epoch
        states'."""
        return self.epoch_dims() + 2 * len(self.shear_ids)

    def inject(self, dx: np.ndarray) -> None:
        """The error dx (the error state's layout, module doc) injected into the nominal state: true = estimate (+)
        error, the attitude's about map axes (left), the misalignment's in the DVL frame (right). Each attribute
        is replaced, never changed in place (a shallow copy of the state keeps its own values)."""
        nav = self.nav
        self.nav = NavState(so3_exp(dx[PHI]) @ nav.n_R_b, nav.n_v + dx[VEL], nav.n_p + dx[POS])
        self.gyro_bias = self.gyro_bias + dx[BG]
        self.accel_bias = self.accel_bias + dx[BA]
        self.scale = self.scale + float(dx[SCALE])
        self.b_R_d = self.b_R_d @ so3_exp(dx[MIS])
        slices = self.epoch_slices()  # the per-epoch states' (epoch_states.py)
        self.epoch = {name: value + dx[slices[name]] for name, value in self.epoch.items()}
        if (sh := self.shear_slice()) is not None:
            assert self.shear is not None
            self.shear = self.shear + dx[sh].reshape(-1, 2)
        if len(dx) - self.extra_states() > OFFSET:
            self.time_offset = self.time_offset + float(dx[OFFSET])


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
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


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


def propagate_interval(
    state: NavState,
    b_omega: np.ndarray,
    b_f: np.ndarray,
    dt: np.ndarray,
    n_omega_ie: np.ndarray,
    n_g: np.ndarray,
    G: np.ndarray,
) -> IntervalResult:
    """Integrate bias-corrected IMU pieces (b_omega, b_f (m, 3); durations dt (m,)) from `state`.

    n_g is gravity at the interval's mid position and G its gradient (the interval is short: gravity
    changes by 1.6e-7 rad per metre, about 3e-7 m/s^2 over one interval at 2 m/s).
    """
    T = float(dt.sum())
    dtheta = b_omega * dt[:, None]
    dv = b_f * dt[:, None]
    B = prefix_rotations(dtheta)  # (m + 1, 3, 3)
    tau = np.concatenate([[0.0], np.cumsum(dt)])  # piece boundaries relative to the interval start
    R0B = state.n_R_b @ B  # (m + 1, 3, 3) = R0 B_j
    W = skew(n_omega_ie)
    R = so3_exp(-np.outer(tau, n_omega_ie)) @ R0B  # Exp(-w tau) R0 B_j
    # turn relative to map
    dtheta_nb = dtheta - np.einsum("jba,b->ja", R[:-1], n_omega_ie) * dt[:, None]
    dv_start = dv + 0.5 * _cross_rows(dtheta_nb, dv)  # delta-v in the body at the sample's start
    dv_n = np.einsum("jab,jb->ja", R[:-1], dv_start)  # specific-force velocity increments in map
    sum_dv = np.concatenate([np.zeros((1, 3)), np.cumsum(dv_n, axis=0)])  # (m + 1, 3)
    v_nc = state.n_v + sum_dv + np.outer(tau, n_g)  # velocity without Coriolis at the boundaries
    dp_nc = np.cumsum((v_nc[:-1] + 0.5 * (dv_n + n_g * dt[:, None])) * dt[:, None], axis=0)
    dp_nc = np.concatenate([np.zeros((1, 3)), dp_nc])  # position change without Coriolis
    # Coriolis -2 w x v integrates to -2 w x dp (exact up to w^2 terms: 5e-9 m/s^2)
    dv_cor = -2.0 * W @ dp_nc[-1]
    dp_cor = -2.0 * W @ np.sum(0.5 * (dp_nc[:-1] + dp_nc[1:]) * dt[:, None], axis=0)
    n_R_b = R[-1]
    new = NavState(n_R_b, v_nc[-1] + dv_cor, state.n_p + dp_nc[-1] + dp_cor)

    # ----- transition matrix: closed-form integrals of the linearised dynamics over the interval
    R_mid = 0.5 * (R[:-1] + R[1:])  # attitude over each piece
    R_dt = R_mid * dt[:, None, None]
    S_R = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(R_dt, axis=0)])  # int_0^tau n_R_b
    S_R_mid = S_R[:-1] + 0.5 * R_dt
    dv_skew = skew(dv_n)  # [a dt]x per piece
    tau_mid = 0.5 * (tau[:-1] + tau[1:])
    zero = np.zeros((1, 3, 3))
    # velocity error at each piece boundary per unit initial phi, dbg, dba (without Coriolis), (m + 1, 3, 9):
    # phi(tau) = phi - tau w x phi - int n_R_b dbg enters through -[a]x; dba through -n_R_b
    V = np.concatenate(
        [
            -skew(sum_dv)
            + np.concatenate([zero, np.cumsum(dv_skew * tau_mid[:, None, None], axis=0)]) @ W,
            np.concatenate([zero, np.cumsum(dv_skew @ S_R_mid, axis=0)]),
            -S_R,
        ],
        axis=2,
    )
    P = np.concatenate(
        [np.zeros((1, 3, 9)), np.cumsum(0.5 * (V[:-1] + V[1:]) * dt[:, None, None], axis=0)]
    )
    Q = np.sum(0.5 * (P[:-1] + P[1:]) * dt[:, None, None], axis=0)
    cols = np.r_[0:3, 9:15]  # phi, dbg, dba
    Phi = np.eye(N_ERR)
    Phi[PHI, PHI] = small_rotation(-n_omega_ie * T)
    # a gyro bias error at tau turns with the Earth rate until T: -int (I - (T - tau) [w]x) n_R_b dtau
    Phi[PHI, BG] = -S_R[-1] + W @ np.sum(R_dt * (T - tau_mid)[:, None, None], axis=0)
    # Coriolis on the velocity error built up in the interval
    Phi[VEL, cols] = V[-1] - 2.0 * W @ P[-1]
    Phi[POS, cols] = P[-1] - 2.0 * W @ Q
    Phi[VEL, VEL] = np.eye(3) - 2.0 * W * T
    Phi[VEL, POS] = G * T
    Phi[POS, VEL] = np.eye(3) * T - W * T**2
    Phi[POS, POS] = np.eye(3) + 0.5 * G * T**2
    return IntervalResult(new, Phi, T)


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise a x b of (m, 3) arrays (np.cross's axis handling costs more than the product here)."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )
