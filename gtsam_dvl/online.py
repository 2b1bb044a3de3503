"""Online estimation: an incremental (iSAM2) estimator fed message by message, with bounded latency.

A vehicle or a script creates an `OnlineEstimator`, pushes IMU and DVL messages in time order
(`push_imu`, `push_imu_batch`, `push_dvl`) and reads `estimate()` after each DVL epoch: pose, velocity,
biases, scale and misalignment, each with its marginal (filtering) covariance. `smooth_online(log, config)`
drives it over a whole log and returns the same `NavResult` as the batch smoother, with a `Timeline` of the
filtering sigmas at every epoch.

Which mode:
- `fixed_lag` (default): states older than `window_s` behind the newest are marginalised; the bias, scale and
  misalignment never leave. The cost per DVL epoch is bounded however long the mission: use it on the vehicle
  and for anything longer than a few minutes. Its final calibration differs from the batch smoother's by the
  linearisation of what left the window (well inside one sigma once the window has passed the manoeuvres).
- `full`: every state is kept and iSAM2 relinearises any of them; its final estimate is the batch smoother's
  (within 0.1 sigma). Each relinearisation of the calibration touches every DVL factor of the mission through a
  Python callback that receives a copy of all the variables, so its cost per update grows with the mission
  (tens of seconds for ten minutes of data, minutes for the 2060 s paper run): use it to check the fixed-lag
  mode on short logs, or when every past state must stay adjustable.

Design (see also online_smoother.py for the iSAM2 engine):
- The same GraphBuilder as the batch smoother makes every factor, prior and initial guess; `GraphBuilder.
  incremental` gives one without a log, and its per-epoch methods are shared with the batch path.
- IMU samples are kept raw since the last epoch and preintegrated when the epoch's ping is taken, exactly as
  the batch smoother does (a sample straddling the ping is split), so a ping that arrives after IMU samples
  past its stamp (another topic, another latency) is still placed exactly.
- Alignment: the estimator waits for `align_s` seconds of the initial static segment (or motion, if sooner,
  after alignment.min_static_s) and aligns on them with the batch smoother's coarse alignment, then processes
  the buffered messages; it reports nothing before. alignment.initial_attitude_deg skips the wait.
- Slow pings do not inform the calibration (`calibration_min_speed_m_s`): below it the DVL sees noise, the
  scale's Jacobian R^T n_v is the velocity estimate's own noise, and linearising it at a different velocity
  estimate every time a state leaves the window turns that noise into information (the scale wandered to 2.2
  +- 0.27 over the static phase without this; the batch smoother, linearised once at its solution, does not
  do that). Such a ping gets a DVL factor on pose and velocity with the scale and misalignment held at their
  current estimate: it still measures the velocity (a zero-velocity update when static). What is given up is
  the information of pings slower than the threshold, (v / sigma)^2 per ping: nothing next to a manoeuvre.
- Bad input: a message older than or as old as the previous one of its kind, or with a non-finite value, is
  rejected with GtsamDvlError (`bad_messages = "raise"`, the default) or dropped with a warning the first time
  and counted in `counters` (`"drop"`). DVL pings without a valid velocity, faster than dvl.max_speed_m_s or
  not after the first IMU sample are counted and skipped, as the batch smoother does.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.alignment import STATIC_MARGIN_S, Alignment, align
from gtsam_dvl.config import DEG_PER_H, UG, EstimatorConfig
from gtsam_dvl.earth import LocalFrame
from gtsam_dvl.errors import GtsamDvlError
from gtsam_dvl.factors import dvl_beam_error, dvl_velocity_error
from gtsam_dvl.graph import C_MISALIGN, K_SCALE, GraphBuilder, V, X, map_frame_of
from gtsam_dvl.online_smoother import IncrementalSmoother, RelinearizationThresholds, StateEstimate
from gtsam_dvl.progress import ProgressFn
from gtsam_dvl.result import NavResult, Timeline, misalignment_rpy_and_cov
from gtsam_dvl.types import DvlData, ImuData, LogData, Mounting

MODES = ("fixed_lag", "full")


class MessageDropped(UserWarning):
    """A message was dropped (bad_messages = "drop"); OnlineEstimator.counters counts them by kind."""


@dataclass
class OnlineConfig:
    """Options of the online estimator. The models, priors and alignment thresholds come from EstimatorConfig."""

    mode: str = "fixed_lag"  # "fixed_lag" (bounded cost) or "full" (every state kept; see the module doc)
    window_s: float = 30.0  # fixed_lag: states this far behind the newest are marginalised, s
    align_s: float = 60.0  # seconds of the initial static segment to align on before the first estimate
    calibration_min_speed_m_s: float = 0.1  # slower pings do not inform scale and misalignment (module doc)
    bad_messages: str = "raise"  # "raise" (GtsamDvlError) or "drop" (counted, warned once per kind)
    covariances: bool = True  # marginal covariances after every epoch (the timeline needs them)
    record_history: bool = True  # keep every epoch's estimate for timeline() and result()
    final_updates: int = 10  # iSAM2 updates without new data at finish(), until nothing is relinearised
    relinearization: RelinearizationThresholds = field(default_factory=RelinearizationThresholds)

    def check(self) -> None:
        if self.mode not in MODES:
            raise GtsamDvlError(f"unknown online mode '{self.mode}' (available: {', '.join(MODES)})")
        if self.bad_messages not in ("raise", "drop"):
            raise GtsamDvlError(f"bad_messages must be 'raise' or 'drop', got '{self.bad_messages}'")
        if not self.window_s > 0:
            raise GtsamDvlError(f"window_s must be positive, got {self.window_s}")
        if not self.align_s > 0:
            raise GtsamDvlError(f"align_s must be positive, got {self.align_s}")


@dataclass
class OnlineEstimate:
    """The estimate after one DVL epoch, with marginal covariances given the data so far (SI units, GTSAM
    tangents: pose [rotation, translation] in body axes, b_R_d perturbed on the right). The properties give
    the user units of NavResult."""

    t: float
    n_p: np.ndarray
    n_R_b: np.ndarray
    n_v: np.ndarray
    pose_cov: np.ndarray  # (6, 6)
    vel_cov: np.ndarray  # (3, 3)
    pose_vel_cross: np.ndarray  # (6, 3)
    accel_bias: np.ndarray  # m/s^2
    gyro_bias: np.ndarray  # rad/s
    bias_cov: np.ndarray  # (6, 6) [accel, gyro]
    scale: float
    scale_sigma: float
    b_R_d: np.ndarray
    b_R_d_cov: np.ndarray  # (3, 3) rad^2
    b_R_d0: np.ndarray
    calib_cov: np.ndarray  # (10, 10) [accel, gyro] bias, scale, b_R_d

    @classmethod
    def from_state(cls, s: StateEstimate, b_R_d0: np.ndarray) -> OnlineEstimate:
        return cls(t=s.t, n_p=np.asarray(s.pose.translation()), n_R_b=s.pose.rotation().matrix(), n_v=s.n_v,
                   pose_cov=s.pose_cov, vel_cov=s.vel_cov, pose_vel_cross=s.pose_vel_cross,
                   accel_bias=np.asarray(s.bias.accelerometer()), gyro_bias=np.asarray(s.bias.gyroscope()),
                   bias_cov=s.cov[9:15, 9:15], scale=s.scale, scale_sigma=float(np.sqrt(s.cov[15, 15])),
                   b_R_d=s.b_R_d, b_R_d_cov=s.cov[16:19, 16:19], b_R_d0=b_R_d0, calib_cov=s.calib_cov)

    @property
    def misalignment_deg(self) -> np.ndarray:
        """[roll, pitch, yaw] of R_c = b_R_d b_R_d0^T, deg."""
        return misalignment_rpy_and_cov(self.b_R_d, self.b_R_d0, self.b_R_d_cov)[0]

    @property
    def misalignment_sigma_deg(self) -> np.ndarray:
        return np.sqrt(np.diag(misalignment_rpy_and_cov(self.b_R_d, self.b_R_d0, self.b_R_d_cov)[1]))

    @property
    def attitude_sigma_deg(self) -> np.ndarray:
        """Attitude sigmas about map axes (east, north, up), deg."""
        return np.degrees(np.sqrt(np.diag(self.n_R_b @ self.pose_cov[:3, :3] @ self.n_R_b.T)))

    @property
    def gyro_bias_deg_per_h(self) -> np.ndarray:
        return self.gyro_bias / DEG_PER_H

    @property
    def gyro_bias_sigma_deg_per_h(self) -> np.ndarray:
        return np.sqrt(np.diag(self.bias_cov)[3:]) / DEG_PER_H

    @property
    def accel_bias_ug(self) -> np.ndarray:
        return self.accel_bias / UG

    @property
    def accel_bias_sigma_ug(self) -> np.ndarray:
        return np.sqrt(np.diag(self.bias_cov)[:3]) / UG


@dataclass
class _Ping:
    t: float
    d_v: np.ndarray
    d_cov: np.ndarray
    valid: bool
    beams: tuple[np.ndarray, np.ndarray, np.ndarray] | None


def _considered_calibration_factor(noise: gtsam.noiseModel.Base, i: int, b_omega: np.ndarray, b_l: np.ndarray,
                                   d_y: np.ndarray | None = None,
                                   beam: tuple[np.ndarray, float] | None = None) -> gtsam.CustomFactor:
    """The DVL factor of factors/ on [X_i, V_i, K, C] for a ping too slow to inform the calibration (module
    doc): same error, same Jacobians for pose and velocity, none for scale and misalignment, which are
    "considered" at their current estimate (the velocity's information scales with it). d_y: the 3-D velocity;
    beam: (d_u, y_j) for one beam."""

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose, n_v = values.atPose3(X(i)), values.atVector(V(i))
        k, b_R_d = values.atVector(K_SCALE), values.atRot3(C_MISALIGN)
        slots: list[Any] | None = None if H is None else [None] * 4
        if beam is not None:
            e = dvl_beam_error(pose, n_v, k, b_R_d, beam[0], beam[1], b_omega, b_l, slots)
        else:
            e = dvl_velocity_error(pose, n_v, k, b_R_d, d_y, b_omega, b_l, slots)
        if H is not None and slots is not None:
            H[0], H[1] = slots[0], slots[1]
            H[2], H[3] = np.zeros((len(e), 1)), np.zeros((len(e), 3))
        return e

    return gtsam.CustomFactor(noise, [X(i), V(i), K_SCALE, C_MISALIGN], error_func)


class OnlineEstimator:
    """Incremental estimator fed message by message (module doc). Times are seconds on the caller's clock,
    the same for IMU and DVL; IMU sample t covers (previous sample, t] (ImuData's convention)."""

    def __init__(self, config: EstimatorConfig | None = None, *, frame: LocalFrame, mounting: Mounting | None = None,
                 options: OnlineConfig | None = None, source: str = "") -> None:
        self.config = config or EstimatorConfig()
        self.options = options or OnlineConfig()
        self.options.check()
        self.frame, self.mounting, self.source = frame, mounting or Mounting(), source
        self.counters: dict[str, int] = {}
        self.latencies_s: list[float] = []  # per DVL epoch: preintegration, factors, iSAM2 update, covariances
        self.builder: GraphBuilder | None = None
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
        self._buf_start: float | None = None  # end of the sample before the buffer's first
        self._pending: deque[_Ping] = deque()
        self._last_key_t = -math.inf
        self._latest: OnlineEstimate | None = None
        self._history: list[tuple[OnlineEstimate, np.ndarray]] = []  # (estimate, epoch body rate)
        if self.config.alignment.initial_attitude_deg is not None:
            self._start(align(_empty_imu(), _empty_dvl(), frame, self.config.alignment))

    @classmethod
    def for_log(cls, log: LogData, config: EstimatorConfig | None = None,
                options: OnlineConfig | None = None) -> OnlineEstimator:
        """An estimator with the map origin and mounting of a log (to replay it)."""
        config = config or EstimatorConfig()
        return cls(config, frame=map_frame_of(log, config), mounting=log.mounting, options=options,
                   source=log.source)

    # ----- input ---------------------------------------------------------------------------------
    def push_imu(self, t: float, b_omega: Any, b_f: Any) -> int:
        """One IMU sample: gyro b_omega (rad/s) and specific force b_f (m/s^2) averaged over (previous t, t].
        Returns the number of DVL epochs it completed."""
        t = float(t)
        w = np.asarray(b_omega, dtype=float).reshape(3)
        f = np.asarray(b_f, dtype=float).reshape(3)
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
        w = np.asarray(b_omega, dtype=float).reshape(-1, 3)
        f = np.asarray(b_f, dtype=float).reshape(-1, 3)
        if not (len(t) == len(w) == len(f)):
            raise GtsamDvlError(f"IMU batch: {len(t)} stamps, {len(w)} gyro and {len(f)} accelerometer rows")
        if len(t) == 0:
            return 0
        prev = np.maximum.accumulate(np.concatenate([[self._last_imu_t], np.where(np.isfinite(t), t, -np.inf)]))[:-1]
        in_order = np.isfinite(t) & (t > prev)
        finite = np.isfinite(w).all(axis=1) & np.isfinite(f).all(axis=1)
        keep = in_order & finite
        if not keep.all():
            j = int(np.argmin(keep))
            for mask, kind, what in ((~in_order & (t == prev), "imu_duplicate", "repeats the previous stamp"),
                                     (~in_order & (t != prev), "imu_out_of_order", "is older than the previous one"),
                                     (in_order & ~finite, "imu_not_finite", "has a non-finite value")):
                n_bad = int(mask.sum())
                if n_bad:
                    j = int(np.argmax(mask))
                    self._bad(kind, f"IMU sample at t = {t[j]:.6f} s {what}", n_bad)
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
        d_v = np.asarray(d_v, dtype=float).reshape(3)
        d_cov = np.full((3, 3), np.nan) if d_cov is None else np.asarray(d_cov, dtype=float).reshape(3, 3)
        if beams is not None:
            beams = (np.asarray(beams[0], dtype=float).reshape(-1, 3), np.asarray(beams[1], dtype=float).reshape(-1),
                     np.asarray(beams[2], dtype=bool).reshape(-1))
        ping = _Ping(t, d_v, d_cov, bool(valid), beams)
        if self.smoother is None:
            self._pre_dvl.append(ping)
            return 0
        return self._take_ping(ping)

    def finish(self) -> OnlineEstimate | None:
        """End of data: align on what there is if still waiting, drop pings no IMU sample reached, and let
        iSAM2 relinearise until converged (options.final_updates). Returns the final estimate."""
        if self.smoother is None and self._pre_imu:
            self._align(final=True)
        self._count("dvl_after_imu", len(self._pending))
        self._pending.clear()
        if self.smoother is not None and self.smoother.n > 0:
            self.smoother.refresh_gravity()
            self.smoother.refine(self.options.final_updates)
            self._latest = self._read_estimate()
        return self._latest

    # ----- output --------------------------------------------------------------------------------
    def estimate(self) -> OnlineEstimate | None:
        """The estimate after the latest epoch (None before the first)."""
        return self._latest

    @property
    def epochs(self) -> int:
        return 0 if self.smoother is None else self.smoother.n

    def timeline(self) -> Timeline:
        """Filtering estimates and sigmas after every epoch (options.record_history)."""
        h = [e for e, _ in self._history]
        mis = [misalignment_rpy_and_cov(e.b_R_d, e.b_R_d0, e.b_R_d_cov) for e in h]
        return Timeline(
            t=np.array([e.t for e in h]), scale=np.array([e.scale for e in h]),
            scale_sigma=np.array([e.scale_sigma for e in h]),
            misalignment_deg=np.array([m[0] for m in mis]).reshape(-1, 3),
            misalignment_sigma_deg=np.sqrt(np.array([np.diag(m[1]) for m in mis]).reshape(-1, 3)),
            gyro_bias_deg_per_h=np.array([e.gyro_bias_deg_per_h for e in h]).reshape(-1, 3),
            gyro_bias_sigma_deg_per_h=np.array([e.gyro_bias_sigma_deg_per_h for e in h]).reshape(-1, 3),
            accel_bias_ug=np.array([e.accel_bias_ug for e in h]).reshape(-1, 3),
            accel_bias_sigma_ug=np.array([e.accel_bias_sigma_ug for e in h]).reshape(-1, 3),
            attitude_sigma_deg=np.array([e.attitude_sigma_deg for e in h]).reshape(-1, 3))

    def result(self, t0_ns: int = 0) -> NavResult:
        """NavResult: the trajectory as estimated online (each state when its ping was processed, with its
        filtering covariance), the bias and calibration after finish(), and the timeline."""
        if not self._history or self._latest is None or self.builder is None:
            raise GtsamDvlError(f"{self.source or 'online estimator'}: no DVL epoch was processed")
        h = [e for e, _ in self._history]
        final = self._latest
        info: dict[str, Any] = {
            "mode": self.options.mode, "window_s": self.options.window_s if self.options.mode == "fixed_lag" else None,
            "trajectory": "filtered: each state as estimated when its DVL ping was processed",
            "counters": dict(self.counters), "epochs": len(h),
            "alignment": {"method": self.builder.alignment.method, "t_static_end": self.builder.alignment.t_static_end},
            "latency_ms": latency_stats(self.latencies_s),
        }
        if self.smoother is not None:
            info["isam2"] = {"rebases": self.smoother.rebases, "states_marginalized": self.smoother.marginalised}
        return NavResult(
            estimator=f"online-{self.options.mode.replace('_', '-')}",
            t=np.array([e.t for e in h]), n_p=np.array([e.n_p for e in h]), n_R_b=np.array([e.n_R_b for e in h]),
            n_v=np.array([e.n_v for e in h]), pose_cov=np.array([e.pose_cov for e in h]),
            vel_cov=np.array([e.vel_cov for e in h]), pose_vel_cross=np.array([e.pose_vel_cross for e in h]),
            accel_bias=final.accel_bias, gyro_bias=final.gyro_bias, bias_cov=final.bias_cov,
            scale=final.scale, scale_sigma=final.scale_sigma, b_R_d=final.b_R_d, b_R_d_cov=final.b_R_d_cov,
            b_R_d0=self.mounting.b_R_d0, t0_ns=t0_ns,
            b_omega=np.array([w for _, w in self._history]) - final.gyro_bias,
            calib_joint_cov=final.calib_cov, timeline=self.timeline(), info=info, config=self.config.to_dict())

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
        if t == self._last_imu_t:
            self._bad("imu_duplicate", f"IMU sample at t = {t:.6f} s repeats the previous stamp")
        else:
            self._bad("imu_out_of_order", f"IMU sample at t = {t:.6f} s is older than the previous one "
                                          f"({self._last_imu_t:.6f} s)")
        return False

    def _take_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> int:
        if self._first_imu_t is None:
            self._first_imu_t = float(t[0])
        if self.smoother is None:
            self._pre_imu.append((t, w, f))
            if t[-1] - self._first_imu_t >= self.options.align_s + STATIC_MARGIN_S + 1.0:
                return self._align(final=False)
            return 0
        return self._ingest_imu(t, w, f)

    def _ingest_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> int:
        if self._buf_start is None:  # the very first sample: its interval's start is unknown, it only opens
            self._buf_start = float(t[0])
            t, w, f = t[1:], w[1:], f[1:]
        if len(t):
            self._chunks.append((t, w, f))
        return self._close_ready()

    def _align(self, final: bool) -> int:
        t = np.concatenate([c[0] for c in self._pre_imu])
        w = np.concatenate([c[1] for c in self._pre_imu])
        f = np.concatenate([c[2] for c in self._pre_imu])
        pings = self._pre_dvl
        dvl = DvlData(np.array([p.t for p in pings]), np.array([p.d_v for p in pings]).reshape(-1, 3),
                      np.array([p.d_cov for p in pings]).reshape(-1, 3, 3), np.array([p.valid for p in pings], bool))
        cfg = dataclasses.replace(self.config.alignment)
        cfg.max_static_s = min(cfg.max_static_s, self.options.align_s) if cfg.max_static_s > 0 else self.options.align_s
        try:
            alignment = align(ImuData(t, w, f), dvl, self.frame, cfg)
        except GtsamDvlError as exc:
            raise GtsamDvlError(f"{self.source + ': ' if self.source else ''}online alignment: {exc}") from None
        self._start(alignment)
        self._pre_imu, self._pre_dvl = [], []
        done = self._ingest_imu(t, w, f)
        for p in pings:
            done += self._take_ping(p)
        return done

    def _start(self, alignment: Alignment) -> None:
        self.builder = GraphBuilder.incremental(self.config, self.frame, alignment, self.mounting, self.source)
        window = self.options.window_s if self.options.mode == "fixed_lag" else None
        self.smoother = IncrementalSmoother(self.builder, window, self.options.relinearization)

    def _take_ping(self, p: _Ping) -> int:
        cfg = self.config.dvl
        if self._first_imu_t is None or p.t <= self._first_imu_t:
            self._count("dvl_unusable")  # no IMU sample before it, as in the batch smoother
            return 0
        if cfg.use_beams and p.beams is not None:
            usable = bool(p.beams[2].any() and np.isfinite(p.beams[1][p.beams[2]]).all()
                          and np.isfinite(p.beams[0][p.beams[2]]).all())
        else:
            usable = p.valid and bool(np.isfinite(p.d_v).all())
            if usable and np.linalg.norm(p.d_v) > cfg.max_speed_m_s:
                self._count("dvl_too_fast")
                return 0
        if not usable:
            self._count("dvl_unusable")
            return 0
        if p.t - self._last_key_t < self.config.solver.keyframe_interval_s:
            self._count("dvl_not_keyframe")
            return 0
        self._last_key_t = p.t
        self._pending.append(p)
        return self._close_ready()

    def _close_ready(self) -> int:
        done = 0
        while self._pending and self._chunks and self._pending[0].t <= self._chunks[-1][0][-1]:
            self._close(self._pending.popleft())
            done += 1
        return done

    def _close(self, p: _Ping) -> None:
        """Make the epoch of ping p: preintegrate since the previous one, add its factors, update iSAM2."""
        assert self.builder is not None and self.smoother is not None and self._buf_start is not None
        t0 = time.perf_counter()
        b, sm = self.builder, self.smoother
        if len(self._chunks) > 1:
            self._chunks = [tuple(np.concatenate(c) for c in zip(*self._chunks, strict=True))]  # type: ignore[list-item]
        T, W, F = self._chunks[0]
        gi = int(np.searchsorted(T, p.t, side="left"))  # the sample covering the ping
        b_omega = b.body_rate(W[gi])
        i = sm.n
        dvl = self._dvl_factors(i, p, b_omega)
        if i == 0:
            sm.add_epoch(p.t, dvl, first_values=b.first_state_values(p.d_v if p.valid else None))
        else:
            starts = np.concatenate([[self._buf_start], T[:-1]])
            b_f = b.compensate_rotation(F, W, T - starts)
            pim, params = b.preintegrate_interval(sm.t_last, p.t, T, starts, b_f, W)
            sm.add_epoch(p.t, dvl, pim, params)
        keep = T > p.t
        if not keep[0]:
            self._buf_start = float(T[~keep][-1])
        self._chunks = [(T[keep], W[keep], F[keep])] if keep.any() else []
        self._latest = self._read_estimate()
        if self.options.record_history:
            self._history.append((self._latest, b_omega))
        self.latencies_s.append(time.perf_counter() - t0)

    def _dvl_factors(self, i: int, p: _Ping, b_omega: np.ndarray) -> list[gtsam.NonlinearFactor]:
        b = self.builder
        assert b is not None
        use_beams = self.config.dvl.use_beams and p.beams is not None
        if use_beams and p.beams is not None:
            speed = float(np.abs(p.beams[1][p.beams[2]]).max())  # a beam sees at most the speed
        else:
            speed = float(np.linalg.norm(p.d_v))
        if speed >= self.options.calibration_min_speed_m_s:
            return b.dvl_factors_for(i, p.d_v, p.d_cov, b_omega, p.beams)
        b_l = self.mounting.b_l
        if use_beams and p.beams is not None:
            d_u, v, valid = p.beams
            noise1 = b.beam_noise()
            return [_considered_calibration_factor(noise1, i, b_omega, b_l, beam=(d_u[j], float(v[j])))
                    for j in np.flatnonzero(valid)]
        return [_considered_calibration_factor(b.dvl_noise(p.d_cov), i, b_omega, b_l, d_y=p.d_v)]

    def _read_estimate(self) -> OnlineEstimate:
        assert self.smoother is not None
        state = self.smoother.estimate(with_covariance=self.options.covariances)
        return OnlineEstimate.from_state(state, self.mounting.b_R_d0)


def _empty_imu() -> ImuData:
    return ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))


