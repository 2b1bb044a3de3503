"""Live view in Foxglove: the online estimator's state served on a Foxglove WebSocket as it is computed.

`LiveView` starts a Foxglove WebSocket server (the foxglove-sdk package, an optional extra: `pip install
gtsam-dvl[live]`) and publishes what an `OnlineEstimator` gives after each DVL epoch; `replay_log` drives a log
through the estimator at X times real time and publishes as it goes (`gtsam-dvl live LOG`). A user's own loop
attaches the view the same way (examples/live_view.py):

    view = LiveView(port=8765)                      # ws://127.0.0.1:8765, open in Foxglove
    if estimator.push_dvl(t, d_v, d_cov):           # an epoch was completed
        view.publish_epoch(estimator.estimate(), counters=estimator.counters)
    view.close()

Topics (log time = the log's t0_ns + t; the same frames as the result MCAP, docs/conventions.md):

- `/tf` (cdr, tf2_msgs/msg/TFMessage): map -> base_link, the estimated pose. `/tf_static`: base_link -> imu_link,
  dvl_link (the nominal mounting), re-sent with the path (a client may connect late).
- `/gtsam_dvl/odometry` (cdr, nav_msgs/msg/Odometry): the pose with its marginal covariance (ROS order, map axes)
  and the body velocity with its covariance; `/gtsam_dvl/path` (cdr, nav_msgs/msg/Path): the path so far, each
  state as estimated when it was processed.
- `/gtsam_dvl/live/scale`, `.../misalignment_deg` (roll, pitch, yaw of R_c, deg, body FLU, ZYX),
  `.../time_offset_s` (dt_d; estimated = false: held at 0), `.../imu_bias` (accelerometer micro-g, gyro deg/h per
  axis, imu_link): JSON, each value as {value, sigma, lower = value - sigma, upper = value + sigma}.
- `/gtsam_dvl/live/status` (JSON): epochs published, the estimator's counters, the last epoch's latency, wall time,
  real-time factor. `/gtsam_dvl/live/log` (foxglove.Log): the health warnings and notes (the log's checks at the
  start, the run's at the end), dropped messages, each counter when it first appears.
- `/raw/imu` (gyro rad/s, specific force m/s^2, imu_link), `/raw/dvl` (d_v m/s in dvl_link, its sigmas, valid),
  `/raw/depth` (m below the surface, pressure Pa): JSON, the input messages as pushed.
- `/ground_truth/odometry`, `/ground_truth/path` (cdr): the simulated truth at the epochs, when the log has it.

Every JSON value is in SI or the unit its name says; a value without a sigma (not estimated, no covariance) is
null, so the Plot panel leaves a gap instead of drawing a wrong band. The path is re-sent at most once per
`path_period_s` of wall time (a 6-hour mission's path is 20000 poses: re-sent each epoch it would be O(N^2)),
thinned to at most `MAX_PATH_POSES` poses. Raw messages are encoded only while a client subscribes to them.

The layout `layouts/gtsam_dvl_live.json` (written by `layout()`) shows these topics: a 3-D panel following
base_link in map with the path, the odometry's covariance and the truth; Plot panels of the calibration and the
biases with their sigma bands; a Log panel and a Raw Messages panel of the status.
"""

from __future__ import annotations

import json
import math
import socket
import threading
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, skew
from gtsam_dvl.core.types import LogData, Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG

if TYPE_CHECKING:
    from gtsam_dvl.estimators.online import OnlineEstimate, OnlineEstimator

INSTALL_HINT = "the live view needs the foxglove-sdk package: pip install 'gtsam-dvl[live]'"
DEFAULT_PORT = 8765
MAX_PATH_POSES = 5000
# messages buffered per client before the oldest is dropped (the SDK's default is 1024): an epoch is about ten
# messages, and at full speed a few hundred epochs may be computed while a client is busy drawing
BACKLOG_MESSAGES = 8192
TOPICS = {
    "tf": "/tf",
    "tf_static": "/tf_static",
    "odometry": "/gtsam_dvl/odometry",
    "path": "/gtsam_dvl/path",
    "scale": "/gtsam_dvl/live/scale",
    "misalignment": "/gtsam_dvl/live/misalignment_deg",
    "time_offset": "/gtsam_dvl/live/time_offset_s",
    "imu_bias": "/gtsam_dvl/live/imu_bias",
    "status": "/gtsam_dvl/live/status",
    "log": "/gtsam_dvl/live/log",
    "imu": "/raw/imu",
    "dvl": "/raw/dvl",
    "depth": "/raw/depth",
    "truth": "/ground_truth/odometry",
    "truth_path": "/ground_truth/path",
}


def import_foxglove() -> Any:
    """The foxglove module, or GtsamDvlError with how to install it."""
    try:
        import foxglove
        import foxglove.websocket  # noqa: F401
    except ImportError:
        raise GtsamDvlError(INSTALL_HINT) from None
    return foxglove


# ----- JSON schemas ------------------------------------------------------------------------------------------

