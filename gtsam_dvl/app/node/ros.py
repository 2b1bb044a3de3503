"""The rclpy side of the node: subscriptions, publishers, the save service and the timer around a NodeCore.

Every input is a raw subscription (rclpy hands over the serialized CDR body): NodeCore decodes it with the reader's
layouts, which is also faster than building a Python message object per IMU sample. Odometry and Path go out as
bytes from io/ros2/messages.py, the encoders of the result logs; the calibration (std_msgs/Float64MultiArray) and
the diagnostics (diagnostic_msgs/DiagnosticArray) are built as rclpy messages (a few per second).

No exception leaves a callback (rclpy would end the spin with it): each is one log line, the first of its kind in
full and then counted, and the node goes on. The timer runs on the steady clock, so use_sim_time without a /clock
does not stop the diagnostics.
"""

from __future__ import annotations

import importlib
import json
import math
import os
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from gtsam_dvl.app.node.core import CALIBRATION_ROWS, NodeCore
from gtsam_dvl.core.errors import GtsamDvlError

INSTALL_HINT = (
    "gtsam-dvl node needs ROS 2's rclpy and message packages (wheels from PyPI, no system ROS): "
    "pip install 'gtsam-dvl[ros2]'"
)
# diagnostic_msgs/DiagnosticStatus levels of the health verdicts: OK, WARN, ERROR (degraded: the estimate goes on
# but is not to be trusted at its stated accuracy; failed: no estimate or a stopped estimator)
LEVELS = {"ok": 0, "warn": 1, "degraded": 2, "failed": 2}
DIAGNOSTIC_NAME = "gtsam_dvl: navigation"
# the verdict is checked this often in sensor time (as the IMU comes) and published when it changes, besides the
# estimates and the wall-time timer: a stall shows within this of its threshold, at any replay rate
CHECK_EVERY_S = 0.5


def import_ros() -> Any:
    """rclpy, or GtsamDvlError with how to install it (the message packages are checked with it)."""
    try:
        import rclpy

        importlib.import_module("sensor_msgs.msg")
        importlib.import_module("nav_msgs.msg")
        importlib.import_module("diagnostic_msgs.msg")
        importlib.import_module("std_srvs.srv")
    except ImportError as exc:
        raise GtsamDvlError(f"{INSTALL_HINT} ({exc.name or exc} is missing)") from None
    return rclpy


def message_class(type_name: str) -> Any:
    """The rclpy class of "pkg/msg/Type", None when its package is not importable."""
    pkg, kind, name = type_name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    except (ImportError, AttributeError):
        return None


# the wait for acknowledgements looks at the stop signals this often
ACK_SLICE_S = 0.1
# Reliable publishers' heartbeat period (Fast DDS's default: 3 s). DDS repairs a message a subscriber missed (its
# reception starved of CPU on a loaded machine) only once the publisher's heartbeat announces it, and acknowledges
# only then: with 3 s, a missed DVL ping reached the node seconds after the IMU samples that followed it (20 s of log
# time at a 20x replay, fed out of order), and waiting for the acknowledgements of the last messages took seconds.
HEARTBEAT_S = 0.01
# Fast DDS's default profile for a process's publishers (rmw_fastrtps reads it when DDS starts)
PROFILES_VARIABLE = "FASTDDS_DEFAULT_PROFILES_FILE"
PUBLISHER_PROFILE = f"""<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <data_writer profile_name="gtsam_dvl_publishers" is_default_profile="true">
      <times>
        <heartbeat_period><sec>0</sec><nanosec>{round(HEARTBEAT_S * 1e9)}</nanosec></heartbeat_period>
      </times>
    </data_writer>
  </profiles>
</dds>
"""


@contextmanager
def fast_repairs() -> Iterator[None]:
    """Around the creation of a process's first node (rmw_fastrtps starts DDS then): Fast DDS's publishers with a
    heartbeat every HEARTBEAT_S, by a default profile it reads then; none when the user gives profiles of their own
    (PROFILES_VARIABLE, or Fast DDS 2's name), and none in a process whose DDS started before. Other DDS
    implementations ignore it."""
    if os.environ.get(PROFILES_VARIABLE) or os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE"):
        yield
        return
    with tempfile.TemporaryDirectory(prefix="gtsam_dvl_dds_") as folder:
        profile = Path(folder) / "publishers.xml"
        profile.write_text(PUBLISHER_PROFILE)
        os.environ[PROFILES_VARIABLE] = str(profile)
        try:
            yield
        finally:
            del os.environ[PROFILES_VARIABLE]


def wait_for_acknowledgements(
    publishers: Iterable[Any], timeout_s: float, hurry: Callable[[], bool] | None = None
) -> bool:
    """Wait until every reliable subscriber acknowledged every message of these publishers, at most timeout_s in all:
    a publisher destroyed earlier takes the messages a lagging subscriber has not received with it. In slices of
    ACK_SLICE_S (rmw's wait blocks signal handlers), ended early when hurry() turns True. Whether all were."""
    from rclpy.duration import Duration

    deadline = time.monotonic() + timeout_s
    waiting = list(publishers)
    while waiting and not (hurry is not None and hurry()):
        left = deadline - time.monotonic()
        if left <= 0:
            break
        slice_s = Duration(seconds=min(left, ACK_SLICE_S))
        waiting = [p for p in waiting if not p.wait_for_all_acked(slice_s)]
    return not waiting


