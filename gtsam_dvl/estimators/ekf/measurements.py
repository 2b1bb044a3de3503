"""The error-state EKF's measurements (filter.py runs them): the DVL velocity of factors/dvl_model.py with its
Jacobian on the error state (strapdown.py's layout), with the time offset, the depth sensor's height, a ping's
measurement (the 3-D velocity or the valid beams) and the depth samples' updates between pings."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.rotations import skew
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.ekf.kalman import update
from gtsam_dvl.estimators.ekf.strapdown import (
    BA,
    BG,
    MIS,
    OFFSET,
    PHI,
    POS,
    SCALE,
    VEL,
    FilterState,
)
from gtsam_dvl.estimators.inputs.depth import DepthSamples
from gtsam_dvl.estimators.inputs.selection import ping_covariance, water_covariance
from gtsam_dvl.factors.dvl_model import DvlJacobians, OffsetInput, dvl_model

RateInput = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # FactorMaker.velocity_rate_input: b_a, mean b_omega, G


def measurement_model(
    fs: FilterState,
    b_omega_m: np.ndarray,
    b_l: np.ndarray,
    n_omega_ie: np.ndarray,
    n_v: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted DVL velocity y (3,) (factors/dvl_model.py), its Jacobian H (3, n) w.r.t. the error state, and the
    body rate relative to map used for the lever arm, b_omega = b_omega_m - b_g - n_R_b^T n_omega_ie (its attitude
    dependence -n_R_b^T [n_omega_ie]x phi enters H through the model's b_omega Jacobian). n_v (m/s, map): the
    velocity the DVL sees, fs.nav.n_v unless given (a water-track ping's: relative to the water)."""
    R = fs.nav.n_R_b
    b_omega = b_omega_m - fs.gyro_bias - R.T @ n_omega_ie
    y, J = dvl_model(
        R,
        fs.nav.n_v if n_v is None else n_v,
        fs.scale,
        fs.b_R_d,
        b_omega,
        np.asarray(b_l, dtype=float),
        inputs=True,
    )
    assert J is not None
    return y, error_state_jacobian(fs, J, -R.T @ skew(n_omega_ie)), b_omega