def _number(description: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": description}


def _band(unit: str) -> dict[str, Any]:
    """A value with its sigma and the band value -+ sigma (null when unknown)."""
    return {"type": "object", "properties": {
        "value": _number(f"estimate, {unit}"), "sigma": _number(f"marginal 1-sigma, {unit}"),
        "lower": _number(f"value - sigma, {unit}"), "upper": _number(f"value + sigma, {unit}")}}


def _object(title: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "type": "object",
            "properties": {"t_s": _number("log time of the epoch, s since the log's t0"),
                           "final": {"type": "boolean", "description": "after finish(): the final estimate"},
                           **properties}}


def _axes(unit: str, names: tuple[str, ...] = ("x", "y", "z")) -> dict[str, Any]:
    return {"type": "object", "properties": {n: _band(unit) for n in names}}


SCHEMAS: dict[str, dict[str, Any]] = {
    "scale": _object("gtsam_dvl.live.Scale", _band("DVL scale factor (1 = perfect)")["properties"]),
    "misalignment": _object("gtsam_dvl.live.MisalignmentDeg", _axes("deg", ("roll", "pitch", "yaw"))["properties"]),
    "time_offset": _object("gtsam_dvl.live.TimeOffset", {
        **_band("s (dt_d > 0: the DVL's stamps are early)")["properties"],
        "estimated": {"type": "boolean", "description": "false: not estimated, held at 0"}}),
    "imu_bias": _object("gtsam_dvl.live.ImuBias", {"accel_ug": _axes("micro-g, imu_link"),
                                                    "gyro_deg_per_h": _axes("deg/h, imu_link")}),
    "status": _object("gtsam_dvl.live.Status", {
        "epochs": {"type": "integer"}, "counters": {"type": "object", "additionalProperties": {"type": "integer"}},
        "latency_ms": _number("the last epoch's update, ms"), "wall_s": _number("wall time since the start, s"),
        "real_time_factor": _number("log seconds per wall second so far")}),
    "imu": {"title": "gtsam_dvl.live.Imu", "type": "object", "properties": {
        "t_s": _number("s"), "b_omega_rad_s": _axes("rad/s, imu_link"),
        "b_f_m_s2": _axes("specific force, m/s^2, imu_link")}},
    "dvl": {"title": "gtsam_dvl.live.Dvl", "type": "object", "properties": {
        "t_s": _number("s"), "valid": {"type": "boolean"}, "d_v_m_s": _axes("m/s, dvl_link"),
        "sigma_m_s": _axes("m/s, from the message's covariance (null: none)"),
        "speed_m_s": _number("norm of d_v, m/s")}},
    "depth": {"title": "gtsam_dvl.live.Depth", "type": "object", "properties": {
        "t_s": _number("s"), "depth_m": _number("m below the surface, positive down"),
        "pressure_pa": _number("absolute pressure, Pa (null: a depth topic)")}},
}


def _num(x: float) -> float | None:
    """A JSON number, None (null) for NaN or infinity (JSON has neither)."""
    x = float(x)
    return x if math.isfinite(x) else None


def band(value: float, sigma: float) -> dict[str, float | None]:
    """{value, sigma, lower, upper} with lower/upper = value -+ sigma (null where unknown)."""
    ok = math.isfinite(value) and math.isfinite(sigma)
    return {"value": _num(value), "sigma": _num(sigma), "lower": _num(value - sigma) if ok else None,
            "upper": _num(value + sigma) if ok else None}


def _xyz(v: np.ndarray, sigma: np.ndarray | None = None, names: tuple[str, ...] = ("x", "y", "z")) -> dict[str, Any]:
    if sigma is None:
        return {n: _num(v[k]) for k, n in enumerate(names)}
    return {n: band(float(v[k]), float(sigma[k])) for k, n in enumerate(names)}


def _sqrt_diag(P: np.ndarray) -> np.ndarray:
    d = np.diag(np.asarray(P, dtype=float))
    return np.sqrt(np.where(d >= 0, d, np.nan))


# ----- ROS 2 CDR payloads ------------------------------------------------------------------------------------

def _ros_schema(foxglove: Any, type_name: str) -> Any:
    from gtsam_dvl.io.ros2.msgdefs import full_definition

    return foxglove.Schema(name=type_name, encoding="ros2msg", data=full_definition(type_name).encode())


def odometry_cdr(stamp_ns: int, n_p: np.ndarray, n_q_b: np.ndarray, b_v: np.ndarray, b_omega: np.ndarray,
                 pose_cov: np.ndarray, twist_cov: np.ndarray, frame_id: str = "map",
                 child_frame_id: str = "base_link") -> bytes:
    """One nav_msgs/msg/Odometry in little-endian CDR; covariances (6, 6) in ROS order."""
    from gtsam_dvl.io.ros2 import cdr

    arr = cdr.new_messages(cdr.ODOMETRY, {"frame_id": frame_id, "child_frame_id": child_frame_id}, 1)
    cdr.set_stamps(arr, np.array([stamp_ns]))
    arr["position"], arr["orientation"] = n_p, n_q_b
    arr["linear"], arr["angular"] = b_v, b_omega
    arr["pose_covariance"] = np.asarray(pose_cov, dtype=float).reshape(36)
    arr["twist_covariance"] = np.asarray(twist_cov, dtype=float).reshape(36)
    return arr.tobytes()


def tf_cdr(transforms: list[tuple[int, str, str, np.ndarray, np.ndarray]]) -> bytes:
    """tf2_msgs/msg/TFMessage: (stamp_ns, parent, child, parent_p_child (3,), parent_q_child [x, y, z, w])."""
    from gtsam_dvl.io.ros2 import cdr

    w = cdr.CdrWriter()
    w.u32(len(transforms))
    for ns, parent, child, p, q in transforms:
        w.stamp(ns)
        w.string(parent)
        w.string(child)
        w.f64(np.concatenate([p, q]))
    return bytes(w.buf)


def path_cdr(stamp_ns: int, stamps_ns: np.ndarray, n_p: np.ndarray, n_q_b: np.ndarray, frame_id: str = "map") -> bytes:
    """nav_msgs/msg/Path stamped stamp_ns holding the poses (PoseStamped at stamps_ns[k])."""
    from gtsam_dvl.io.ros2 import cdr

    w = cdr.CdrWriter()
    w.stamp(stamp_ns)
    w.string(frame_id)
    w.u32(len(stamps_ns))
    for k in range(len(stamps_ns)):
        w.stamp(int(stamps_ns[k]))
        w.string(frame_id)
        w.f64(np.concatenate([n_p[k], n_q_b[k]]))
    return bytes(w.buf)


def ros_covariances(estimate: OnlineEstimate) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(b_v, pose covariance in ROS order [trans_map, rot_map], twist covariance of (b_v, b_omega) in base_link,
    angular block zero = unknown), as io/result_writer.py converts GTSAM's tangents for the result MCAP."""
    from gtsam_dvl.io.result_writer import ros_pose_covariance

    R = estimate.n_R_b
    b_v = R.T @ estimate.n_v
    pose_ros = ros_pose_covariance(R[None], estimate.pose_cov[None])[0]
    # b_v = R^T n_v: d b_v = [b_v]x d theta_body + R^T d n_v
    J = np.hstack([skew(b_v), np.zeros((3, 3)), R.T])
    joint = np.zeros((9, 9))
    joint[:6, :6], joint[6:, 6:] = estimate.pose_cov, estimate.vel_cov
    joint[:6, 6:], joint[6:, :6] = estimate.pose_vel_cross, estimate.pose_vel_cross.T
    twist = np.zeros((6, 6))
    twist[:3, :3] = J @ joint @ J.T
    return b_v, pose_ros, twist


# ----- the view ----------------------------------------------------------------------------------------------

def _wait_port_free(host: str, port: int, timeout_s: float = 2.0) -> None:
    """WebSocketServer.stop() returns before the listening socket is closed: wait until a new server could bind
    the port (SO_REUSEADDR, as servers bind), at most timeout_s."""
    deadline = time.monotonic() + timeout_s
    while True:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((host, port))
                return
            except OSError:
                if time.monotonic() > deadline:
                    return
        time.sleep(0.01)


class _Subscriptions:
    """ServerListener counting the channels clients subscribe to (wait_for_subscribers)."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.topics: dict[str, int] = {}

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.cond:
            self.topics[channel.topic] = self.topics.get(channel.topic, 0) + 1
            self.cond.notify_all()

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self.cond:
            self.topics[channel.topic] = max(0, self.topics.get(channel.topic, 0) - 1)
            self.cond.notify_all()


@dataclass
class _Path:
    stamps_ns: list[int] = field(default_factory=list)
    n_p: list[np.ndarray] = field(default_factory=list)
    n_q_b: list[np.ndarray] = field(default_factory=list)
    sent_wall: float = -math.inf

    def add(self, ns: int, p: np.ndarray, q: np.ndarray) -> None:
        self.stamps_ns.append(ns)
        self.n_p.append(np.asarray(p, dtype=float))
        self.n_q_b.append(np.asarray(q, dtype=float))

    def payload(self, stamp_ns: int) -> bytes:
        n = len(self.stamps_ns)
        keep: Any = np.unique(np.append(np.arange(0, n, max(1, math.ceil(n / MAX_PATH_POSES))), n - 1)) if n else []
        return path_cdr(stamp_ns, np.asarray(self.stamps_ns)[keep], np.asarray(self.n_p)[keep],
                        np.asarray(self.n_q_b)[keep])


class LiveView:
    """Publishes an online estimator's epochs, the raw messages and the truth on a Foxglove WebSocket (module
    doc for the topics). port: start a server on host:port (0: a free port, see .port); or server: a
    foxglove WebSocketServer the caller started, with the context it was started with (None: the SDK's global
    context). t0_ns: the ROS time of t = 0 (LogData.t0_ns). mounting: the nominal mounting, sent on /tf_static
    and used for the misalignment angles. path_period_s: the least wall time between two path messages."""

    def __init__(self, port: int | None = DEFAULT_PORT, *, host: str = "127.0.0.1", server: Any = None,
                 context: Any = None, t0_ns: int = 0, mounting: Mounting | None = None,
                 path_period_s: float = 1.0, name: str = "gtsam-dvl") -> None:
        fg = import_foxglove()
        from foxglove.channels import LogChannel
        from foxglove.websocket import Capability

        self._fg = fg
        self.t0_ns = int(t0_ns)
        self.mounting = mounting or Mounting()
        self.path_period_s = float(path_period_s)
        self._listener = _Subscriptions()
        self._owns_server = server is None
        if server is None:
            if port is None or not 0 <= int(port) <= 65535:
                raise GtsamDvlError(f"live view: port must be 0-65535 (0: any free port), got {port}")
            context = fg.Context()
            try:
                server = fg.start_server(name=name, host=host, port=int(port), context=context,
                                         capabilities=[Capability.Time], server_listener=self._listener,
                                         message_backlog_size=BACKLOG_MESSAGES)
            except Exception as exc:  # the SDK raises its own error types (address in use, bad host)
                raise GtsamDvlError(f"live view: cannot serve on {host}:{port} ({exc})") from None
        self.server = server
        self.host = host
        self._context = context  # the channels live as long as their context: keep it
        self._closed = False
        self._wall0 = time.monotonic()
        self._last_t: float | None = None
        self._broadcast_ns = -1
        self._first_t: float | None = None
        self._counters: dict[str, int] = {}
        self._path, self._truth_path = _Path(), _Path()
        ch: dict[str, Any] = {}
        self._channels = ch
        for key in ("tf", "tf_static"):
            ch[key] = fg.Channel(TOPICS[key], schema=_ros_schema(fg, "tf2_msgs/msg/TFMessage"), message_encoding="cdr",
                                 context=context)
        for key in ("odometry", "truth"):
            ch[key] = fg.Channel(TOPICS[key], schema=_ros_schema(fg, "nav_msgs/msg/Odometry"), message_encoding="cdr",
                                 context=context)
        for key in ("path", "truth_path"):
            ch[key] = fg.Channel(TOPICS[key], schema=_ros_schema(fg, "nav_msgs/msg/Path"), message_encoding="cdr",
                                 context=context)
        for key, schema in SCHEMAS.items():
            ch[key] = fg.Channel(TOPICS[key], schema=schema, context=context)
        self._log = LogChannel(TOPICS["log"], context=context)

    # ----- server --------------------------------------------------------------------------------------------
    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self.server.port)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def wait_for_subscribers(self, topics: list[str] | None = None, timeout_s: float = 10.0) -> bool:
        """Block until a client subscribes to every topic of topics (None: to any topic), at most timeout_s.
        Returns whether it did (a replay started before would be missed by the client). Only for a server this
        view started (the subscriptions are seen through its listener): with server= it returns False."""
        deadline = time.monotonic() + timeout_s
        with self._listener.cond:
            while True:
                subs = self._listener.topics
                if (all(subs.get(t, 0) > 0 for t in topics) if topics else any(subs.values())):
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._listener.cond.wait(left)

    def close(self) -> None:
        """Stop the server (if this view started it) and free its port."""
        if self._closed:
            return
        self._closed = True
        if self._owns_server:
            port = self.port
            self.server.stop()
            _wait_port_free(self.host, port)
        else:  # the caller's server goes on: unadvertise this view's channels
            for channel in self._channels.values():
                channel.close()
            self._log.close()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ----- publishing ----------------------------------------------------------------------------------------
    def stamp_ns(self, t: float) -> int:
        """Log time of t (s since t0_ns), ns."""
        return self.t0_ns + round(float(t) * 1e9)

    def _tick(self, t: float, broadcast: bool = False) -> int:
        """The stamp of t; broadcast: tell the clients the log time (Foxglove's clock), once per epoch (a time
        message per IMU batch would crowd the clients' control queue)."""
        ns = self.stamp_ns(t)
        if self._last_t is None or t > self._last_t:
            self._last_t = float(t)
        if broadcast and ns > self._broadcast_ns:
            self._broadcast_ns = ns
            self.server.broadcast_time(ns)
        if self._first_t is None:
            self._first_t = float(t)
        return ns

    def publish_epoch(self, estimate: OnlineEstimate, *, counters: dict[str, int] | None = None,
                      latency_s: float | None = None, final: bool = False) -> None:
        """One epoch's estimate (OnlineEstimator.estimate()): tf, odometry with covariance, the path, scale,
        misalignment, time offset and biases with their sigmas, and the status with the estimator's counters
        (new counters also go to the log channel). final: the estimate after finish()."""
        t = float(estimate.t)
        ns = self._tick(t, broadcast=True)
        q = matrix_to_quat_xyzw(estimate.n_R_b)
        ch = self._channels
        ch["tf"].log(tf_cdr([(ns, "map", "base_link", estimate.n_p, q)]), log_time=ns)
        b_v, pose_ros, twist_ros = ros_covariances(estimate)
        ch["odometry"].log(odometry_cdr(ns, estimate.n_p, q, b_v, np.zeros(3), pose_ros, twist_ros), log_time=ns)
        if not final:
            self._path.add(ns, estimate.n_p, q)
        self._send_paths(ns, force=final)
        head = {"t_s": t, "final": final}
        ch["scale"].log({**head, **band(estimate.scale, estimate.scale_sigma)}, log_time=ns)
        rpy, cov = misalignment_rpy_and_cov(estimate.b_R_d, self.mounting.b_R_d0, estimate.b_R_d_cov)
        ch["misalignment"].log({**head, **_xyz(rpy, _sqrt_diag(cov), ("roll", "pitch", "yaw"))}, log_time=ns)
        estimated = math.isfinite(estimate.time_offset_sigma_s)
        ch["time_offset"].log({**head, **band(estimate.time_offset_s, estimate.time_offset_sigma_s),
                               "estimated": estimated}, log_time=ns)
        sig = _sqrt_diag(estimate.bias_cov)
        ch["imu_bias"].log({**head, "accel_ug": _xyz(estimate.accel_bias / UG, sig[:3] / UG),
                            "gyro_deg_per_h": _xyz(estimate.gyro_bias / DEG_PER_H, sig[3:] / DEG_PER_H)}, log_time=ns)
        if counters is not None:
            self._publish_counters(t, ns, counters)
        wall = time.monotonic() - self._wall0
        span = t - (self._first_t if self._first_t is not None else t)
        ch["status"].log({**head, "epochs": len(self._path.stamps_ns), "counters": dict(self._counters),
                          "latency_ms": None if latency_s is None else _num(latency_s * 1e3), "wall_s": wall,
                          "real_time_factor": _num(span / wall) if wall > 0 and span > 0 else None}, log_time=ns)

    def _publish_counters(self, t: float, ns: int, counters: dict[str, int]) -> None:
        for name, n in counters.items():
            if name not in self._counters and n:
                self.log("info", f"counter {name}: {n} at t = {t:.1f} s", t)
        self._counters = dict(counters)

    def _send_paths(self, ns: int, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._path.sent_wall < self.path_period_s:
            return
        self._path.sent_wall = now
        if self._path.stamps_ns:
            self._channels["path"].log(self._path.payload(ns), log_time=ns)
        if self._truth_path.stamps_ns:
            self._channels["truth_path"].log(self._truth_path.payload(ns), log_time=ns)
        m = self.mounting
        self._channels["tf_static"].log(tf_cdr([
            (ns, "base_link", "imu_link", m.b_p_imu, matrix_to_quat_xyzw(m.b_R_imu)),
            (ns, "base_link", "dvl_link", m.b_p_dvl, matrix_to_quat_xyzw(m.b_R_d0))]), log_time=ns)

    def log(self, level: str, message: str, t: float | None = None) -> None:
        """A line on the log channel; level "debug", "info", "warning", "error" or "fatal"."""
        from foxglove.messages import Log, LogLevel, Timestamp

        t = self._last_t if t is None else t
        ns = self.stamp_ns(t) if t is not None else time.time_ns()
        levels = {"debug": LogLevel.Debug, "info": LogLevel.Info, "warning": LogLevel.Warning,
                  "error": LogLevel.Error, "fatal": LogLevel.Fatal}
        self._log.log(Log(timestamp=Timestamp(ns // 1_000_000_000, ns % 1_000_000_000), level=levels[level],
                          message=message, name="gtsam-dvl"), log_time=ns)

    def publish_health(self, health: Any, t: float | None = None) -> None:
        """An analysis.health.Health: its status, each warning (level warning) and note (level info)."""
        level = {"ok": "info", "degraded": "warning", "failed": "error"}.get(health.status, "warning")
        self.log(level, f"health: {health.status}", t)
        for w in health.warnings:
            self.log("warning", w, t)
        for n in health.notes:
            self.log("info", n, t)

    def publish_imu(self, t: np.ndarray, b_omega: np.ndarray, b_f: np.ndarray) -> None:
        """IMU samples (N,), (N, 3) rad/s, (N, 3) m/s^2 in imu_link, as pushed (only while subscribed)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if len(t):
            self._tick(float(t[-1]))
        channel = self._channels["imu"]
        if not channel.has_sinks():
            return
        w, f = np.reshape(b_omega, (-1, 3)), np.reshape(b_f, (-1, 3))
        for k in range(len(t)):
            channel.log({"t_s": float(t[k]), "b_omega_rad_s": _xyz(w[k]), "b_f_m_s2": _xyz(f[k])},
                        log_time=self.stamp_ns(t[k]))

    def publish_dvl(self, t: float, d_v: np.ndarray, d_cov: np.ndarray | None = None, valid: bool = True) -> None:
        """A DVL ping: d_v (m/s, dvl_link), its covariance (3, 3) or None, valid flag."""
        ns = self._tick(t)
        channel = self._channels["dvl"]
        if not channel.has_sinks():
            return
        d_v = np.asarray(d_v, dtype=float)
        sigma = _sqrt_diag(d_cov) if d_cov is not None else np.full(3, np.nan)
        channel.log({"t_s": float(t), "valid": bool(valid), "d_v_m_s": _xyz(d_v), "sigma_m_s": _xyz(sigma),
                     "speed_m_s": _num(float(np.linalg.norm(d_v)))}, log_time=ns)

    def publish_depth(self, t: float, depth_m: float, pressure_pa: float | None = None) -> None:
        """A depth sample: m below the surface (positive down) and the absolute pressure (Pa) if measured."""
        ns = self._tick(t)
        channel = self._channels["depth"]
        if channel.has_sinks():
            channel.log({"t_s": float(t), "depth_m": _num(depth_m),
                         "pressure_pa": None if pressure_pa is None else _num(pressure_pa)}, log_time=ns)

    def publish_truth(self, t: float, n_p: np.ndarray, n_q_b: np.ndarray, n_v: np.ndarray,
                      b_omega: np.ndarray | None = None) -> None:
        """The true pose of base_link in map (quaternion [x, y, z, w]) and velocity (m/s, map) at t."""
        ns = self._tick(t)
        from gtsam_dvl.core.rotations import quat_xyzw_to_matrix

        b_v = quat_xyzw_to_matrix(np.asarray(n_q_b, dtype=float)).T @ np.asarray(n_v, dtype=float)
        w = np.zeros(3) if b_omega is None else np.asarray(b_omega, dtype=float)
        self._channels["truth"].log(odometry_cdr(ns, np.asarray(n_p, dtype=float), np.asarray(n_q_b, dtype=float),
                                                 b_v, w, np.zeros((6, 6)), np.zeros((6, 6))), log_time=ns)
        self._truth_path.add(ns, n_p, n_q_b)


# ----- replay ------------------------------------------------------------------------------------------------

def parse_speed(text: str | float) -> float:
    """--speed: a positive factor of real time; 0, "max" or "inf": as fast as possible (math.inf)."""
    if isinstance(text, str) and text.strip().lower() in ("max", "inf", "0"):
        return math.inf
    try:
        speed = float(text)
    except ValueError:
        raise GtsamDvlError(f"--speed must be a number (times real time) or 'max', got {text!r}") from None
    if speed == 0 or speed == math.inf:
        return math.inf
    if not speed > 0:
        raise GtsamDvlError(f"--speed must be > 0 (times real time) or 'max', got {text!r}")
    return speed


@dataclass
class ReplayOutcome:
    """What replay_log did: the estimator (its result() and counters), epochs published, wall and log time (s)."""

    estimator: OnlineEstimator
    epochs_published: int
    wall_s: float
    log_s: float
    health: Any = None  # analysis.health.Health of the run (replay_log with health=True and an epoch)

    def describe(self) -> str:
        rate = f"{self.log_s / self.wall_s:.1f}x real time" if self.wall_s > 0 else "-"
        return (f"replayed {self.log_s:.0f} s of log in {self.wall_s:.1f} s ({rate}), {self.epochs_published} "
                f"epochs published, {self.estimator.epochs} states")


def replay_log(log: LogData, view: LiveView, estimator: OnlineEstimator | None = None, *, speed: float = math.inf,
               step_s: float = 0.1, health: bool = True, stop: threading.Event | None = None,
               clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
               ) -> ReplayOutcome:
    """Push a log's messages through the online estimator in feed_log's order (the IMU samples up to each ping,
    then the depth samples up to it, then the ping; the rest; finish()), publishing each message as it is pushed
    and each epoch as it is completed (the estimate after the push, the latest when a push completes several),
    then the final estimate. speed: times real time (math.inf: as fast as possible); with a finite speed the IMU
    goes in pieces of step_s log seconds, each pushed when the wall clock reaches its last stamp. health: the
    log's health checks at the start and the run's (analysis/health.py assess_health) at the end on the log
    channel. stop: set to end the replay early (finish() is still called). estimator None:
    OnlineEstimator.for_log(log)."""
    from gtsam_dvl.estimators.online import MessageDropped, OnlineEstimator

    if not (speed > 0):
        raise GtsamDvlError(f"replay speed must be > 0 (math.inf: as fast as possible), got {speed}")
    est = estimator if estimator is not None else OnlineEstimator.for_log(log)
    imu, dvl, depth, truth = log.imu, log.dvl, log.depth, log.truth
    if len(imu) == 0:
        raise GtsamDvlError(f"{log.source or 'log'}: no IMU samples to replay")
    if health:
        from gtsam_dvl.analysis.health import assess_log_health

        view.publish_health(assess_log_health(log), float(imu.t[0]))
    t_first = float(min(imu.t[0], dvl.t[0] if len(dvl) else imu.t[0]))
    wall0 = clock()
    published = 0
    run_health = None

    def pace(t: float) -> None:
        if math.isfinite(speed):
            wait = wall0 + (t - t_first) / speed - clock()
            if wait > 0:
                sleep(wait)

    def epoch_done(n: int) -> None:
        nonlocal published
        e = est.estimate()
        if n and e is not None:
            view.publish_epoch(e, counters=est.counters, latency_s=est.latencies_s[-1] if est.latencies_s else None)
            published += 1
            if truth is not None and len(truth):
                k = min(int(np.searchsorted(truth.t, e.t)), len(truth) - 1)
                if k > 0 and abs(truth.t[k - 1] - e.t) < abs(truth.t[k] - e.t):
                    k -= 1
                view.publish_truth(float(truth.t[k]), truth.n_p[k], truth.n_q_b[k], truth.n_v[k], truth.b_omega[k])

    def push_imu(a: int, b: int) -> None:
        step = len(imu) if not math.isfinite(speed) else max(1, int(np.searchsorted(imu.t, imu.t[a] + step_s) - a))
        for s in range(a, b, step):
            e = min(b, s + step)
            pace(float(imu.t[e - 1]))
            n = est.push_imu_batch(imu.t[s:e], imu.b_omega[s:e], imu.b_f[s:e])
            view.publish_imu(imu.t[s:e], imu.b_omega[s:e], imu.b_f[s:e])
            epoch_done(n)

    def push_depth(k: int) -> None:
        assert depth is not None
        pace(float(depth.t[k]))
        pa = None if depth.pressure_pa is None else float(depth.pressure_pa[k])
        if pa is not None:
            var = math.nan if depth.pressure_variance_pa2 is None else float(depth.pressure_variance_pa2[k])
            est.push_depth(float(depth.t[k]), pressure_pa=pa, pressure_variance_pa2=var)
        else:
            est.push_depth(float(depth.t[k]), float(depth.depth_m[k]), float(depth.variance_m2[k]))
        view.publish_depth(float(depth.t[k]), float(depth.depth_m[k]), pa)

    ends = np.searchsorted(imu.t, dvl.t, side="right")
    start, k, n_depth = 0, 0, 0 if depth is None else len(depth)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MessageDropped)
        seen = 0
        for j in range(len(dvl)):
            if stop is not None and stop.is_set():
                break
            end = int(ends[j])
            if end > start:
                push_imu(start, end)
                start = end
            while depth is not None and k < n_depth and depth.t[k] <= dvl.t[j]:
                push_depth(k)
                k += 1
            beams = None if dvl.beams is None else (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
            pace(float(dvl.t[j]))
            n = est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]), beams)
            view.publish_dvl(float(dvl.t[j]), dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
            epoch_done(n)
            for w in caught[seen:]:
                view.log("warning", str(w.message), float(dvl.t[j]))
            seen = len(caught)
        if stop is None or not stop.is_set():
            while depth is not None and k < n_depth:
                push_depth(k)
                k += 1
            if start < len(imu):
                push_imu(start, len(imu))
        final = est.finish()
        for w in caught[seen:]:
            view.log("warning", str(w.message))
    if final is not None:
        view.publish_epoch(final, counters=est.counters, final=True)
        published += 1
        if health:
            from gtsam_dvl.analysis.health import assess_health

            run_health = assess_health(est.result(log.t0_ns), log)
            view.publish_health(run_health, final.t)
    elif health:
        view.log("error", f"{log.source or 'log'}: no DVL epoch was processed (nothing to estimate)")
    return ReplayOutcome(est, published, clock() - wall0, float(imu.t[-1] - t_first), run_health)


def serve_log(log_path: Path, *, speed: str | float = 1.0, port: int = DEFAULT_PORT, host: str = "127.0.0.1",
              config_path: Path | None = None, read_options: dict[str, Any] | None = None, wait: bool = False,
              linger: bool = True, echo: Callable[[str], None] = print) -> ReplayOutcome:
    """`gtsam-dvl live`: read the log, serve the view on host:port, replay the log through the online estimator at
    speed (parse_speed), print the outcome and the run's health; then, with linger, keep serving until Ctrl-C.
    wait: start the replay only once a client subscribes. The foxglove package is checked before anything else."""
    import_foxglove()
    factor = parse_speed(speed)
    from gtsam_dvl.app.commands import load_log
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.estimators.online import OnlineEstimator

    config = EstimatorConfig.load(config_path) if config_path else None
    log = load_log(log_path, **(read_options or {}))
    config = config or EstimatorConfig.for_log(log.metadata)
    estimator = OnlineEstimator.for_log(log, config)
    with LiveView(port, host=host, t0_ns=log.t0_ns, mounting=log.mounting) as view:
        echo(f"live view on {view.url}: in Foxglove, Open connection > Foxglove WebSocket > {view.url}, and "
             "Layouts > Import from file > layouts/gtsam_dvl_live.json")
        outcome: ReplayOutcome | None = None
        try:
            if wait:
                echo("waiting for a client to subscribe (Ctrl-C to stop)")
                while not view.wait_for_subscribers(timeout_s=1.0):
                    pass
            pace = "as fast as possible" if math.isinf(factor) else f"at {factor:g}x real time"
            echo(f"replaying {Path(log_path).name} {pace} through the online estimator "
                 f"({estimator.options.mode.replace('_', '-')})")
            outcome = replay_log(log, view, estimator, speed=factor)
            echo(outcome.describe())
            if outcome.health is not None:
                echo("\n".join(outcome.health.lines()))
            if linger:
                echo(f"replay done; still serving on {view.url} (Ctrl-C to stop)")
                while True:
                    time.sleep(0.5)
        except KeyboardInterrupt:
            echo("live view stopped")
    return outcome or ReplayOutcome(estimator, 0, 0.0, 0.0)


# ----- layout ------------------------------------------------------------------------------------------------

def _series(topic: str, field_path: str, label: str, color: str, dashed: bool = False) -> dict[str, Any]:
    s: dict[str, Any] = {"value": f"{topic}.{field_path}", "enabled": True, "timestampMethod": "receiveTime",
                         "label": label, "color": color, "showLine": True}
    if dashed:
        s["lineSize"] = 0.75
    return s


def _band_series(topic: str, path: str, label: str, color: str) -> list[dict[str, Any]]:
    return [_series(topic, f"{path}value", label, color),
            _series(topic, f"{path}lower", f"{label} - sigma", color, dashed=True),
            _series(topic, f"{path}upper", f"{label} + sigma", color, dashed=True)]


def _plot(title: str, y_label: str, paths: list[dict[str, Any]]) -> dict[str, Any]:
    return {"paths": paths, "title": title, "yAxisLabel": y_label, "showLegend": True, "legendDisplay": "floating",
            "showXAxisLabels": True, "showYAxisLabels": True, "isSynced": True, "xAxisVal": "timestamp",
            "sidebarDimension": 240}


AXIS_COLORS = ("#e6194b", "#3cb44b", "#4363d8")


def layout() -> dict[str, Any]:
    """The Foxglove layout of layouts/gtsam_dvl_live.json (Layouts > Import from file): a 3-D panel following
    base_link in map with the estimated path, odometry covariance and truth; Plot panels of scale,
    misalignment, time offset and biases, each series drawn with its value - sigma and value + sigma; a Log
    panel of the health and a Raw Messages panel of the status."""
    T = TOPICS
    three_d = {
        "followTf": "base_link", "followMode": "follow-position",
        "cameraState": {"distance": 80, "perspective": True, "phi": 55, "thetaOffset": 30, "target": [0, 0, 0],
                        "targetOffset": [0, 0, 0], "targetOrientation": [0, 0, 0, 1], "fovy": 45, "near": 0.5,
                        "far": 20000},
        "scene": {"enableStats": False, "transforms": {"showLabel": True, "axisScale": 2}},
        "transforms": {"frame:map": {"visible": True}, "frame:base_link": {"visible": True}},
        "topics": {
            T["odometry"]: {"visible": True, "type": "arrow", "showCovariance": True, "covarianceColor": "#ff8c0055",
                            "color": "#ff8c00ff", "arrowScale": [4, 0.6, 0.6]},
            T["path"]: {"visible": True, "type": "line", "lineWidth": 0.4, "gradient": ["#ff8c00ff", "#ff8c00ff"]},
            T["truth"]: {"visible": True, "type": "arrow", "color": "#00b4ffff", "arrowScale": [4, 0.6, 0.6]},
            T["truth_path"]: {"visible": True, "type": "line", "lineWidth": 0.3,
                              "gradient": ["#00b4ffff", "#00b4ffff"]},
        },
        "layers": {"grid": {"visible": True, "frameLocked": False, "label": "Grid (10 m)", "instanceId": "grid",
                            "layerId": "foxglove.Grid", "frameId": "map", "size": 2000, "divisions": 200,
                            "lineWidth": 1, "color": "#248eff40", "position": [0, 0, 0], "rotation": [0, 0, 0],
                            "order": 1}},
        "publish": {"type": "point", "poseTopic": "/move_base_simple/goal", "pointTopic": "/clicked_point",
                    "poseEstimateTopic": "/initialpose", "poseEstimateXDeviation": 0.5,
                    "poseEstimateYDeviation": 0.5, "poseEstimateThetaDeviation": 0.26179939},
        "imageMode": {},
    }
    axes = ("x", "y", "z")
    config_by_id: dict[str, Any] = {
        "3D!live": three_d,
        "Plot!scale": _plot("DVL scale (+- 1 sigma)", "scale factor (1 = perfect)",
                            _band_series(T["scale"], "", "scale", "#ff8c00")),
        "Plot!misalignment": _plot("DVL misalignment (+- 1 sigma)", "angle (deg)", [
            s for name, c in zip(("roll", "pitch", "yaw"), AXIS_COLORS, strict=True)
            for s in _band_series(T["misalignment"], f"{name}.", name, c)]),
        "Plot!time_offset": _plot("DVL time offset (+- 1 sigma)", "dt_d (s)",
                                  _band_series(T["time_offset"], "", "time offset", "#911eb4")),
        "Plot!accel_bias": _plot("Accelerometer bias (+- 1 sigma)", "bias (micro-g)", [
            s for a, c in zip(axes, AXIS_COLORS, strict=True) for s in _band_series(T["imu_bias"], f"accel_ug.{a}.",
                                                                                     a, c)]),
        "Plot!gyro_bias": _plot("Gyro bias (+- 1 sigma)", "bias (deg/h)", [
            s for a, c in zip(axes, AXIS_COLORS, strict=True)
            for s in _band_series(T["imu_bias"], f"gyro_deg_per_h.{a}.", a, c)]),
        "RosOut!health": {"searchTerms": [], "minLogLevel": 1, "topicToRender": T["log"]},
        "RawMessages!status": {"topicPath": T["status"], "diffEnabled": False, "diffMethod": "custom",
                               "diffTopicPath": "", "showFullMessageForDiff": False, "expansion": "all"},
    }
    plots = {"first": {"first": "Plot!scale", "second": "Plot!misalignment", "direction": "column",
                       "splitPercentage": 50},
             "second": {"first": {"first": "Plot!time_offset", "second": "Plot!accel_bias", "direction": "column",
                                  "splitPercentage": 50},
                        "second": "Plot!gyro_bias", "direction": "column", "splitPercentage": 66},
             "direction": "column", "splitPercentage": 40}
    left = {"first": "3D!live", "second": {"first": "RosOut!health", "second": "RawMessages!status",
                                           "direction": "row", "splitPercentage": 60},
            "direction": "column", "splitPercentage": 70}
    return {"configById": config_by_id, "globalVariables": {}, "userNodes": {}, "playbackConfig": {"speed": 1},
            "layout": {"first": left, "second": plots, "direction": "row", "splitPercentage": 55}}


def layout_json() -> str:
    """layout() as the text of layouts/gtsam_dvl_live.json."""
    return json.dumps(layout(), indent=2) + "\n"


if __name__ == "__main__":  # pragma: no cover
    import sys

    if sys.argv[1:] == ["--write-layout"]:  # regenerate layouts/gtsam_dvl_live.json from layout()
        out = Path(__file__).resolve().parents[2] / "layouts" / "gtsam_dvl_live.json"
        out.parent.mkdir(exist_ok=True)
        out.write_text(layout_json())
        print(out)
    else:
        sys.exit("usage: python -m gtsam_dvl.app.live --write-layout")
