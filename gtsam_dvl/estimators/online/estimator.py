"""Online estimation: an incremental (iSAM2) estimator fed message by message, with bounded latency.

A vehicle or a script creates an `OnlineEstimator`, pushes IMU and DVL messages in time order
(`push_imu`, `push_imu_batch`, `push_dvl`) and reads `estimate()` after each DVL epoch: pose, velocity,
biases, scale and misalignment, each with its marginal (filtering) covariance. `smooth_online(log, config)`
(whole_log.py) drives it over a whole log and returns the same `NavResult` as the batch smoother, with a
`Timeline` of the filtering sigmas at every epoch.

Which mode:
- `fixed_lag` (default): states older than `window_s` (20 s) behind the newest are marginalised; the bias,
  scale and misalignment never leave. The cost per DVL epoch is bounded however long the mission
  (bench/bench_online.py prints the latencies; docs/results.md, "Online estimator"): use it on the vehicle and
  for any log longer than a few minutes. Its final calibration is the batch smoother's to a fraction of a sigma
  (what left the window stays linearised where it was when it left) and so are its sigmas, but the vertical
  accelerometer bias's is larger (the static phase's zero-velocity pings left the window while the
  scale was still its prior 0.8, and are credited the velocity information k^2 / sigma^2 at that scale).
- `full`: every state is kept and iSAM2 may relinearise any of them; its final estimate is the batch
  smoother's to a few hundredths of a sigma (docs/results.md, "Online estimator"). Each relinearisation of the
  calibration touches every DVL factor of the mission through a Python callback that receives a copy of all the
  variables, so its cost per update grows with the mission: use it to check the fixed-lag mode on short logs, or
  when every past state must stay adjustable.
- The trajectory of the returned NavResult is the filtering one in both modes: each state as estimated when its
  ping was processed, what the vehicle knew then (the batch smoother gives the smoothed one).

Keyframes (`[solver] keyframe_spacing_s`, 1 s by default; online/between_pings.py): the states are the batch
smoother's, at the keyframes (selection.KeyframeRule, decided ping by ping: the first usable ping, then each
first one at least 0.98 spacings after the previous keyframe) and at the DVL-dropout fillers; every
other usable ping becomes the batch smoother's DVL factor on the state before it through the IMU motion since
that state (FactorMaker.dvl_keyframe_factors_for; the motion integrated as the pings come, to the same bits as
keyframes.interval_with_snapshots). That state is always the newest: a ping between keyframes comes less than a spacing
after its keyframe, a filler max_state_spacing_s >= spacing after a state. At finish() the last ping still
between keyframes becomes a keyframe, as the batch smoother makes the last usable ping one. On a 1 Hz DVL, 1 s
keyframes are a state per ping (the same result to the last bit as keyframe_spacing_s = 0).
- Where a ping between keyframes goes (`defer_between_pings`): True (default), its factor waits for the next
  state's iSAM2 update; False, an iSAM2 update of its own at once. Deferred, because it gives the lower p99
  and the higher real-time factor (bench/bench_online_long.py --between deferred / immediate; docs/results.md,
  "Online estimator"). An iSAM2 update has a fixed cost (the ordering, re-eliminating the cliques of the newest
  state and the shared keys, the relinearisation check, the marginal covariance of the estimate) that deferral
  pays once per state instead of once per ping, while the ping's own work (its IMU motion, its factor, the
  prediction below) is a fraction of it; the state's update linearises four more factors. What it gives up:
  until the next state, the pings since the newest state are not in the estimate.
- estimate() after a ping between keyframes: the state at the ping predicted from the newest state's estimate
  through the IMU motion up to it (online/between_pings.predict_at_ping: the keyframe factor's own model, its
  covariance propagated to first order), OnlineEstimate.t the ping's time and predicted_from_t the state's
  (nan for the estimate of a state). Its errors against the simulated truth are consistent with its sigmas
  (tests/estimators/test_online_keyframes.py). The Timeline and the NavResult hold the states only, each as
  estimated when it was made, as the batch smoother's hold its states.
- latencies_s, latencies_cpu_s and latency_t: one entry per epoch processed, each state (with or without a ping)
  and each ping between keyframes.

Design (the modules of this package):
- window.py, the iSAM2 engine; keyframes.py, the IMU motion to the pings between keyframes; the DVL factors of a
  ping, with the calibration "considered" for slow pings: dvl_factors.py; the IMU samples since the newest state:
  imu_buffer.py; the time offset's IMU windows: offset_windows.py; the depth samples: depth_queue.py; the start
  (the alignment wait): alignment_wait.py; the checks of the messages pushed: messages.py; replaying a log:
  feed.py; the options and estimate types: types.py.
- The FactorMaker the batch smoother's whole-log graph uses (estimators/graph/factor_maker.py) makes every factor,
  prior and initial guess from explicit measurements; pings are classified, screened and made epochs by
  selection.EpochScheduler, ping by ping, with the rules the batch smoother and the EKF apply to the whole log
  (selection.KeyframeRule); IMU intervals are split by the rules of estimators/inputs/selection.py.
- IMU samples are kept raw since the newest state and preintegrated up to the next one as its pings come and
  when the state is made, exactly as the batch smoother does (a sample straddling the state's ping is split;
  online/between_pings.StatePreintegration: the same pieces in the same order), so a ping that arrives after IMU samples
  past its stamp (another topic, another latency) is still placed exactly.
- Pings without a valid velocity, faster than dvl.max_speed_m_s or not after the first IMU sample are counted and
  skipped, as the batch smoother does; so are bogus pings (selection.PingScreen: exact zeros while moving,
  repeats, implausible jumps), decided once the IMU samples reach the ping (the screen looks at the IMU since the
  previous accepted ping), whatever the message order.
"""

