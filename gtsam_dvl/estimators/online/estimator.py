"""Online estimation: an incremental (iSAM2) estimator fed message by message, with bounded latency.

A vehicle or a script creates an `OnlineEstimator`, pushes IMU and DVL messages in time order
(`push_imu`, `push_imu_batch`, `push_dvl`) and reads `estimate()` after each DVL epoch: pose, velocity,
biases, scale and misalignment, each with its marginal (filtering) covariance. `smooth_online(log, config)`
drives it over a whole log and returns the same `NavResult` as the batch smoother, with a `Timeline` of the
filtering sigmas at every epoch.

Which mode:
- `fixed_lag` (default): states older than `window_s` (20 s) behind the newest are marginalised; the bias,
  scale and misalignment never leave. The cost per DVL epoch is bounded however long the mission
  (bench/bench_online.py prints the latencies; README, "Online estimator"): use it on the vehicle and for any
  log longer than a few minutes. Its final calibration is the batch smoother's within 0.2 of a sigma (what
  left the window stays linearised where it was when it left); its sigmas are the batch's within 3 %, the
  vertical accelerometer bias's 10 % larger (the static phase's zero-velocity pings left the window while the
  scale was still its prior 0.8, and are credited the velocity information k^2 / sigma^2 at that scale).
- `full`: every state is kept and iSAM2 may relinearise any of them; its final estimate is the batch
  smoother's (within 0.03 sigma measured). Each relinearisation of the calibration touches every DVL factor of
  the mission through a Python callback that receives a copy of all the variables, so its cost per update
  grows with the mission (README, "Online estimator"): use it to check the fixed-lag mode on short logs, or
  when every past state must stay adjustable.
- The trajectory of the returned NavResult is the filtering one in both modes: each state as estimated when its
  ping was processed, what the vehicle knew then (the batch smoother gives the smoothed one).

Keyframes (`[solver] keyframe_spacing_s`, 1 s by default; online/keyframes.py): the states are the batch
smoother's, at the keyframes (selection.keyframe_mask's rule, decided ping by ping: the first usable ping,
then each first one at least 0.98 spacings after the previous keyframe) and at the DVL-dropout fillers; every
other usable ping becomes the batch smoother's DVL factor on the state before it through the IMU motion since
that state (FactorMaker.dvl_keyframe_factors_for; the motion integrated as the pings come, to the same bits as
keyframes.interval_with_snapshots). That state is always the newest: a ping between keyframes comes less than a spacing
after its keyframe, a filler max_state_spacing_s >= spacing after a state. At finish() the last ping still
between keyframes becomes a keyframe, as the batch smoother makes the last usable ping one. On a 1 Hz DVL, 1 s
keyframes are a state per ping (the same result to the last bit as keyframe_spacing_s = 0).
- Where a ping between keyframes goes (`defer_between_pings`): True (default), its factor waits for the next
  state's iSAM2 update; False, an iSAM2 update of its own at once. Deferred, because it gives the lower p99
  and the higher real-time factor: on bench/bench_online_long.py (1 h, 200 Hz IMU / 5 Hz DVL, the two runs
  back to back on the shared 2-core machine, load 3.2) the CPU time per epoch has p99 2.8 ms deferred against
  4.4 ms at once, p50 0.9 against 1.6 ms, and the real-time factor is 130 against 97 (the wall-time p99s, 6.2
  and 5.9 ms, are the other processes' preemptions; a pair at load 3: 6.1 against 9.7 ms). An iSAM2 update has a fixed
  cost (the ordering, re-eliminating the cliques of the newest state and the shared keys, the relinearisation
  check, the marginal covariance of the estimate: about 1 ms) that deferral pays once per state instead of once
  per ping, while the ping's own work (its IMU motion, its factor, the prediction below) is a fraction of a
  millisecond; the state's update linearises four more factors (60 us each). What it gives up: until the next
  state, the pings since the newest state are not in the estimate.
- estimate() after a ping between keyframes: the state at the ping predicted from the newest state's estimate
  through the IMU motion up to it (online/keyframes.predict_at_ping: the keyframe factor's own model, its
  covariance propagated to first order), OnlineEstimate.t the ping's time and predicted_from_t the state's
  (nan for the estimate of a state). Its errors against the simulated truth are consistent with its sigmas
  (tests/estimators/test_online_keyframes.py). The Timeline and the NavResult hold the states only, each as
  estimated when it was made, as the batch smoother's hold its states.
- latencies_s, latencies_cpu_s and latency_t: one entry per epoch processed, each state (with or without a ping)
  and each ping between keyframes.

Design (see also window.py for the iSAM2 engine):
- The FactorMaker the batch smoother's whole-log graph uses (estimators/factor_maker.py) makes every factor,
  prior and initial guess from explicit measurements; pings are selected and IMU intervals split by the rules
  of estimators/selection.py, as in the batch smoother and the EKF.
- IMU samples are kept raw since the newest state and preintegrated up to the next one as its pings come and
  when the state is made, exactly as the batch smoother does (a sample straddling the state's ping is split;
  online/keyframes.StatePreintegration: the same pieces in the same order), so a ping that arrives after IMU samples
  past its stamp (another topic, another latency) is still placed exactly.
- Alignment: the estimator waits for `align_s` seconds of the initial static segment (or motion, if sooner,
  after alignment.min_static_s) and aligns on them with the batch smoother's coarse alignment, then processes
  the buffered messages; it reports nothing before. alignment.initial_attitude_deg skips the wait.
- Slow pings do not inform the calibration (`calibration_min_speed_m_s`, default 0.1 m/s): below it the DVL
  sees noise, the scale's Jacobian k R^T n_v is the velocity estimate's own noise, and linearising it at a
  different velocity estimate each time a state leaves the window turns that noise into information: without
  this, on paper-3d the scale went from 0.8 +- 0.5 to 1.17 +- 0.15 over the static phase, where the batch
  smoother's filtering sigma stays at 0.37 (linearised once, at its solution). Such a ping keeps its DVL factor
  (the same model, on pose, velocity, scale and misalignment: a zero-velocity update when static) with zero
  Jacobians for scale and misalignment, which are "considered" at their current value (a slow ping between
  keyframes likewise: online/keyframes.considered_keyframe_factor). Given up: the
  information of pings slower than the threshold, (v / sigma)^2 per ping, nothing next to a manoeuvre (the
  final estimates agree with the batch smoother's to 0.03 sigma in the full-history mode).
- Depth (`push_depth`, LogData.depth in feed_log; [depth], estimators/depth.py): each sample is converted as the
  batch smoother converts it and waits until the state nearest to it in time is known, i.e. until the first
  state at or after its stamp exists (or finish(), for samples after the newest state); its factor goes in with
  that state's update, the time between them bridged by the state's velocity (factors/depth.py), the same factor
  as the batch smoother's on the same state. Counters "depth_used", "depth_too_far" (farther than
  max_time_to_state_s from the nearest state still held), "depth_invalid".
- DVL time offset ([dvl] estimate_time_offset): T_OFFSET is a shared variable with its prior, like the scale, and
  each ping's factor is the batch smoother's make_dvl_velocity_offset_factor with the IMU constants of
  FactorMaker.velocity_rate_input over the IMU samples within time_offset_window_s of [t, t + dt_c], dt_c the
  current estimate of the offset (clipped to the prior +- 3 prior sigmas): the batch smoother's second pass
  re-centres its windows on its first estimate, the online estimator on the estimate it has when the ping is
  processed. A ping therefore waits for the IMU to reach t + max(0, dt_c) + time_offset_window_s: a causal
  delay of that much (0.25 s at dt_c <= 0; the epochs after it wait behind it); at finish() a ping still
  waiting takes the IMU there is. Not with use_beams (as in the batch smoother). The estimate and its marginal
  sigma are NavResult.time_offset_s / time_offset_sigma_s, as the batch smoother reports them.
- Bad input: a message older than or as old as the previous one of its kind, or with a non-finite value, is
  rejected with GtsamDvlError (`bad_messages = "raise"`, the default) or dropped with a warning the first time
  and counted in `counters` (`"drop"`). DVL pings without a valid velocity, faster than dvl.max_speed_m_s or
  not after the first IMU sample are counted and skipped, as the batch smoother does; so are bogus pings
  (selection.PingScreen: exact zeros while moving, repeats, implausible jumps), decided once the IMU samples
  reach the ping (the screen looks at the IMU since the previous accepted ping), whatever the message order.
"""

