"""The factor maker: explicit measurements in, GTSAM factors, priors and initial guesses out.

Every estimator on a factor graph makes its factors here: the whole-log graph of the batch smoother and the
planner (estimators/graph.py) and the online iSAM2 estimator (estimators/online/), which feeds it one epoch
at a time. It holds no log and no epoch list, only what the factors depend on: the configuration, the map
frame (Earth model), the alignment (initial attitude) and the sensor mounting.

Earth model in the Earth-fixed map frame (docs/conventions.md):
- Earth rate through the preintegration's omegaCoriolis (constant in map).
- Gravity per IMU factor as a function of the interval's mid position, with its gradient in the
  Jacobian (factors/imu_earth.py), so the solver sees the true model: gravity turns by 1.6e-7 rad per
  metre. GTSAM 4.3's prediction subtracts the centrifugal term about the map origin, -w x (w x p);
  normal gravity already contains the centrifugal acceleration at p, so the factor is given
  n_g(p) + w x (w x p) (tests/estimators/test_graph_earth.py shows a static vehicle 20 km from the origin
  predicted exactly only with this).
- GTSAM integrates each sample with the attitude at the sample's start; a real IMU's delta-v is
  accumulated while the body turns, so each delta-v is rotated back to its interval start
  (dv + 1/2 dtheta x dv) before preintegration. Without it a 0.05 rad/s turn through gravity
  gives a 130 micro-g error.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame, gravity_gradient, normal_gravity
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, B, V, X
from gtsam_dvl.core.types import Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.alignment import Alignment
from gtsam_dvl.estimators.gaps import Gaps, hold_covariance, pieces_with_holds
from gtsam_dvl.estimators.selection import imu_pieces
from gtsam_dvl.factors import EarthImuFactor, make_dvl_beam_factor, make_dvl_velocity_factor, make_earth_imu_factor

Beams = tuple[np.ndarray, np.ndarray, np.ndarray]  # d_u (B, 3) unit vectors in dvl_link, v (B,) m/s, valid (B,)


@dataclass
class FactorMaker:
    """Factors, priors and initial guesses of one epoch from explicit measurements (module doc)."""

    config: EstimatorConfig
    frame: LocalFrame
    alignment: Alignment
    mounting: Mounting
    source: str = ""

    # ----- keys and rates ------------------------------------------------------------------------
    def bias_key(self, i: int) -> int:
        return B(i) if self.config.imu.bias_model == "random_walk" else B(0)

    def body_rate(self, b_omega_gyro: np.ndarray) -> np.ndarray:
        """Body rate relative to map for the lever-arm term of a DVL epoch: the gyro sample covering the
        ping minus Earth rate (attitude from the alignment; the Earth-rate term times a lever arm of a metre
        is 7e-5 m/s, so attitude errors do not matter)."""
        return np.asarray(b_omega_gyro - self.alignment.n_R_b.T @ self.n_omega_ie(), dtype=float)

    def n_omega_ie(self) -> np.ndarray:
        """Earth rate in map, rad/s (zero in the flat model)."""
        return np.zeros(3) if self.config.solver.earth_model == "flat" else self.frame.n_omega_ie

    # ----- preintegration ------------------------------------------------------------------------
    def make_params(self) -> gtsam.PreintegrationParams:
        """A new PreintegrationParams (one per IMU factor: the factor writes its gravity into it)."""
        imu_cfg = self.config.imu
        g0 = normal_gravity(self.frame.lat0, self.frame.height_m)
        params = gtsam.PreintegrationParams(np.array([0.0, 0.0, -float(g0)]))
        gyro_sigma = imu_cfg.gyro_noise_deg_per_h_rthz * DEG_PER_H
        accel_sigma = imu_cfg.accel_noise_ug_rthz * UG
        params.setGyroscopeCovariance(np.eye(3) * gyro_sigma**2)
        params.setAccelerometerCovariance(np.eye(3) * accel_sigma**2)
        params.setIntegrationCovariance(np.eye(3) * imu_cfg.integration_sigma_m_rts**2)
        params.setOmegaCoriolis(self.n_omega_ie())
        return params

    def compensate_rotation(self, b_f: np.ndarray, b_omega: np.ndarray, dt_sample: np.ndarray) -> np.ndarray:
        """Each delta-v rotated back to its sample's start (see module doc), if the configuration asks."""
        if not self.config.imu.rotation_compensation:
            return b_f
        return np.asarray(b_f + 0.5 * dt_sample[:, None] * np.cross(b_omega, b_f))

    def preintegrate_interval(self, t_a: float, t_b: float, t: np.ndarray, starts: np.ndarray, b_f: np.ndarray,
                              b_omega: np.ndarray, gaps: Gaps | None = None) -> tuple[
                                  gtsam.PreintegratedImuMeasurements, gtsam.PreintegrationParams, float]:
        """Preintegration over (t_a, t_b] of samples i covering (starts[i], t[i]] (b_f already compensated);
        a sample straddling t_a or t_b contributes its overlap (selection.imu_pieces), a gap the sample held
        across it (estimators/gaps.py). Returns the pim, its own parameters and the held time, s."""
        params = self.make_params()
        pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
        if gaps is None:
            idx, dt = imu_pieces(t, starts, t_a, t_b)
            held_s = 0.0
        else:
            idx, dt, held_s = pieces_with_holds(t, starts, gaps, t_a, t_b)
        # Python floats and ints for the loop: numpy scalars cost more than the integration itself
        for i, dt_i in zip(idx.tolist(), dt.tolist(), strict=True):
            pim.integrateMeasurement(b_f[i], b_omega[i], dt_i)
        return pim, params, held_s

    # ----- gravity -------------------------------------------------------------------------------
    def gravity_model(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gravity for GTSAM's prediction at map positions n_p (..., 3) and its gradient (..., 3, 3)
        (see module doc)."""
        w = self.frame.n_omega_ie
        w_x2 = np.outer(w, w) - np.dot(w, w) * np.eye(3)  # d/dp of w x (w x p)
        g = self.frame.n_gravity(n_p) + np.cross(w, np.cross(w, n_p))
        return g, gravity_gradient(self.frame, n_p) + w_x2

    # ----- factors -------------------------------------------------------------------------------
    def new_imu_factor(self, i: int, pim: gtsam.PreintegratedImuMeasurements, params: gtsam.PreintegrationParams,
                       dt: float, held_s: float = 0.0) -> EarthImuFactor:
        """The IMU factor between states i and i+1 from its preintegration (constant gravity if flat); held_s
        seconds of it crossed an IMU gap (their motion-model covariance is added: gaps.hold_covariance)."""
        gravity = None if self.config.solver.earth_model == "flat" else self.gravity_model
        extra = hold_covariance(self.config.imu, held_s, dt) if held_s > 0 else None
        return make_earth_imu_factor(pim, params, (X(i), V(i), X(i + 1), V(i + 1), self.bias_key(i)), dt, gravity,
                                     extra)

    def bias_link_factors(self, i: int, dt: float) -> list[gtsam.NonlinearFactor]:
        """Random-walk bias link B_i -> B_i+1 over dt seconds (none for a random-constant bias)."""
        if self.config.imu.bias_model != "random_walk":
            return []
        imu_cfg = self.config.imu
        sig_a = imu_cfg.accel_bias_rw_ug_per_rth * UG / 60.0 * np.sqrt(dt)
        sig_g = imu_cfg.gyro_bias_rw_deg_per_h_per_rth * DEG_PER_H / 60.0 * np.sqrt(dt)
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sig_a] * 3 + [sig_g] * 3))
        return [gtsam.BetweenFactorConstantBias(B(i), B(i + 1), gtsam.imuBias.ConstantBias(), noise)]

    def dvl_factors_for(self, i: int, d_y: np.ndarray, cov: np.ndarray, b_omega: np.ndarray,
                        beams: Beams | None = None) -> list[gtsam.NonlinearFactor]:
        """DVL factors of state i from one ping: velocity d_y (m/s, dvl_link) with covariance cov, or, with
        dvl.use_beams, beams = (d_u (B, 3), v (B,), valid (B,)); b_omega the epoch's body_rate()."""
        b_l = self.mounting.b_l
        if self.config.dvl.use_beams and beams is not None:
            d_u, v, valid = beams
            noise1 = self.beam_noise()
            return [make_dvl_beam_factor(noise1, X(i), V(i), K_SCALE, C_MISALIGN, d_u[b], float(v[b]), b_omega, b_l)
                    for b in np.flatnonzero(valid)]
        return [make_dvl_velocity_factor(self.dvl_noise(cov), X(i), V(i), K_SCALE, C_MISALIGN, d_y, b_omega, b_l)]

    def dvl_noise(self, cov: np.ndarray) -> gtsam.noiseModel.Base:
        """Noise model of a ping's 3-D velocity: the configured sigma, else its covariance if positive
        definite, else the default sigma; in the robust kernel if configured (_robust)."""
        cfg = self.config.dvl
        noise: gtsam.noiseModel.Base
        if cfg.noise_m_s > 0:
            noise = gtsam.noiseModel.Isotropic.Sigma(3, cfg.noise_m_s)
        elif np.all(np.isfinite(cov)) and np.all(np.linalg.eigvalsh(cov) > 0):
            noise = gtsam.noiseModel.Gaussian.Covariance(cov)
        else:
            noise = gtsam.noiseModel.Isotropic.Sigma(3, cfg.default_noise_m_s)
        return self._robust(noise)

    def beam_noise(self) -> gtsam.noiseModel.Base:
        """Noise model of one beam velocity (robust if configured)."""
        return self._robust(gtsam.noiseModel.Isotropic.Sigma(1, self.config.dvl.beam_noise_m_s))

    def _robust(self, noise: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
        """noise wrapped in the configured robust kernel ([dvl] robust, threshold robust_k in sigmas of the
        whitened error: GTSAM applies it to the norm of the whitened 3-D error, or of one beam's)."""
        cfg = self.config.dvl
        k = cfg.robust_threshold()
        if cfg.robust == "huber":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(k), noise)
        if cfg.robust == "cauchy":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(k), noise)
        return noise

    def prior_factors(self, values: gtsam.Values) -> list[gtsam.NonlinearFactor]:
        """Priors on the first state, the bias, the scale and the misalignment."""
        pri, imu_cfg = self.config.priors, self.config.imu
        n_R_b = self.alignment.n_R_b
        rp, yaw = np.radians(pri.roll_pitch_sigma_deg), np.radians(pri.yaw_sigma_deg)
        # attitude sigmas are about map axes (roll/pitch ~ horizontal, yaw ~ vertical); Pose3's tangent is
        # in body axes, so rotate the covariance into the body
        cov_rot = n_R_b.T @ np.diag([rp**2, rp**2, yaw**2]) @ n_R_b
        cov_pose = np.zeros((6, 6))
        cov_pose[:3, :3] = cov_rot
        cov_pose[3:, 3:] = np.eye(3) * pri.position_sigma_m**2
        b_R_d0 = self.mounting.b_R_d0
        mis = np.radians(np.asarray(pri.misalignment_sigma_deg, dtype=float))
        # misalignment sigmas are about body axes (R_c on the left); b_R_d is perturbed on the right
        cov_c = b_R_d0.T @ np.diag(mis**2) @ b_R_d0
        bias_sig = np.array([imu_cfg.accel_bias_sigma_ug * UG] * 3
                            + [imu_cfg.gyro_bias_sigma_deg_per_h * DEG_PER_H] * 3)
        return [
            gtsam.PriorFactorPose3(X(0), values.atPose3(X(0)), gtsam.noiseModel.Gaussian.Covariance(cov_pose)),
            gtsam.PriorFactorVector(V(0), values.atVector(V(0)),
                                    gtsam.noiseModel.Isotropic.Sigma(3, pri.velocity_sigma_m_s)),
            gtsam.PriorFactorConstantBias(B(0), gtsam.imuBias.ConstantBias(),
                                          gtsam.noiseModel.Diagonal.Sigmas(bias_sig)),
            gtsam.PriorFactorVector(K_SCALE, np.array([pri.scale_initial]),
                                    gtsam.noiseModel.Isotropic.Sigma(1, pri.scale_sigma)),
            gtsam.PriorFactorRot3(C_MISALIGN, gtsam.Rot3(b_R_d0), gtsam.noiseModel.Gaussian.Covariance(cov_c)),
        ]

    # ----- initial guesses -----------------------------------------------------------------------
    def velocity_from_ping(self, n_R_b: np.ndarray, d_y: np.ndarray | None) -> np.ndarray | None:
        """n_v from a ping at the initial scale and nominal mounting (None if the ping has no velocity)."""
        if d_y is None or not np.all(np.isfinite(d_y)):
            return None
        return np.asarray(n_R_b @ (self.mounting.b_R_d0 @ d_y) / self.config.priors.scale_initial)

    def first_state_values(self, d_y: np.ndarray | None) -> gtsam.Values:
        """Initial guess of the first state X(0), V(0) (attitude from the alignment, at the map origin,
        velocity from ping d_y at the initial scale and nominal mounting) and of the bias, scale and
        misalignment."""
        values = gtsam.Values()
        n_R_b = gtsam.Rot3(self.alignment.n_R_b)
        n_v = self.velocity_from_ping(n_R_b.matrix(), d_y)
        values.insert(X(0), gtsam.Pose3(n_R_b, np.zeros(3)))
        values.insert(V(0), np.zeros(3) if n_v is None else n_v)
        values.insert(self.bias_key(0), gtsam.imuBias.ConstantBias())
        values.insert(K_SCALE, np.array([self.config.priors.scale_initial]))
        values.insert(C_MISALIGN, gtsam.Rot3(self.mounting.b_R_d0))
        return values
