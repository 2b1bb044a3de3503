"""The factor maker: explicit measurements in, GTSAM factors, priors and initial guesses out.

Every estimator on a factor graph makes its factors here: the whole-log graph of the batch smoother and the
planner (estimators/graph/log_graph.py) and the online iSAM2 estimator (estimators/online/), which feeds it one epoch
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

from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame, gaussian_radius, gravity_gradient, normal_gravity
from gtsam_dvl.core.keys import B, V, X
from gtsam_dvl.core.states import correlated_error, dvl_factor_keys, enabled, water_current
from gtsam_dvl.core.states import initial_values as initial_shared_values
from gtsam_dvl.core.states import prior_factors as shared_prior_factors
from gtsam_dvl.core.types import ImuData, Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.inputs.alignment import Alignment, FirstState, first_state
from gtsam_dvl.estimators.inputs.gaps import Holds, ImuPieces, hold_covariance
from gtsam_dvl.estimators.inputs.selection import ping_covariance, water_covariance
from gtsam_dvl.estimators.models.noise_levels import median_ping_sigma
from gtsam_dvl.factors import (
    DvlOptions,
    EarthImuFactor,
    OffsetInput,
    PingMotion,
    keyframe_ping_covariance,
    make_depth_factor,
    make_dvl_factor,
    make_earth_imu_factor,
    make_gnss_factor,
)

Beams = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # d_u (B, 3) unit vectors in dvl_link, v (B,) m/s, valid (B,)


def _mean_exp(phi: np.ndarray, wgt: np.ndarray) -> np.ndarray:
    """sum_k wgt_k Exp(phi_k) (P, 3, 3) for rotation vectors phi (P, W, 3) and weights wgt (P, 1, W), by Rodrigues'
    formula Exp(phi) = (1 - c theta^2) I + s [phi] + c phi phi^T (s = sin(theta)/theta, c = (1 - cos)/theta^2) summed
    term by term: no 3x3 matrix per sample (a day of 5 Hz pings has 43 million samples in their windows).
    Series below 1e-2 rad (exact to rounding there; the closed forms cancel)."""
    t2 = np.einsum("pwi,pwi->pw", phi, phi)
    small = t2 < 1e-4
    ts = np.sqrt(np.where(small, 1.0, t2))
    s = np.where(small, 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0)), np.sin(ts) / ts)
    c = np.where(
        small,
        0.5 * (1.0 - t2 / 12.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0))),
        (1.0 - np.cos(ts)) / ts**2,
    )
    w = wgt[:, 0, :]
    sum_s_phi = np.einsum("pw,pwi->pi", w * s, phi)
    out = np.swapaxes(phi * (w * c)[..., None], 1, 2) @ phi  # sum_k wgt c phi phi^T
    diag = np.einsum("pw,pw->p", w, 1.0 - c * t2)
    out[:, 0, 0] += diag
    out[:, 1, 1] += diag
    out[:, 2, 2] += diag
    x, y, z = sum_s_phi[:, 0], sum_s_phi[:, 1], sum_s_phi[:, 2]
    out[:, 0, 1] -= z
    out[:, 0, 2] += y
    out[:, 1, 0] += z
    out[:, 1, 2] -= x
    out[:, 2, 0] -= y
    out[:, 2, 1] += x
    return out


def integrate_pieces(
    pim: gtsam.PreintegratedImuMeasurements, b_f: np.ndarray, b_omega: np.ndarray, dt: list[float]
) -> None:
    """Integrate the pieces (rows of b_f m/s^2 and b_omega rad/s, durations dt s as Python floats: numpy scalars
    cost more than the integration itself) into pim, in order."""
    for f_i, w_i, dt_i in zip(b_f, b_omega, dt, strict=True):
        pim.integrateMeasurement(f_i, w_i, dt_i)


@dataclass
class FactorMaker:
    """Factors, priors and initial guesses of one epoch from explicit measurements (module doc)."""

    config: EstimatorConfig
    frame: LocalFrame
    alignment: Alignment
    mounting: Mounting
    source: str = ""
    # the given initial attitude and origin carried to the first state (carry_to_first); None: not yet
    first: FirstState | None = None
    # a vehicle's calibration (already inflated for its age): the joint prior of the states it holds
    # (core/states.py calibration_prior) and their initial values; None: the configuration's priors
    calibration: VehicleCalibration | None = None
    # offset_gravity()'s cache
    _offset_gravity: np.ndarray | None = field(default=None, init=False, repr=False)

    # ----- keys and rates ------------------------------------------------------------------------
    def bias_key(self, i: int) -> int:
        return B(i) if self.config.imu.bias_model == "random_walk" else B(0)

    def body_rate(self, b_omega_gyro: np.ndarray) -> np.ndarray:
        """Body rate relative to map for the lever-arm term of a DVL epoch: the gyro sample covering the
        ping minus Earth rate (attitude from the alignment; the Earth-rate term times a lever arm of a metre
        is 7e-5 m/s, so attitude errors do not matter)."""
        return np.asarray(b_omega_gyro - self.alignment.n_R_b.T @ self.n_omega_ie(), dtype=float)

    def velocity_rate_input(
        self,
        t: float,
        imu_t: np.ndarray,
        b_f: np.ndarray,
        b_omega: np.ndarray,
        dt: float = 0.0,
        bias: tuple[np.ndarray, np.ndarray] | None = None,
        n_R_b: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU constants of the DVL time-offset model at an epoch t: the mean specific force b_a and the
        mean body rate relative to map (base_link) over the samples of a window centred on t + dt / 2, of length
        max(|dt|, 2 w), w = [dvl] time_offset_window_s. dt is the current offset estimate: dt times the mean rate
        over [t, t + dt] is the secant b_v(t + dt) - b_v(t) whatever the rate's shape (an offset shorter than 2 w
        averages over 2 w, exact for a rate linear in time, and the noise of a few samples averaged out). The third
        constant is G, the mean over those samples of dR^T, dR the body's rotation since t (from the gyros, a
        rotation vector integrated from t): the specific force is measured in the rotating body, so gravity
        must be seen there too (G n_R_b(t)^T n_g). The Coriolis acceleration (2 Omega x v: 3e-4 m/s^2 at
        2 m/s) is left out. bias = (accelerometer m/s^2, gyro rad/s): the current estimate of the IMU biases,
        taken off the samples (a 280 micro-g accelerometer bias over a 1 s offset is a 3 mm/s phantom velocity);
        n_R_b: the body's attitude at the ping for the Earth rate's removal (default: the alignment's)."""
        b_a, w_mean, G = self.velocity_rate_inputs(
            np.array([t], dtype=float),
            imu_t,
            b_f,
            b_omega,
            dt,
            bias=bias,
            n_R_b=None if n_R_b is None else np.asarray(n_R_b)[None],
        )
        return b_a[0], w_mean[0], G[0]

    def velocity_rate_inputs(
        self,
        t: np.ndarray,
        imu_t: np.ndarray,
        b_f: np.ndarray,
        b_omega: np.ndarray,
        dt: float = 0.0,
        chunk_samples: int = 500_000,
        bias: tuple[np.ndarray, np.ndarray] | None = None,
        n_R_b: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """velocity_rate_input at the epochs t (P,) at once: b_a (P, 3), the mean body rate (P, 3), G (P, 3, 3).
        Vectorised over the pings (a Python call per ping would cost 18,000 calls per hour of a 5 Hz log): each
        window's samples are gathered into a padded block, chunk_samples (ping, sample) pairs at a time, and the
        per-window sums of velocity_rate_input are taken (the cumulative rotation from the window's first
        sample). bias: (accelerometer (3,) or (P, 3) m/s^2, gyro (3,) or (P, 3) rad/s) taken off the samples;
        n_R_b (P, 3, 3): each ping's attitude for its Earth rate (default: the alignment's)."""
        w = self.config.dvl.time_offset_window_s
        t = np.asarray(t, dtype=float).reshape(-1)
        n_imu = len(imu_t)
        # the samples in each window by binary search (imu_t is sorted): never a mask over every sample
        # centred on t + dt / 2, of length max(|dt|, 2 w): for an offset longer than the window exactly [t, t + dt]
        # (the secant: a longer window's mean attenuates a curved rate, on a 9 s heave by 2.5 % over 1.5 s against
        # 1 s, and the offset came out 2.5 % long, +1.5 sigma at dt = 1 s: docs/results.md)
        half = 0.5 * max(abs(dt), 2.0 * w)
        lo = np.searchsorted(imu_t, t + 0.5 * dt - half, side="left")
        hi = np.searchsorted(imu_t, t + 0.5 * dt + half, side="right")
        empty = hi <= lo  # no sample in the window: the sample covering t alone
        lo = np.where(empty, np.clip(np.searchsorted(imu_t, t), 0, n_imu - 1), lo)
        hi = np.where(empty, lo + 1, hi)
        # Earth rate in each ping's body (the same for every sample of its window: the body turns by at most a few
        # degrees in one) plus the gyro bias: what each sample's rate loses to be relative to map
        n_omega = self.n_omega_ie()
        w_off = np.broadcast_to(
            self.alignment.n_R_b.T @ n_omega
            if n_R_b is None
            else np.einsum("pji,j->pi", np.asarray(n_R_b, dtype=float), n_omega),
            (len(t), 3),
        )
        a_off = np.zeros((len(t), 3))
        if bias is not None:
            a_off = np.broadcast_to(np.asarray(bias[0], dtype=float), (len(t), 3))
            w_off = w_off + np.broadcast_to(np.asarray(bias[1], dtype=float), (len(t), 3))
        b_a, w_mean, G = np.empty((len(t), 3)), np.empty((len(t), 3)), np.empty((len(t), 3, 3))
        width = int((hi - lo).max()) if len(t) else 0
        step_p = max(1, chunk_samples // max(width, 1))
        col = np.arange(width)
        for a in range(0, len(t), step_p):
            sl = slice(a, a + step_p)
            n_in = (hi[sl] - lo[sl])[:, None]
            inside = col[None, :] < n_in
            wgt = (inside / n_in)[
                :, None, :
            ]  # (P, 1, W): the mean over the window's samples as a product
            idx = np.minimum(lo[sl][:, None] + col[None, :], n_imu - 1)
            ts = imu_t[idx]
            b_a[sl] = (wgt @ b_f[idx])[:, 0] - a_off[sl]
            w_rel = b_omega[idx] - w_off[sl][:, None, :]
            w_mean[sl] = (wgt @ w_rel)[:, 0]
            step = np.where(inside, np.diff(ts, axis=1, prepend=ts[:, :1]), 0.0)
            phi = np.cumsum(w_rel * step[..., None], axis=1)
            near = np.argmin(np.where(inside, np.abs(ts - t[sl][:, None]), np.inf), axis=1)
            phi -= phi[np.arange(len(near)), near][:, None, :]  # rotation since t
            G[sl] = _mean_exp(-phi, wgt)
        return b_a, w_mean, G

    def offset_gravity(self) -> np.ndarray:
        """Gravity in map for the time-offset model: at the map origin (its direction turns by 1.6e-7 rad per
        metre, far below what the offset's first-order term resolves). Computed once, not once per
        ping."""
        if self._offset_gravity is None:
            g0 = normal_gravity(self.frame.lat0, self.frame.height_m)
            if self.config.solver.earth_model == "flat":
                self._offset_gravity = np.array([0.0, 0.0, -float(g0)])
            else:
                self._offset_gravity = np.asarray(
                    self.frame.n_gravity(np.zeros((1, 3)))[0], dtype=float
                )
        return self._offset_gravity

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

    def compensate_rotation(
        self, b_f: np.ndarray, b_omega: np.ndarray, dt_sample: np.ndarray
    ) -> np.ndarray:
        """Each delta-v rotated back to its sample's start (see module doc), if the configuration asks."""
        if not self.config.imu.rotation_compensation:
            return b_f
        out = np.cross(b_omega, b_f)  # in place from here: one array of the log's size, not three
        out *= 0.5 * dt_sample[:, None]
        out += b_f
        return np.asarray(out)

    def preintegrate_interval(
        self, t_a: float, t_b: float, imu: ImuPieces
    ) -> tuple[gtsam.PreintegratedImuMeasurements, gtsam.PreintegrationParams, Holds]:
        """Preintegration over (t_a, t_b] of the samples imu (ImuPieces: b_f already compensated); a sample
        straddling t_a or t_b contributes its overlap (selection.imu_pieces), a gap the sample held across it
        (estimators/inputs/gaps.py). Returns the pim, its own parameters and what was held (Holds)."""
        params = self.make_params()
        pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
        idx, dt, held = imu.pieces(t_a, t_b)
        integrate_pieces(pim, imu.b_f[idx], imu.b_omega[idx], dt.tolist())
        return pim, params, held

    # ----- gravity -------------------------------------------------------------------------------
    def gravity_model(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gravity for GTSAM's prediction at map positions n_p (..., 3) and its gradient (..., 3, 3)
        (see module doc)."""
        w = self.frame.n_omega_ie
        w_x2 = np.outer(w, w) - np.dot(w, w) * np.eye(3)  # d/dp of w x (w x p)
        g = self.frame.n_gravity(n_p) + np.cross(w, np.cross(w, n_p))
        return g, gravity_gradient(self.frame, n_p) + w_x2

    # ----- factors -------------------------------------------------------------------------------
    def imu_keys(self, i: int) -> tuple[int, int, int, int, int]:
        """The keys of the IMU factor between states i and i+1: X_i, V_i, X_i+1, V_i+1 and state i's bias."""
        return X(i), V(i), X(i + 1), V(i + 1), self.bias_key(i)

    def imu_hold_cov(self, held: Holds | None, dt: float) -> np.ndarray | None:
        """(9, 9) covariance added to an IMU factor of dt seconds for what it held across IMU gaps (the motion
        model: gaps.hold_covariance); None if nothing was held."""
        return hold_covariance(self.config.imu, held, dt) if held else None

    def new_imu_factor(
        self,
        i: int,
        pim: gtsam.PreintegratedImuMeasurements,
        params: gtsam.PreintegrationParams,
        dt: float,
        held: Holds | None = None,
    ) -> EarthImuFactor:
        """The IMU factor between states i and i+1 from its preintegration (constant gravity if flat); held_s
        seconds of it crossed an IMU gap (their motion-model covariance is added: imu_hold_cov)."""
        gravity = None if self.config.solver.earth_model == "flat" else self.gravity_model
        return make_earth_imu_factor(
            pim, params, self.imu_keys(i), dt, gravity, self.imu_hold_cov(held, dt)
        )

    def dvl_factors_for(
        self,
        i: int,
        d_y: np.ndarray,
        cov: np.ndarray,
        b_omega: np.ndarray,
        beams: Beams | None = None,
        rate_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        water: bool = False,
    ) -> list[gtsam.NonlinearFactor]:
        """DVL factors of state i from one ping: velocity d_y (m/s, dvl_link) with covariance cov, or, with
        dvl.use_beams, beams = (d_u (B, 3), v (B,), valid (B,)); b_omega the epoch's body_rate(). With
        dvl.estimate_time_offset, rate_input = velocity_rate_input() of the epoch gives the time-offset
        model on T_OFFSET too. With dvl.estimate_lever_arm the lever arm is the variable L_LEVER, else the constant
        mounting.b_l (factors/dvl.py make_dvl_factor). water: a water-track ping (the 3-D velocity relative to the
        water, on the current W(i) too: estimators/models/current.py; its noise [current] water_track_sigma_m_s)."""
        return self._dvl_factors(i, d_y, cov, b_omega, beams, rate_input, water=water)

    def keyframe_gravity(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normal gravity in map at map positions n_p (N, 3), m/s^2, and its gradient (N, 3, 3), 1/s^2, for the
        keyframe DVL factors (factors/ping_motion.py; no centrifugal term about the origin: only GTSAM's IMU
        prediction needs it). Flat model: the constant gravity at the origin, zero gradient."""
        n_p = np.asarray(n_p, dtype=float).reshape(-1, 3)
        if self.config.solver.earth_model == "flat":
            g0 = normal_gravity(self.frame.lat0, self.frame.height_m)
            return np.tile([0.0, 0.0, -float(g0)], (len(n_p), 1)), np.zeros((len(n_p), 3, 3))
        return (
            np.asarray(self.frame.n_gravity(n_p), dtype=float).reshape(-1, 3),
            np.asarray(gravity_gradient(self.frame, n_p), dtype=float).reshape(-1, 3, 3),
        )

    def dvl_keyframe_factors_for(
        self,
        i: int,
        d_y: np.ndarray,
        cov: np.ndarray,
        b_omega: np.ndarray,
        motion: PingMotion,
        pim_cov: np.ndarray,
        beams: Beams | None = None,
        rate_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        water: bool = False,
    ) -> list[gtsam.NonlinearFactor]:
        """DVL factors of a ping between keyframes on state i (X(i), V(i), the bias, K_SCALE, C_MISALIGN, and
        T_OFFSET / L_LEVER when estimated): the ping seen through the IMU motion from state i (motion, with its
        Earth model: factors/ping_motion.py), as dvl_factors_for does for a ping at a state. pim_cov (9x9, [rotation,
        position, velocity]): the preintegration's covariance up to the ping, mapped into the ping's noise at
        the prior calibration (keyframe_ping_covariance; 1e-4 m/s at 1 s with the paper's IMU, against 2 cm/s)."""
        k0 = self.config.priors.scale_initial
        b_R_d0 = self.mounting.b_R_d0
        d_y = np.asarray(d_y, dtype=float)
        b_v = b_R_d0 @ d_y / k0 if np.all(np.isfinite(d_y)) else np.zeros(3)
        extra = keyframe_ping_covariance(pim_cov, motion.dR, b_R_d0.T, b_v, k0)
        return self._dvl_factors(i, d_y, cov, b_omega, beams, rate_input, motion, extra, water)

    def dvl_keys(self, i: int, motion: bool = False, water: bool = False) -> list[int]:
        """The keys of a DVL factor of state i (states.dvl_factor_keys; motion: a ping between keyframes; water: a
        water-track ping)."""
        return dvl_factor_keys(self.config, i, motion, water)

    def _dvl_factors(
        self,
        i: int,
        d_y: np.ndarray,
        cov: np.ndarray,
        b_omega: np.ndarray,
        beams: Beams | None,
        rate_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
        motion: PingMotion | None = None,
        extra: np.ndarray | None = None,
        water: bool = False,
    ) -> list[gtsam.NonlinearFactor]:
        """dvl_factors_for, or with motion and extra (the preintegration's noise in the ping, 3x3 m^2/s^2)
        dvl_keyframe_factors_for."""
        cfg = self.config.dvl
        b_l, lever = self.mounting.b_l, enabled(self.config, "lever_arm")
        water = water and water_current(self.config)
        keys = self.dvl_keys(i, motion is not None, water)
        # the correlated error E(i) a variable of every DVL factor
        gm = correlated_error(self.config)
        if enabled(self.config, "time_offset"):
            if rate_input is None:
                raise ValueError(
                    "a DVL factor with the time offset needs its IMU constants (rate_input)"
                )
            b_a, b_omega_mean, G = rate_input
            o = DvlOptions(
                b_omega_mean,
                b_l,
                offset=OffsetInput(b_a, self.offset_gravity(), G),
                motion=motion,
                lever_variable=lever,
                error_variable=gm,
                current_variable=water,
            )
            return [make_dvl_factor(self.dvl_noise(cov, extra, water), keys, d_y, o)]
        # (a water-track ping: its 3-D velocity)
        if cfg.use_beams and beams is not None and not water:
            d_u, v, valid = beams
            out: list[gtsam.NonlinearFactor] = []
            for b in np.flatnonzero(valid).tolist():
                o = DvlOptions(
                    b_omega, b_l, d_u[b], motion=motion, lever_variable=lever, error_variable=gm
                )
                noise = (
                    self.beam_noise()
                    if extra is None
                    else self._robust(
                        gtsam.noiseModel.Isotropic.Sigma(
                            1, float(np.sqrt(cfg.beam_sigma_m_s() ** 2 + d_u[b] @ extra @ d_u[b]))
                        )
                    )
                )
                out.append(make_dvl_factor(noise, keys, float(v[b]), o))
            return out
        o = DvlOptions(
            b_omega,
            b_l,
            motion=motion,
            lever_variable=lever,
            error_variable=gm,
            current_variable=water,
        )
        return [make_dvl_factor(self.dvl_noise(cov, extra, water), keys, d_y, o)]

    def dvl_noise(
        self, cov: np.ndarray, extra: np.ndarray | None = None, water: bool = False
    ) -> gtsam.noiseModel.Base:
        """Noise model of a ping's 3-D velocity: the configured sigma, else its covariance if positive
        definite, else the default sigma (a water-track ping: [current] water_track_sigma_m_s), plus extra (3x3,
        m^2/s^2: a keyframe ping's preintegration noise) when given; in the robust kernel if configured (_robust)."""
        c = water_covariance(self.config, cov) if water else ping_covariance(self.config.dvl, cov)
        return self._robust(gtsam.noiseModel.Gaussian.Covariance(c if extra is None else c + extra))

    def beam_noise(self) -> gtsam.noiseModel.Base:
        """Noise model of one beam velocity (robust if configured)."""
        return self._robust(gtsam.noiseModel.Isotropic.Sigma(1, self.config.dvl.beam_sigma_m_s()))

    def depth_factors_for(
        self, i: int, z_meas: float, sigma: float, lever: np.ndarray, dt: float = 0.0
    ) -> list[gtsam.NonlinearFactor]:
        """The depth factor of state i from one sample: the sensor's height above the origin's height z_meas
        (m, up; estimators/inputs/depth.py), its sigma (m), the sensor's lever arm in base_link and the time from the
        state to the sample dt (s; bridged by V(i) when non-zero). Not robust: a depth sensor has no outliers
        of the DVL's kind. The map's z axis leaves the ellipsoid with the Earth's curvature (factors/depth.py)."""
        noise = gtsam.noiseModel.Isotropic.Sigma(1, float(sigma))
        radius = gaussian_radius(self.frame.lat0)
        vel_key = V(i) if dt != 0.0 else None
        return [make_depth_factor(noise, X(i), z_meas, lever, radius, vel_key, dt)]

    def gnss_factors_for(
        self, i: int, z: np.ndarray, cov: np.ndarray, lever: np.ndarray, dt: float = 0.0
    ) -> list[gtsam.NonlinearFactor]:
        """The GNSS factor of state i from one fix: the antenna's position in map z (m; estimators/inputs/gnss.py),
        its covariance cov (3x3, map axes, m^2), the antenna in base_link and the time from the state to the
        fix dt (s; bridged by V(i) when non-zero). Not robust: the fixes come with their own covariance."""
        vel_key = V(i) if dt != 0.0 else None
        return [
            make_gnss_factor(
                gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=float)),
                X(i),
                z,
                lever,
                vel_key,
                dt,
            )
        ]

    def _robust(self, noise: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
        """noise wrapped in the configured robust kernel ([dvl] robust, threshold robust_k in sigmas of the
        whitened error: GTSAM applies it to the norm of the whitened 3-D error, or of one beam's)."""
        cfg = self.config.dvl
        k = cfg.robust_threshold()
        if cfg.robust == "huber":
            return gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Huber.Create(k), noise
            )
        if cfg.robust == "cauchy":
            return gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Cauchy.Create(k), noise
            )
        return noise

    def prior_factors(
        self, values: gtsam.Values, position_cov: np.ndarray | None = None
    ) -> list[gtsam.NonlinearFactor]:
        """Priors on the first state and on the shared states (core/states.py: the bias, the scale and the
        misalignment, and the time offset and lever arm when estimated). position_cov: the first position's prior
        covariance in map axes (m^2) instead of priors.position_sigma_m (estimators/inputs/gnss.py: when the map origin
        is
        a GNSS fix)."""
        pri = self.config.priors
        n_R_b = self.alignment.n_R_b
        if self.first is not None and self.first.carried:  # map axes -> Pose3's tangent (body axes)
            cov_pose = np.kron(np.eye(2), n_R_b.T) @ self.first.cov @ np.kron(np.eye(2), n_R_b)
            if position_cov is not None:  # the origin is a GNSS fix: its covariance, at the fix
                cov_pose[3:, :3] = cov_pose[:3, 3:] = 0.0
                cov_pose[3:, 3:] = n_R_b.T @ position_cov @ n_R_b
        else:
            # attitude sigmas are about map axes (roll/pitch ~ horizontal, yaw ~ vertical): the alignment's own
            # (attitude sensor, in motion) when it has them, else [priors]; Pose3's tangent is in body axes, so
            # rotate the covariance into the body
            if self.alignment.sigma_rpy_deg is not None:
                sig_att = np.radians(np.asarray(self.alignment.sigma_rpy_deg, dtype=float))
            else:
                sig_att = np.radians(
                    [pri.roll_pitch_sigma_deg, pri.roll_pitch_sigma_deg, pri.yaw_sigma_deg]
                )
            cov_pose = np.zeros((6, 6))
            cov_pose[:3, :3] = n_R_b.T @ np.diag(sig_att**2) @ n_R_b
            cov_pose[3:, 3:] = (
                np.eye(3) * pri.position_sigma_m**2
                if position_cov is None
                else n_R_b.T @ position_cov @ n_R_b
            )  # translation tangent in body axes
        return [
            gtsam.PriorFactorPose3(
                X(0), values.atPose3(X(0)), gtsam.noiseModel.Gaussian.Covariance(cov_pose)
            ),
            gtsam.PriorFactorVector(
                V(0),
                values.atVector(V(0)),
                gtsam.noiseModel.Isotropic.Sigma(3, pri.velocity_sigma_m_s),
            ),
            # the shared states' (core/states.py)
        ] + shared_prior_factors(self.config, self.mounting, self.calibration)

    # ----- initial guesses -----------------------------------------------------------------------
    def alignment_info(self) -> dict[str, Any]:
        """NavResult.info["alignment"]: the alignment's, with the given state carried to the first (first_state)."""
        out = self.alignment.info()
        if self.first is not None:
            out["first_state"] = self.first.info()
        return out

    def carry_to_first(
        self,
        imu: ImuData,
        t1: float,
        d_y: np.ndarray | None,
        d_cov: np.ndarray,
        cov0: np.ndarray | None = None,
        t_origin: float | None = None,
    ) -> FirstState:
        """The given initial attitude and map origin (at the log's first IMU stamp, imu's first sample, or the
        origin at t_origin: see alignment.first_state) carried to the first state's time t1 (s) with imu
        (base_link) and the first ping (d_y m/s in dvl_link, d_cov its covariance); sets self.first and
        self.alignment (the attitude at t1)."""
        b_v = self.velocity_from_ping(np.eye(3), d_y)
        sigma = median_ping_sigma(self.config, np.asarray(d_cov, dtype=float).reshape(1, 3, 3))
        if not np.isfinite(sigma) or b_v is None:
            sigma = self.config.priors.velocity_sigma_m_s
        self.first = first_state(
            self.alignment, imu, self.frame, t1, b_v, self.config, sigma, cov0, t_origin
        )
        self.alignment = self.first.alignment
        return self.first

    def velocity_from_ping(self, n_R_b: np.ndarray, d_y: np.ndarray | None) -> np.ndarray | None:
        """n_v from a ping at the initial scale and nominal mounting (None if the ping has no velocity)."""
        if d_y is None or not np.all(np.isfinite(d_y)):
            return None
        return np.asarray(n_R_b @ (self.mounting.b_R_d0 @ d_y) / self.config.priors.scale_initial)

    def first_state_values(self, d_y: np.ndarray | None) -> gtsam.Values:
        """Initial guess of the first state X(0), V(0) (attitude from the alignment, position the map origin
        carried to the first state by carry_to_first, velocity from ping d_y at the initial scale and nominal
        mounting) and of the bias, scale and misalignment (and the time offset and lever arm when estimated:
        their priors' values)."""
        values = gtsam.Values()
        n_R_b = gtsam.Rot3(self.alignment.n_R_b)
        n_v = self.velocity_from_ping(n_R_b.matrix(), d_y)
        # the map origin carried to the first state
        n_p = np.zeros(3) if self.first is None else self.first.n_p
        values.insert(X(0), gtsam.Pose3(n_R_b, n_p))
        values.insert(V(0), np.zeros(3) if n_v is None else n_v)
        values.insert(initial_shared_values(self.config, self.mounting, self.calibration))
        return values