from __future__ import annotations

import math
import time
import warnings
from array import array
from collections import deque
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, T_OFFSET, V, X
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.core.types import DepthData, DvlData, ImuData, LogData, Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.alignment import STATIC_MARGIN_S, Alignment, align, map_frame_of
from gtsam_dvl.estimators.depth import depth_samples, nearest_states
from gtsam_dvl.estimators.factor_maker import FactorMaker
from gtsam_dvl.estimators.gaps import (
    Gaps,
    check_gaps,
    check_spacing,
    filler_due,
    find_gaps,
    nominal_period,
    sample_starts_with_gaps,
)
from gtsam_dvl.estimators.keyframes import PimSnapshot
from gtsam_dvl.estimators.mounting import imu_is_rotated, rotate_imu_samples
from gtsam_dvl.estimators.online.keyframes import (
    KeyframeGravity,
    StatePreintegration,
    considered_keyframe_factor,
    predict_at_ping,
)
from gtsam_dvl.estimators.online.types import (
    MODES,
    EpochHistory,
    MessageDropped,
    OnlineConfig,
    OnlineEstimate,
    latency_stats,
    misalignment_deg_and_cov,
)
from gtsam_dvl.estimators.online.window import IncrementalSmoother, RelinearizationThresholds, StateEstimate
from gtsam_dvl.estimators.selection import (
    KEYFRAME_TOLERANCE,
    USABLE,
    KeyframeThinning,
    PingScreen,
    classify_pings,
    count_reasons,
    screened_value,
)
from gtsam_dvl.factors import PingMotion, dvl_beam_error, dvl_velocity_error, dvl_velocity_offset_error

__all__ = ["MODES", "MessageDropped", "OnlineConfig", "OnlineEstimate", "OnlineEstimator", "RelinearizationThresholds",
           "feed_log", "latency_stats", "smooth_online"]


@dataclass
class _Ping:
    t: float
    d_v: np.ndarray
    d_cov: np.ndarray
    valid: bool
    beams: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    key: bool = True  # a keyframe (a state), else a ping between keyframes (a factor on the state before it)


RateInput = tuple[np.ndarray, np.ndarray, np.ndarray]  # FactorMaker.velocity_rate_input: b_a, mean b_omega, G


def _considered_calibration_factor(noise: gtsam.noiseModel.Base, i: int, b_omega: np.ndarray, b_l: np.ndarray,
                                   d_y: np.ndarray | None = None,
                                   beam: tuple[np.ndarray, float] | None = None,
                                   offset: tuple[RateInput, np.ndarray] | None = None) -> gtsam.CustomFactor:
    """The DVL factor of factors/ on [X_i, V_i, K, C] for a ping too slow to inform the calibration (module
    doc): same error, same Jacobians for pose and velocity, none for scale and misalignment, which are
    "considered" at their current estimate (the velocity's information scales with it). d_y: the 3-D velocity;
    beam: (d_u, y_j) for one beam. offset = (rate_input, n_g): the time-offset model of
    make_dvl_velocity_offset_factor on [X_i, V_i, K, C, T_OFFSET] (with d_y), its T_OFFSET Jacobian kept (it is
    the IMU's velocity rate, not the velocity's noise)."""
    if (beam is None) == (d_y is None) or (offset is not None and d_y is None):
        raise ValueError("a considered-calibration DVL factor needs either d_y or beam (d_y with offset)")

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose, n_v = values.atPose3(X(i)), values.atVector(V(i))
        k, b_R_d = values.atVector(K_SCALE), values.atRot3(C_MISALIGN)
        slots: list[Any] | None = None if H is None else [None] * (4 if offset is None else 5)
        if offset is not None:
            assert d_y is not None  # checked above; tells mypy
            (b_a, b_omega_mean, G), n_g = offset
            e = dvl_velocity_offset_error(pose, n_v, k, b_R_d, values.atVector(T_OFFSET), d_y, b_omega_mean, b_l,
                                          b_a, n_g, G, slots)
            if H is not None and slots is not None:
                H[0], H[1], H[4] = slots[0], slots[1], slots[4]
                H[2], H[3] = np.zeros((3, 1)), np.zeros((3, 3))
            return e
        if beam is not None:
            e = dvl_beam_error(pose, n_v, k, b_R_d, beam[0], beam[1], b_omega, b_l, slots)
        else:
            assert d_y is not None  # checked above; tells mypy
            e = dvl_velocity_error(pose, n_v, k, b_R_d, d_y, b_omega, b_l, slots)
        if H is not None and slots is not None:
            H[0], H[1] = slots[0], slots[1]
            H[2], H[3] = np.zeros((len(e), 1)), np.zeros((len(e), 3))
        return e

    keys = [X(i), V(i), K_SCALE, C_MISALIGN] + ([T_OFFSET] if offset is not None else [])
    return gtsam.CustomFactor(noise, keys, error_func)


