"""What the ROS 2 node does with its messages, without ROS: decode, order, feed the online estimator, and make what
it publishes. app/node/ros.py only moves bytes between DDS and NodeCore, so that this part is tested without a
ROS graph (tests/app/test_node_core.py feeds a log's own message bodies through it).

The path of a message: its serialized CDR body (rclpy's raw subscription) is decoded with the reader's layouts and
mappings (io/ros2/decode.py; io/reader.py dvl_from_messages, pressure_from_messages; io/gnss.py), so the node sees
a message as `gtsam-dvl smooth` sees it in a bag: the same stamps (the header's, ns), the same covariance rules (an
all-zero DVL covariance is unknown), the same bottom-lock flag. A DVL, pressure or GNSS stamp more than
clock_skew_s from the IMU's newest is dropped as being on another clock. The rest go into the ReorderBuffer
(app/node/reorder.py) and come out in stamp order a window later; consecutive IMU samples are pushed as one batch.
Times given to the estimator are seconds since t0_ns, the first IMU stamp rounded down to the second, as the reader
makes them: a node fed a log's messages and `smooth --mode online` on that log give the same estimates.

The estimator starts when the map origin is known (the configuration's alignment.origin_*, else the first good GNSS
fix, which is then the origin and its time origin_t, as estimators/inputs/gnss.py makes it for a log) and the first IMU
sample is released; every fix then goes to the estimator (OnlineEstimator.push_gnss, as `smooth --mode online` gives
a log's), and until it has aligned so does the IMU message's own orientation when the driver fills it (ENU, REP-103);
the mounting is /tf_static's when it was received, else the settings'. An exception inside the estimator never reaches
ROS: one log line, the error kept for the diagnostics ("failed: the estimator stopped"),
and nothing more fed to it; the node itself goes on (diagnostics, services) until it is restarted. A new estimator
is not started in its place: in motion it could not align again, nor know its position.

calibration_out is written while the node runs, not only at a clean exit (a node killed or powered off keeps the
last one): at the first estimate, then whenever a vehicle calibration state has moved by more than
calibration_out_move_sigma of its sigma since the last write, and calibration_out_period_s of sensor time after
it at the latest (a temporary file renamed into place: the file is always whole). The node's estimator leaves
out the per-epoch timeline of its result, which the file does not hold (NodeEstimator).
"""

from __future__ import annotations

import math
import time
import warnings
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.analysis.health import Health
from gtsam_dvl.analysis.live_health import LiveState, LiveThresholds, StreamState, assess_live
from gtsam_dvl.app.live.server import PosePath
from gtsam_dvl.app.node.reorder import Held, ReorderBuffer
from gtsam_dvl.app.node.settings import NodeSettings
from gtsam_dvl.core.calibration import (
    SourceLog,
    VehicleCalibration,
    from_result,
    iso_date,
    vehicle_state_names,
)
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import Timeline, misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, rpy_deg_to_matrix, so3_log
from gtsam_dvl.core.states import Estimate
from gtsam_dvl.core.types import GnssData, Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.online import OnlineEstimator
from gtsam_dvl.io.calibration_file import write_calibration
from gtsam_dvl.io.gnss import NAVSATFIX_TYPE, gnss_from_messages, good_fixes
from gtsam_dvl.io.reader import IMU_TYPE, PRESSURE_TYPE, dvl_from_messages, pressure_from_messages
from gtsam_dvl.io.ros2 import messages
from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.covariance import ros_pose_covariance, ros_twist_covariance
from gtsam_dvl.io.ros2.decode import MessageDecoder, decode_tf, first_string, to_base
from gtsam_dvl.io.storage.raw import Bodies

if TYPE_CHECKING:
    from gtsam_dvl.estimators.online import OnlineEstimate

# the rows of the calibration message (Float64MultiArray, rows x [value, sigma]; docs/ros2.md): name with unit
CALIBRATION_ROWS = (
    "stamp_s",
    "scale",
    "misalignment_roll_deg",
    "misalignment_pitch_deg",
    "misalignment_yaw_deg",
    "time_offset_s",
    "accel_bias_x_ug",
    "accel_bias_y_ug",
    "accel_bias_z_ug",
    "gyro_bias_x_deg_per_h",
    "gyro_bias_y_deg_per_h",
    "gyro_bias_z_deg_per_h",
)
TIMINGS_KEPT = 200_000  # per-epoch timing records kept for stats_file (about 40 h of 1 Hz states)