def _empty_dvl() -> DvlData:
    return DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, dtype=bool))


def latency_stats(latencies_s: list[float] | np.ndarray) -> dict[str, float]:
    """p50, p99 and max of per-epoch latencies, ms."""
    lat = np.asarray(latencies_s, dtype=float) * 1e3
    if lat.size == 0:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan}
    return {"p50": float(np.percentile(lat, 50)), "p99": float(np.percentile(lat, 99)), "max": float(lat.max())}


def feed_log(estimator: OnlineEstimator, log: LogData, progress: ProgressFn | None = None) -> None:
    """Push a log's messages in time order: the IMU samples up to each ping's stamp as one batch, then the
    ping (a sample stamped like the ping comes first), then the rest; finish()."""
    imu, dvl = log.imu, log.dvl
    ends = np.searchsorted(imu.t, dvl.t, side="right")
    start = 0
    n = len(dvl)
    step = max(1, n // 100)
    for j in range(n):
        end = int(ends[j])
        if end > start:
            estimator.push_imu_batch(imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end])
            start = end
        beams = None
        if dvl.beams is not None:
            beams = (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
        estimator.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]), beams)
        if progress is not None and j % step == 0:
            progress(0.95 * j / n)
    if start < len(imu):
        estimator.push_imu_batch(imu.t[start:], imu.b_omega[start:], imu.b_f[start:])
    estimator.finish()


def smooth_online(log: LogData, config: EstimatorConfig | None = None, *, mode: str = "fixed_lag",
                  window_s: float | None = None, progress: ProgressFn | None = None,
                  options: OnlineConfig | None = None) -> NavResult:
    """Run the online estimator over a whole log, message by message, and return its NavResult with the
    timeline of filtering sigmas at every epoch (mode "fixed_lag" or "full"; window_s overrides the
    options' window)."""
    config = config or EstimatorConfig()
    options = dataclasses.replace(options) if options is not None else OnlineConfig()
    options.mode = mode
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