from __future__ import annotations

import math
import time
from array import array
from collections import deque
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import S as S_KEY  # (the water current's layer boundaries)
from gtsam_dvl.core.keys import W as W_KEY  # (W: the IMU gyro samples in this module)
from gtsam_dvl.core.result import NavResult, Timeline, WaterCurrentProfile
from gtsam_dvl.core.states import calibration_info, enabled, water_current
from gtsam_dvl.core.types import ImuData, LogData, Mounting
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.alignment import Alignment, map_frame_of
from gtsam_dvl.estimators.inputs.gaps import (
    check_spacing,
    filler_due,
)
from gtsam_dvl.estimators.inputs.gnss import origin_fix_time
from gtsam_dvl.estimators.inputs.mounting import imu_is_rotated, rotate_imu_samples
from gtsam_dvl.estimators.inputs.prepare import refuse_combinations, refuse_unsupported
from gtsam_dvl.estimators.inputs.selection import EpochScheduler, Ping
from gtsam_dvl.estimators.models import current
from gtsam_dvl.estimators.models.current import resolve_water_track
from gtsam_dvl.estimators.models.noise_levels import (
    NoiseReport,
    dvl_fit_enabled,
    held_levels,
    imu_levels,
    median_ping_sigma,
    with_multiplier,
)
from gtsam_dvl.estimators.online.alignment_wait import AlignmentWait, given_attitude
from gtsam_dvl.estimators.online.between_pings import (
    KeyframeGravity,
    StatePreintegration,
    predict_at_ping,
)
from gtsam_dvl.estimators.online.depth_queue import DepthQueue
from gtsam_dvl.estimators.online.dvl_factors import (
    RateInput,
    keyframe_dvl_factors,
    state_dvl_factors,
)
from gtsam_dvl.estimators.online.gnss_queue import GnssQueue
from gtsam_dvl.estimators.online.imu_buffer import ImuBuffer
from gtsam_dvl.estimators.online.messages import MessageChecks, vector3
from gtsam_dvl.estimators.online.noise_fit import OnlineNoiseFit
from gtsam_dvl.estimators.online.offset_windows import OffsetWindows
from gtsam_dvl.estimators.online.types import (
    EpochHistory,
    OnlineConfig,
    OnlineEstimate,
    latency_stats,
)
from gtsam_dvl.estimators.online.window import (
    IncrementalSmoother,
    StateEstimate,
)

__all__ = ["OnlineEstimator"]  # the package's __init__ exports the rest


def _effective_config(
    config: EstimatorConfig, options: OnlineConfig | None
) -> tuple[OnlineConfig, EstimatorConfig]:
    """The online options (options=: overrides config.online) and the effective configuration, validated, with
    water track "auto" taken as "use" (live: water-track pings may come; for_log resolves by the log);
    GtsamDvlError for what the online estimator does not support (keyframe spacing beyond the state spacing, the
    time offset with beams, the lever arm)."""
    if config.current.water_track == "auto":
        config = config.model_copy(
            update={"current": config.current.model_copy(update={"water_track": "use"})}
        )
    options = options or config.online
    config = config.model_copy(update={"online": options}).validate()
    solver = config.solver
    check_spacing(solver)
    spacing = solver.keyframe_spacing_s
    # the batch smoother's rule (estimators/graph/log_graph.py)
    if spacing > solver.max_state_spacing_s:
        raise GtsamDvlError(
            f"solver.keyframe_spacing_s = {spacing:g} s needs solver.max_state_spacing_s >= "
            f"{spacing:g} s: states without a ping would take the places of the keyframes"
        )
    # what no estimator does and what the online estimator does not, in the runner's words (inputs/prepare.py):
    # an estimator made without a log (the ROS 2 node, the live view) is checked here
    refuse_combinations(config, None)
    refuse_unsupported("online", config, None)
    return options, config


