"""The live view's Foxglove WebSocket server: LiveView publishes an online estimator's epochs, the raw messages
and the truth on the topics of schemas.TOPICS (the package doc lists them).

ROS 2 topics go out as CDR (io/ros2/messages.py, covariances in ROS order by io/ros2/covariance.py), the others
as JSON (schemas.py). The path is re-sent at most once per path_period_s of wall time (a 6-hour mission's path
is 20000 poses: re-sent each epoch it would be O(N^2)), thinned to at most MAX_PATH_POSES poses. Raw messages
are encoded only while a client subscribes to them.
"""

from __future__ import annotations

import math
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.app.live.schemas import SCHEMAS, TOPICS, band, num, sqrt_diag, xyz
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, quat_xyzw_to_matrix
from gtsam_dvl.core.types import Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.io.ros2 import messages
from gtsam_dvl.io.ros2.covariance import ros_pose_covariance, ros_twist_covariance
from gtsam_dvl.io.ros2.msgdefs import full_definition

if TYPE_CHECKING:
    from gtsam_dvl.estimators.online import OnlineEstimate

INSTALL_HINT = "the live view needs the foxglove-sdk package: pip install 'gtsam-dvl[live]'"
DEFAULT_PORT = 8765
MAX_PATH_POSES = 5000
# messages buffered per client before the oldest is dropped (the SDK's default is 1024): an epoch is about ten
# messages, and at full speed a few hundred epochs may be computed while a client is busy drawing
BACKLOG_MESSAGES = 8192


def import_foxglove() -> Any:
    """The foxglove module, or GtsamDvlError with how to install it."""
    try:
        import foxglove
        import foxglove.websocket  # noqa: F401
    except ImportError:
        raise GtsamDvlError(INSTALL_HINT) from None
    return foxglove


def _odometry(
    stamp_ns: int,
    n_p: np.ndarray,
    n_q_b: np.ndarray,
    b_v: np.ndarray,
    b_omega: np.ndarray,
    pose_cov: np.ndarray,
    twist_cov: np.ndarray,
) -> bytes:
    """The CDR body of one nav_msgs/msg/Odometry of base_link in map (io/ros2/messages.odometry)."""
    return messages.odometry(
        np.array([stamp_ns]),
        np.reshape(n_p, (1, 3)),
        np.reshape(n_q_b, (1, 4)),
        np.reshape(b_v, (1, 3)),
        np.reshape(b_omega, (1, 3)),
        np.reshape(pose_cov, (1, 6, 6)),
        np.reshape(twist_cov, (1, 6, 6)),
    ).tobytes()


WILDCARD_HOSTS = ("0.0.0.0", "::", "")  # serve on every interface: not an address a client can open


def ws_url(host: str, port: int) -> str:
    """ws://host:port, an IPv6 address in brackets."""
    return f"ws://[{host}]:{port}" if ":" in host else f"ws://{host}:{port}"


def _outward_address(ipv6: bool) -> str | None:
    """This machine's address on the network it routes to (the UDP socket is only connected: no packet is sent;
    the documentation prefixes of RFC 5737 / RFC 3849 as the peer), or None without a route."""
    family, peer = (socket.AF_INET6, "2001:db8::1") if ipv6 else (socket.AF_INET, "192.0.2.1")
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as s:
            s.connect((peer, 9))
            address = str(s.getsockname()[0])
    except OSError:
        return None
    return None if address.startswith("127.") or address in ("::1", "0.0.0.0", "::") else address


def reachable_urls(host: str, port: int) -> list[str]:
    """The addresses a client opens for a server on host:port: the host itself; for a wildcard host (0.0.0.0 or
    ::, every interface), this machine's loopback address, then its hostname and its address on the network for
    other machines (ws://0.0.0.0 is not an address a browser can open)."""
    if host not in WILDCARD_HOSTS:
        return [ws_url(host, port)]
    ipv6 = host == "::"
    urls = [ws_url("::1" if ipv6 else "127.0.0.1", port)]
    for name in (socket.gethostname(), _outward_address(ipv6)):
        if name and ws_url(name, port) not in urls:
            urls.append(ws_url(name, port))
    return urls


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
class PosePath:
    """The poses of one path topic so far (stamps ns, n_p m, n_q_b [x, y, z, w]) and when it was last sent (wall
    clock, s)."""

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
        keep: Any = (
            np.unique(np.append(np.arange(0, n, max(1, math.ceil(n / MAX_PATH_POSES))), n - 1))
            if n
            else []
        )
        return messages.path(
            stamp_ns,
            np.asarray(self.stamps_ns)[keep],
            np.asarray(self.n_p)[keep],
            np.asarray(self.n_q_b)[keep],
        )