@dataclass
class EpochTiming:
    """One published estimate: its time (s), the wall times (steady clock, s) at which the message that released
    it arrived, the estimator finished and the message was published, the estimator's own time for the epoch
    (s, OnlineEstimator.latencies_s) and which message released it."""

    t: float
    arrived: float
    done: float
    processing_s: float
    published: float = math.nan
    trigger: tuple[str, int] = (
        "",
        0,
    )  # the message that released it: input kind and header stamp (ns)


class NodeEstimator(OnlineEstimator):
    """The online estimator whose result() has no timeline: the node's result only makes its calibration file,
    which holds none, and the timeline is computed per epoch in Python (37 us each: 0.5 s after an hour of 5 Hz
    pings, a stall of the node at every write of calibration_out)."""

    def timeline(self) -> Timeline:
        one, three = np.empty(0), np.empty((0, 3))
        return Timeline(
            **{f: one if f in ("t", "scale", "scale_sigma") else three for f in Timeline.FIELDS}
        )


def moved(before: dict[str, Estimate], now: dict[str, Estimate], fraction: float) -> bool:
    """Whether a state of now moved from before by more than fraction of its sigma (now's) in a component of its
    tangent (a rotation by its right perturbation, as its covariance is given); a state new or gone counts."""
    for name, b in now.items():
        a = before.get(name)
        if a is None:
            return True
        va, vb = np.asarray(a.value, dtype=float), np.asarray(b.value, dtype=float)
        d = so3_log(va.T @ vb) if vb.shape == (3, 3) else vb - va
        if np.any(np.abs(d) > fraction * b.sigma):
            return True
    return set(before) != set(now)


