"""The paper's practical estimator (its section 3): an error-state extended Kalman filter on the full
navigation equations with the DVL measurement of eq. 7, as a baseline for the factor-graph smoothers.
The equations are the paper's eq. 3-5 written in the Earth-fixed map frame, as the smoother uses them:
Earth rate and normal gravity at the vehicle's position, no transport rate, Cartesian position.

Nominal state: n_R_b, n_v, n_p (map frame), gyro and accelerometer biases, DVL scale k, misalignment
b_R_d; error state of dimension 19 (ekf_strapdown.py gives its definition and dynamics). The strapdown runs
at the IMU rate (vectorised per DVL interval); the covariance is propagated once per DVL interval with the
interval's closed-form transition matrix. Each valid ping is a measurement update with

    y = k * d_R_b * ( n_R_b^T n_v + b_omega x b_l ) + noise,     d_R_b = b_R_d^T      (docs/conventions.md)

Same Earth model, initialisation, priors and noise as the smoother (estimators/graph/log_graph.py, core/config/):
coarse alignment
on the static segment, scale 0.8, misalignment at the nominal mounting, the first ping's velocity at that
calibration, position 0 at the first ping. The error is injected after every update (no reset Jacobian:
its effect is second order in the correction). Every ping is used: solver.keyframe_interval_s only thins
the smoother's states.

Depth ([depth], LogData.depth, converted by estimators/inputs/depth.py depth_samples as the batch smoother converts
it): a scalar update of the vertical position at the sample's own time (the propagation stops there), with the
model of factors/depth.py, h = z + (x^2 + y^2) / (2 R) + (n_R_b b_p_s)_z, the sensor's lever arm b_p_s and the
Earth's curvature; a sample before the first state or after the last one is bridged to it by the velocity,
within [depth] max_time_to_state_s (else counted "depth_too_far"). The chi^2 gate of the DVL (1 dof) applies,
reopened after gate_reopen_after gated samples in a row; counters "depth_used" (updates made), "depth_gated",
"depth_too_far", "depth_invalid".

DVL time offset ([dvl] estimate_time_offset, not with use_beams): dt_d is a 20th error-state component (a random
constant with the prior time_offset_prior_s +- time_offset_sigma_s, no process noise). The ping stamped t
measures the velocity at t + dt_d; the update is made with the filter's state at t and the batch smoother's
first-order model (factors/dvl_model.py),

    y = k d_R_b (b_v + dt_d (b_a - b_a_bias + G n_R_b^T n_g - b_omega x b_v) + b_omega x b_l),  b_v = n_R_b^T n_v

with the IMU constants of FactorMaker.velocity_rate_input (mean specific force, mean body rate less the gyro
bias, mean body rotation G) over the samples of [t, t + dt_c] (widened to 2 time_offset_window_s about its
middle when shorter), dt_c the filter's
estimate of the offset when the ping is processed (clipped to the prior +- 3 prior sigmas), as the online
estimator re-centres its windows. Those samples come after the stamp: the ping is buffered, the filter held at
its stamp until the IMU has reached t + max(0, dt_c) + time_offset_window_s (run_ekf, given the whole log, reads
them from it; a real-time filter would wait that long, as the online estimator does). The estimate and its
sigma are NavResult.time_offset_s / time_offset_sigma_s, as the batch smoother reports them.

Outliers: the pings are those the smoothers use (selection.usable_pings, with the screen for bogus data).
An update whose normalised innovation squared exceeds the chi^2 quantile of [ekf] gate_probability (0.99999
by default; dof the measurement's dimension) is skipped and counted in counters["dvl_gated"] (the state is
still recorded at the ping); after [ekf] gate_reopen_after gated pings in a row the next one is used anyway,
so that a filter that lost track recovers. The others are weighted by the smoothers' robust kernel
([dvl] robust, robust_k) on the whitened innovation (counters["dvl_downweighted"]).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core import states
from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EkfConfig, EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame, gaussian_radius, gravity_gradient, normal_gravity
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import so3_log
from gtsam_dvl.core.states import enabled, water_current
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.ekf.divergence import FROZEN_ON_DIVERGENCE, DivergenceWatch
from gtsam_dvl.estimators.ekf.history import History, history_result
from gtsam_dvl.estimators.ekf.kalman import gate_threshold, propagate_covariance, update
from gtsam_dvl.estimators.ekf.measurements import (
    DepthUpdates,
    measurement_model,
    offset_measurement_model,
    ping_measurement,
)
from gtsam_dvl.estimators.ekf.model import initial_state, process_noise
from gtsam_dvl.estimators.ekf.origin import origin_fix
from gtsam_dvl.estimators.ekf.strapdown import (
    CALIBRATION,
    LAYOUT,
    OFFSET,
    PHI,
    POS,
    VEL,
    FilterState,
    propagate_interval,
)
from gtsam_dvl.estimators.ekf.warmup import contradicted, recentred_offset, with_offset_prior
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.alignment import (
    Alignment,
    align_log,
    given_covariance,
)
from gtsam_dvl.estimators.inputs.depth import depth_samples
from gtsam_dvl.estimators.inputs.gaps import (
    Gaps,
    check_gaps,
    find_gaps,
    gaps_within,
    hold_covariance,
    pieces_with_holds,
    sample_starts_with_gaps,
    screened_losses,
    with_fillers,
)
from gtsam_dvl.estimators.inputs.gnss import origin_fix_time
from gtsam_dvl.estimators.inputs.mounting import log_in_base_link
from gtsam_dvl.estimators.inputs.prepare import prepare
from gtsam_dvl.estimators.inputs.selection import (
    covering_sample,
    usable_pings,
)
from gtsam_dvl.estimators.models import current, weak_hold
from gtsam_dvl.estimators.models.constant_error import consider_constant_error
from gtsam_dvl.estimators.models.current import resolve_water_track, water_pings
from gtsam_dvl.estimators.models.epoch_states import (
    EpochEstimate,
    ekf_states,
    reports,
)
from gtsam_dvl.estimators.models.noise_levels import (
    NoiseReport,
    WarmupFit,
    dvl_fit_enabled,
    held_levels,
    imu_levels,
    median_ping_sigma,
    with_multiplier,
)

# Scale and misalignment enter the measurement multiplied by the velocity. Linearised about a velocity estimate that
# is only noise (a static vehicle), the filter reads that noise as information: regression on a noisy regressor drags
# k towards 0 (0.8 -> 0.4 over the 600 s static start of paper-3d, sigma 0.045). Treating them as consider states is
# not enough: with the k uncertainty times the noisy velocity in the innovation covariance the DVL stops constraining
# the velocity, which then drifts (5 m/s in 600 s). The true sensitivity of y to k and b_R_d is the true velocity,
# about zero, so below MIN_CALIBRATION_SPEED_M_S ("slow") their Jacobian columns are zero. A vehicle that moves while
# its velocity is still uncertain (under CALIBRATION_SPEED_SIGMAS velocity sigmas, its ping faster than as many of its
# own sigmas: an underway start's first ping, whose velocity the filter takes from that ping) has a good regressor but
# no velocity to separate the calibration from: there they are consider states. Zeroing their columns there instead
# pinned the velocity as if the calibration had no part in the ping, and the next pings read the misalignment off that
# velocity: the pitch and yaw misalignment at 0.65 of their prior's sigma after two pings of a straight run
# (realistic-turns; the smoother: 1.00), the pitch's error/sigma std 1.85 over 50 runs. Both are set by the
# configuration's [ekf] section (EkfConfig); these are its defaults.
MIN_CALIBRATION_SPEED_M_S = EkfConfig().min_calibration_speed_m_s  # 0.1
CALIBRATION_SPEED_SIGMAS = EkfConfig().calibration_speed_sigmas  # 5.0
# longer DVL gaps are propagated in steps of at most this (Phi is first order in w_ie T)
MAX_STEP_S = 1.0
GRADIENT_REFRESH_M = 100.0  # gravity is re-linearised after this distance


class _Earth:
    """Earth rate and gravity for the filter: WGS84 normal gravity at the position, or the flat model.

    Gravity is linearised about a point refreshed every GRADIENT_REFRESH_M: its curvature over that
    distance is g (100 m / 6400 km)^2 = 2e-9 m/s^2."""

    def __init__(self, frame: LocalFrame, flat: bool) -> None:
        self.frame, self.flat = frame, flat
        self.n_omega_ie = np.zeros(3) if flat else frame.n_omega_ie
        self._g = np.array([0.0, 0.0, -float(normal_gravity(frame.lat0, frame.height_m))])
        self._G = np.zeros((3, 3))
        self._at = np.full(3, np.inf)

    def gravity(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.flat:
            return self._g, self._G
        if np.linalg.norm(n_p - self._at) > GRADIENT_REFRESH_M:
            self._at = n_p.copy()
            self._g, self._G = self.frame.n_gravity(n_p), gravity_gradient(self.frame, n_p)
        return self._g + self._G @ (n_p - self._at), self._G


def run_ekf(
    log: LogData,
    config: EstimatorConfig | None = None,
    progress: ProgressFn | None = None,
    *,
    min_calibration_speed_m_s: float | None = None,
    calibration: VehicleCalibration | None = None,
) -> NavResult:
    """Filter a whole log: trajectory and calibration at every usable DVL ping, with the filtering history.

    Below config.ekf.min_calibration_speed_m_s (or the keyword, which overrides it) or
    config.ekf.calibration_speed_sigmas velocity sigmas the measurement is taken as insensitive to scale and
    misalignment (see MIN_CALIBRATION_SPEED_M_S). config None: the one the log's scenario names, else the
    defaults (EstimatorConfig.for_log).

    Noise levels from the data ([noise], estimators/models/noise_levels.py): the IMU's quantisation floor; the DVL's
    variance component by covariance matching of the innovations over the warm-up window ([noise] warmup_s), the
    window filtered again with each new fit until it changes by at most [noise] fit_tolerance (a covariance
    matching is only unbiased with the P of the right R: P is computed with the R assumed), at most fit_passes
    times, then held for the whole log (a real-time filter keeps the window's messages for that); the time offset's
    prior centred on the window's estimate where the window supports it, and back at the configured one when the
    filtered log holds its offset at that centre's bound (warmup.py: filtered again). calibration: a vehicle's
    calibration (inflated): the start of the states it holds (initial_state), its offset not recentred."""
    config = config or EstimatorConfig.for_log(log.metadata)
    if min_calibration_speed_m_s is not None:  # the effective value goes into result.config
        ekf = config.ekf.model_copy(update={"min_calibration_speed_m_s": min_calibration_speed_m_s})
        config = config.model_copy(update={"ekf": ekf})
    # the configuration checked, what the EKF does not do refused, the IMU screened when the reader did not
    # (inputs/prepare.py); [current] water_track is resolved with the filter's inputs (_checked_inputs)
    prepared = prepare(log, config, "ekf", calibration)
    log, config = prepared.log, prepared.stated
    noise = NoiseReport()
    # what result.config records (noise_levels.py: the levels used are in info["noise"])
    stated = config
    config = imu_levels(log, config, noise)  # the IMU's white noise from the data ([noise])
    # (the depth and the DVL's correlated error: the batch smoother fits them)
    held_levels(log, config, "EKF", noise)
    offset_info: dict[str, Any] = {}
    config = _warm_up(log, config, calibration, noise, offset_info)
    result = _held_at_nominal(log, config, progress, calibration)
    # the whole log held the offset at the bound of the prior the warm-up centred: filtered again at the configured one
    if (why := contradicted(result, config, offset_info)) is not None:
        offset_info.pop("centre_s")
        offset_info["why"] = why
        config = with_offset_prior(config, offset_info["configured_s"])
        result = _held_at_nominal(log, config, progress, calibration)
    consider_constant_error(result, config, calibration is not None)  # (constant_error.py)
    result.info["noise"] = noise.as_dict()
    # what the screen of an in-memory log found (gaps.py)
    if (screened := screened_losses(log)) is not None:
        result.info["screened_losses"] = screened
    if offset_info:
        result.info["time_offset_prior"] = offset_info
    if calibration is not None:
        result.info["calibration_prior"] = states.calibration_info(config, calibration)
    result.config = stated.to_dict()
    return result


def _warm_up(
    log: LogData,
    config: EstimatorConfig,
    calibration: VehicleCalibration | None,
    noise: NoiseReport,
    offset_info: dict[str, Any],
) -> EstimatorConfig:
    """The configuration after the warm-up window's passes (run_ekf): the DVL's noise level by covariance matching
    of the innovations (noise.dvl) and, with [ekf] recentre_time_offset (not from a calibration file), the time
    offset's prior centred on the window's estimate where the window supports it (warmup.py; offset_info), until
    both settle or [noise] fit_passes."""
    recentre = (
        enabled(config, "time_offset")
        and config.ekf.recentre_time_offset
        and "time_offset" not in states.calibration_in_layout(config, calibration, LAYOUT)[0]
    )
    if not (dvl_fit_enabled(config) or recentre):
        return config
    n = config.noise
    stated_multiplier = config.dvl.noise_multiplier
    for k in range(n.fit_passes):
        fit = WarmupFit(config, stated=stated_multiplier)
        window_config = config
        window = _filter(log, config, None, fit, calibration)
        settled = True
        if dvl_fit_enabled(config):
            new = fit.finish("covariance matching of the EKF's innovations")
            settled = abs(new / config.dvl.noise_multiplier - 1.0) <= n.fit_tolerance
            config = with_multiplier(config, new)
            noise.dvl = {**fit.report, "passes": k + 1, "settled": settled}
        if recentre:
            config, moved, recentre = recentred_offset(
                config, window, offset_info, k + 1, window_config, stated_multiplier
            )
            settled = settled and not moved
        if settled:
            break
    return config


def _held_at_nominal(
    log: LogData,
    config: EstimatorConfig,
    progress: ProgressFn | None,
    calibration: VehicleCalibration | None,
) -> NavResult:
    """The filtered log; when the filtered calibration does not pay over the nominal (weak_hold.py nominal_check),
    filtered again with the scale and misalignment as consider states at the nominal (info["calibration_hold"])."""
    result = _filter(log, config, progress, calibration=calibration)
    check = result.info["filter"].pop("nominal", None)
    if check is None:
        return result
    # in core/summary.py's one shape: the calibration's directions with their information (weak_hold.py)
    assert result.calib_joint_cov is not None
    hold = weak_hold.filter_nominal_hold(config, log.mounting, result.calib_joint_cov, check)
    if not check["pays"]:
        result = _filter(log, config, progress, calibration=calibration, consider_calibration=True)
        result.info["filter"].pop("nominal", None)
    result.info["calibration_hold"] = hold
    return result


def _checked_inputs(
    log: LogData, config: EstimatorConfig, counters: dict[str, int]
) -> tuple[LogData, EstimatorConfig, LocalFrame, Alignment, np.ndarray, np.ndarray]:
    """The log in base_link, the configuration with water track resolved, the map frame, the alignment, the
    water-track pings (M,) bool and the usable pings (no keyframe thinning). What the EKF does not support was
    refused before, once (run_ekf: inputs/prepare.py)."""
    log = log_in_base_link(log)  # IMU samples in base_link (estimators/inputs/mounting.py)
    frame, alignment = align_log(log, config)
    # [current] water_track "auto": "use" when the log has water track
    config = resolve_water_track(config, log)
    wc_on = water_current(config)
    water = water_pings(log) if wc_on else np.zeros(len(log.dvl), dtype=bool)
    # every usable ping: no keyframe thinning
    pings = usable_pings(log.dvl, log.imu, config.dvl, counters, wc_on)
    if len(pings) < 2:
        raise GtsamDvlError(f"{log.source or 'log'}: fewer than two usable DVL pings")
    return log, config, frame, alignment, water, pings


def _depth_updates(log: LogData, config: EstimatorConfig, frame: LocalFrame) -> DepthUpdates | None:
    """The depth samples the filter updates with ([depth] use and the log has them), else None."""
    if log.depth is None or not config.depth.use or not len(log.depth):
        return None
    dcounters = {"depth_used": 0, "depth_gated": 0, "depth_too_far": 0}
    samples = depth_samples(log.depth, config.depth, frame, dcounters)
    return DepthUpdates(
        samples,
        gaussian_radius(frame.lat0),
        config.depth.max_time_to_state_s,
        gate_threshold(config.ekf.gate_probability, 1),
        config.ekf.gate_reopen_after,
        counters=dcounters,
    )


@dataclass
class _Pass:
    """One pass of the filter over a log (_filter): what its propagation, updates and result share."""

    log: LogData  # in base_link
    config: EstimatorConfig
    frame: LocalFrame
    maker: FactorMaker  # the time offset's IMU constants, the alignment's report
    fs: FilterState
    pings: np.ndarray  # the usable pings
    water: np.ndarray  # (M,) bool: the water-track pings
    gaps: Gaps  # the IMU's gaps
    depth: DepthUpdates | None
    counters: dict[str, int]
    fit: WarmupFit | None
    consider_calibration: bool
    hist: History = field(default_factory=History)
    watch: DivergenceWatch = field(default_factory=DivergenceWatch)
    # the water current at each update: (t, z, W, its covariance, water)
    currents: list[tuple[float, float, np.ndarray, np.ndarray, bool]] = field(default_factory=list)
    # gate_threshold per measurement dimension
    gates: dict[int, float] = field(default_factory=dict)
    updates: int = 0  # pings taken (update_at_ping): every usable ping, or the warm-up window's
    gated: int = 0  # gated pings
    gated_run: int = 0  # and how many in a row
    nis_sum: float = 0.0
    nis_dof: int = 0
    downweighted: int = 0
    timing: dict[str, float] = field(default_factory=lambda: {"propagate": 0.0, "update": 0.0})

    def __post_init__(self) -> None:
        self.earth = _Earth(self.frame, self.config.solver.earth_model == "flat")
        t = self.log.imu.t
        self.starts = sample_starts_with_gaps(t, self.gaps)
        self.gyro_index = covering_sample(t, self.log.dvl.t)
        self.offset = enabled(self.config, "time_offset")
        self.offset_bound = 3.0 * self.config.dvl.time_offset_sigma_s
        self.gravity = float(np.linalg.norm(self.maker.offset_gravity()))  # m/s^2
        # the time offset prior's centre (the configured one, or the calibration's)
        self.offset_centre = self.fs.time_offset
        self.t_first = float(self.log.dvl.t[self.pings[0]])

    def states(self) -> tuple[np.ndarray, np.ndarray]:
        """The states of the factor-graph estimators: every usable ping, and states without a ping across DVL
        dropouts (estimators/inputs/gaps.py); the filter updates at the pings and records at both. Their stamps
        and each one's ping (-1: none); the gaps narrowed to those the states cross."""
        config = self.config
        state_t, is_filler = with_fillers(
            self.log.dvl.t[self.pings], float(self.log.imu.t[-1]), config.solver.max_state_spacing_s
        )
        ping_at = np.full(len(state_t), -1)
        ping_at[~is_filler] = self.pings
        self.counters["states_without_ping"] = int(is_filler.sum())
        self.gaps = gaps_within(self.gaps, float(state_t[0]), float(state_t[-1]))
        check_gaps(self.gaps, config.imu, self.log.source)
        self.counters["imu_gaps"] = len(self.gaps)
        return state_t, ping_at

    # ----- propagation ---------------------------------------------------------------------------
    def propagate(self, t_prev: float, t_j: float) -> float:
        """From t_prev to t_j in steps of at most MAX_STEP_S, stopping at depth samples (updated there)."""
        depth = self.depth
        while t_prev < t_j - 1e-9:
            t_next = min(t_j, t_prev + MAX_STEP_S)
            if depth is not None and (t_d := depth.due(t_next)) is not None and t_d > t_prev:
                t_next = t_d
            self._step(t_prev, t_next)
            t_prev = t_next
            if depth is not None:
                depth.apply(self.fs, t_prev, t_prev)
        return t_prev

    def _step(self, t_prev: float, t_next: float) -> None:
        """The strapdown, the covariance and the per-epoch states' processes over [t_prev, t_next]; across an IMU
        gap the motion model's uncertainty, as in the factor graphs."""
        fs, config, imu, earth = self.fs, self.config, self.log.imu, self.earth
        idx, dt, held = pieces_with_holds(imu.t, self.starts, self.gaps, t_prev, t_next)
        if not len(idx):
            return
        n_g, G = earth.gravity(fs.nav.n_p + 0.5 * (t_next - t_prev) * fs.nav.n_v)
        step = propagate_interval(
            fs.nav,
            imu.b_omega[idx] - fs.gyro_bias,
            imu.b_f[idx] - fs.accel_bias,
            dt,
            earth.n_omega_ie,
            n_g,
            G,
        )
        fs.nav = step.state
        fs.P = propagate_covariance(fs.P, step.Phi, process_noise(config, step.Phi, step.duration))
        # the per-epoch states' processes: the correlated DVL error decays, the current's random walk in time and
        # depth or across the layer boundaries, ... (epoch_states.py)
        for s in ekf_states(config):
            s.ekf_propagate(config, fs, t_next - t_prev, self.frame.height_m)
        if held:
            q = np.diag(hold_covariance(config.imu, held, t_next - t_prev))
            fs.P[PHI, PHI] += np.diag(q[0:3])
            fs.P[POS, POS] += np.diag(q[3:6])
            fs.P[VEL, VEL] += np.diag(q[6:9])

    # ----- updates -------------------------------------------------------------------------------
    def record_without_ping(self, t_j: float) -> None:
        """A state without a ping: recorded, not updated."""
        fs, imu = self.fs, self.log.imu
        g_j = int(covering_sample(imu.t, t_j))
        self.hist.record(
            fs, t_j, imu.b_omega[g_j] - fs.gyro_bias - fs.nav.n_R_b.T @ self.earth.n_omega_ie
        )

    def _prediction(
        self, t_j: float, j: int, on_water: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ping's predicted velocity y_hat, its Jacobian H on the error state and the body rate: the DVL model,
        with the time offset its velocity at t + dt_d (module doc, the IMU window centred on the estimate), plus the
        correlated error, relative to the water for a water-track ping."""
        fs, imu, maker = self.fs, self.log.imu, self.maker
        b_l = self.log.mounting.b_l
        # (m/s, map): over ground, or relative to the water
        n_v = current.seen_velocity(fs, on_water)
        y_hat, H, b_omega = measurement_model(
            fs, imu.b_omega[self.gyro_index[j]], b_l, self.earth.n_omega_ie, n_v
        )
        if self.offset:
            lo, hi = self.offset_centre - self.offset_bound, self.offset_centre + self.offset_bound
            dt_c = float(np.clip(fs.time_offset, lo, hi))
            # the window held at the bound: counted, reported (analysis/health.py)
            if dt_c != fs.time_offset:
                self.counters["time_offset_window_clipped"] = (
                    self.counters.get("time_offset_window_clipped", 0) + 1
                )
            rate = maker.velocity_rate_input(
                t_j, imu.t, imu.b_f, imu.b_omega, dt_c, n_R_b=fs.nav.n_R_b
            )
            y_hat, H = offset_measurement_model(fs, b_l, rate, maker.offset_gravity(), n_v)
        if (gm := fs.error_slice()) is not None:  # y = h + E (estimators/models/correlated.py)
            assert fs.dvl_error is not None
            y_hat, H[:, gm] = y_hat + fs.dvl_error, np.eye(3)
        # dh/dW: minus the velocity's east and north columns
        if (wc := fs.current_slice()) is not None:
            H[:, wc] = -H[:, VEL][:, :2] if on_water else 0.0
        return y_hat, H, b_omega

    def _calibration_columns(
        self, y_hat: np.ndarray, H: np.ndarray, z: np.ndarray, Rm: np.ndarray
    ) -> tuple[bool, bool]:
        """(slow, unsure): below the calibration speed the scale's and misalignment's columns of H zero, and
        while the velocity is still uncertain and the ping moving, the calibration a consider state (see the
        comment at MIN_CALIBRATION_SPEED_M_S); after a divergence the self-calibration's columns zero."""
        fs, ekf_cfg = self.fs, self.config.ekf
        speed = np.linalg.norm(y_hat) / fs.scale
        slow = bool(speed < ekf_cfg.min_calibration_speed_m_s)
        unsure = not slow and speed < ekf_cfg.calibration_speed_sigmas * np.sqrt(
            np.trace(fs.P[VEL, VEL])
        )
        # the ping itself moving beyond its noise (an underway start's first ping), while the filter's velocity
        # is still uncertain: the calibration as consider states; a still vehicle whose filtered velocity wanders
        # above the speed keeps the columns zero
        moving = len(z) == 3 and np.linalg.norm(z) / fs.scale > max(
            ekf_cfg.min_calibration_speed_m_s,
            ekf_cfg.calibration_speed_sigmas * np.sqrt(np.trace(Rm)),
        )
        if slow or (unsure and not moving):
            H[:, CALIBRATION] = 0.0
        # the self-calibration stopped (DivergenceWatch): a plain INS/DVL filter
        if self.watch.diverged:
            H[:, FROZEN_ON_DIVERGENCE] = 0.0
            if self.offset:
                H[:, OFFSET] = 0.0
        return slow, bool(unsure and moving)

    def _offset_column(self, H: np.ndarray) -> None:
        """The time offset's column of H zero while the model's velocity rate, its regressor, is within [ekf]
        calibration_speed_sigmas of what the attitude's uncertainty alone puts into it (gravity through the roll
        and pitch sigmas), as the calibration's columns below the calibration speed (MIN_CALIBRATION_SPEED_M_S).

        The column is k d_R_b times the rate the IMU window gives at the filter's attitude; at constant velocity the
        true rate is zero and the column is the tilt's error times g. Read as information, that noise with the
        offset's 0.5 s sigma pulled the first pings of an underway start at the surface (field-survey seed 8: the
        pitch 0.7 deg off after two pings, the offset's column 0.1-0.25 m/s^2): the offset went to -0.9 s in 1.2 s,
        the heading 21 deg off, and the warm-up window ended at -0.54 +- 0.02 s on a truth of +0.3 s. The offset
        is taken from the pings once the rate stands out of that noise (descents, speed changes, turns)."""
        fs = self.fs
        # (phi about the map's east and north axes: the tilt)
        leak = self.gravity * math.sqrt(max(fs.P[0, 0] + fs.P[1, 1], 0.0))
        if (
            np.linalg.norm(H[:, OFFSET])
            < self.config.ekf.calibration_speed_sigmas * fs.scale * leak
        ):
            H[:, OFFSET] = 0.0
            self.counters["time_offset_unobserved"] = (
                self.counters.get("time_offset_unobserved", 0) + 1
            )

    def _restart_velocity(self) -> None:
        """The velocity back at its prior ([priors] velocity_sigma_m_s, uncorrelated), before the gate reopens
        for a ping when the filter has used only its first ping: its velocity rests on that ping alone and every
        ping since contradicted it, so the first ping was the outlier (field-survey seed 15: 1 m/s off, the next
        ten pings gated). Forced into the velocity it set, the reopened ping's innovation went partly into the
        attitude and the time offset through their correlations with the velocity: the innovations grew to 0.8
        m/s within 2 s and the offset went to -1.9 s. Restarted, the reopened ping sets the velocity."""
        fs = self.fs
        fs.P[VEL, :] = 0.0
        fs.P[:, VEL] = 0.0
        fs.P[VEL, VEL] = np.eye(3) * self.config.priors.velocity_sigma_m_s**2
        self.counters["velocity_restarted"] = self.counters.get("velocity_restarted", 0) + 1

    def _gate(self, dof: int) -> float:
        """The chi^2 gate, reopened after [ekf] gate_reopen_after gated pings in a row (a filter that lost
        track)."""
        ekf_cfg = self.config.ekf
        if self.gated_run >= ekf_cfg.gate_reopen_after:
            return math.inf
        if dof not in self.gates:  # chi2.ppf once per measurement dimension, not once per ping
            self.gates[dof] = gate_threshold(ekf_cfg.gate_probability, dof)
        return self.gates[dof]

    def update_at_ping(self, t_j: float, j: int) -> None:
        """The measurement update of ping j at t_j (gated, robust, the time offset held within its window's bound),
        the divergence watch, the warm-up fit's innovation, the counters; the state recorded."""
        fs, config = self.fs, self.config
        on_water = bool(self.water[j])
        A, z, Rm = ping_measurement(self.log, config, j, on_water)
        y_hat, H, b_omega = self._prediction(t_j, j, on_water)
        slow, unsure = self._calibration_columns(y_hat, H, z, Rm)
        if self.offset and not self.watch.diverged:
            self._offset_column(H)
        gate_nis = self._gate(len(z))
        if self.gated_run >= config.ekf.gate_reopen_after and self.updates == self.gated + 1:
            self._restart_velocity()
        if self.fit is not None:
            AH = A @ H
            hph = AH @ fs.P @ AH.T
        nis, down, was_gated = update(
            fs,
            A @ H,
            z - A @ y_hat,
            Rm,
            config.dvl.robust,
            config.dvl.robust_threshold(),
            gate_nis,
            CALIBRATION if self.consider_calibration or unsure else None,
        )
        bounded = self.offset and abs(fs.time_offset - self.offset_centre) > self.offset_bound
        if bounded:
            lo, hi = self.offset_centre - self.offset_bound, self.offset_centre + self.offset_bound
            # held within its window's bound
            fs.time_offset = float(np.clip(fs.time_offset, lo, hi))
            self.counters["time_offset_bounded"] = self.counters.get("time_offset_bounded", 0) + 1
        # (from the warm-up window's end: a filter converging from a wrong prior, a mounting tens of degrees off,
        # has a large and growing NIS while the vehicle gathers speed; one converging from a far offset touches the
        # bound for a few updates)
        warm = t_j > self.t_first + config.noise.warmup_s
        if not was_gated and warm:
            found = self.watch.add(t_j, nis / len(z))
            if self.watch.held(t_j, bounded) or found:
                self.counters["diverged_at_ping"] = int(j)
        if self.fit is not None and not was_gated:
            self.fit.add_innovation(z - A @ y_hat, hph, Rm, nis)
        self.counters["dvl_slow"] += int(slow)
        self.updates += 1
        self.gated, self.gated_run = (
            self.gated + int(was_gated),
            self.gated_run + 1 if was_gated else 0,
        )
        if not was_gated:
            self.nis_sum, self.nis_dof = self.nis_sum + nis, self.nis_dof + len(z)
            self.downweighted += int(down)
        self._record(t_j, b_omega, on_water)

    def _record(self, t_j: float, b_omega: np.ndarray, on_water: bool) -> None:
        """The state after an update, with the water current's when carried."""
        fs = self.fs
        self.hist.record(fs, t_j, b_omega)
        if (wc := fs.current_slice()) is not None:
            assert fs.current is not None
            self.currents.append(
                (t_j, float(fs.nav.n_p[2]), fs.current.copy(), fs.P[wc, wc].copy(), on_water)
            )

    # ----- the result ----------------------------------------------------------------------------
    def result(self, n_states: int, calibration: VehicleCalibration | None) -> NavResult:
        """The NavResult of the pass: the history, the counters, the filter's consistency, the per-epoch states'
        reports, the nominal calibration's check and the water current."""
        config, fs, counters = self.config, self.fs, self.counters
        # the pings the filter took (a warm-up window's: those up to its end), dvl_gated of them not used
        counters["dvl_updates"] = self.updates
        counters["dvl_downweighted"] = self.downweighted
        counters["dvl_gated"] = self.gated
        if self.depth is not None:
            counters.update(self.depth.counters)
        result = history_result(self.hist, self.log, config)
        result.dvl_pings = self.pings
        result.info = {
            "alignment": self.maker.alignment_info(),
            "counters": counters,
            "epochs": n_states,
            "imu_gaps": self.gaps.summary(),
            "filter": {
                "mean_nis_per_dof": self.nis_sum / max(self.nis_dof, 1),
                "nis_dof": self.nis_dof,
                "error_state": len(fs.P),
                **self.watch.info(),
            },
        }
        t_last = float(self.hist.t[-1]) if self.hist.t else 0.0
        result.info.update(reports(config, ekf_estimates(fs, t_last)))
        if (
            calibration is None
            and self.fit is None
            and config.priors.nominal_check
            and config.priors.hold_weak_information > 0
        ):
            k0, b_R_d0, _ = weak_hold.calibration_prior(config, self.log.mounting)
            d = np.r_[fs.scale - k0, so3_log(np.asarray(b_R_d0).T @ fs.b_R_d)]
            result.info["filter"]["nominal"] = weak_hold.nominal_check(
                d, fs.P[np.ix_(CALIBRATION, CALIBRATION)]
            )
        # the current at each update, its filtered sigmas (estimators/models/current.py)
        if self.currents:
            c = self.currents
            result.water_current = current.profile(
                np.array([x[0] for x in c]),
                np.array([x[1] for x in c]),
                np.array([x[2] for x in c]),
                np.array([x[3] for x in c]),
                config,
                np.array([x[4] for x in c], dtype=bool),
                current.ekf_shear(fs),
            )
        return result


def _start(
    log: LogData,
    config: EstimatorConfig,
    fit: WarmupFit | None,
    calibration: VehicleCalibration | None,
    consider_calibration: bool,
) -> _Pass:
    """A pass at its first ping: the inputs checked (_checked_inputs), the given attitude and map origin (at the
    log's first IMU stamp, an attitude sensor's at its own time) carried to the first ping (alignment.first_state;
    the filter's initial covariance starts from the [priors] attitude sigmas, wider than the alignment's; the
    position's, when the origin is the first GNSS fix, from that fix's covariance: origin.py), the filter's initial
    state (initial_state) and the depth updates."""
    counters: dict[str, int] = {"dvl_slow": 0}
    log, config, frame, alignment, water, pings = _checked_inputs(log, config, counters)
    maker = FactorMaker(config, frame, alignment, log.mounting, log.source)
    p0 = int(pings[0])
    cov0 = given_covariance(alignment, config, alignment_sigmas=False)
    fix = origin_fix(log, config, frame)
    if fix is not None:
        cov0[3:, 3:] = fix.cov
    first = maker.carry_to_first(
        log.imu,
        float(log.dvl.t[p0]),
        log.dvl.d_v[p0] if log.dvl.valid[p0] and not water[p0] else None,
        log.dvl.d_cov[p0],
        cov0,
        origin_fix_time(log, config),
    )
    gaps = find_gaps(log.imu.t, config.imu.gap_samples)
    depth = _depth_updates(log, config, frame)
    fs = initial_state(log, config, maker.alignment.n_R_b, p0, first, calibration)
    if fix is not None:
        fix.place(fs, first.carried)
    current.ekf_start(config, fs, frame.height_m)
    run = _Pass(
        log,
        config,
        frame,
        maker,
        fs,
        pings,
        water,
        gaps,
        depth,
        counters,
        fit,
        consider_calibration,
    )
    if fit is not None:
        fit.start(run.t_first, median_ping_sigma(config, log.dvl.d_cov[pings]))
    return run


def _filter(
    log: LogData,
    config: EstimatorConfig,
    progress: ProgressFn | None,
    fit: WarmupFit | None = None,
    calibration: VehicleCalibration | None = None,
    consider_calibration: bool = False,
) -> NavResult:
    """run_ekf at config's noise levels; with fit, only up to its warm-up window's end, the innovations there
    collected into it (the NavResult then holds the window's states). consider_calibration: the DVL scale and
    misalignment held at their start as consider states (kalman.update). Without a calibration file and with
    [priors] nominal_check (and the hold on), info["filter"]["nominal"] has the final calibration's nominal check
    (estimators/models/weak_hold.py nominal_check)."""
    t_start = time.perf_counter()
    run = _start(log, config, fit, calibration, consider_calibration)
    state_t, ping_at = run.states()
    t_prev = run.t_first
    if run.depth is not None:  # samples before the first state: bridged to it if near enough
        run.depth.apply(run.fs, t_prev, t_prev)
    for count, (t_j, j) in enumerate(zip(state_t.tolist(), ping_at.tolist(), strict=True)):
        t0 = time.perf_counter()
        t_prev = run.propagate(t_prev, t_j)
        t1 = time.perf_counter()
        # samples after the last state: bridged to it
        if run.depth is not None and count == len(state_t) - 1:
            run.depth.apply(run.fs, t_j, t_j, bridge_to=math.inf)
        run.timing["propagate"] += t1 - t0
        if j < 0:  # a state without a ping: recorded, not updated
            run.record_without_ping(t_j)
            continue
        if fit is not None and t_j > fit.t_end:
            run.timing["propagate"] -= t1 - t0  # (not counted: the window ended before it)
            break
        run.update_at_ping(t_j, int(j))
        run.timing["update"] += time.perf_counter() - t1
        if progress and count % 100 == 0:
            progress(count / len(state_t))
    result = run.result(len(state_t), calibration)
    result.timing_s = {**run.timing, "total": time.perf_counter() - t_start}
    if progress:
        progress(1.0)
    return result


def ekf_estimates(fs: FilterState, t: float) -> dict[str, EpochEstimate]:
    """The per-epoch states' filtered estimates at the filter's last state (stamped t s) and their covariance
    blocks (estimators/models/epoch_states.py)."""
    return {
        name: EpochEstimate(
            np.array([t]), fs.epoch[name][None, :].copy(), fs.P[cols, cols][None].copy(), False
        )
        for name, cols in fs.epoch_slices().items()
    }
