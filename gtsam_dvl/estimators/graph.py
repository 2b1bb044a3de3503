"""The one graph builder that every estimator shares (batch, online iSAM2, covariance analysis).

States (pose X_i = n_T_b, velocity V_i = n_v) at the DVL epochs; preintegrated IMU factors between
consecutive states, integrated exactly to the DVL stamps; DVL velocity (or beam) factors on
(X_i, V_i, scale K, misalignment C = b_R_d); IMU bias B (one random constant, or B_i as a random walk).

Earth model in the Earth-fixed map frame (CONVENTIONS.md):
- Earth rate through the preintegration's omegaCoriolis (constant in map).
- Gravity per IMU factor as a function of the interval's mid position, with its gradient in the
  Jacobian (factors/imu_earth.py), so the solver sees the true model: gravity turns by 1.6e-7 rad per
  metre. GTSAM 4.3's prediction subtracts the centrifugal term about the map origin, -w x (w x p);
  normal gravity already contains the centrifugal acceleration at p, so the factor is given
  n_g(p) + w x (w x p) (tests/test_graph_earth.py shows a static vehicle 20 km from the origin
  predicted exactly only with this).
- GTSAM integrates each sample with the attitude at the sample's start; a real IMU's delta-v is
  accumulated while the body turns, so each delta-v is rotated back to its interval start
  (dv + 1/2 dtheta x dv) before preintegration. Without it a 0.05 rad/s turn through gravity
  gives a 130 micro-g error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame, gravity_gradient, normal_gravity
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, B, V, X
from gtsam_dvl.core.types import DvlData, ImuData, LogData, Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.alignment import Alignment, align
from gtsam_dvl.factors import EarthImuFactor, make_dvl_beam_factor, make_dvl_velocity_factor, make_earth_imu_factor


def map_frame_of(log: LogData, config: EstimatorConfig) -> LocalFrame:
    """The map origin: from the configuration if given, else from the log's metadata."""
    a = config.alignment
    if a.origin_lat_deg is not None:
        return LocalFrame(a.origin_lat_deg, a.origin_lon_deg or 0.0, a.origin_height_m or 0.0)
    origin = log.metadata.get("origin")
    if not origin:
        raise GtsamDvlError(f"{log.source or 'log'}: no map origin in the log; set alignment.origin_lat_deg "
                            "(and lon, height) in the configuration: Earth rate and gravity need the latitude")
    return LocalFrame(float(origin["lat_deg"]), float(origin["lon_deg"]), float(origin["height_m"]))


@dataclass
class Epoch:
    """One state of the graph: a DVL ping used as keyframe."""

    t: float
    dvl_index: int
    b_omega: np.ndarray  # body rate relative to map at t (for the lever arm), rad/s