class NodeCore:
    """The node without ROS (module doc). receive() takes a serialized message and returns the estimates to publish;
    tick() is called on a wall-time timer (flush, stalls); odometry(), calibration_rows(), health() and path() make
    what is published. log(level, text): the node's logger ("info", "warn", "error")."""

    def __init__(
        self,
        settings: NodeSettings,
        config: EstimatorConfig,
        *,
        calibration: VehicleCalibration | None = None,
        clock: Callable[[], float] = time.monotonic,
        log: Callable[[str, str], None] | None = None,
    ) -> None:
        self.settings = settings
        # a message the estimator refuses is dropped and counted, never raised (a node does not stop on one)
        self.config = config.model_copy(
            update={"online": config.online.model_copy(update={"bad_messages": "drop"})}
        )
        self.calibration_file = calibration
        self.clock = clock
        self.log: Callable[[str, str], None] = log or (lambda level, text: None)
        s = settings
        self.topics = {
            "imu": s.imu_topic,
            "dvl": s.dvl_topic,
            "pressure": s.pressure_topic,
            "gnss": s.gnss_topic,
        }
        self.types = {
            "imu": IMU_TYPE,
            "dvl": s.dvl_type,
            "pressure": PRESSURE_TYPE,
            "gnss": NAVSATFIX_TYPE,
        }
        self.decoders = {k: MessageDecoder(self.topics[k] or k, self.types[k]) for k in self.topics}
        self.buffer = ReorderBuffer(round(s.reorder_window_s * 1e9), round(s.stamp_jump_s * 1e9))
        self.off_clock = {k: 0 for k in self.topics}
        self.undecodable = {k: 0 for k in self.topics}
        self.frames = {
            "imu": "imu_link",
            "dvl": "dvl_link",
            "pressure": "pressure_link",
            "gnss": "gnss_link",
        }
        self.tf: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
        a = self.config.alignment
        self.frame = (
            LocalFrame(a.origin_lat_deg, a.origin_lon_deg or 0.0, a.origin_height_m or 0.0)
            if a.origin_lat_deg is not None
            else None
        )
        self.origin_t: float | None = None
        self.fixes: deque[GnssData] = deque()  # fixes waiting for the estimator (_take_fix)
        self.t0_ns: int | None = None
        self.estimator: OnlineEstimator | None = None
        self.prior: VehicleCalibration | None = None
        self.latest: OnlineEstimate | None = None
        self.path = PosePath()
        self.timings: deque[EpochTiming] = deque(maxlen=TIMINGS_KEPT)
        self.stop_error, self.stop_t, self.stops = "", math.nan, 0
        self.last_ping_t, self.last_valid_ping_t = math.nan, math.nan
        self.last_wall = -math.inf
        self.finished = False
        self._trigger: tuple[str, int] = ("", 0)
        # calibration_out while running (module doc): each write's estimate time and duration (s), the sensor time
        # and vehicle states of the last one tried, the last error said
        self.calibration_writes: deque[tuple[float, float]] = deque(maxlen=TIMINGS_KEPT)
        self._kept: tuple[float, dict[str, Estimate]] | None = None
        self._vehicle_states = set(vehicle_state_names(self.config))
        self._keep_error = ""

    def _say(self, level: str, text: str) -> None:
        """A log line; a logger that fails loses the line, never the message being processed."""
        try:
            self.log(level, text)
        except Exception:  # noqa: BLE001, S110
            pass

    # ----- input ---------------------------------------------------------------------------------------------
    def receive(self, kind: str, body: bytes, wall: float | None = None) -> list[OnlineEstimate]:
        """A serialized message of one input ("imu", "dvl", "pressure", "gnss"): the estimates it completed."""
        wall = self.clock() if wall is None else wall
        self.last_wall = wall
        try:
            arr = self.decoders[kind](body)
        except GtsamDvlError as exc:
            self.undecodable[kind] += 1
            if self.undecodable[kind] == 1:
                self._say("warn", f"{exc}: dropped (further ones are counted)")
            return []
        ns = int(stamps_ns(arr)[0])
        frame = first_string(arr)
        if frame and kind in self.frames:
            self.frames[kind] = frame
        imu_newest = self.buffer.streams["imu"].newest_ns
        if (
            kind != "imu"
            and imu_newest is not None
            and abs(ns - imu_newest) > self.settings.clock_skew_s * 1e9
        ):
            self.off_clock[kind] += 1
            if self.off_clock[kind] == 1:
                skew = (ns - imu_newest) * 1e-9
                self._say(
                    "warn",
                    f"{self.topics[kind]}: stamp {skew:+.3f} s from the IMU's newest: not on the IMU's "
                    "clock, dropped (further ones are counted)",
                )
            return []
        if kind == "imu" and self.t0_ns is None:
            self.t0_ns = ns // 1_000_000_000 * 1_000_000_000
        self.buffer.push(kind, ns, arr, wall)
        # nothing is released before the first IMU sample sets the time origin
        if self.t0_ns is None:
            return []
        self._trigger = (kind, ns)
        return self._release(self.buffer.ready(), wall)

    def receive_tf(self, body: bytes) -> None:
        """A tf2_msgs/msg/TFMessage of /tf_static: its transforms kept for the mounting (read when the estimator
        starts)."""
        try:
            self.tf.update(
                decode_tf(
                    Path(self.settings.tf_static_topic),
                    self.settings.tf_static_topic,
                    Bodies(np.zeros(1, np.int64), var=[body]),
                )
            )
        except GtsamDvlError as exc:
            self._say("warn", str(exc))

    def tick(self, wall: float | None = None) -> list[OnlineEstimate]:
        """The wall-time timer: with no message for flush_after_s, every held message is released."""
        wall = self.clock() if wall is None else wall
        if (
            len(self.buffer)
            and self.t0_ns is not None
            and wall - self.last_wall > self.settings.flush_after_s
        ):
            return self._release(self.buffer.flush(), wall)
        return []

    def finish(self) -> OnlineEstimate | None:
        """End of data (shutdown): release what is held, then the estimator's finish(); the final estimate."""
        if self.t0_ns is not None:
            self._release(self.buffer.flush(), self.clock())
        if self.estimator is None or self.finished:
            return None
        self.finished = True
        try:
            final = self.estimator.finish()
        except Exception as exc:  # noqa: BLE001  (a node never dies on the estimator's error)
            self._stopped(exc)
            return None
        self.latest = final
        return final

    # ----- feeding -------------------------------------------------------------------------------------------
    def _t(self, ns: int) -> float:
        assert self.t0_ns is not None
        return (ns - self.t0_ns) / 1e9

    def _release(self, held: list[Held], arrived: float) -> list[OnlineEstimate]:
        out: list[OnlineEstimate] = []
        i = 0
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            while i < len(held):
                j = i + 1
                if held[i].kind == "imu":
                    while j < len(held) and held[j].kind == "imu":
                        j += 1
                try:
                    done = self._feed(held[i:j])
                except Exception as exc:  # noqa: BLE001  (module doc: the node goes on)
                    self._stopped(exc)
                    done = 0
                if (
                    done
                    and self.estimator is not None
                    and (e := self.estimator.estimate()) is not None
                ):
                    self._published(e, arrived)
                    out.append(e)
                i = j
        for w in caught:
            self._say("warn", str(w.message))
        return out

    def _feed(self, group: list[Held]) -> int:
        kind = group[0].kind
        if kind == "gnss":
            for m in group:
                self._take_fix(m)
            return 0
        est = self._ensure_estimator()
        if est is None:
            return 0
        if kind == "imu":
            t_imu = np.array([self._t(m.stamp_ns) for m in group])
            w = np.array([m.payload["angular_velocity"][0] for m in group], dtype=float)
            f = np.array([m.payload["linear_acceleration"][0] for m in group], dtype=float)
            done = est.push_imu_batch(t_imu, w, f)
            # until aligned, the IMU message's own orientation when the driver fills it (push_attitude ignores an
            # unfilled one: orientation_covariance[0] = -1 or a zero quaternion)
            for m, t in zip(group, t_imu, strict=True):
                if est.smoother is not None:
                    break
                o = m.payload
                cov = o["orientation_covariance"][0]
                done += est.push_attitude(t, o["orientation"][0], cov, frame="imu_link")
            return done
        m = group[0]
        t = self._t(m.stamp_ns)
        if kind == "pressure":
            p, var = pressure_from_messages(m.payload)
            est.push_depth(t, pressure_pa=float(p[0]), pressure_variance_pa2=float(var[0]))
            return 0
        dvl = dvl_from_messages(self.settings.dvl_type, m.payload)
        self.last_ping_t = t
        if dvl.valid[0]:
            self.last_valid_ping_t = t
        beams = (
            None if dvl.beams is None else (dvl.beams.d_u[0], dvl.beams.v[0], dvl.beams.valid[0])
        )
        return est.push_dvl(
            t,
            dvl.d_v[0],
            dvl.d_cov[0],
            bool(dvl.valid[0]),
            beams,
            water_track=dvl.water_track is not None and bool(dvl.water_track[0]),
        )

    def _take_fix(self, m: Held) -> None:
        """A GNSS fix: the map origin when none is configured and none was taken (estimators/inputs/gnss.py: the first
        good fix is the origin, at its time); once the origin is known, pushed to the estimator (kept until it
        starts)."""
        if self.t0_ns is None:
            return
        gnss = gnss_from_messages(m.payload, np.array([m.stamp_ns]), self.t0_ns)
        if self.frame is not None:
            self.fixes.append(gnss)
            self._push_fixes()
            return
        if good_fixes(gnss)[0]:
            self.fixes.append(gnss)
            self.frame = LocalFrame(
                float(gnss.lat_deg[0]), float(gnss.lon_deg[0]), float(gnss.height_m[0])
            )
            self.origin_t = float(gnss.t[0])
            o = self.frame
            self._say(
                "info",
                f"map origin from the GNSS fix at t = {self.origin_t:.1f} s: lat {o.lat_deg:.7f}, "
                f"lon {o.lon_deg:.7f}, height {o.height_m:.2f} m",
            )

    def _ensure_estimator(self) -> OnlineEstimator | None:
        if (
            self.estimator is not None
            or self.frame is None
            or self.t0_ns is None
            or self.stop_error
        ):
            return self.estimator
        if self.calibration_file is not None and self.prior is None:
            from gtsam_dvl.app.calibration_files import inflated_at

            self.prior, _ = inflated_at(self.calibration_file, self.t0_ns, self.config)
        mounting, depth_sensor = self.mounting()
        antenna = (
            to_base(self.tf, self.frames["gnss"], self.settings.base_frame) if self.tf else None
        )
        est = NodeEstimator(
            self.config,
            frame=self.frame,
            mounting=mounting,
            source=self.settings.node_name,
            depth_sensor=depth_sensor,
            calibration=self.prior,
            gnss_antenna=None if antenna is None else antenna[1],
        )
        est.origin_t = self.origin_t
        self.estimator = est
        self._push_fixes()
        return est

    def _push_fixes(self) -> None:
        """The fixes kept, to the estimator once it exists (OnlineEstimator.push_gnss)."""
        while self.estimator is not None and self.fixes:
            g = self.fixes.popleft()
            self.estimator.push_gnss(
                float(g.t[0]),
                g.lat_deg[0],
                g.lon_deg[0],
                g.height_m[0],
                g.cov_enu_m2[0],
                g.status[0],
            )

    def mounting(self) -> tuple[Mounting, np.ndarray]:
        """The nominal mounting and the pressure sensor's position in base_link: /tf_static's transforms from
        base_frame to each sensor's frame (its messages' frame_id) when received, else the settings'."""
        s = self.settings
        m = Mounting()
        chosen = {}
        for kind, rpy, xyz in (
            ("imu", s.imu_rpy_deg, s.imu_xyz_m),
            ("dvl", s.dvl_rpy_deg, s.dvl_xyz_m),
            ("pressure", (0.0, 0.0, 0.0), s.pressure_xyz_m),
        ):
            pose = to_base(self.tf, self.frames[kind], s.base_frame) if self.tf else None
            chosen[kind] = (
                pose if pose is not None else (rpy_deg_to_matrix(rpy), np.asarray(xyz, dtype=float))
            )
        m.b_R_imu, m.b_p_imu = chosen["imu"]
        m.b_R_d0, m.b_p_dvl = chosen["dvl"]
        return m, np.asarray(chosen["pressure"][1], dtype=float)

    def _stopped(self, exc: BaseException) -> None:
        """The estimator raised: say it in one line, keep the error for the diagnostics, feed nothing more (module
        doc)."""
        t = self.latest.t if self.latest is not None else math.nan
        self.stop_error = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
        self.stop_t = self.sensor_t()
        self.stops += 1
        self._say(
            "error",
            f"estimator stopped at t = {t:.2f} s ({self.stop_error}): no estimate from here on; "
            "the node goes on (diagnostics, services) until it is restarted",
        )
        self.estimator = None

    def _published(self, e: OnlineEstimate, arrived: float) -> None:
        self.latest = e
        est = self.estimator
        processing = est.latencies_s[-1] if est is not None and len(est.latencies_s) else math.nan
        self.timings.append(
            EpochTiming(float(e.t), arrived, self.clock(), processing, trigger=self._trigger)
        )
        if math.isnan(e.predicted_from_t):  # a state (not a ping between keyframes): on the path
            self.path.add(self.stamp_ns(e.t), e.n_p, matrix_to_quat_xyzw(e.n_R_b))
        self._keep_calibration(e)

    def _keep_calibration(self, e: OnlineEstimate) -> None:
        """calibration_out written while running (module doc). A failure is one log line (again only when its
        text changes) and is tried again when the next write is due: never an exception here, where it would cost
        the estimates of the messages being released."""
        s = self.settings
        if not s.calibration_out:
            return
        states = {n: v for n, v in e.calibration.items() if n in self._vehicle_states}
        if (
            self._kept is not None
            and e.t - self._kept[0] < s.calibration_out_period_s
            and not moved(self._kept[1], states, s.calibration_out_move_sigma)
        ):
            return
        self._kept = (float(e.t), states)
        try:
            self.save_calibration(s.calibration_out)
        except Exception as exc:  # noqa: BLE001  (docstring)
            text = (
                f"{type(exc).__name__}: {exc}" if not isinstance(exc, GtsamDvlError) else str(exc)
            )
            if text != self._keep_error:
                self._say("error", f"calibration_out: {text.splitlines()[0]}")
            self._keep_error = text
            return
        self._keep_error = ""

    # ----- output --------------------------------------------------------------------------------------------
    def stamp_ns(self, t: float) -> int:
        """ROS time (ns) of t (s since t0_ns)."""
        return int(self.t0_ns or 0) + round(float(t) * 1e9)

    def odometry(self, e: OnlineEstimate) -> bytes:
        """nav_msgs/msg/Odometry of base_link in map (io/ros2/messages.odometry; covariances in ROS order by
        io/ros2/covariance.py): the pose with its marginal covariance, the velocity in base_link with its own. The
        angular velocity is not estimated: zeros, covariance zero (ROS: unknown)."""
        s = self.settings
        q = matrix_to_quat_xyzw(e.n_R_b)
        b_v, twist = ros_twist_covariance(e.n_R_b, e.n_v, e.pose_cov, e.vel_cov, e.pose_vel_cross)
        return messages.odometry(
            np.array([self.stamp_ns(e.t)]),
            np.reshape(e.n_p, (1, 3)),
            q.reshape(1, 4),
            b_v.reshape(1, 3),
            np.zeros((1, 3)),
            ros_pose_covariance(e.n_R_b, e.pose_cov).reshape(1, 6, 6),
            twist.reshape(1, 6, 6),
            frame_id=s.map_frame,
            child_frame_id=s.base_frame,
        ).tobytes()

    def calibration_rows(self, e: OnlineEstimate) -> np.ndarray:
        """(len(CALIBRATION_ROWS), 2) [value, sigma] in the rows' units: the stamp (s since the Unix epoch, sigma 0),
        scale, misalignment (roll, pitch, yaw of R_c, deg), time offset (s; sigma nan when not estimated),
        accelerometer bias (micro-g) and gyro bias (deg/h)."""
        assert e.b_R_d0 is not None
        rpy, cov = misalignment_rpy_and_cov(e.b_R_d, e.b_R_d0, e.b_R_d_cov)
        sig = np.sqrt(np.clip(np.diag(e.bias_cov), 0.0, None))
        values = np.r_[
            self.stamp_ns(e.t) * 1e-9,
            e.scale,
            rpy,
            e.time_offset_s,
            e.accel_bias / UG,
            e.gyro_bias / DEG_PER_H,
        ]
        sigmas = np.r_[
            0.0,
            e.scale_sigma,
            np.sqrt(np.clip(np.diag(cov), 0.0, None)),
            e.time_offset_sigma_s,
            sig[:3] / UG,
            sig[3:] / DEG_PER_H,
        ]
        return np.column_stack([values, sigmas])

    def path_message(self) -> bytes | None:
        """nav_msgs/msg/Path of the states so far (thinned: PosePath), None before the first."""
        if not self.path.stamps_ns:
            return None
        return self.path.payload(self.path.stamps_ns[-1])

    def sensor_t(self) -> float:
        """The node's sensor time (s): the IMU's newest stamp released to the estimator, a reorder window behind
        the newest received. The verdicts are judged there, on the messages released in stamp order, so that they
        do not depend on the order the executor hands the topics' messages over in: a node behind its inputs takes
        the few pings queued before the many IMU samples queued with them (measured: pings 30 s of stamps ahead of
        the IMU at a 20x replay), and judged on the newest received, a DVL silence was over before it began."""
        return self._released_t("imu")

    def _released_t(self, kind: str) -> float:
        n = self.buffer.streams[kind].released_ns
        return math.nan if n is None or self.t0_ns is None else self._t(n)

    def live_state(self, wall: float | None = None) -> LiveState:
        """The snapshot the diagnostics judge (analysis/live_health.py)."""
        wall = self.clock() if wall is None else wall
        now = self.sensor_t()
        streams = {}
        for kind, topic in self.topics.items():
            if not topic:
                continue
            st = self.buffer.streams[kind]
            jump = st.last_jump_ns
            since_jump = math.inf if jump is None or self.t0_ns is None else now - self._t(jump)
            streams[kind] = StreamState(
                topic,
                st.received,
                now - self._released_t(kind),
                st.late,
                st.duplicates,
                self.off_clock[kind],
                st.jumps,
                st.largest_jump_s,
                since_jump,
            )
        imu = self.buffer.streams["imu"]
        est = self.estimator
        phase = (
            "waiting_origin"
            if self.frame is None
            else "running"
            if est is not None and est.epochs > 0
            else "aligning"
        )
        no_lock = 0.0
        if math.isfinite(self.last_ping_t) and not self.last_ping_t == self.last_valid_ping_t:
            since = self.last_valid_ping_t if math.isfinite(self.last_valid_ping_t) else 0.0
            no_lock = self.last_ping_t - since
        imu_silent = max(0.0, wall - imu.last_wall) if imu.received else math.inf
        return LiveState(
            phase="stopped" if self.stop_error else phase,
            streams=streams,
            imu_wall_silent_s=imu_silent,
            no_lock_s=no_lock,
            stop_error=self.stop_error,
            since_stop_s=now - self.stop_t if self.stop_error else math.inf,
            counters=dict(est.counters) if est is not None else {},
            epochs=est.epochs if est is not None else 0,
            t=now,
        )

    def health(self, wall: float | None = None) -> Health:
        """The verdict now (analysis/live_health.py assess_live) with the settings' thresholds."""
        s = self.settings
        return assess_live(
            self.live_state(wall),
            LiveThresholds(
                s.dvl_silent_warn_s,
                s.dvl_silent_degraded_s,
                s.bottom_lock_degraded_s,
                s.imu_silent_s,
            ),
        )

    def key_values(self) -> dict[str, str]:
        """The figures beside the verdict in the diagnostics: its sensor time (sensor_t_s), the latest estimate
        (t_s, its time, and its values with sigmas) and each input's counts."""
        out: dict[str, str] = {"sensor_t_s": f"{self.sensor_t():.3f}"}  # the verdict's time
        e = self.latest
        if e is not None:
            rows = self.calibration_rows(e)
            out["t_s"] = f"{e.t:.3f}"
            for name, (v, sg) in zip(CALIBRATION_ROWS[1:], rows[1:], strict=True):
                out[name] = f"{v:.6g} +- {sg:.3g}"
            out["position_sigma_m"] = " ".join(
                f"{x:.3g}" for x in np.sqrt(np.clip(np.diag(e.pose_cov)[3:], 0, None))
            )
        if self.settings.calibration_out:
            w = self.calibration_writes
            out["calibration_out"] = self._keep_error or (
                f"written {len(w)} times, last with the estimate of t = {w[-1][0]:.1f} s"
                if w
                else "not written yet (after the first estimate)"
            )
        if self.estimator is not None:
            out["epochs"] = str(self.estimator.epochs)
            out.update(
                {f"counter {k}": str(v) for k, v in sorted(self.estimator.counters.items()) if v}
            )
        for kind, topic in self.topics.items():
            if topic:
                counts = {
                    **self.buffer.streams[kind].as_dict(),
                    "other_clock": self.off_clock[kind],
                    "undecodable": self.undecodable[kind],
                }
                out[f"input {topic}"] = (
                    ", ".join(f"{k} {v}" for k, v in counts.items() if v) or "nothing received"
                )
        return out

    def save_calibration(self, path: Path | str) -> VehicleCalibration:
        """Write the vehicle's calibration as estimated so far to path (io/calibration_file.py, the file of `smooth
        --calibration-out`, with the estimator's report as smooth --mode online gives it: estimators/online
        run_result); its source names this node and its start, after the prior file's sources. Each write's
        estimate time and duration are kept (calibration_writes)."""
        from gtsam_dvl.estimators.online import run_result

        start = time.perf_counter()
        est = self.estimator
        if est is None or est.epochs == 0 or self.t0_ns is None:
            raise GtsamDvlError(
                "no estimate yet: the calibration is saved once the estimator has made a state"
            )
        result = run_result(est, self.config, self.t0_ns)
        vehicle = (
            self.settings.vehicle
            or (self.prior.vehicle if self.prior is not None else "")
            or self.settings.node_name
        )
        earlier = self.prior.sources if self.prior is not None else ()
        source = SourceLog(f"ros2 node {self.settings.node_name} from {iso_date(self.t0_ns)}", "")
        cal = from_result(result, self.config, vehicle, sources=(*earlier, source))
        write_calibration(path, cal)
        t = self.latest.t if self.latest is not None else math.nan
        self.calibration_writes.append((float(t), time.perf_counter() - start))
        return cal

    def timing_records(self) -> list[dict[str, Any]]:
        """The per-epoch timings (EpochTiming) as dicts, for stats_file."""
        return [
            {
                "t": r.t,
                "stamp_ns": self.stamp_ns(r.t),
                "arrived": r.arrived,
                "done": r.done,
                "processing_s": r.processing_s,
                "published": r.published,
                "trigger_kind": r.trigger[0],
                "trigger_ns": r.trigger[1],
            }
            for r in self.timings
        ]
