"""GTSAM 4.3's ImuFactor with the EarthImuFactor's gravity gradient, evaluated for N factors at once with numpy.

Why: through GTSAM's CustomFactor each IMU factor of the batch smoother costs a Python call per linearisation
and per error evaluation (factors/imu_earth.py), and a day of 1 s keyframes has 86,400 of them (the timings:
docs/results.md, Speed). The batch smoother owns its Gauss-Newton loop, so it evaluates them all in a few
vectorised operations instead (estimators/graph/bulk_imu.py). The model is GTSAM's, written for stacks of factors; it is
checked against gtsam.ImuFactor.evaluateError (errors and Jacobians to 1e-9) and against numerical derivatives
in tests/factors/test_imu_bulk.py.

The model (GTSAM 4.3: tangent preintegration, the rotating-frame prediction NavState::predictPIM, the SE_2(3)
Logmap error of ImuFactorErrorMode::Logmap, the default). Per factor, from the preintegration at bias estimate
zero: x = [theta, dp, dv] (PreintegratedImuMeasurements.preintegrated()), H = dx/d[b_a, b_g] (9x6), dt. With
the bias b = [b_a, b_g] of state i the bias-corrected increment is x_c = x + H b, and with Earth rate Omega in map
(zero: the inertial prediction, the same formula with A = I), A = Exp(-Omega dt), Gv = J_l(-Omega dt),
Gp = Gv - Gamma_2(-Omega dt):

    R_P = A n_R_i Exp(theta_c)
    p_P = Gp n_g dt^2 + A (n_p_i + vbar dt + n_R_i dp_c),        vbar = n_v_i + Omega x n_p_i
    v_P = Gv n_g dt   + A (vbar + n_R_i dv_c) - Omega x p_P
    e   = Logmap_SE23( X_j^-1 * P )                                 [rotation, position, velocity]

Jacobians on GTSAM's tangents: poses perturbed on the right ([rotation, translation], translation in body
axes), velocities in map, bias [accelerometer, gyroscope]. With E = X_j^-1 P and J = LogmapDerivative(e), a
variation of P (dR_P = R_P [eps_R], dp_P, dv_P) moves e by J [eps_R; R_P^T dp_P; R_P^T dv_P], one of X_j by
J [-R_E^T w; R_E^T ([p_E] w - dp); R_E^T [v_E] w - R_P^T dv_j].

The gravity n_g is the factor's reference extrapolated to the mid position, and its gradient enters the
translation Jacobians as the EarthImuFactor adds it (factors/imu_earth.py): rows [position, velocity] of
X_i and X_j get R_j^T (M G / 2) R_i and R_j^T (M G / 2) R_j.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np

from .so3 import exp, inv_right_jacobian, log, right_jacobian, skew

# rad: below, the rotation functions' coefficients from their series (closed forms cancel)
_SMALL = 0.1


def _theta2(phi: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", phi, phi)


def _left_jacobian_apply_derivative(phi: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """d(J_l(phi) rho) / d phi (N, 3, 3), with J_l(phi) rho = rho + B phi x rho + C phi x (phi x rho),
    B = (1 - cos)/theta^2, C = (theta - sin)/theta^3 (their derivatives B'/theta, C'/theta by series below
    _SMALL)."""
    t2 = _theta2(phi)
    t = np.sqrt(t2)
    small = t < _SMALL
    ts = np.where(small, 1.0, t)
    s, c = np.sin(ts), np.cos(ts)
    B = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - c) / ts**2)
    C = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (ts - s) / ts**3)
    dB = np.where(
        small, -1.0 / 12.0 + t2 / 180.0 - t2 * t2 / 6720.0, (ts * s - 2.0 * (1.0 - c)) / ts**4
    )
    dC = np.where(
        small,
        -1.0 / 60.0 + t2 / 1260.0 - t2 * t2 / 60480.0,
        (1.0 - c) / ts**4 - 3.0 * (ts - s) / ts**5,
    )
    phi_x_rho = np.cross(phi, rho)
    phi_x2_rho = np.cross(phi, phi_x_rho)
    phi_dot_rho = np.einsum("ni,ni->n", phi, rho)
    D = (
        phi_dot_rho[:, None, None] * np.eye(3)
        + phi[:, :, None] * rho[:, None, :]
        - 2.0 * rho[:, :, None] * phi[:, None, :]
    )  # d(phi x (phi x rho)) / d phi
    return (
        -B[:, None, None] * skew(rho)
        + dB[:, None, None] * phi_x_rho[:, :, None] * phi[:, None, :]
        + C[:, None, None] * D
        + dC[:, None, None] * phi_x2_rho[:, :, None] * phi[:, None, :]
    )


def se23_log_n(R: np.ndarray, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Logmap of SE_2(3) elements (R, p, v) -> xi (N, 9) = [phi, J_l(phi)^-1 p, J_l(phi)^-1 v] and its derivative
    LogmapDerivative (N, 9, 9) = [[Jw, 0, 0], [-Jw Q_p Jw, Jw, 0], [-Jw Q_v Jw, 0, Jw]], Jw = J_r(phi)^-1,
    Q_x = Exp(phi)^T d(J_l(phi) x)/d phi at x = the log's translation parts (GTSAM's NavState::LogmapDerivative)."""
    phi = log(R)
    Jw = inv_right_jacobian(phi)
    Jl_inv = np.swapaxes(Jw, 1, 2)  # J_l^-1 = (J_r^-1)^T
    rho = np.einsum("nij,nj->ni", Jl_inv, p)
    nu = np.einsum("nij,nj->ni", Jl_inv, v)
    Rt = np.swapaxes(R, 1, 2)
    J = np.zeros((len(phi), 9, 9))
    J[:, 0:3, 0:3] = J[:, 3:6, 3:6] = J[:, 6:9, 6:9] = Jw
    J[:, 3:6, 0:3] = -Jw @ (Rt @ _left_jacobian_apply_derivative(phi, rho)) @ Jw
    J[:, 6:9, 0:3] = -Jw @ (Rt @ _left_jacobian_apply_derivative(phi, nu)) @ Jw
    return np.concatenate([phi, rho, nu], axis=1), J