@dataclass
class GraphBuilder:
    """Turns a log into factors and an initial guess. Solvers take what they need from it."""

    log: LogData
    config: EstimatorConfig
    frame: LocalFrame = field(init=False)
    alignment: Alignment = field(init=False)
    epochs: list[Epoch] = field(init=False)
    pims: list[gtsam.PreintegratedImuMeasurements] = field(init=False)
    imu_params: list[gtsam.PreintegrationParams] = field(init=False)
    imu_factors: list[EarthImuFactor] = field(init=False)
    counters: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        cfg = self.config
        self.frame = map_frame_of(self.log, cfg)
        self.alignment = align(self.log.imu, self.log.dvl, self.frame, cfg.alignment)
        self.epochs = self._select_epochs()
        if len(self.epochs) < 2:
            raise GtsamDvlError(f"{self.log.source or 'log'}: fewer than two usable DVL pings")
        self._preintegrate()
        self.imu_factors = [self.new_imu_factor(i, pim, params, self.epochs[i + 1].t - self.epochs[i].t)
                            for i, (pim, params) in enumerate(zip(self.pims, self.imu_params, strict=True))]

    @classmethod
    def incremental(cls, config: EstimatorConfig, frame: LocalFrame, alignment: Alignment,
                    mounting: Mounting, source: str = "") -> GraphBuilder:
        """A builder without a log, for estimators fed message by message (gtsam_dvl/estimators/online.py): it holds
        the configuration, map frame, alignment and mounting, and makes the factors and initial guesses of
        each new epoch from explicit measurements (preintegrate_interval, new_imu_factor, dvl_factors_for,
        bias_link_factors, first_state_values, prior_factors). Its epoch lists stay empty: the caller
        keeps the epochs it still needs, so memory stays bounded on long missions."""
        builder = cls.__new__(cls)
        builder.log = LogData(ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))),
                              DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, dtype=bool)),
                              mounting=mounting, source=source)
        builder.config = config
        builder.counters = {}
        builder.frame = frame
        builder.alignment = alignment
        builder.epochs, builder.pims, builder.imu_params, builder.imu_factors = [], [], [], []
        return builder

    # ----- epochs and preintegration -------------------------------------------------------------
    def _select_epochs(self) -> list[Epoch]:
        dvl, imu, cfg = self.log.dvl, self.log.imu, self.config
        usable: np.ndarray = dvl.valid.copy()
        if cfg.dvl.use_beams and dvl.beams is not None:
            usable = np.asarray(dvl.beams.valid.any(axis=1))
        speed = np.linalg.norm(np.nan_to_num(dvl.d_v), axis=1)
        too_fast = usable & (speed > cfg.dvl.max_speed_m_s) & (not cfg.dvl.use_beams)
        self.counters["dvl_too_fast"] = int(too_fast.sum())
        usable &= ~too_fast
        usable &= (dvl.t > imu.t[0]) & (dvl.t <= imu.t[-1])
        self.counters["dvl_unusable"] = int((~usable).sum())
        epochs: list[Epoch] = []
        last_t = -np.inf
        gyro_index = np.searchsorted(imu.t, dvl.t)
        for j in np.flatnonzero(usable):
            if dvl.t[j] - last_t < cfg.solver.keyframe_interval_s:
                continue
            gi = min(int(gyro_index[j]), len(imu) - 1)
            epochs.append(Epoch(float(dvl.t[j]), int(j), self.body_rate(imu.b_omega[gi])))
            last_t = dvl.t[j]
        return epochs

    def body_rate(self, b_omega_gyro: np.ndarray) -> np.ndarray:
        """Body rate relative to map for the lever-arm term of a DVL epoch: the gyro sample covering the
        ping minus Earth rate (attitude from the alignment; the Earth-rate term times a lever arm of a metre
        is 7e-5 m/s, so attitude errors do not matter)."""
        return np.asarray(b_omega_gyro - self.alignment.n_R_b.T @ self._n_omega_ie(), dtype=float)

    def _n_omega_ie(self) -> np.ndarray:
        return np.zeros(3) if self.config.solver.earth_model == "flat" else self.frame.n_omega_ie

    def _make_params(self) -> gtsam.PreintegrationParams:
        imu_cfg = self.config.imu
        g0 = normal_gravity(self.frame.lat0, self.frame.height_m)
        params = gtsam.PreintegrationParams(np.array([0.0, 0.0, -float(g0)]))
        gyro_sigma = imu_cfg.gyro_noise_deg_per_h_rthz * DEG_PER_H
        accel_sigma = imu_cfg.accel_noise_ug_rthz * UG
        params.setGyroscopeCovariance(np.eye(3) * gyro_sigma**2)
        params.setAccelerometerCovariance(np.eye(3) * accel_sigma**2)
        params.setIntegrationCovariance(np.eye(3) * imu_cfg.integration_sigma_m_rts**2)
        params.setOmegaCoriolis(self._n_omega_ie())
        return params

    def _preintegrate(self) -> None:
        imu = self.log.imu
        t = imu.t
        dt_sample = np.diff(t, prepend=t[0] - (np.median(np.diff(t)) if len(t) > 1 else 0.01))
        b_f = self.compensate_rotation(imu.b_f, imu.b_omega, dt_sample)
        starts = t - dt_sample
        self.pims, self.imu_params = [], []
        for a, b in zip(self.epochs[:-1], self.epochs[1:], strict=True):
            pim, params = self.preintegrate_interval(a.t, b.t, t, starts, b_f, imu.b_omega)
            self.pims.append(pim)
            self.imu_params.append(params)

    def compensate_rotation(self, b_f: np.ndarray, b_omega: np.ndarray, dt_sample: np.ndarray) -> np.ndarray:
        """Each delta-v rotated back to its sample's start (see module doc), if the configuration asks."""
        if not self.config.imu.rotation_compensation:
            return b_f
        return np.asarray(b_f + 0.5 * dt_sample[:, None] * np.cross(b_omega, b_f))

    def preintegrate_interval(self, t_a: float, t_b: float, t: np.ndarray, starts: np.ndarray, b_f: np.ndarray,
                              b_omega: np.ndarray) -> tuple[gtsam.PreintegratedImuMeasurements,
                                                            gtsam.PreintegrationParams]:
        """Preintegration over (t_a, t_b] of samples i covering (starts[i], t[i]] (b_f already compensated);
        a sample straddling t_a or t_b contributes its overlap. Returns the pim and its own parameters."""
        params = self._make_params()
        pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
        lo = int(np.searchsorted(t, t_a, side="right"))  # first sample ending after t_a
        hi = int(np.searchsorted(t, t_b, side="left"))  # last sample that reaches t_b
        end = min(hi, len(t) - 1) + 1
        # Python floats for the interval arithmetic: numpy scalars cost more than the integration itself
        for i, t_i, start_i in zip(range(lo, end), t[lo:end].tolist(), starts[lo:end].tolist(), strict=True):
            dt = min(t_i, t_b) - max(start_i, t_a)
            if dt > 0.0:
                pim.integrateMeasurement(b_f[i], b_omega[i], dt)
        return pim, params

    # ----- gravity -------------------------------------------------------------------------------
    def gravity_model(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gravity for GTSAM's prediction at map positions n_p (..., 3) and its gradient (..., 3, 3)
        (see module doc)."""
        w = self.frame.n_omega_ie
        w_x2 = np.outer(w, w) - np.dot(w, w) * np.eye(3)  # d/dp of w x (w x p)
        g = self.frame.n_gravity(n_p) + np.cross(w, np.cross(w, n_p))
        return g, gravity_gradient(self.frame, n_p) + w_x2

    def set_gravity_from_positions(self, n_p: np.ndarray, only_stale: bool = False) -> int:
        """Reference gravity of the IMU factors at the mid positions of states n_p (N+1, 3), evaluated
        for all factors in one vectorised call (per-factor evaluation costs 1 ms each). only_stale: just
        the factors whose mid position left their reference's range. Returns how many were updated."""
        if self.config.solver.earth_model == "flat":
            return 0
        mid = 0.5 * (n_p[:-1] + n_p[1:])
        idx = [i for i, f in enumerate(self.imu_factors) if not only_stale or f.needs_reference(mid[i])]
        if idx:
            g, G = self.gravity_model(mid[idx])
            for k, i in enumerate(idx):
                self.imu_factors[i].set_reference(mid[i], g[k], G[k])
                self.imu_factors[i].set_gravity(mid[i])
        return len(idx)

    def refresh_gravity(self, values: gtsam.Values) -> bool:
        """Between solver iterations: re-reference the factors that moved far (see factors/imu_earth.py).
        The objective changes by less than 1e-8 m/s^2 of gravity, so this reports no change."""
        n_p = np.array([values.atPose3(X(i)).translation() for i in range(len(self.epochs))])
        self.set_gravity_from_positions(n_p, only_stale=True)
        return False

    # ----- factors -------------------------------------------------------------------------------
    def bias_key(self, i: int) -> int:
        return B(i) if self.config.imu.bias_model == "random_walk" else B(0)

    def imu_factor(self, i: int) -> gtsam.NonlinearFactor:
        """IMU factor between states i and i+1, gravity following position."""
        return self.imu_factors[i].factor

    def new_imu_factor(self, i: int, pim: gtsam.PreintegratedImuMeasurements, params: gtsam.PreintegrationParams,
                       dt: float) -> EarthImuFactor:
        """The IMU factor between states i and i+1 from its preintegration (constant gravity if flat)."""
        gravity = None if self.config.solver.earth_model == "flat" else self.gravity_model
        return make_earth_imu_factor(pim, params, (X(i), V(i), X(i + 1), V(i + 1), self.bias_key(i)), dt, gravity)

    def bias_factors(self, i: int) -> list[gtsam.NonlinearFactor]:
        """Random-walk bias link between states i and i+1 (none for a random-constant bias)."""
        if self.config.imu.bias_model != "random_walk":
            return []
        return self.bias_link_factors(i, self.epochs[i + 1].t - self.epochs[i].t)

    def bias_link_factors(self, i: int, dt: float) -> list[gtsam.NonlinearFactor]:
        """Random-walk bias link B_i -> B_i+1 over dt seconds (none for a random-constant bias)."""
        if self.config.imu.bias_model != "random_walk":
            return []
        imu_cfg = self.config.imu
        sig_a = imu_cfg.accel_bias_rw_ug_per_rth * UG / 60.0 * np.sqrt(dt)
        sig_g = imu_cfg.gyro_bias_rw_deg_per_h_per_rth * DEG_PER_H / 60.0 * np.sqrt(dt)
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sig_a] * 3 + [sig_g] * 3))
        return [gtsam.BetweenFactorConstantBias(B(i), B(i + 1), gtsam.imuBias.ConstantBias(), noise)]

    def dvl_factors(self, i: int) -> list[gtsam.NonlinearFactor]:
        """DVL factors of state i: the 3-D velocity, or one per valid beam."""
        dvl, ep = self.log.dvl, self.epochs[i]
        j = ep.dvl_index
        beams = None if dvl.beams is None else (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
        return self.dvl_factors_for(i, dvl.d_v[j], dvl.d_cov[j], ep.b_omega, beams)

    def dvl_factors_for(self, i: int, d_y: np.ndarray, cov: np.ndarray, b_omega: np.ndarray,
                        beams: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> list[gtsam.NonlinearFactor]:
        """DVL factors of state i from one ping: velocity d_y (m/s, dvl_link) with covariance cov, or, with
        dvl.use_beams, beams = (d_u (B, 3), v (B,), valid (B,)); b_omega the epoch's body_rate()."""
        b_l = self.log.mounting.b_l
        if self.config.dvl.use_beams and beams is not None:
            d_u, v, valid = beams
            noise1 = self.beam_noise()
            return [make_dvl_beam_factor(noise1, X(i), V(i), K_SCALE, C_MISALIGN, d_u[b], float(v[b]), b_omega, b_l)
                    for b in np.flatnonzero(valid)]
        return [make_dvl_velocity_factor(self.dvl_noise(cov), X(i), V(i), K_SCALE, C_MISALIGN, d_y, b_omega, b_l)]

    def dvl_noise(self, cov: np.ndarray) -> gtsam.noiseModel.Base:
        """Noise model of a ping's 3-D velocity: the configured sigma, else its covariance if positive
        definite, else the default sigma; robust if configured."""
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
        if self.config.dvl.robust == "huber":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(self.config.dvl.huber_k),
                                                  noise)
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
        b_R_d0 = self.log.mounting.b_R_d0
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

    # ----- initial guess -------------------------------------------------------------------------
    def initial_values(self) -> gtsam.Values:
        """Dead reckoning: attitude from the gyros (from the alignment), velocity from the DVL at the
        initial scale and nominal mounting, position by integrating that velocity."""
        values = gtsam.Values()
        dvl = self.log.dvl
        k0 = self.config.priors.scale_initial
        b_R_d0 = self.log.mounting.b_R_d0
        zero_bias = gtsam.imuBias.ConstantBias()
        n_p_all = np.zeros((len(self.epochs), 3))
        self.set_gravity_from_positions(n_p_all)
        n_R_b = gtsam.Rot3(self.alignment.n_R_b)
        n_p, n_v = np.zeros(3), np.zeros(3)
        for i, ep in enumerate(self.epochs):
            if i > 0:
                state = self.pims[i - 1].predict(gtsam.NavState(n_R_b, n_p, n_v), zero_bias)
                n_R_b = state.attitude()
            d_y = dvl.d_v[ep.dvl_index]
            if dvl.valid[ep.dvl_index] and np.all(np.isfinite(d_y)):
                n_v_new = n_R_b.matrix() @ (b_R_d0 @ d_y) / k0
            else:
                n_v_new = n_v
            if i > 0:
                n_p = n_p + 0.5 * (n_v + n_v_new) * (ep.t - self.epochs[i - 1].t)
            n_v = n_v_new
            n_p_all[i] = n_p
            values.insert(X(i), gtsam.Pose3(n_R_b, n_p))
            values.insert(V(i), n_v)
            if i == 0 or self.config.imu.bias_model == "random_walk":
                values.insert(self.bias_key(i), zero_bias)
        values.insert(K_SCALE, np.array([k0]))
        values.insert(C_MISALIGN, gtsam.Rot3(b_R_d0))
        self.set_gravity_from_positions(n_p_all)
        return values

    def first_state_values(self, d_y: np.ndarray | None) -> gtsam.Values:
        """Initial guess of an incremental estimator's first state X(0), V(0) (attitude from the alignment,
        at the map origin, velocity from ping d_y at the initial scale and nominal mounting, as in
        initial_values) and of the bias, scale and misalignment."""
        values = gtsam.Values()
        n_R_b = gtsam.Rot3(self.alignment.n_R_b)
        n_v = np.zeros(3)
        if d_y is not None and np.all(np.isfinite(d_y)):
            n_v = n_R_b.matrix() @ (self.log.mounting.b_R_d0 @ d_y) / self.config.priors.scale_initial
        values.insert(X(0), gtsam.Pose3(n_R_b, np.zeros(3)))
        values.insert(V(0), n_v)
        values.insert(self.bias_key(0), gtsam.imuBias.ConstantBias())
        values.insert(K_SCALE, np.array([self.config.priors.scale_initial]))
        values.insert(C_MISALIGN, gtsam.Rot3(self.log.mounting.b_R_d0))
        return values

    def build(self) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The whole graph and its initial guess (batch smoothing, covariance analysis)."""
        values = self.initial_values()
        graph = gtsam.NonlinearFactorGraph()
        for f in self.prior_factors(values):
            graph.add(f)
        for i in range(len(self.epochs)):
            for f in self.dvl_factors(i):
                graph.add(f)
            if i + 1 < len(self.epochs):
                graph.add(self.imu_factor(i))
                for f in self.bias_factors(i):
                    graph.add(f)
        return graph, values

    def elimination_ordering(self) -> gtsam.Ordering:
        """States in time order, the shared calibration and bias keys last: the Bayes net is a chain
        whose root holds the calibration block, and marginals follow by one backward pass."""
        ordering = gtsam.Ordering()
        rw = self.config.imu.bias_model == "random_walk"
        for i in range(len(self.epochs)):
            ordering.push_back(X(i))
            ordering.push_back(V(i))
            if rw:
                ordering.push_back(B(i))
        if not rw:
            ordering.push_back(B(0))
        ordering.push_back(K_SCALE)
        ordering.push_back(C_MISALIGN)
        return ordering