def offset_measurement_model(
    fs: FilterState,
    b_l: np.ndarray,
    rate_input: RateInput,
    n_g: np.ndarray,
    n_v: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The DVL velocity with the time offset (module doc; factors/dvl_model.py), y (3,), and its Jacobian H (3, n)
    w.r.t. the error state. rate_input = (b_a, b_omega, G): FactorMaker.velocity_rate_input of the ping (body rate
    relative to map, gyro bias not removed); n_g gravity in map. The model's inputs b_a - accelerometer bias and
    b_omega - gyro bias give the bias columns. n_v: as in measurement_model."""
    b_a, b_omega_mean, G = rate_input
    y, J = dvl_model(
        fs.nav.n_R_b,
        fs.nav.n_v if n_v is None else n_v,
        fs.scale,
        fs.b_R_d,
        b_omega_mean - fs.gyro_bias,
        np.asarray(b_l, dtype=float),
        dt_d=fs.time_offset,
        offset=OffsetInput(b_a - fs.accel_bias, np.asarray(n_g, dtype=float), G),
        inputs=True,
    )
    assert J is not None
    return y, error_state_jacobian(fs, J, None)


def error_state_jacobian(
    fs: FilterState, J: DvlJacobians, d_omega_d_phi: np.ndarray | None
) -> np.ndarray:
    """The model's Jacobians (factors/dvl_model.py) on the error state (strapdown.py): phi is a left perturbation in
    map axes (n_R_b Exp(theta) = Exp(n_R_b theta) n_R_b: theta = n_R_b^T phi), the biases enter through the inputs
    b_omega and b_a with a minus sign, psi is b_R_d's right tangent as in the model; d_omega_d_phi: the body rate's
    dependence on phi, if any."""
    H = np.zeros((3, len(fs.P)))
    assert J.b_omega is not None
    H[:, PHI] = J.pose[:, :3] @ fs.nav.n_R_b.T + (
        0.0 if d_omega_d_phi is None else J.b_omega @ d_omega_d_phi
    )
    H[:, VEL] = J.vel
    H[:, BG] = -J.b_omega
    if J.b_a is not None:
        H[:, BA] = -J.b_a
    H[:, SCALE] = J.scale[:, 0]
    H[:, MIS] = J.b_R_d
    if J.offset is not None:
        H[:, OFFSET] = J.offset[:, 0]
    return H


def depth_measurement_model(
    fs: FilterState, b_p_s: np.ndarray, radius_m: float, dt: float = 0.0
) -> tuple[float, np.ndarray]:
    """Predicted height of the depth sensor above the map origin's height (m, up; factors/depth.py), dt seconds
    after the filter's time (bridged by the vertical velocity), and its Jacobian (1, n) w.r.t. the error state:
    phi (map axes, left) moves the lever arm a = n_R_b b_p_s by phi x a, whose z is phi_x a_y - phi_y a_x."""
    n_p, a = fs.nav.n_p, fs.nav.n_R_b @ b_p_s
    x, y = float(n_p[0]), float(n_p[1])
    h = float(n_p[2]) + 0.5 * (x * x + y * y) / radius_m + float(a[2]) + dt * float(fs.nav.n_v[2])
    H = np.zeros((1, len(fs.P)))
    H[0, PHI] = [a[1], -a[0], 0.0]
    H[0, POS] = [x / radius_m, y / radius_m, 1.0]
    H[0, 5] = dt  # vertical velocity
    return h, H


def ping_measurement(
    log: LogData, config: EstimatorConfig, j: int, water: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, z, Rm): the measurement A y = z with noise covariance Rm: the 3-D velocity (A = I) or the valid
    beams (rows of A the beam unit vectors); a water-track ping (water): its 3-D velocity, its own noise."""
    cfg, dvl = config.dvl, log.dvl
    if water:
        return np.eye(3), dvl.d_v[j], water_covariance(config, dvl.d_cov[j])
    if cfg.use_beams and dvl.beams is not None:
        ok = dvl.beams.valid[j]
        A = dvl.beams.d_u[j][ok]
        return A, dvl.beams.v[j][ok], np.eye(int(ok.sum())) * cfg.beam_sigma_m_s() ** 2
    return np.eye(3), dvl.d_v[j], ping_covariance(cfg, dvl.d_cov[j])


@dataclass
class DepthUpdates:
    """The depth samples of a log (depth_samples) and the filter's use of them (module doc)."""

    samples: DepthSamples
    radius_m: float
    max_dt: float
    gate_nis: float
    reopen_after: int
    next: int = 0
    gated_run: int = 0
    counters: dict[str, int] = field(default_factory=dict)

    def due(self, t: float) -> float | None:
        """The next sample's time if it is before t (the propagation stops there), else None."""
        return (
            float(self.samples.t[self.next])
            if self.next < len(self.samples.t) and self.samples.t[self.next] < t - 1e-9
            else None
        )

    def apply(
        self, fs: FilterState, t: float, until: float, bridge_to: float | None = None
    ) -> None:
        """Update with the samples stamped up to `until`, the filter at t; a sample more than 1e-9 s from t is
        bridged by the velocity if within max_dt (bridge_to: also those after t up to it, the last state)."""
        s, c = self.samples, self.counters
        end = until if bridge_to is None else bridge_to
        while self.next < len(s.t) and s.t[self.next] <= end + 1e-9:
            dt = float(s.t[self.next]) - t
            if abs(dt) <= 1e-9:
                dt = 0.0
            if abs(dt) > self.max_dt + 1e-9:
                c["depth_too_far"] += 1
            else:
                h, H = depth_measurement_model(fs, s.b_p_sensor, self.radius_m, dt)
                gate = self.gate_nis if self.gated_run < self.reopen_after else math.inf
                _, _, gated = update(
                    fs,
                    H,
                    np.array([s.z_meas[self.next] - h]),
                    np.array([[float(s.sigma[self.next]) ** 2]]),
                    gate_nis=gate,
                )
                self.gated_run = self.gated_run + 1 if gated else 0
                c["depth_gated" if gated else "depth_used"] += 1
            self.next += 1