def _epoch_scheduler(config: EstimatorConfig, counters: dict[str, int]) -> EpochScheduler:
    """Classification, screen and keyframes of the pings (selection.EpochScheduler: the batch smoother's
    decisions)."""
    solver, online = config.solver, config.online
    return EpochScheduler(
        config.dvl,
        solver.keyframe_interval_s,
        solver.keyframe_spacing_s,
        counters,
        keep_usable=online.record_history,
        water_usable=water_current(config),
    )


def _noise_fit(config: EstimatorConfig) -> OnlineNoiseFit | None:
    """The DVL noise fitted on the warm-up window (online/noise_fit.py) when [noise] fits it, its lag (s) within
    a fixed-lag window."""
    online = config.online
    lag = min(10.0, 0.5 * online.window_s) if online.mode == "fixed_lag" else 10.0
    return OnlineNoiseFit(config, lag) if dvl_fit_enabled(config) else None


def _offset_windows(
    dvl: DvlConfig, calibration: VehicleCalibration | None, counters: dict[str, int]
) -> OffsetWindows:
    """The time offset's IMU windows, centred on a calibration file's offset when it holds one."""
    held = calibration.values.get("time_offset") if calibration is not None else None
    return OffsetWindows(
        dvl
        if held is None
        else dvl.model_copy(update={"time_offset_prior_s": float(np.ravel(held)[0])}),
        counters,
    )