PERIOD_SAMPLES = 64  # IMU stamps that measure the nominal period (the median spacing)


class OnlineEstimator:
    """Incremental estimator fed message by message (module doc). Times are seconds on the caller's clock,
    the same for IMU and DVL; IMU sample t covers (previous sample, t] (ImuData's convention). IMU samples are
    given in imu_link and rotated into base_link with mounting.b_R_imu (estimators/mounting.py). depth_sensor:
    the pressure sensor's position in base_link (m, from /tf_static; [depth] lever_arm_m overrides it).
    recentre_offset_window (attribute, default True): the time offset's IMU windows centred on the current
    estimate (module doc); False keeps them at the prior (to measure what the re-centring gives)."""

    def __init__(self, config: EstimatorConfig | None = None, *, frame: LocalFrame, mounting: Mounting | None = None,
                 options: OnlineConfig | None = None, source: str = "", depth_sensor: Any = None) -> None:
        config = config or EstimatorConfig()
        self.options = options or config.online  # options=: overrides config.online
        self.config = config.model_copy(update={"online": self.options}).validate()  # the effective config
        check_spacing(self.config.solver)
        spacing = self.config.solver.keyframe_spacing_s
        if spacing > self.config.solver.max_state_spacing_s:  # the batch smoother's rule (estimators/graph.py)
            raise GtsamDvlError(f"solver.keyframe_spacing_s = {spacing:g} s needs solver.max_state_spacing_s >= "
                                f"{spacing:g} s: states without a ping would take the places of the keyframes")
        if self.config.dvl.estimate_time_offset and self.config.dvl.use_beams:
            raise GtsamDvlError("[dvl] estimate_time_offset works with the 3-D velocity only, not with use_beams")
        if self.config.dvl.estimate_lever_arm:
            raise GtsamDvlError("[dvl] estimate_lever_arm is batch only (the batch smoother), not online")
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
        self._keyframes = KeyframeThinning(self.config.solver.keyframe_interval_s)
        # keyframes ([solver] keyframe_spacing_s): selection.keyframe_mask's rule, ping by ping
        self._spacing = KeyframeThinning(spacing * (1.0 - KEYFRAME_TOLERANCE))
        # pings between keyframes: their factors wait for the next state's update (True) or each goes into iSAM2
        # at once (False; module doc, "Keyframes")
        self.defer_between_pings = True
        self._interval: StatePreintegration | None = None  # the next IMU factor's, integrated at the pings between
        self._gravity: KeyframeGravity | None = None
        self._deferred: list[tuple[_Ping, list[gtsam.NonlinearFactor]]] = []
        self._state: StateEstimate | None = None  # the newest state's estimate (after its update, or the last)
        self.smoother: IncrementalSmoother | None = None
        self._last_imu_t = -math.inf
        self._last_dvl_t = -math.inf
        self._first_imu_t: float | None = None
        self._warned: set[str] = set()
        # before alignment: everything is kept
        self._pre_imu: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._pre_dvl: list[_Ping] = []
        # after alignment: IMU samples since the last epoch (and the one straddling it), pings waiting for IMU
        self._chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._imu_period: float | None = None  # nominal IMU period, s
        self._period_t: list[float] = []  # the first IMU stamps, to measure it
        self._gaps_seen: dict[float, float] = {}  # IMU gaps crossed: start -> duration, s
        self._replaying = False  # replaying the messages buffered before the alignment
        self._pending: deque[_Ping] = deque()
        # usable pings waiting for the IMU to reach them, then screened for bogus data (_screen_ready)
        self._screen = PingScreen(self.config.dvl)
        self._unscreened: deque[_Ping] = deque()
        self._latest: OnlineEstimate | None = None
        self._history = EpochHistory()
        # the DVL time offset: the IMU samples of the last seconds (velocity-rate windows), pings closed at finish
        self._offset = self.config.dvl.estimate_time_offset
        self.recentre_offset_window = True
        self._recent: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self._flushing = False
        # depth samples (t, z_meas, sigma) waiting for their nearest state
        self._depth: deque[tuple[float, float, float]] = deque()
        self._depth_sensor = None if depth_sensor is None else _vector3("depth_sensor", depth_sensor)
        self._depth_lever = np.zeros(3)
        self._last_depth_t = -math.inf
        if self.config.alignment.initial_attitude_deg is not None:
            self._start(align(_empty_imu(), _empty_dvl(), frame,
                              self.config.alignment.model_copy(update={"method": "auto"})))

    @classmethod
    def for_log(cls, log: LogData, config: EstimatorConfig | None = None,
                options: OnlineConfig | None = None) -> OnlineEstimator:
        """An estimator with the map origin and mounting of a log (to replay it). config None: the one the
        log's scenario names, else the defaults (EstimatorConfig.for_log)."""
        config = config or EstimatorConfig.for_log(log.metadata)
        return cls(config, frame=map_frame_of(log, config), mounting=log.mounting, options=options,
                   source=log.source, depth_sensor=None if log.depth is None else log.depth.b_p_sensor)

    # ----- input ---------------------------------------------------------------------------------
    def push_imu(self, t: float, b_omega: Any, b_f: Any) -> int:
        """One IMU sample: gyro b_omega (rad/s) and specific force b_f (m/s^2) averaged over (previous t, t].
        Returns the number of DVL epochs it completed."""
        t = float(t)
        w, f = _vector3("IMU b_omega", b_omega), _vector3("IMU b_f", b_f)
        if not self._imu_time_ok(t):
            return 0
        if not (np.isfinite(w).all() and np.isfinite(f).all()):
            self._bad("imu_not_finite", f"IMU sample at t = {t:.6f} s has a non-finite value")
            return 0
        self._last_imu_t = t
        return self._take_imu(np.array([t]), w[None, :], f[None, :])

    def push_imu_batch(self, t: Any, b_omega: Any, b_f: Any) -> int:
        """Several IMU samples in time order, (N,), (N, 3), (N, 3). Returns the number of epochs completed."""
        t = np.asarray(t, dtype=float).reshape(-1)
        w, f = np.asarray(b_omega, dtype=float), np.asarray(b_f, dtype=float)
        if w.shape != (len(t), 3) or f.shape != (len(t), 3):
            raise GtsamDvlError(f"IMU batch: {len(t)} stamps need gyro and accelerometer arrays of shape "
                                f"({len(t)}, 3), got {w.shape} and {f.shape}")
        if len(t) == 0:
            return 0
        stamped = np.isfinite(t)
        prev = np.maximum.accumulate(np.concatenate([[self._last_imu_t], np.where(stamped, t, -np.inf)]))[:-1]
        in_order = stamped & (t > prev)
        finite = np.isfinite(w).all(axis=1) & np.isfinite(f).all(axis=1)
        keep = in_order & finite
        if not keep.all():
            for mask, kind, what in ((~stamped, "imu_bad_time", "has a non-finite stamp"),
                                     (stamped & (t == prev), "imu_duplicate", "repeats the previous stamp"),
                                     (stamped & (t < prev), "imu_out_of_order", "is older than the previous one"),
                                     (in_order & ~finite, "imu_not_finite", "has a non-finite value")):
                n_bad = int(mask.sum())
                if n_bad:
                    j = int(np.argmax(mask))
                    self._bad(kind, f"IMU sample {j} of the batch (t = {t[j]:.6f} s) {what}", n_bad)
            t, w, f = t[keep], w[keep], f[keep]
            if len(t) == 0:
                return 0
        self._last_imu_t = float(t[-1])
        return self._take_imu(t, w, f)

    def push_dvl(self, t: float, d_v: Any, d_cov: Any = None, valid: bool = True,
                 beams: tuple[Any, Any, Any] | None = None) -> int:
        """One DVL ping at t: velocity d_v (m/s, dvl_link) with covariance d_cov (3x3, None: the configured
        default), valid flag, and optionally beams = (d_u (B, 3), v (B,), valid (B,)). A ping without a valid
        velocity (NaN) is counted, not an error. Returns the number of epochs completed."""
        t = float(t)
        if not math.isfinite(t):
            self._bad("dvl_bad_time", f"DVL ping with a non-finite stamp ({t})")
            return 0
        if t <= self._last_dvl_t:
            kind = "dvl_duplicate" if t == self._last_dvl_t else "dvl_out_of_order"
            what = "repeats the previous ping's stamp" if t == self._last_dvl_t else "is older than the previous ping"
            self._bad(kind, f"DVL ping at t = {t:.6f} s {what} ({self._last_dvl_t:.6f} s)")
            return 0
        self._last_dvl_t = t
        d_v = _vector3("DVL d_v", d_v)
        d_cov = np.full((3, 3), np.nan) if d_cov is None else np.asarray(d_cov, dtype=float)
        if d_cov.shape != (3, 3):
            raise GtsamDvlError(f"DVL d_cov must be 3x3, got shape {d_cov.shape}")
        if beams is not None:
            d_u, v, ok = (np.asarray(beams[0], dtype=float), np.asarray(beams[1], dtype=float),
                          np.asarray(beams[2], dtype=bool))
            if d_u.shape != (len(v), 3) or ok.shape != v.shape:
                raise GtsamDvlError(f"DVL beams: d_u {d_u.shape}, v {v.shape}, valid {ok.shape} do not match")
            beams = (d_u, v, ok)
        ping = _Ping(t, d_v, d_cov, bool(valid), beams)
        if self.smoother is None:
            self._pre_dvl.append(ping)
            return 0
        return self._take_ping(ping)

    def push_depth(self, t: float, depth_m: float = math.nan, variance_m2: float = math.nan, *,
                   pressure_pa: float | None = None, pressure_variance_pa2: float = math.nan) -> None:
        """One depth sample at t: the pressure sensor's depth (m below the surface, positive down) and its
        variance (m^2, NaN: unknown), or with pressure_pa its absolute pressure (Pa) and variance (Pa^2),
        converted with [depth] (estimators/depth.py depth_samples). Its factor is added with the first state at or
        after t (module doc). A non-finite value is counted ("depth_invalid"), not an error; nothing is done with
        [depth] use = false."""
        t = float(t)
        if not math.isfinite(t):
            self._bad("depth_bad_time", f"depth sample with a non-finite stamp ({t})")
            return
        if t <= self._last_depth_t:
            kind = "depth_duplicate" if t == self._last_depth_t else "depth_out_of_order"
            what = "repeats the previous stamp" if t == self._last_depth_t else "is older than the previous one"
            self._bad(kind, f"depth sample at t = {t:.6f} s {what} ({self._last_depth_t:.6f} s)")
            return
        self._last_depth_t = t
        cfg = self.config.depth
        if not cfg.use:
            return
        for name in ("depth_used", "depth_too_far", "depth_invalid"):  # reported even when zero, as by the batch
            self.counters.setdefault(name, 0)
        pressure = pressure_pa is not None
        data = DepthData(np.array([t]), np.array([float(depth_m)]), np.array([float(variance_m2)]),
                         np.array([float(pressure_pa)]) if pressure_pa is not None else None,
                         np.array([float(pressure_variance_pa2)]) if pressure else None, b_p_sensor=self._depth_sensor)
        invalid: dict[str, int] = {}
        s = depth_samples(data, cfg, self.frame, invalid)
        self._count("depth_invalid", invalid.get("depth_invalid", 0))
        if len(s.t):
            self._depth.append((float(s.t[0]), float(s.z_meas[0]), float(s.sigma[0])))
            self._depth_lever = s.b_p_sensor

    def finish(self) -> OnlineEstimate | None:
        """End of data: align on what there is if still waiting, process the pings that waited only for the IMU
        after them (the time offset's window, cut at the end of the data), drop pings no IMU sample reached, put
        the depth samples after the newest state on it (if near enough), and let iSAM2 relinearise until
        converged (options.final_updates). Returns the final estimate."""
        if self.smoother is None and self._pre_imu:
            self._align()
        self._flushing = True
        self._close_ready()
        self._flushing = False
        self._count("dvl_after_imu", len(self._pending) + len(self._unscreened))
        self._pending.clear()
        self._unscreened.clear()
        if self._deferred:  # the batch smoother makes the last usable ping a keyframe: so does this
            last, _ = self._deferred.pop()
            self._count("pings_between_keyframes", -1)
            last.key = True
            self._close(last)
        if self.smoother is not None and self.smoother.n > 0:
            self.smoother.add_factors(self._depth_factors(self.smoother.n - 1, self.smoother.t_last, final=True))
            self.smoother.refresh_gravity()
            self.smoother.refine(self.options.final_updates)
            self._latest = self._read_estimate(with_covariance=True)
        return self._latest

    # ----- output --------------------------------------------------------------------------------
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
        h = self._history
        mis = [misalignment_deg_and_cov(R, self.mounting.b_R_d0, P) for R, P in zip(h["b_R_d"], h["b_R_d_cov"],
                                                                                    strict=True)]
        n_R_b = h["n_R_b"]
        att_cov = n_R_b @ h["pose_cov"][:, :3, :3] @ np.transpose(n_R_b, (0, 2, 1))
        bias_var = np.einsum("nii->ni", h["bias_cov"])
        return Timeline(
            t=h["t"].copy(), scale=h["scale"].copy(), scale_sigma=h["scale_sigma"].copy(),
            misalignment_deg=np.array([m[0] for m in mis]).reshape(-1, 3),
            misalignment_sigma_deg=np.sqrt(np.array([np.diag(m[1]) for m in mis]).reshape(-1, 3)),
            gyro_bias_deg_per_h=h["gyro_bias"] / DEG_PER_H,
            gyro_bias_sigma_deg_per_h=np.sqrt(bias_var[:, 3:]) / DEG_PER_H,
            accel_bias_ug=h["accel_bias"] / UG, accel_bias_sigma_ug=np.sqrt(bias_var[:, :3]) / UG,
            attitude_sigma_deg=np.degrees(np.sqrt(np.einsum("nii->ni", att_cov))))

    def result(self, t0_ns: int = 0) -> NavResult:
        """NavResult: the trajectory as estimated online (each state when its ping was processed, with its
        filtering covariance), the bias and calibration after finish(), and the timeline."""
        h, final = self._history, self._latest
        if len(h) == 0 or final is None or self.builder is None or self.smoother is None:
            raise GtsamDvlError(f"{self.source or 'online estimator'}: no DVL epoch was processed (or "
                                "options.record_history is off)")
        n_vars, n_factors = self.smoother.size()
        info: dict[str, Any] = {
            "mode": self.options.mode, "window_s": self.options.window_s if self.options.mode == "fixed_lag" else None,
            "trajectory": "filtered: each state as estimated when its DVL ping was processed",
            "counters": dict(self.counters), "epochs": len(h),
            "keyframe_spacing_s": self.config.solver.keyframe_spacing_s,
            "imu_gaps": {"count": len(self._gaps_seen), "total_s": float(sum(self._gaps_seen.values())),
                         "longest_s": float(max(self._gaps_seen.values(), default=0.0))},
            "alignment": self.builder.alignment.info(),
            "latency_ms": latency_stats(self.latencies_s),
            "isam2": {"rebases": self.smoother.rebases, "states_marginalized": self.smoother.marginalised,
                      "variables": n_vars, "factors": n_factors},
        }
        return NavResult(
            estimator=f"online-{self.options.mode.replace('_', '-')}",
            t=h["t"].copy(), n_p=h["n_p"].copy(), n_R_b=h["n_R_b"].copy(), n_v=h["n_v"].copy(),
            pose_cov=h["pose_cov"].copy(), vel_cov=h["vel_cov"].copy(), pose_vel_cross=h["pose_vel_cross"].copy(),
            accel_bias=final.accel_bias, gyro_bias=final.gyro_bias, bias_cov=final.bias_cov,
            scale=final.scale, scale_sigma=final.scale_sigma, b_R_d=final.b_R_d, b_R_d_cov=final.b_R_d_cov,
            b_R_d0=self.mounting.b_R_d0, t0_ns=t0_ns, b_omega=h["b_omega"] - final.gyro_bias,
            calib_joint_cov=final.calib_cov, timeline=self.timeline(), info=info, config=self.config.to_dict(),
            time_offset_s=final.time_offset_s, time_offset_sigma_s=final.time_offset_sigma_s)

    # ----- internals -----------------------------------------------------------------------------
    def _bad(self, kind: str, message: str, n: int = 1) -> None:
        if self.options.bad_messages == "raise":
            raise GtsamDvlError(f"{self.source + ': ' if self.source else ''}{message}")
        self._count(kind, n)
        if kind not in self._warned:
            self._warned.add(kind)
            warnings.warn(f"{message}: dropped (further ones are counted in counters['{kind}'])", MessageDropped,
                          stacklevel=3)

    def _count(self, kind: str, n: int = 1) -> None:
        if n:
            self.counters[kind] = self.counters.get(kind, 0) + n

    def _imu_time_ok(self, t: float) -> bool:
        if math.isfinite(t) and t > self._last_imu_t:
            return True
        if not math.isfinite(t):
            self._bad("imu_bad_time", f"IMU sample with a non-finite stamp ({t})")
        elif t == self._last_imu_t:
            self._bad("imu_duplicate", f"IMU sample at t = {t:.6f} s repeats the previous stamp")
        else:
            self._bad("imu_out_of_order", f"IMU sample at t = {t:.6f} s is older than the previous one "
                                          f"({self._last_imu_t:.6f} s)")
        return False

    def _take_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> int:
        if self._imu_rotated:  # samples in imu_link -> base_link (estimators/mounting.py)
            w, f = rotate_imu_samples(self.mounting.b_R_imu, w, f)
        if self._first_imu_t is None:
            self._first_imu_t = float(t[0])
        if self.smoother is None:
            self._pre_imu.append((t, w, f))
            if t[-1] - self._first_imu_t >= self.options.align_s + STATIC_MARGIN_S + 1.0:
                return self._align()
            return 0
        return self._ingest_imu(t, w, f)

    def _ingest_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> int:
        if self._imu_period is None:  # the nominal period, for the gap rule (estimators/gaps.py): from the first
            self._period_t.extend(t[:PERIOD_SAMPLES].tolist())  # PERIOD_SAMPLES stamps, across chunks
            if len(self._period_t) >= PERIOD_SAMPLES:
                self._imu_period = nominal_period(np.asarray(self._period_t[:PERIOD_SAMPLES]))
        if len(t):
            self._chunks.append((t, w, f))
            self._screen.push_imu(t, w, f)
            if self._offset:
                self._recent.append((t, w, f))
        self._screen_ready()
        return self._close_ready()

    def _align(self) -> int:
        t = np.concatenate([c[0] for c in self._pre_imu])
        w = np.concatenate([c[1] for c in self._pre_imu])
        f = np.concatenate([c[2] for c in self._pre_imu])
        pings = self._pre_dvl
        dvl = DvlData(np.array([p.t for p in pings]), np.array([p.d_v for p in pings]).reshape(-1, 3),
                      np.array([p.d_cov for p in pings]).reshape(-1, 3, 3), np.array([p.valid for p in pings], bool))
        cfg = self.config.alignment.model_copy()
        cfg.max_static_s = min(cfg.max_static_s, self.options.align_s) if cfg.max_static_s > 0 else self.options.align_s
        where = f"{self.source + ': ' if self.source else ''}"
        # causal in-motion alignment and attitude topics are not done online (batch and EKF only)
        need = ("online needs an attitude source or a static start: set alignment.initial_attitude_deg, or log "
                f"a static start of alignment.min_static_s ({cfg.min_static_s:g} s)")
        if cfg.method in ("attitude_topic", "in_motion"):
            raise GtsamDvlError(f"{where}{need}; alignment.method = {cfg.method!r} is for the batch smoother and "
                                "the EKF")
        cfg.method = "static"
        try:
            alignment = align(ImuData(t, w, f), dvl, self.frame, cfg)
        except GtsamDvlError as exc:
            if str(exc).startswith("no static segment"):
                raise GtsamDvlError(f"{where}online alignment: {str(exc).split(';')[0]}; {need}") from None
            raise GtsamDvlError(f"{where}online alignment: {exc}") from None
        self._start(alignment)
        self._pre_imu, self._pre_dvl = [], []
        # replay: every buffered ping is queued before any epoch is made, so that the states without a ping
        # (DVL dropouts) are placed between them as in the batch smoother
        self._replaying = True
        self._ingest_imu(t, w, f)
        for p in pings:
            self._take_ping(p)
        self._replaying = False
        return self._close_ready()

    def _start(self, alignment: Alignment) -> None:
        self.builder = FactorMaker(self.config, self.frame, alignment, self.mounting, self.source)
        window = self.options.window_s if self.options.mode == "fixed_lag" else None
        self.smoother = IncrementalSmoother(self.builder, window, self.options.relinearization)
        self._interval = StatePreintegration(self.builder.make_params, self.config.imu)
        self._gravity = KeyframeGravity(self.builder.keyframe_gravity)

    def _take_ping(self, p: _Ping) -> int:
        first = self._first_imu_t if self._first_imu_t is not None else math.inf
        beam_valid: np.ndarray | None = None
        beam_finite: np.ndarray | None = None
        if p.beams is not None:
            d_u, v, ok = p.beams
            beam_valid = ok[None, :]
            beam_finite = np.array([bool(np.isfinite(v[ok]).all() and np.isfinite(d_u[ok]).all())])
        code = classify_pings(np.array([p.t]), p.d_v[None, :], np.array([p.valid]), beam_valid, beam_finite,
                              self.config.dvl, first)
        if code[0] != USABLE:
            count_reasons(code, self.counters, keep_zero=False)
            return 0
        self._unscreened.append(p)
        self._screen_ready()
        return self._close_ready()

    def _screen_ready(self) -> None:
        """Screen the usable pings the IMU now reaches, in order (selection.PingScreen: the batch smoother's
        causal rule, on the previous accepted ping and the IMU samples since it), then thin them to keyframes;
        the others wait for the IMU."""
        while self._unscreened and self._screen.reaches(self._unscreened[0].t):
            p = self._unscreened.popleft()
            code = self._screen.check_buffered(p.t, screened_value(p.d_v, p.beams, self.config.dvl))
            if code != USABLE:
                count_reasons(np.array([code]), self.counters, keep_zero=False)
            elif not self._keyframes.keep(p.t):
                self._count("dvl_not_keyframe")
            else:
                p.key = self._spacing.keep(p.t)
                self._pending.append(p)

    def _close_ready(self) -> int:
        """Make the epochs the IMU samples now reach: pings, and states without a ping where pings are missing
        (estimators/gaps.py, filler_due: the batch smoother's rule)."""
        if self._replaying:
            return 0
        done = 0
        spacing = self.config.solver.max_state_spacing_s
        # with the time offset a ping waits for the IMU window after it (module doc), unless at finish()
        ahead = max(0.0, self._offset_centre()) + self.config.dvl.time_offset_window_s if self._offset else 0.0
        while self._chunks and self.smoother is not None:
            t_end = float(self._chunks[-1][0][-1])
            if self._pending and self.smoother.n > 0 and self._pending[0].t <= self.smoother.t_last:
                # a ping later than FILLER_MARGIN_S behind the IMU, older than the state without a ping made in
                # its place: it cannot be inserted behind the newest state
                self._pending.popleft()
                self._count("dvl_late")
                continue
            nxt = self._pending[0].t if self._pending else None
            if self.smoother.n > 0 and (t_f := filler_due(self.smoother.t_last, nxt, t_end, spacing)) is not None:
                self._close(None, t_f)
            elif self._pending and self._pending[0].t <= t_end and (self._flushing
                                                                     or self._pending[0].t + ahead <= t_end):
                p = self._pending.popleft()
                if p.key or self.smoother.n == 0:
                    self._close(p)
                else:
                    self._between_ping(p)
                ahead = max(0.0, self._offset_centre()) + self.config.dvl.time_offset_window_s if self._offset else 0.0
            else:
                break
            done += 1
        return done

    def _close(self, p: _Ping | None, t_state: float | None = None) -> None:
        """Make the epoch of ping p (or, p None, a state without a ping at t_state): preintegrate since the
        previous one, add its factors, update iSAM2. The buffer keeps, first, the last sample at or before the
        previous epoch: the sample held across a gap that starts there (estimators/gaps.py)."""
        assert self.builder is not None and self.smoother is not None
        t0, c0 = time.perf_counter(), time.process_time()
        b, sm = self.builder, self.smoother
        t_epoch = p.t if p is not None else float(t_state)  # type: ignore[arg-type]
        T, W, F = self._buffer()
        gi = int(np.searchsorted(T, t_epoch, side="left"))  # the sample covering the epoch
        b_omega = b.body_rate(W[gi])
        i = sm.n
        rate_input = self._rate_input(t_epoch) if self._offset and p is not None else None
        dvl = self._dvl_factors(i, p, b_omega, rate_input) if p is not None else []
        self._count("states_without_ping" if p is None else "keyframes")
        dvl += self._depth_factors(i, t_epoch)
        if i == 0:
            assert p is not None  # the first epoch is a ping (_close_ready)
            sm.add_epoch(t_epoch, dvl, first_values=b.first_state_values(p.d_v if p.valid else None))
        else:
            starts, b_f, gaps = self._buffer_pieces(T, W, F, final=True)
            assert self._interval is not None
            # FactorMaker.preintegrate_interval(sm.t_last, t_epoch, ...), the part up to the last ping done then
            pim, params, held = self._interval.close(t_epoch, T, starts, b_f, W, gaps)
            between = [f for _, fs in self._deferred for f in fs]  # the pings since the previous state (on it)
            sm.add_epoch(t_epoch, between + dvl, pim, params, held=held)
        self._deferred = []
        assert self._interval is not None
        self._interval.reset(t_epoch)
        first_kept = max(int(np.searchsorted(T, t_epoch, side="right")) - 1, 0)  # the last sample <= the epoch
        self._chunks = [(T[first_kept:], W[first_kept:], F[first_kept:])]
        if self._offset:  # keep what the next epochs' velocity-rate windows can reach
            cfg = self.config.dvl
            reach = abs(cfg.time_offset_prior_s) + 3.0 * cfg.time_offset_sigma_s + cfg.time_offset_window_s
            Tr, Wr, Fr = self._recent_imu()
            k0 = int(np.searchsorted(Tr, t_epoch - reach - 1.0))
            self._recent = [(Tr[k0:], Wr[k0:], Fr[k0:])]
        self._state = self._read_state()
        self._latest = OnlineEstimate.from_state(self._state, self.mounting.b_R_d0)
        if self.options.record_history:
            self._history.append(self._latest, b_omega)
        self._record(t0, c0, t_epoch)

    def _buffer(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU samples held since the newest state (and the last one at or before it), as one chunk."""
        if len(self._chunks) > 1:
            self._chunks = [tuple(np.concatenate(c) for c in zip(*self._chunks, strict=True))]  # type: ignore[list-item]
        return self._chunks[0]

    def _buffer_pieces(self, T: np.ndarray, W: np.ndarray, F: np.ndarray,
                       final: bool) -> tuple[np.ndarray, np.ndarray, Gaps]:
        """The buffer's sample starts, rotation-compensated specific forces and gaps (estimators/gaps.py);
        final: the buffer of a new state's interval, whose gaps are checked and counted."""
        assert self.builder is not None
        # until PERIOD_SAMPLES stamps have come, the median of those seen (an epoch's buffer may hold a gap)
        period = self._imu_period or nominal_period(np.asarray(self._period_t) if len(self._period_t) > 2 else T)
        gaps = find_gaps(T, self.config.imu.gap_samples, period)
        if final:
            check_gaps(gaps, self.config.imu, self.source)
            for g0, g1 in zip(gaps.start.tolist(), gaps.end.tolist(), strict=True):
                if g0 not in self._gaps_seen:
                    self._gaps_seen[g0] = g1 - g0
                    self._count("imu_gaps")
        starts = sample_starts_with_gaps(T, gaps)
        return starts, self.builder.compensate_rotation(F, W, T - starts), gaps

    def _between_ping(self, p: _Ping) -> None:
        """A ping between keyframes: the IMU motion from the newest state up to it (online/keyframes.py,
        StatePreintegration.snapshot_at), its keyframe DVL factor on that state, deferred to the next state's update
        or added to iSAM2 now (defer_between_pings), and the estimate at the ping predicted from the newest state."""
        assert self.builder is not None and self.smoother is not None
        assert self._gravity is not None and self._state is not None
        t0, c0 = time.perf_counter(), time.process_time()
        b, sm = self.builder, self.smoother
        T, W, F = self._buffer()
        starts, b_f, gaps = self._buffer_pieces(T, W, F, final=False)
        assert self._interval is not None  # the next IMU factor's samples up to the ping, the last stamp <= it
        snap = self._interval.snapshot_at(p.t, T, starts, b_f, W, gaps)
        n_p0, n_g0, n_G = self._gravity.at(np.asarray(self._state.pose.translation(), dtype=float))
        motion = snap.motion(b.n_omega_ie(), n_g0, n_p0, n_G)
        b_omega = b.body_rate(W[int(np.searchsorted(T, p.t, side="left"))])
        rate_input = self._rate_input(p.t) if self._offset else None
        factors = self._keyframe_factors(sm.n - 1, p, b_omega, snap, motion, rate_input)
        self._count("pings_between_keyframes")
        if self.defer_between_pings:
            self._deferred.append((p, factors))
        else:
            sm.add_factors(factors)
            self._state = self._read_state()
        self._latest = OnlineEstimate.from_state(predict_at_ping(self._state, p.t, snap, motion),
                                                 self.mounting.b_R_d0)
        self._record(t0, c0, p.t)

    def _record(self, t0: float, c0: float, t: float) -> None:
        self.latencies_s.append(time.perf_counter() - t0)
        self.latencies_cpu_s.append(time.process_time() - c0)
        self.latency_t.append(t)

    def _keyframe_factors(self, i: int, p: _Ping, b_omega: np.ndarray, snap: PimSnapshot, motion: PingMotion,
                          rate_input: RateInput | None) -> list[gtsam.NonlinearFactor]:
        """The batch smoother's DVL factors of a ping between keyframes on state i (FactorMaker.
        dvl_keyframe_factors_for), with the calibration considered for a slow ping (as in _dvl_factors)."""
        b = self.builder
        assert b is not None
        use_beams = self.config.dvl.use_beams and p.beams is not None
        factors = b.dvl_keyframe_factors_for(i, p.d_v, p.d_cov, b_omega, motion, snap.cov,
                                             p.beams if use_beams else None, rate_input)
        if self._speed(p) >= self.options.calibration_min_speed_m_s:
            return factors
        b_l = self.mounting.b_l
        if rate_input is not None:  # estimate_time_offset (never with beams)
            b_a, b_omega_mean, G = rate_input
            return [considered_keyframe_factor(factors[0], p.d_v, b_omega_mean, b_l, motion,
                                               offset_input=(b_a, b.offset_gravity(), G))]
        if use_beams and p.beams is not None:
            d_u, v, valid = p.beams
            return [considered_keyframe_factor(f, float(v[j]), b_omega, b_l, motion, d_u=d_u[j])
                    for f, j in zip(factors, np.flatnonzero(valid).tolist(), strict=True)]
        return [considered_keyframe_factor(factors[0], p.d_v, b_omega, b_l, motion)]

    def _speed(self, p: _Ping) -> float:
        """What the DVL saw of the speed (m/s): the 3-D velocity's norm, or the fastest valid beam (with beams)."""
        if self.config.dvl.use_beams and p.beams is not None:
            return float(np.abs(p.beams[1][p.beams[2]]).max())  # a beam sees at most the speed
        return float(np.linalg.norm(p.d_v))

    def _offset_centre(self) -> float:
        """The offset the velocity-rate windows are centred on: the current estimate (the prior before the first
        epoch, or with recentre_offset_window off), clipped to the prior +- 3 prior sigmas (module doc)."""
        cfg = self.config.dvl
        prior = cfg.time_offset_prior_s
        if not self.recentre_offset_window or self._latest is None:
            return prior
        bound = 3.0 * cfg.time_offset_sigma_s
        return float(np.clip(self._latest.time_offset_s, prior - bound, prior + bound))

    def _recent_imu(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if len(self._recent) > 1:
            self._recent = [tuple(np.concatenate(c) for c in zip(*self._recent, strict=True))]  # type: ignore[list-item]
        return self._recent[0] if self._recent else (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))

    def _rate_input(self, t: float) -> RateInput:
        """The time-offset model's IMU constants of a ping at t (FactorMaker.velocity_rate_input) over the IMU
        samples kept, the window centred on _offset_centre()."""
        assert self.builder is not None
        T, W, F = self._recent_imu()
        return self.builder.velocity_rate_input(t, T, F, W, self._offset_centre())

    def _depth_factors(self, i: int, t_i: float, final: bool = False) -> list[gtsam.NonlinearFactor]:
        """Depth factors of the waiting samples whose nearest state is now known: those stamped at or before
        the new state i at t_i (all of them with final: i is the newest state), each on the nearest of the
        states held and state i, within [depth] max_time_to_state_s (else "depth_too_far")."""
        if not self._depth or (self._depth[0][0] > t_i and not final):
            return []
        assert self.builder is not None and self.smoother is not None
        ready: list[tuple[float, float, float]] = []
        while self._depth and (final or self._depth[0][0] <= t_i):
            ready.append(self._depth.popleft())
        held = sorted(k for k in self.smoother.times if k != i)
        index = np.array(held + [i])
        t_states = np.array([self.smoother.times[k] for k in held] + [t_i])
        t_s = np.array([r[0] for r in ready])
        near, dt = nearest_states(t_states, t_s, self.config.depth.max_time_to_state_s)
        self._count("depth_used", int((near >= 0).sum()))
        self._count("depth_too_far", int((near < 0).sum()))
        out: list[gtsam.NonlinearFactor] = []
        for k in np.flatnonzero(near >= 0).tolist():
            out += self.builder.depth_factors_for(int(index[near[k]]), ready[k][1], ready[k][2], self._depth_lever,
                                                  float(dt[k]))
        return out

    def _dvl_factors(self, i: int, p: _Ping, b_omega: np.ndarray,
                     rate_input: RateInput | None = None) -> list[gtsam.NonlinearFactor]:
        b = self.builder
        assert b is not None
        use_beams = self.config.dvl.use_beams and p.beams is not None
        if self._speed(p) >= self.options.calibration_min_speed_m_s:
            return b.dvl_factors_for(i, p.d_v, p.d_cov, b_omega, p.beams, rate_input)
        b_l = self.mounting.b_l
        if rate_input is not None:  # estimate_time_offset (never with beams)
            return [_considered_calibration_factor(b.dvl_noise(p.d_cov), i, b_omega, b_l, d_y=p.d_v,
                                                   offset=(rate_input, b.offset_gravity()))]
        if use_beams and p.beams is not None:
            d_u, v, valid = p.beams
            noise1 = b.beam_noise()
            return [_considered_calibration_factor(noise1, i, b_omega, b_l, beam=(d_u[j], float(v[j])))
                    for j in np.flatnonzero(valid)]
        return [_considered_calibration_factor(b.dvl_noise(p.d_cov), i, b_omega, b_l, d_y=p.d_v)]

    def _read_state(self, with_covariance: bool | None = None) -> StateEstimate:
        assert self.smoother is not None
        cov = self.options.covariances if with_covariance is None else with_covariance
        return self.smoother.estimate(with_covariance=cov)

    def _read_estimate(self, with_covariance: bool | None = None) -> OnlineEstimate:
        return OnlineEstimate.from_state(self._read_state(with_covariance), self.mounting.b_R_d0)


def _vector3(name: str, x: Any) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.shape != (3,):
        raise GtsamDvlError(f"{name} must be a 3-vector, got shape {arr.shape}")
    return arr


def _empty_imu() -> ImuData:
    return ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))