@dataclass
class Progress:
    """A run's progress: the epochs published, the log time pushed (t_first to t_last, s) and the wall time it took
    (clock, s). The status topic and the console's last line (ReplayOutcome) both read it, so they give the same
    numbers. It starts at start() (replay_log: when the replay starts, after any wait for a client) or at the
    first message; finish() freezes the wall time at the final estimate."""

    clock: Callable[[], float] = time.monotonic
    wall0: float | None = None
    wall_end: float | None = None
    t_first: float | None = None
    t_last: float | None = None
    epochs: int = 0

    def start(self, t_first: float, clock: Callable[[], float] | None = None) -> float:
        """Restart at log time t_first (s) now; returns the wall clock's start."""
        if clock is not None:
            self.clock = clock
        self.wall0, self.wall_end = self.clock(), None
        self.t_first = self.t_last = float(t_first)
        self.epochs = 0
        return self.wall0

    def tick(self, t: float) -> None:
        """A message at log time t (s) was pushed."""
        if self.wall0 is None or self.t_first is None or self.t_last is None:
            self.start(t)
        else:
            self.t_first, self.t_last = min(self.t_first, float(t)), max(self.t_last, float(t))

    def finish(self) -> None:
        """Freeze the wall time (the run is over)."""
        if self.wall_end is None:
            self.wall_end = self.clock()

    @property
    def wall_s(self) -> float:
        """Wall time since start(), s (frozen by finish())."""
        if self.wall0 is None:
            return 0.0
        return (self.wall_end if self.wall_end is not None else self.clock()) - self.wall0

    @property
    def log_s(self) -> float:
        """Log time pushed, s."""
        return 0.0 if self.t_first is None or self.t_last is None else self.t_last - self.t_first

    @property
    def real_time_factor(self) -> float | None:
        """Log seconds per wall second; None before both are positive (or if not finite)."""
        wall, span = self.wall_s, self.log_s
        return num(span / wall) if wall > 0 and span > 0 else None


