"""The error-state EKF's model (filter.py runs it): its initial state, the smoother's priors as the filter's mean
and covariance in the error state's layout (strapdown.py), and the process noise of a propagation interval."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core import states
from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.states import BY_NAME, ekf_layout, enabled
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.ekf.strapdown import (
    LAYOUT,
    N_ERR,
    N_NAV,
    PHI,
    POS,
    VEL,
    FilterState,
    NavState,
)
from gtsam_dvl.estimators.inputs.alignment import FirstState
from gtsam_dvl.estimators.models.epoch_states import ekf_states, enabled_epoch_states


def initial_state(
    log: LogData,
    config: EstimatorConfig,
    n_R_b: np.ndarray,
    ping: int,
    first: FirstState | None = None,
    calibration: VehicleCalibration | None = None,
) -> FilterState:
    """The smoother's priors (graph.prior_factors) as the filter's initial mean and covariance; first: the given
    attitude and origin carried to the first ping (alignment.first_state), its position and covariance;
    calibration: the states it holds (states.calibration_states) at its values with its joint covariance."""
    pri = config.priors
    file, held, held_cov = states.calibration_in_layout(
        config, calibration, ekf_layout(config, N_NAV)
    )
    b_R_d0 = file.get("misalignment", log.mounting.b_R_d0)
    k0 = float(file.get("scale", [pri.scale_initial])[0])
    d_y = log.dvl.d_v[ping]
    n_v = n_R_b @ (b_R_d0 @ d_y) / k0 if np.all(np.isfinite(d_y)) else np.zeros(3)
    offset = enabled(config, "time_offset")
    layout = ekf_layout(config, N_NAV)
    n = N_NAV + sum(sl.stop - sl.start for sl in layout.values())
    P = np.zeros((n, n))
    rp, yaw = np.radians(pri.roll_pitch_sigma_deg), np.radians(pri.yaw_sigma_deg)
    P[PHI, PHI] = np.diag([rp**2, rp**2, yaw**2])  # map axes: the error phi is about map axes
    P[VEL, VEL] = np.eye(3) * pri.velocity_sigma_m_s**2
    P[POS, POS] = np.eye(3) * pri.position_sigma_m**2
    n_p = np.zeros(3)
    if first is not None and first.carried:
        n_p = first.n_p.copy()
        for r, rows in ((0, PHI), (3, POS)):
            for c, cols in ((0, PHI), (3, POS)):
                P[rows, cols] = first.cov[r : r + 3, c : c + 3]
    # the shared states' priors (the misalignment's in b_R_d's right tangent)
    for name, sl in layout.items():
        P[sl, sl] = BY_NAME[name].prior(config, log.mounting).cov
    # a calibration's joint covariance over the states it holds, in their place
    P[np.ix_(held, held)] = held_cov
    epoch: dict[str, np.ndarray] = {}
    # the per-epoch states' blocks, last: their priors (epoch_states.py)
    for s in ekf_states(config):
        m = len(P)
        P = np.pad(P, ((0, s.dim), (0, s.dim)))
        P[m:, m:] = s.ekf_prior_cov(config)
        epoch[s.name] = np.asarray(s.initial(config), dtype=float)
    return FilterState(
        NavState(n_R_b.copy(), n_v, n_p),
        np.zeros(3),
        np.zeros(3),
        k0,
        b_R_d0.copy(),
        P,
        file.get("time_offset", [config.dvl.time_offset_prior_s])[0] if offset else 0.0,
        epoch=epoch,
    )


def process_noise(config: EstimatorConfig, Phi: np.ndarray, T: float) -> np.ndarray:
    """Discrete process noise of an interval: trapezoid of the continuous white noise through Phi."""
    imu_cfg = config.imu
    q = np.zeros(N_ERR)
    q[PHI] = (imu_cfg.gyro_noise_deg_per_h_rthz * DEG_PER_H) ** 2
    q[VEL] = (imu_cfg.accel_noise_ug_rthz * UG) ** 2
    q[POS] = imu_cfg.integration_sigma_m_rts**2
    # the random walk of states in the shared block (the biases)
    for s in enabled_epoch_states(config):
        for name, density in s.ekf_noise(config).items():
            q[LAYOUT[name]] = density
    Qc = np.diag(q)
    return 0.5 * T * (Phi @ Qc @ Phi.T + Qc)