def _empty_dvl() -> DvlData:
    return DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, dtype=bool))


def feed_log(estimator: OnlineEstimator, log: LogData, progress: ProgressFn | None = None) -> None:
    """Push a log's messages in time order: the IMU samples up to each ping's stamp as one batch, then the
    depth samples up to it, then the ping (a sample stamped like the ping comes first), then the rest; finish()."""
    imu, dvl = log.imu, log.dvl
    ends = np.searchsorted(imu.t, dvl.t, side="right")
    start = 0
    n = len(dvl)
    step = max(1, n // 100)
    depth = log.depth
    n_depth = 0 if depth is None else len(depth)
    k = 0
    for j in range(n):
        end = int(ends[j])
        if end > start:
            estimator.push_imu_batch(imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end])
            start = end
        while depth is not None and k < n_depth and depth.t[k] <= dvl.t[j]:
            _push_depth_sample(estimator, depth, k)
            k += 1
        beams = None
        if dvl.beams is not None:
            beams = (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
        estimator.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]), beams)
        if progress is not None and j % step == 0:
            progress(0.95 * j / n)
    while depth is not None and k < n_depth:
        _push_depth_sample(estimator, depth, k)
        k += 1
    if start < len(imu):
        estimator.push_imu_batch(imu.t[start:], imu.b_omega[start:], imu.b_f[start:])
    estimator.finish()