class LiveView:
    """Publishes an online estimator's epochs, the raw messages and the truth on a Foxglove WebSocket (the
    package doc lists the topics). port: start a server on host:port (0: a free port, see .port); or server: a
    foxglove WebSocketServer the caller started, with the context it was started with (None: the SDK's global
    context). t0_ns: the ROS time of t = 0 (LogData.t0_ns). mounting: the nominal mounting, sent on /tf_static
    and used for the misalignment angles. path_period_s: the least wall time between two path messages."""

    def __init__(
        self,
        port: int | None = DEFAULT_PORT,
        *,
        host: str = "127.0.0.1",
        server: Any = None,
        context: Any = None,
        t0_ns: int = 0,
        mounting: Mounting | None = None,
        path_period_s: float = 1.0,
        name: str = "gtsam-dvl",
    ) -> None:
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
                raise GtsamDvlError(
                    f"live view: port must be 0-65535 (0: any free port), got {port}"
                )
            context = fg.Context()
            try:
                server = fg.start_server(
                    name=name,
                    host=host,
                    port=int(port),
                    context=context,
                    capabilities=[Capability.Time],
                    server_listener=self._listener,
                    message_backlog_size=BACKLOG_MESSAGES,
                )
            # the SDK raises its own error types (address in use, bad host)
            except Exception as exc:
                raise GtsamDvlError(f"live view: cannot serve on {host}:{port} ({exc})") from None
        self.server = server
        self.host = host
        self._context = context  # the channels live as long as their context: keep it
        self._closed = False
        self.progress = Progress()  # epochs published, log and wall time: the status's numbers
        self._last_t: float | None = None
        self._broadcast_ns = -1
        self._counters: dict[str, int] = {}
        self._path, self._truth_path = PosePath(), PosePath()
        ch: dict[str, Any] = {}
        self._channels = ch
        for keys, type_name in (
            (("tf", "tf_static"), messages.TF),
            (("odometry", "truth"), messages.ODOMETRY),
            (("path", "truth_path"), messages.PATH),
        ):
            schema = fg.Schema(
                name=type_name, encoding="ros2msg", data=full_definition(type_name).encode()
            )
            for key in keys:
                ch[key] = fg.Channel(
                    TOPICS[key], schema=schema, message_encoding="cdr", context=context
                )
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
        """The address to open on this machine (for host 0.0.0.0: ws://127.0.0.1:port)."""
        return self.urls[0]

    @property
    def urls(self) -> list[str]:
        """The addresses to open: url, then, when serving on every interface, the ones for other machines
        (reachable_urls)."""
        return reachable_urls(self.host, self.port)

    def wait_for_subscribers(
        self, topics: list[str] | None = None, timeout_s: float = 10.0
    ) -> bool:
        """Block until a client subscribes to every topic of topics (None: to any topic), at most timeout_s.
        Returns whether it did (a replay started before would be missed by the client). Only for a server this
        view started (the subscriptions are seen through its listener): with server= it returns False."""
        deadline = time.monotonic() + timeout_s
        with self._listener.cond:
            while True:
                subs = self._listener.topics
                if all(subs.get(t, 0) > 0 for t in topics) if topics else any(subs.values()):
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._listener.cond.wait(left)

    def close(self) -> None:
        """Stop the server (if this view started it) and free its port. Each client gets a close frame (a normal
        closing handshake; foxglove-sdk sends it without a status code: clients report 1005)."""
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
        self.progress.tick(t)
        return ns

    def publish_epoch(
        self,
        estimate: OnlineEstimate,
        *,
        counters: dict[str, int] | None = None,
        latency_s: float | None = None,
        final: bool = False,
    ) -> None:
        """One epoch's estimate (OnlineEstimator.estimate()): tf, odometry with covariance, the path, scale,
        misalignment, time offset and biases with their sigmas, and the status with the estimator's counters
        (new counters also go to the log channel). final: the estimate after finish()."""
        t = float(estimate.t)
        ns = self._tick(t, broadcast=True)
        q = matrix_to_quat_xyzw(estimate.n_R_b)
        ch = self._channels
        ch["tf"].log(messages.tf_message([(ns, "map", "base_link", estimate.n_p, q)]), log_time=ns)
        pose_ros = ros_pose_covariance(estimate.n_R_b, estimate.pose_cov)
        b_v, twist_ros = ros_twist_covariance(
            estimate.n_R_b,
            estimate.n_v,
            estimate.pose_cov,
            estimate.vel_cov,
            estimate.pose_vel_cross,
        )
        ch["odometry"].log(
            _odometry(ns, estimate.n_p, q, b_v, np.zeros(3), pose_ros, twist_ros), log_time=ns
        )
        if not final:
            self._path.add(ns, estimate.n_p, q)
        self._send_paths(ns, force=final)
        head = {"t_s": t, "final": final}
        ch["scale"].log({**head, **band(estimate.scale, estimate.scale_sigma)}, log_time=ns)
        rpy, cov = misalignment_rpy_and_cov(
            estimate.b_R_d, self.mounting.b_R_d0, estimate.b_R_d_cov
        )
        ch["misalignment"].log(
            {**head, **xyz(rpy, sqrt_diag(cov), ("roll", "pitch", "yaw"))}, log_time=ns
        )
        estimated = math.isfinite(estimate.time_offset_sigma_s)
        ch["time_offset"].log(
            {
                **head,
                **band(estimate.time_offset_s, estimate.time_offset_sigma_s),
                "estimated": estimated,
            },
            log_time=ns,
        )
        sig = sqrt_diag(estimate.bias_cov)
        ch["imu_bias"].log(
            {
                **head,
                "accel_ug": xyz(estimate.accel_bias / UG, sig[:3] / UG),
                "gyro_deg_per_h": xyz(estimate.gyro_bias / DEG_PER_H, sig[3:] / DEG_PER_H),
            },
            log_time=ns,
        )
        if counters is not None:
            self._publish_counters(t, ns, counters)
        progress = self.progress
        progress.epochs += 1
        if final:
            progress.finish()
        ch["status"].log(
            {
                **head,
                "epochs": progress.epochs,
                "counters": dict(self._counters),
                "latency_ms": None if latency_s is None else num(latency_s * 1e3),
                "wall_s": progress.wall_s,
                "log_s": progress.log_s,
                "real_time_factor": progress.real_time_factor,
            },
            log_time=ns,
        )

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
        self._channels["tf_static"].log(
            messages.tf_message(
                [
                    (ns, "base_link", "imu_link", m.b_p_imu, matrix_to_quat_xyzw(m.b_R_imu)),
                    (ns, "base_link", "dvl_link", m.b_p_dvl, matrix_to_quat_xyzw(m.b_R_d0)),
                ]
            ),
            log_time=ns,
        )

    def log(self, level: str, message: str, t: float | None = None) -> None:
        """A line on the log channel; level "debug", "info", "warning", "error" or "fatal"."""
        from foxglove.messages import Log, LogLevel, Timestamp

        t = self._last_t if t is None else t
        ns = self.stamp_ns(t) if t is not None else time.time_ns()
        levels = {
            "debug": LogLevel.Debug,
            "info": LogLevel.Info,
            "warning": LogLevel.Warning,
            "error": LogLevel.Error,
            "fatal": LogLevel.Fatal,
        }
        self._log.log(
            Log(
                timestamp=Timestamp(ns // 1_000_000_000, ns % 1_000_000_000),
                level=levels[level],
                message=message,
                name="gtsam-dvl",
            ),
            log_time=ns,
        )

    def publish_health(self, health: Any, t: float | None = None) -> None:
        """An analysis.health.Health: its status, each warning (level warning) and note (level info)."""
        level = {"ok": "info", "warn": "warning", "degraded": "warning", "failed": "error"}.get(
            health.status, "warning"
        )
        self.log(level, f"health: {health.status}", t)
        for w in health.warnings:
            self.log("warning", w, t)
        for n in health.notes:
            self.log("info", n, t)

    def publish_imu(self, t: np.ndarray, b_omega: np.ndarray, b_f: np.ndarray) -> None:
        """IMU samples (N,), (N, 3) rad/s, (N, 3) m/s^2 in imu_link, as pushed (only while subscribed)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if len(t):
            self.progress.tick(float(t[0]))
            self._tick(float(t[-1]))
        channel = self._channels["imu"]
        if not channel.has_sinks():
            return
        w, f = np.reshape(b_omega, (-1, 3)), np.reshape(b_f, (-1, 3))
        for k in range(len(t)):
            channel.log(
                {"t_s": float(t[k]), "b_omega_rad_s": xyz(w[k]), "b_f_m_s2": xyz(f[k])},
                log_time=self.stamp_ns(t[k]),
            )

    def publish_dvl(
        self, t: float, d_v: np.ndarray, d_cov: np.ndarray | None = None, valid: bool = True
    ) -> None:
        """A DVL ping: d_v (m/s, dvl_link), its covariance (3, 3) or None, valid flag."""
        ns = self._tick(t)
        channel = self._channels["dvl"]
        if not channel.has_sinks():
            return
        d_v = np.asarray(d_v, dtype=float)
        sigma = sqrt_diag(d_cov) if d_cov is not None else np.full(3, np.nan)
        channel.log(
            {
                "t_s": float(t),
                "valid": bool(valid),
                "d_v_m_s": xyz(d_v),
                "sigma_m_s": xyz(sigma),
                "speed_m_s": num(float(np.linalg.norm(d_v))),
            },
            log_time=ns,
        )

    def publish_depth(self, t: float, depth_m: float, pressure_pa: float | None = None) -> None:
        """A depth sample: m below the surface (positive down) and the absolute pressure (Pa) if measured."""
        ns = self._tick(t)
        channel = self._channels["depth"]
        if channel.has_sinks():
            channel.log(
                {
                    "t_s": float(t),
                    "depth_m": num(depth_m),
                    "pressure_pa": None if pressure_pa is None else num(pressure_pa),
                },
                log_time=ns,
            )

    def publish_truth(
        self,
        t: float,
        n_p: np.ndarray,
        n_q_b: np.ndarray,
        n_v: np.ndarray,
        b_omega: np.ndarray | None = None,
    ) -> None:
        """The true pose of base_link in map (quaternion [x, y, z, w]) and velocity (m/s, map) at t."""
        ns = self._tick(t)
        b_v = quat_xyzw_to_matrix(np.asarray(n_q_b, dtype=float)).T @ np.asarray(n_v, dtype=float)
        w = np.zeros(3) if b_omega is None else np.asarray(b_omega, dtype=float)
        self._channels["truth"].log(
            _odometry(ns, n_p, n_q_b, b_v, w, np.zeros((6, 6)), np.zeros((6, 6))), log_time=ns
        )
        self._truth_path.add(ns, n_p, n_q_b)