class OnlineEstimator:
    """Incremental estimator fed message by message (module doc). Times are seconds on the caller's clock,
    the same for IMU and DVL; IMU sample t covers (previous sample, t] (ImuData's convention). IMU samples are
    given in imu_link and rotated into base_link with mounting.b_R_imu (estimators/inputs/mounting.py). depth_sensor:
    the pressure sensor's position in base_link (m, from /tf_static; [depth] lever_arm_m overrides it); gnss_antenna:
    the GNSS antenna's (m, from /tf_static; [gnss] lever_arm_m overrides it). recentre_offset_window (attribute,
    default True): the time offset's IMU windows centred on the current estimate (online/offset_windows.py); False
    keeps them at the prior (to measure what the re-centring gives)."""

    def __init__(
        self,
        config: EstimatorConfig | None = None,
        *,
        frame: LocalFrame,
        mounting: Mounting | None = None,
        options: OnlineConfig | None = None,
        source: str = "",
        depth_sensor: Any = None,
        calibration: VehicleCalibration | None = None,
        gnss_antenna: Any = None,
    ) -> None:
        # a vehicle's calibration (inflated for its age): the joint prior of the states it holds (FactorMaker)
        self.calibration = calibration
        self.options, self.config = _effective_config(config or EstimatorConfig(), options)
        # what result.config records: the configuration as given, before the levels taken from the data
        # (noise_levels.py; those are in info["noise"]), so that reading it back with -c reproduces the run
        self.stated_config = self.config
        dvl = self.config.dvl
        self.frame, self.mounting, self.source = frame, mounting or Mounting(), source
        self._imu_rotated = imu_is_rotated(self.mounting)
        self.counters: dict[str, int] = {}
        # wall time (s) per epoch processed (a state, with or without a ping, or a ping between keyframes: the
        # preintegration, factors, iSAM2 update, covariances), the process's CPU time over it (s: what other
        # processes on a shared machine do not inflate) and the epoch's time (s): arrays, not lists of Python
        # floats (8 bytes each)
        self.latencies_s: array[float] = array("d")
        self.latencies_cpu_s: array[float] = array("d")
        self.latency_t: array[float] = array("d")
        self.builder: FactorMaker | None = None
        self.smoother: IncrementalSmoother | None = None
        self._checks = MessageChecks(self.options.bad_messages, source, self.counters)
        # classification, screen and keyframes (selection.EpochScheduler: the batch smoother's decisions)
        self._scheduler = _epoch_scheduler(self.config, self.counters)
        # pings between keyframes: their factors wait for the next state's update (True) or each goes into iSAM2
        # at once (False; module doc, "Keyframes")
        self.defer_between_pings = True
        # the next IMU factor's, integrated at the pings between
        self._interval: StatePreintegration | None = None
        self._gravity: KeyframeGravity | None = None
        self._deferred: list[tuple[Ping, list[gtsam.NonlinearFactor]]] = []
        # the newest state's estimate (after its update, or the last)
        self._state: StateEstimate | None = None
        self._first_imu_t: float | None = None
        # the time the map origin refers to (s): None, the first IMU stamp; a GNSS fix's when it is the origin
        # (for_log, the node); the first state's position is the origin carried from it (alignment.first_state)
        self.origin_t: float | None = None
        # before alignment
        self._wait = AlignmentWait(frame, self.config, self.options.align_s, source, self.mounting)
        # after it: the IMU since the newest state
        self._imu = ImuBuffer(self.config.imu, source, self._count)
        self._replaying = False  # replaying the messages buffered before the alignment
        self._pending: deque[Ping] = deque()  # pings decided, waiting for their epoch
        self._pings_pushed = 0  # push_dvl's calls (Ping.index)
        # the water current at each state after its update: (t, z, W, its covariance, water-track pings on it)
        self.current_history: list[tuple[float, float, np.ndarray, np.ndarray, bool]] = []
        self._latest: OnlineEstimate | None = None
        self._history = EpochHistory()
        self._offset = enabled(self.config, "time_offset")
        self._offset_windows = _offset_windows(dvl, calibration, self.counters)
        self._flushing = False
        self._depth = DepthQueue(
            self.config.depth,
            frame,
            None if depth_sensor is None else vector3("depth_sensor", depth_sensor),
            self._count,
        )
        # GNSS fixes at the surface, and the map origin's fix (online/gnss_queue.py; origin_t)
        self._gnss = GnssQueue(self.config, frame, gnss_antenna, self.counters)
        # the DVL noise fitted on the warm-up window (online/noise_fit.py); noise: the levels used and why
        self._noise_fit = _noise_fit(self.config)
        self.noise = NoiseReport()
        if self.config.alignment.initial_attitude_deg is not None:
            self._start(given_attitude(frame, self.config.alignment))

    @classmethod
    def for_log(
        cls,
        log: LogData,
        config: EstimatorConfig | None = None,
        options: OnlineConfig | None = None,
        calibration: VehicleCalibration | None = None,
    ) -> OnlineEstimator:
        """An estimator with the map origin and mounting of a log (to replay it). config None: the one the
        log's scenario names, else the defaults (EstimatorConfig.for_log). calibration: as in __init__."""
        config = resolve_water_track(config or EstimatorConfig.for_log(log.metadata), log)
        noise = NoiseReport()
        stated = config
        config = imu_levels(log, config, noise)  # the IMU's white noise from the log ([noise])
        est = cls(
            config,
            frame=map_frame_of(log, config),
            mounting=log.mounting,
            options=options,
            source=log.source,
            depth_sensor=None if log.depth is None else log.depth.b_p_sensor,
            calibration=calibration,
            gnss_antenna=None if log.gnss is None else log.gnss.b_p_antenna,
        )
        est.noise.imu = noise.imu
        # (depth, correlated DVL error: the batch fits them)
        held_levels(log, config, "online estimator", est.noise)
        est.origin_t = origin_fix_time(log, config)
        # a noise-free simulation's repeats
        est._scheduler.screen.repeats_need_motion = log.dvl.noise_free
        est._scheduler.water_screen.repeats_need_motion = log.dvl.noise_free
        est.stated_config = stated.model_copy(update={"online": est.options}).validate()
        return est

    @property
    def recentre_offset_window(self) -> bool:
        return self._offset_windows.recentre

    @recentre_offset_window.setter
    def recentre_offset_window(self, on: bool) -> None:
        self._offset_windows.recentre = on

    # ----- input ---------------------------------------------------------------------------------
    def push_imu(self, t: float, b_omega: Any, b_f: Any) -> int:
        """One IMU sample: gyro b_omega (rad/s) and specific force b_f (m/s^2) averaged over (previous t, t].
        Returns the number of DVL epochs it completed."""
        chunk = self._checks.imu_sample(float(t), b_omega, b_f)
        return 0 if chunk is None else self._take_imu(*chunk)

    def push_imu_batch(self, t: Any, b_omega: Any, b_f: Any) -> int:
        """Several IMU samples in time order, (N,), (N, 3), (N, 3). Returns the number of epochs completed."""
        chunk = self._checks.imu_batch(t, b_omega, b_f)
        return 0 if chunk is None else self._take_imu(*chunk)

    def push_attitude(
        self, t: float, n_q_b: Any, cov: Any = None, *, frame: str = "base_link"
    ) -> int:
        """One attitude sample at t for the initial attitude (online/alignment_wait.py; ignored once aligned): the
        orientation in map (ENU) of base_link, or with frame "imu_link" of the IMU (an Imu message's own orientation,
        turned with mounting.b_R_imu), as a quaternion [x, y, z, w], with its covariance (3x3 rad^2 about the
        sensor's axes; None, all zeros or NaN: unknown, alignment.attitude_sigma_deg then). A zero or non-finite
        quaternion, or cov[0][0] = -1 (ROS: no orientation), is no sample. Returns the epochs completed."""
        if self.smoother is not None:
            return 0
        b_R_s = self.mounting.b_R_imu if frame == "imu_link" else np.eye(3)
        if frame not in ("base_link", "imu_link"):
            raise GtsamDvlError(
                f'push_attitude: frame must be "base_link" or "imu_link", got {frame!r}'
            )
        return self._align() if self._wait.push_attitude(float(t), n_q_b, cov, b_R_s) else 0

    def push_gnss(
        self, t: float, lat: float, lon: float, h: float, cov: Any = None, status: int = 0
    ) -> None:
        """One GNSS fix of the antenna at t (sensor_msgs/msg/NavSatFix: WGS84 lat, lon (deg), h (m), its ENU position
        covariance cov (m^2; None or NaN: unknown) and status): a position factor while at the surface at the start
        ([gnss] use), else held out (online/gnss_queue.py); the map origin's own fix is the first state's prior."""
        self._gnss.push(float(t), lat, lon, h, cov, int(status), self.origin_t)

    def push_dvl(
        self,
        t: float,
        d_v: Any,
        d_cov: Any = None,
        valid: bool = True,
        beams: tuple[Any, Any, Any] | None = None,
        water_track: bool = False,
    ) -> int:
        """One DVL ping at t: velocity d_v (m/s, dvl_link) with covariance d_cov (3x3, None: the configured
        default), valid flag, and optionally beams = (d_u (B, 3), v (B,), valid (B,)). A ping without a valid
        velocity (NaN) is counted, not an error, and so is a water-track ping (water_track). Returns the number
        of epochs completed."""
        index = self._pings_pushed
        self._pings_pushed += 1
        ping = self._checks.ping(float(t), d_v, d_cov, valid, beams)
        if ping is None:
            return 0
        ping.index, ping.water_track = index, bool(water_track)
        if self.smoother is None:
            self._wait.pings.append(ping)
            return 0
        return self._take_ping(ping)

    def push_depth(
        self,
        t: float,
        depth_m: float = math.nan,
        variance_m2: float = math.nan,
        *,
        pressure_pa: float | None = None,
        pressure_variance_pa2: float = math.nan,
    ) -> None:
        """One depth sample at t: the pressure sensor's depth (m below the surface, positive down) and its
        variance (m^2, NaN: unknown), or with pressure_pa its absolute pressure (Pa) and variance (Pa^2),
        converted with [depth] (estimators/inputs/depth.py depth_samples). Its factor is added with the first state at
        or
        after t (online/depth_queue.py). A non-finite value is counted ("depth_invalid"), not an error; nothing is
        done with [depth] use = false."""
        t = float(t)
        if not self._checks.depth_stamp(t) or not self.config.depth.use:
            return
        for name in (
            "depth_used",
            "depth_too_far",
            "depth_invalid",
        ):  # reported even when zero, as by the batch
            self.counters.setdefault(name, 0)
        n = len(self._depth)
        self._depth.push(t, depth_m, variance_m2, pressure_pa, pressure_variance_pa2)
        if len(self._depth) > n:  # its depth below the surface: the fixes' depth gate
            self._gnss.push_depth(t, -(self._depth.waiting[-1][1] + self.frame.height_m))

    def finish(self) -> OnlineEstimate | None:
        """End of data: align on what there is if still waiting, process the pings that waited only for the IMU
        after them (the time offset's window, cut at the end of the data), drop pings no IMU sample reached, put
        the depth samples after the newest state on it (if near enough), and let iSAM2 relinearise until
        converged (options.final_updates). Returns the final estimate."""
        if self.smoother is None and self._wait.imu:
            self._align(final=True)
        self._flushing = True
        self._close_ready()
        self._flushing = False
        self._count("dvl_after_imu", len(self._pending) + self._scheduler.drop_waiting())
        self._pending.clear()
        if self._deferred:  # the batch smoother makes the last usable ping a keyframe: so does this
            last, _ = self._deferred.pop()
            self._count("pings_between_keyframes", -1)
            last.key = True
            self._close(last)
        if self.smoother is not None and self.smoother.n > 0:
            sm = self.smoother
            assert self.builder is not None
            sm.add_factors(
                self._depth.factors(self.builder, sm.times, sm.n - 1, sm.t_last, final=True)
                + self._gnss.factors(self.builder, sm.times, sm.n - 1, sm.t_last, final=True)
            )
            sm.refresh_gravity()
            sm.refine(self.options.final_updates)
            self._latest = self._read_estimate(with_covariance=True)
        if self._noise_fit is not None and not self._noise_fit.done:
            self.noise.dvl = {
                "multiplier": self.config.dvl.noise_multiplier,
                "why": "DVL noise not fitted: the log ends within the warm-up window ([noise] warmup_s) "
                "and the residuals' lag",
            }
        return self._latest

    # ----- output --------------------------------------------------------------------------------
    def current_profile(self) -> WaterCurrentProfile:
        """NavResult.water_current: the filtered current at each state (estimators/models/current.py
        profile)."""
        h, sm = self.current_history, self.smoother
        shear = (
            {}
            if sm is None
            else {  # with layers, each boundary crossed (never marginalised)
                b: (
                    sm.isam.calculateEstimate([S_KEY(b)]).atVector(S_KEY(b)),
                    sm.joint_covariance([S_KEY(b)]),
                )
                for b in sm.shear
            }
        )
        return current.profile(
            np.array([c[0] for c in h]),
            np.array([c[1] for c in h]),
            np.array([c[2] for c in h]),
            np.array([c[3] for c in h]),
            self.config,
            np.array([c[4] for c in h], dtype=bool),
            shear,
        )

    def estimate(self) -> OnlineEstimate | None:
        """The estimate after the latest epoch (None before the first): the newest state's, or after a ping between
        keyframes the state at that ping predicted from the newest state (module doc, "Keyframes";
        OnlineEstimate.predicted_from_t)."""
        return self._latest

    @property
    def epochs(self) -> int:
        return 0 if self.smoother is None else self.smoother.n

    def timeline(self) -> Timeline:
        """Filtering estimates and sigmas after every epoch (options.record_history)."""
        return self._history.timeline(self.mounting.b_R_d0)

    def result(self, t0_ns: int = 0) -> NavResult:
        """NavResult: the trajectory as estimated online (each state when its ping was processed, with its
        filtering covariance), the bias and calibration after finish(), and the timeline."""
        h, final = self._history, self._latest
        if len(h) == 0 or final is None or self.builder is None or self.smoother is None:
            raise GtsamDvlError(
                f"{self.source or 'online estimator'}: no DVL epoch was processed (or "
                "options.record_history is off)"
            )
        n_vars, n_factors = self.smoother.size()
        info: dict[str, Any] = {
            "mode": self.options.mode,
            "window_s": self.options.window_s if self.options.mode == "fixed_lag" else None,
            "trajectory": "filtered: each state as estimated when its DVL ping was processed",
            "counters": dict(self.counters),
            "epochs": len(h),
            "keyframe_spacing_s": self.config.solver.keyframe_spacing_s,
            "imu_gaps": self._imu.gaps_info(),
            "alignment": {**self.builder.alignment_info(), "latency": dict(self._wait.latency)},
            "noise": self.noise.as_dict(),
            "latency_ms": latency_stats(self.latencies_s),
            "isam2": {
                "rebases": self.smoother.rebases,
                "states_marginalized": self.smoother.marginalised,
                "variables": n_vars,
                "factors": n_factors,
            },
        }
        if self.calibration is not None:
            info["calibration_prior"] = calibration_info(self.config, self.calibration)
        return NavResult(
            estimator=f"online-{self.options.mode.replace('_', '-')}",
            t=h["t"].copy(),
            n_p=h["n_p"].copy(),
            n_R_b=h["n_R_b"].copy(),
            n_v=h["n_v"].copy(),
            pose_cov=h["pose_cov"].copy(),
            vel_cov=h["vel_cov"].copy(),
            pose_vel_cross=h["pose_vel_cross"].copy(),
            calibration=final.calibration,
            b_R_d0=self.mounting.b_R_d0,
            t0_ns=t0_ns,
            b_omega=h["b_omega"] - final.gyro_bias,
            calib_joint_cov=final.calib_cov,
            timeline=self.timeline(),
            info=info,
            config=self.stated_config.to_dict(),
            dvl_pings=np.asarray(self._scheduler.usable, dtype=np.int64),
        )

    # ----- internals -----------------------------------------------------------------------------
    def _count(self, kind: str, n: int = 1) -> None:
        if n:
            self.counters[kind] = self.counters.get(kind, 0) + n

    def _take_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> int:
        if self._imu_rotated:  # samples in imu_link -> base_link (estimators/inputs/mounting.py)
            w, f = rotate_imu_samples(self.mounting.b_R_imu, w, f)
        if self._first_imu_t is None:
            self._first_imu_t = float(t[0])
        if self.smoother is None:
            self._wait.push_imu(t, w, f)
            return self._align()
        return self._ingest_imu(t, w, f)

    def _ingest_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> int:
        self._imu.push(t, w, f)
        if len(t):
            self._scheduler.push_imu(t, w, f)
            if self._offset:
                self._offset_windows.push(t, w, f)
        self._pending.extend(self._scheduler.ready())
        return self._close_ready()

    def _align(self, final: bool = False) -> int:
        """Align when the messages kept allow it (online/alignment_wait.py), then run on them."""
        w0 = time.perf_counter()
        if (aligned := self._wait.try_align(final)) is None:
            return 0
        t, w, f = aligned.imu
        self._start(aligned.alignment)
        # replay: every buffered ping is queued before any epoch is made, so that the states without a ping
        # (DVL dropouts) are placed between them as in the batch smoother
        self._replaying = True
        self._ingest_imu(t, w, f)
        for p in aligned.pings:
            self._take_ping(p)
        self._replaying = False
        done = self._close_ready()
        # data seconds buffered before the alignment, and the wall time of the alignment and the catch-up on them
        self._wait.latency.update(
            aligned_after_s=t[-1] - t[0], catch_up_wall_s=time.perf_counter() - w0
        )
        return done

    def _start(self, alignment: Alignment) -> None:
        self.builder = FactorMaker(
            self.config,
            self.frame,
            alignment,
            self.mounting,
            self.source,
            calibration=self.calibration,
        )
        window = self.options.window_s if self.options.mode == "fixed_lag" else None
        self.smoother = IncrementalSmoother(self.builder, window, self.options.relinearization)
        self._interval = StatePreintegration(self.builder.make_params, self.config.imu)
        self._gravity = KeyframeGravity(self.builder.keyframe_gravity)

    def _take_ping(self, p: Ping) -> int:
        first = self._first_imu_t if self._first_imu_t is not None else math.inf
        if not self._scheduler.push_ping(p, first):
            return 0
        self._pending.extend(self._scheduler.ready())
        return self._close_ready()

    def _offset_estimate(self) -> float | None:
        """The current estimate of the time offset (s), None before the first epoch."""
        return None if self._latest is None else self._latest.time_offset_s

    def _close_ready(self) -> int:
        """Make the epochs the IMU samples now reach: pings, and states without a ping where pings are missing
        (estimators/inputs/gaps.py, filler_due: the batch smoother's rule)."""
        if self._replaying:
            return 0
        done = 0
        spacing = self.config.solver.max_state_spacing_s
        # with the time offset a ping waits for the IMU window after it (online/offset_windows.py), unless at finish()
        ahead = self._offset_windows.wait_s(self._offset_estimate()) if self._offset else 0.0
        while (t_end := self._imu.t_last()) is not None and self.smoother is not None:
            if self._pending and self.smoother.n > 0 and self._pending[0].t <= self.smoother.t_last:
                # a ping later than FILLER_MARGIN_S behind the IMU, older than the state without a ping made in
                # its place: it cannot be inserted behind the newest state
                self._pending.popleft()
                self._count("dvl_late")
                continue
            nxt = self._pending[0].t if self._pending else None
            if (
                self.smoother.n > 0
                and (t_f := filler_due(self.smoother.t_last, nxt, t_end, spacing)) is not None
            ):
                self._close(None, t_f)
            elif (
                self._pending
                and self._pending[0].t <= t_end
                and (self._flushing or self._pending[0].t + ahead <= t_end)
            ):
                p = self._pending.popleft()
                if p.key or self.smoother.n == 0:
                    self._close(p)
                else:
                    self._between_ping(p)
                ahead = (
                    self._offset_windows.wait_s(self._offset_estimate()) if self._offset else 0.0
                )
            else:
                break
            done += 1
        return done

    def _rate_input(self, t: float) -> RateInput:
        """The time-offset IMU constants of a ping at t: the windows on the latest estimate's offset, biases and
        attitude (online/offset_windows.py)."""
        assert self.builder is not None
        est = self._latest
        bias = None if est is None else (est.accel_bias, est.gyro_bias)
        return self._offset_windows.rate_input(
            self.builder, t, self._offset_estimate(), bias, None if est is None else est.n_R_b
        )

    def _close(self, p: Ping | None, t_state: float | None = None) -> None:
        """Make the epoch of ping p (or, p None, a state without a ping at t_state): preintegrate since the
        previous one, add its factors, update iSAM2."""
        assert self.builder is not None and self.smoother is not None and self._interval is not None
        t0, c0 = time.perf_counter(), time.process_time()
        b, sm = self.builder, self.smoother
        t_epoch = p.t if p is not None else float(t_state)  # type: ignore[arg-type]
        T, W, F = self._imu.samples()
        i = sm.n
        # the given attitude and origin (at the first IMU stamp) carried to the epoch
        if i == 0 and p is not None:
            self._gnss.carry_to_first(b, ImuData(T, W, F), t_epoch, p, self.origin_t)
        gi = int(np.searchsorted(T, t_epoch, side="left"))  # the sample covering the epoch
        b_omega = b.body_rate(W[gi])
        rate_input = self._rate_input(t_epoch) if self._offset and p is not None else None
        min_speed = self.options.calibration_min_speed_m_s
        dvl = state_dvl_factors(b, i, p, b_omega, min_speed, rate_input) if p is not None else []
        # the pings of this epoch (those between keyframes, then its own)
        if self._noise_fit is not None:
            for q, fs in [*self._deferred, *(((p, dvl),) if p is not None else ())]:
                self._noise_fit.record(q.t, list(fs), median_ping_sigma(self.config, q.d_cov))
        self._count("states_without_ping" if p is None else "keyframes")
        dvl += self._depth.factors(b, sm.times, i, t_epoch)
        dvl += self._gnss.factors(b, sm.times, i, t_epoch)
        if i == 0:
            assert p is not None  # the first epoch is a ping (_close_ready)
            sm.add_epoch(
                t_epoch, dvl, first_values=b.first_state_values(p.d_v if p.valid else None)
            )
        else:
            imu = self._imu.pieces(b, T, W, F, final=True)
            # FactorMaker.preintegrate_interval(sm.t_last, t_epoch, ...), the part up to the last ping done then
            pim, params, held = self._interval.close(t_epoch, imu)
            between = [
                f for _, fs in self._deferred for f in fs
            ]  # the pings since the previous state (on it)
            sm.add_epoch(t_epoch, between + dvl, pim, params, held=held)
        epoch_water = (p is not None and p.water_track) or any(
            q.water_track for q, _ in self._deferred
        )
        self._deferred = []
        if (
            self._noise_fit is not None
            and (new := self._noise_fit.after_epoch(t_epoch, sm.isam)) is not None
        ):
            self.noise.dvl = self._noise_fit.report  # held from now on: the next factors take it
            self.config = with_multiplier(self.config, new)
            b.config = self.config
        self._interval.reset(t_epoch)
        self._imu.keep_from(t_epoch)
        if self._offset:  # keep what the next epochs' velocity-rate windows can reach
            self._offset_windows.trim(t_epoch)
        self._state = self._read_state()
        self._latest = OnlineEstimate.from_state(self._state, self.mounting.b_R_d0)
        if self.options.record_history:
            self._history.append(self._latest, b_omega)
            # the newest state's current, filtered (as the EKF's), for current_profile
            if water_current(self.config):
                self.current_history.append(
                    (
                        t_epoch,
                        float(self._state.pose.translation()[2]),
                        sm.isam.calculateEstimate([W_KEY(i)]).atVector(W_KEY(i)).copy(),
                        sm.joint_covariance([W_KEY(i)]),
                        epoch_water,
                    )
                )
        self._record(t0, c0, t_epoch)

    def _between_ping(self, p: Ping) -> None:
        """A ping between keyframes: the IMU motion from the newest state up to it (online/between_pings.py,
        StatePreintegration.snapshot_at), its keyframe DVL factor on that state, deferred to the next state's update
        or added to iSAM2 now (defer_between_pings), and the estimate at the ping predicted from the newest state."""
        assert self.builder is not None and self.smoother is not None
        assert self._gravity is not None and self._state is not None and self._interval is not None
        t0, c0 = time.perf_counter(), time.process_time()
        b, sm = self.builder, self.smoother
        T, W, F = self._imu.samples()
        # the next IMU factor's samples up to the ping, the last stamp <= it
        snap = self._interval.snapshot_at(p.t, self._imu.pieces(b, T, W, F, final=False))
        n_p0, n_g0, n_G = self._gravity.at(np.asarray(self._state.pose.translation(), dtype=float))
        motion = snap.motion(b.n_omega_ie(), n_g0, n_p0, n_G)
        b_omega = b.body_rate(W[int(np.searchsorted(T, p.t, side="left"))])
        rate_input = self._rate_input(p.t) if self._offset else None
        factors = keyframe_dvl_factors(
            b,
            sm.n - 1,
            p,
            b_omega,
            snap,
            motion,
            self.options.calibration_min_speed_m_s,
            rate_input,
        )
        self._count("pings_between_keyframes")
        if self.defer_between_pings:
            self._deferred.append((p, factors))
        else:
            sm.add_factors(factors)
            self._state = self._read_state()
        self._latest = OnlineEstimate.from_state(
            predict_at_ping(self._state, p.t, snap, motion), self.mounting.b_R_d0
        )
        self._record(t0, c0, p.t)

    def _record(self, t0: float, c0: float, t: float) -> None:
        # the first estimate: the data seconds from the first IMU sample to the newest when it came out
        self._wait.latency.setdefault(
            "first_estimate_after_s", self._checks.last_imu_t - (self._first_imu_t or 0.0)
        )
        self.latencies_s.append(time.perf_counter() - t0)
        self.latencies_cpu_s.append(time.process_time() - c0)
        self.latency_t.append(t)

    def _read_state(self, with_covariance: bool | None = None) -> StateEstimate:
        assert self.smoother is not None
        cov = self.options.covariances if with_covariance is None else with_covariance
        return self.smoother.estimate(with_covariance=cov)

    def _read_estimate(self, with_covariance: bool | None = None) -> OnlineEstimate:
        return OnlineEstimate.from_state(self._read_state(with_covariance), self.mounting.b_R_d0)