def _push_depth_sample(estimator: OnlineEstimator, depth: DepthData, k: int) -> None:
    if depth.pressure_pa is not None:
        var = math.nan if depth.pressure_variance_pa2 is None else float(depth.pressure_variance_pa2[k])
        estimator.push_depth(float(depth.t[k]), pressure_pa=float(depth.pressure_pa[k]), pressure_variance_pa2=var)
    else:
        estimator.push_depth(float(depth.t[k]), float(depth.depth_m[k]), float(depth.variance_m2[k]))


def smooth_online(log: LogData, config: EstimatorConfig | None = None, *, mode: str | None = None,
                  window_s: float | None = None, progress: ProgressFn | None = None,
                  options: OnlineConfig | None = None) -> NavResult:
    """Run the online estimator over a whole log, message by message, and return its NavResult with the
    timeline of filtering sigmas at every epoch. options (default: config.online, TOML section [online]);
    mode ("fixed_lag" or "full") and window_s override those of options. config None: the one the log's
    scenario names, else the defaults (EstimatorConfig.for_log)."""
    config = config or EstimatorConfig.for_log(log.metadata)
    options = (options if options is not None else config.online).model_copy()
    if mode is not None:
        options.mode = mode  # type: ignore[assignment]  # any str: checked by value in OnlineEstimator
    if window_s is not None:
        options.window_s = window_s
    t_start = time.perf_counter()
    estimator = OnlineEstimator.for_log(log, config, options)
    feed_log(estimator, log, progress)
    result = estimator.result(log.t0_ns)
    total = time.perf_counter() - t_start
    result.timing_s = {"updates": float(np.sum(estimator.latencies_s)), "total": total}
    result.info["real_time_factor"] = float((log.imu.t[-1] - log.imu.t[0]) / total) if total > 0 else None
    if progress is not None:
        progress(1.0)
    return result