def earth_increment(
    n_omega: np.ndarray, dt: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A = Exp(-Omega dt), Gv = J_l(-Omega dt), Gp = Gv - Gamma_2(-Omega dt) (N, 3, 3) for dt (N,), as GTSAM's
    rotating-frame prediction forms them. |Omega dt| is the Earth's turn over an IMU interval (7.3e-5 rad per
    second): the series to the fourth power are exact to rounding for intervals up to hours."""
    w = -np.asarray(n_omega, dtype=float)[None, :] * dt[:, None]
    K = skew(w)
    K2 = K @ K
    K3, K4 = K2 @ K, K2 @ K2
    eye = np.eye(3)
    A = exp(w)
    Gv = eye + K / 2.0 + K2 / 6.0 + K3 / 24.0 + K4 / 120.0
    G2 = eye / 2.0 + K / 6.0 + K2 / 24.0 + K3 / 120.0 + K4 / 720.0
    return A, Gv, Gv - G2


def gravity_maps(n_omega: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """M (N, 6, 3) = d(predicted n_p, n_v) / d n_g of the module doc's prediction: [Gp dt^2; Gv dt - [Omega]x Gp dt^2]
    (the EarthImuFactor measures the same by probing its pim: factors/imu_earth.py)."""
    _, Gv, Gp = earth_increment(n_omega, dt)
    Mp = Gp * (dt * dt)[:, None, None]
    Mv = (
        Gv * dt[:, None, None]
        - skew(np.broadcast_to(np.asarray(n_omega, dtype=float), (len(dt), 3))) @ Mp
    )
    return np.concatenate([Mp, Mv], axis=1)


@dataclass
class ImuArrays:
    """N IMU factors' preintegrations (factor n joins states state[n] and state[n] + 1).

    x (N, 9): [theta (rad), dp (m), dv (m/s)] at bias estimate zero; H (N, 9, 6): dx / d[b_a, b_g]; dt (N,) s the
    integrated time; n_omega (3,) rad/s Earth rate in map (zeros: inertial); M (N, 6, 3) d(predicted n_p, n_v) /
    d n_g (gravity_maps: the EarthImuFactor probes its pim for the same), for the gravity-gradient term."""

    x: np.ndarray
    H: np.ndarray
    dt: np.ndarray
    n_omega: np.ndarray
    M: np.ndarray

    def __post_init__(self) -> None:
        self.A, self.Gv, self.Gp = earth_increment(self.n_omega, self.dt)

    def __len__(self) -> int:
        return len(self.dt)

    def part(self, sl: slice) -> ImuArrays:
        """Factors sl (views, the Earth increments not computed again)."""
        out = ImuArrays.__new__(ImuArrays)
        out.x, out.H, out.dt, out.n_omega, out.M = (
            self.x[sl],
            self.H[sl],
            self.dt[sl],
            self.n_omega,
            self.M[sl],
        )
        out.A, out.Gv, out.Gp = self.A[sl], self.Gv[sl], self.Gp[sl]
        return out


@dataclass
class ImuJacobians:
    """Jacobian blocks of N IMU factors: X_i (N, 9, 6), V_i (N, 9, 3), X_j (N, 9, 6), V_j (N, 9, 3), B (N, 9, 6)."""

    pose_i: np.ndarray
    vel_i: np.ndarray
    pose_j: np.ndarray
    vel_j: np.ndarray
    bias: np.ndarray


def imu_errors(
    f: ImuArrays,
    n_R_i: np.ndarray,
    n_p_i: np.ndarray,
    n_v_i: np.ndarray,
    n_R_j: np.ndarray,
    n_p_j: np.ndarray,
    n_v_j: np.ndarray,
    bias: np.ndarray,
    n_g: np.ndarray,
    MG2: np.ndarray | None = None,
    jacobians: bool = False,
) -> tuple[np.ndarray, ImuJacobians | None]:
    """Errors (N, 9) of N IMU factors (module doc) at states i and j (n_R (N, 3, 3), n_p (N, 3) m, n_v (N, 3)
    m/s), bias (N, 6) [b_a m/s^2, b_g rad/s] and gravity n_g (N, 3) m/s^2; with jacobians, the blocks too, and
    with MG2 (N, 2, 3, 3) = [M_p G; M_v G] / 2 the gravity-gradient term in the translation blocks."""
    dt = f.dt
    x_c = f.x + np.einsum("nij,nj->ni", f.H, bias)
    theta_c, dp_c, dv_c = x_c[:, 0:3], x_c[:, 3:6], x_c[:, 6:9]
    # Earth rate in map, rad/s
    n_omega_ie = np.broadcast_to(np.asarray(f.n_omega, dtype=float), n_p_i.shape)
    R_U = exp(theta_c)
    AR_i = f.A @ n_R_i
    R_P = AR_i @ R_U
    vbar = n_v_i + np.cross(n_omega_ie, n_p_i)
    p_P = (
        np.einsum("nij,nj->ni", f.Gp, n_g) * (dt * dt)[:, None]
        + np.einsum("nij,nj->ni", f.A, n_p_i + vbar * dt[:, None])
        + np.einsum("nij,nj->ni", AR_i, dp_c)
    )
    v_P = (
        np.einsum("nij,nj->ni", f.Gv, n_g) * dt[:, None]
        + np.einsum("nij,nj->ni", f.A, vbar)
        + np.einsum("nij,nj->ni", AR_i, dv_c)
        - np.cross(n_omega_ie, p_P)
    )
    R_jt = np.swapaxes(n_R_j, 1, 2)
    R_E = R_jt @ R_P
    p_E = np.einsum("nij,nj->ni", R_jt, p_P - n_p_j)
    v_E = np.einsum("nij,nj->ni", R_jt, v_P - n_v_j)
    e, Jlog = se23_log_n(R_E, p_E, v_E)
    if not jacobians:
        return e, None

    n = len(dt)
    R_Pt = np.swapaxes(R_P, 1, 2)
    R_Et = np.swapaxes(R_E, 1, 2)
    n_omega_x = skew(n_omega_ie)
    dt3 = dt[:, None, None]

    def from_P(eps_R: np.ndarray | None, dp: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """J [eps_R; R_P^T dp; R_P^T (dv - Omega x dp)] for (N, 3, k) variations of (p_Y, v_Y)."""
        k = dp.shape[2]
        eps = np.zeros((n, 9, k))
        if eps_R is not None:
            eps[:, 0:3] = eps_R
        eps[:, 3:6] = R_Pt @ dp
        eps[:, 6:9] = R_Pt @ (dv - n_omega_x @ dp)
        return np.asarray(Jlog @ eps)

    R_Ut = np.swapaxes(R_U, 1, 2)
    # X_i rotation: R_P -> R_P Exp(R_U^T w); dp_Y = -A R_i [dp_c] w, dv_Y = -A R_i [dv_c] w
    H_Ri = from_P(R_Ut, -AR_i @ skew(dp_c), -AR_i @ skew(dv_c))
    # X_i translation (n_p_i + R_i d): vbar moves by Omega x R_i d
    n_omega_x_R_i = n_omega_x @ n_R_i
    H_pi = from_P(None, f.A @ (n_R_i + n_omega_x_R_i * dt3), f.A @ n_omega_x_R_i)
    # V_i (map)
    A_ = np.broadcast_to(f.A, (n, 3, 3))
    H_vi = from_P(None, A_ * dt3, A_)
    # bias: theta_c, dp_c, dv_c move by H b
    H_B = from_P(right_jacobian(theta_c) @ f.H[:, 0:3], AR_i @ f.H[:, 3:6], AR_i @ f.H[:, 6:9])
    # X_j rotation and translation, V_j
    eps = np.zeros((n, 9, 3))
    eps[:, 0:3] = -R_Et
    eps[:, 3:6] = R_Et @ skew(p_E)
    eps[:, 6:9] = R_Et @ skew(v_E)
    H_Rj = Jlog @ eps
    eps = np.zeros((n, 9, 3))
    eps[:, 3:6] = -R_Et
    H_pj = Jlog @ eps
    eps = np.zeros((n, 9, 3))
    eps[:, 6:9] = -R_Pt
    H_vj = Jlog @ eps

    pose_i = np.concatenate([H_Ri, H_pi], axis=2)
    pose_j = np.concatenate([H_Rj, H_pj], axis=2)
    if MG2 is not None:  # the EarthImuFactor's gravity-gradient term (factors/imu_earth.py)
        T = np.einsum("nba,nkbc->nkac", n_R_j, MG2)  # R_j^T (M G / 2), (N, 2, 3, 3)
        pose_i[:, 3:9, 3:6] += (T @ n_R_i[:, None]).reshape(n, 6, 3)
        pose_j[:, 3:9, 3:6] += (T @ n_R_j[:, None]).reshape(n, 6, 3)
    return e, ImuJacobians(pose_i, H_vi, pose_j, H_vj, H_B)


_Z3 = np.zeros(3)
_BIAS0 = gtsam.imuBias.ConstantBias()
_POSE0 = gtsam.Pose3()


def bias_jacobians(
    pims: list[Any], n_omega: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x (N, 9), H (N, 9, 6), dt (N,)) of N gtsam.PreintegratedImuMeasurements: preintegrated(), its Jacobian
    d x / d[b_a, b_g] at the bias estimate (zero), which GTSAM's Python wrapper does not expose, and deltaTij().
    GTSAM's ImuFactor on each is evaluated once with its Jacobians at X_i = identity, v_i = 0, bias zero and X_j =
    its own prediction there, where the error is zero and the Logmap's derivative the identity, so that its bias
    Jacobian is (module doc, with R_i = I) [J_r(theta) H_theta; R_P^T A H_p; R_P^T (A H_v - Omega x A H_p)], solved
    here for H. n_omega: the Earth rate the pims' parameters hold (zeros if none). Exact to rounding
    (tests/factors/test_imu_bulk.py)."""
    n = len(pims)
    x = np.empty((n, 9))
    H5 = np.empty((n, 9, 6))
    R_P = np.empty((n, 3, 3))
    dt = np.empty(n)
    Hs = [np.zeros((9, d), order="F") for d in (6, 3, 6, 3, 6)]
    state0 = gtsam.NavState()
    for k, pim in enumerate(pims):
        f = gtsam.ImuFactor(0, 1, 2, 3, 4, pim)
        x[k] = pim.preintegrated()
        dt[k] = pim.deltaTij()
        pred = pim.predict(state0, _BIAS0)
        f.evaluateError(_POSE0, _Z3, pred.pose(), pred.velocity(), _BIAS0, *Hs)
        H5[k] = Hs[4]
        R_P[k] = pred.attitude().matrix()
    turn = np.sqrt(_theta2(x[:, 0:3]))
    if n and turn.max() > 2.0 * np.pi - 0.5:  # J_r(theta) is singular at a whole turn
        raise ValueError(
            f"an IMU interval turns by {np.degrees(turn.max()):.0f} deg: more than the bias Jacobian's "
            "inversion takes (shorten the state spacing)"
        )
    A, _, _ = earth_increment(n_omega, dt)
    At = np.swapaxes(A, 1, 2)
    H = np.empty((n, 9, 6))
    H[:, 0:3] = np.linalg.solve(right_jacobian(x[:, 0:3]), H5[:, 0:3])
    A_Hp = R_P @ H5[:, 3:6]
    H[:, 3:6] = At @ A_Hp
    H[:, 6:9] = At @ (R_P @ H5[:, 6:9] + skew(np.broadcast_to(n_omega, (n, 3))) @ A_Hp)
    return x, H, dt