def qos(reliability: str, depth: int, latched: bool = False) -> Any:
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=ReliabilityPolicy.RELIABLE
        if reliability == "reliable"
        else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )


class RosNode:
    """A NodeCore on an rclpy node (module doc). node: the rclpy Node (made by run.py with the parameters)."""

    def __init__(self, node: Any, core: NodeCore) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from nav_msgs.msg import Odometry
        from nav_msgs.msg import Path as PathMsg
        from rclpy.clock import Clock, ClockType
        from std_msgs.msg import Float64MultiArray
        from std_srvs.srv import Trigger

        self.node, self.core = node, core
        s = core.settings
        self._errors: dict[str, int] = {}
        self.callbacks = 0  # callbacks run (run.py drain: until a spin runs none)
        self._last_status: str | None = None
        self._checked_t = -math.inf  # sensor time of the last check of the verdict
        self._path_wall = -math.inf
        core.log = self.say
        inputs = qos(s.qos_inputs.reliability, s.qos_inputs.depth)
        self.subscriptions = []
        for kind, topic in core.topics.items():
            if not topic:
                continue
            cls = message_class(core.types[kind])
            if cls is None:
                raise GtsamDvlError(
                    f"{topic}: {core.types[kind]} has no Python package here (marine_acoustic_msgs "
                    "has no wheel on PyPI): choose dvl_type TwistWithCovarianceStamped or "
                    "TwistStamped, or install the package"
                )
            self.subscriptions.append(
                node.create_subscription(cls, topic, self._callback(kind), inputs, raw=True)
            )
        tf = message_class("tf2_msgs/msg/TFMessage") if s.tf_static_topic else None
        if tf is not None:
            self.subscriptions.append(
                node.create_subscription(
                    tf,
                    s.tf_static_topic,
                    self._guard("tf_static", core.receive_tf),
                    qos("reliable", 100, latched=True),
                    raw=True,
                )
            )
        else:
            core.log(
                "info",
                "tf2_msgs is not importable (no wheel on PyPI): the mounting comes from the parameters "
                "(imu_rpy_deg, dvl_rpy_deg, ...), not /tf_static",
            )
        out = qos(s.qos_outputs.reliability, s.qos_outputs.depth)
        self.odometry = node.create_publisher(Odometry, s.odometry_topic, out)
        self.calibration = (
            node.create_publisher(
                Float64MultiArray,
                s.calibration_topic,
                qos(s.qos_outputs.reliability, 1, latched=True),
            )
            if s.calibration_topic
            else None
        )
        self.diagnostics = (
            node.create_publisher(DiagnosticArray, s.diagnostics_topic, out)
            if s.diagnostics_topic
            else None
        )
        self.path = (
            node.create_publisher(PathMsg, s.path_topic, out)
            if s.path_topic and s.path_period_s
            else None
        )
        self.save_service = node.create_service(
            Trigger, "~/save_calibration", self._guard("save", self._save)
        )
        self.timer = node.create_timer(
            s.diagnostics_period_s,
            self._guard("timer", self._tick),
            clock=Clock(clock_type=ClockType.STEADY_TIME),
        )

    def publishers(self) -> list[Any]:
        """The node's output publishers (Odometry, calibration, diagnostics, Path; those turned off left out)."""
        return [
            p
            for p in (self.odometry, self.calibration, self.diagnostics, self.path)
            if p is not None
        ]

    def say(self, level: str, text: str) -> None:
        """A line on the node's logger at level "info", "warn" or "error" (rclpy wants one severity per call site:
        one call each)."""
        logger = self.node.get_logger()
        if level == "error":
            logger.error(text)
        elif level == "warn":
            logger.warning(text)
        else:
            logger.info(text)

    # ----- callbacks -----------------------------------------------------------------------------------------
    def _guard(self, what: str, fn: Callable[..., Any]) -> Callable[..., Any]:
        """fn with every exception made one log line (the first of each kind in full, then counted)."""

        def call(*args: Any) -> Any:
            self.callbacks += 1
            try:
                return fn(*args)
            except Exception as exc:  # noqa: BLE001  (module doc: no exception ends the node)
                key = f"{what}: {type(exc).__name__}"
                n = self._errors[key] = self._errors.get(key, 0) + 1
                if n == 1 or n % 1000 == 0:
                    self.say(
                        "error",
                        f"{what}: {type(exc).__name__}: {exc}".splitlines()[0]
                        + (f" ({n} times)" if n > 1 else ""),
                    )
                # a service callback returns its response
                return args[-1] if what == "save" else None

        return call

    def _callback(self, kind: str) -> Callable[[bytes], None]:
        core = self.core

        def take(body: bytes) -> None:
            for e in core.receive(kind, body, time.monotonic()):
                self.publish(e)
            # (nan: never checked)
            if kind == "imu" and not core.sensor_t() - self._checked_t < CHECK_EVERY_S:
                self._checked_t = core.sensor_t()
                self.publish_diagnostics()

        return self._guard(kind, take)

    # (rclpy passes a TimerInfo to a callback that takes arguments)
    def _tick(self, *_: Any) -> None:
        for e in self.core.tick(time.monotonic()):
            self.publish(e)
        self.publish_diagnostics(force=True)
        if (
            self.path is not None
            and time.monotonic() - self._path_wall >= self.core.settings.path_period_s
        ):
            self._path_wall = time.monotonic()
            if (body := self.core.path_message()) is not None:
                self.path.publish(body)

    def _save(self, request: Any, response: Any) -> Any:
        path = self.core.settings.calibration_out
        if not path:
            response.success, response.message = (
                False,
                "no calibration_out parameter: set the file to write",
            )
            return response
        try:
            cal = self.core.save_calibration(path)
        except (GtsamDvlError, OSError) as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success = True
        response.message = f"wrote {path}: {', '.join(cal.states)} of {cal.vehicle}"
        self.core.log("info", response.message)
        return response

    # ----- publishing ----------------------------------------------------------------------------------------
    def publish(self, e: Any, final: bool = False) -> None:
        """One estimate: Odometry first (the latency that counts), then the calibration and, on a change of
        verdict, the diagnostics."""
        self.odometry.publish(self.core.odometry(e))
        if (
            self.core.timings
            and self.core.timings[-1].t == float(e.t)
            and math.isnan(self.core.timings[-1].published)
        ):
            self.core.timings[-1].published = time.monotonic()
        if self.calibration is not None:
            self.calibration.publish(self.calibration_message(e))
        self.publish_diagnostics(force=final)

    def calibration_message(self, e: Any) -> Any:
        """std_msgs/Float64MultiArray: rows CALIBRATION_ROWS x columns [value, sigma] (docs/ros2.md); the first
        dimension's label names the rows, the second's the columns."""
        from std_msgs.msg import Float64MultiArray, MultiArrayDimension, MultiArrayLayout

        rows = self.core.calibration_rows(e)
        msg = Float64MultiArray()
        msg.layout = MultiArrayLayout(
            dim=[
                MultiArrayDimension(
                    label=",".join(CALIBRATION_ROWS), size=rows.shape[0], stride=rows.size
                ),
                MultiArrayDimension(label="value,sigma", size=2, stride=2),
            ],
            data_offset=0,
        )
        msg.data = [float(x) for x in rows.ravel()]
        return msg

    def publish_diagnostics(self, force: bool = False) -> None:
        """The verdict (analysis/live_health.py) as one DiagnosticStatus: at once when it changes, else with
        force (the timer)."""
        if self.diagnostics is None:
            return
        health = self.core.health(time.monotonic())
        if not force and health.status == self._last_status:
            return
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

        self._last_status = health.status
        first = health.warnings[0] if health.warnings else (health.notes[0] if health.notes else "")
        values = {"status": health.status}
        values.update({f"warning {i + 1}": w for i, w in enumerate(health.warnings)})
        values.update({f"note {i + 1}": n for i, n in enumerate(health.notes)})
        values.update(self.core.key_values())
        status = DiagnosticStatus(
            level=bytes([LEVELS[health.status]]),
            name=DIAGNOSTIC_NAME,
            message=f"{health.status}: {first}" if first else health.status,
            hardware_id=self.core.settings.node_name,
            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
        )
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.node.get_clock().now().to_msg()
        self.diagnostics.publish(msg)

    # ----- shutdown ------------------------------------------------------------------------------------------
    def shutdown(self, finish: bool = True) -> None:
        """finish() and the final estimate published (finish and finish_on_shutdown), the calibration file written
        (calibration_out), the timings written (stats_file): each its own try, so one failing leaves the others;
        each failure one log line."""
        s, core = self.core.settings, self.core
        if finish and s.finish_on_shutdown:
            try:
                final = core.finish()
                if final is not None:
                    self.publish(final, final=True)
                    core.log("info", f"final estimate at t = {final.t:.2f} s published")
            except Exception as exc:  # noqa: BLE001
                core.log("error", f"finish: {type(exc).__name__}: {exc}".splitlines()[0])
        if s.calibration_out:
            try:
                cal = core.save_calibration(s.calibration_out)
                core.log(
                    "info",
                    f"wrote {s.calibration_out}: {', '.join(cal.states)} of {cal.vehicle} "
                    f"({len(core.calibration_writes)} writes)",
                )
            except Exception as exc:  # noqa: BLE001
                text = (
                    str(exc) if isinstance(exc, GtsamDvlError) else f"{type(exc).__name__}: {exc}"
                )
                core.log("error", f"calibration_out: {text}".splitlines()[0])
        if s.stats_file:
            try:
                Path(s.stats_file).write_text(
                    json.dumps(
                        {
                            "node": s.node_name,
                            "timings": core.timing_records(),
                            "calibration_writes": list(core.calibration_writes),
                        }
                    )
                )
            except OSError as exc:
                core.log("error", f"stats_file: {exc}")
