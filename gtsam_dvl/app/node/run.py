"""`gtsam-dvl node`: read the settings, start rclpy, spin the node until SIGINT or SIGTERM, then stop within a
bounded time.

The signals are the node's own, installed here (Stop): rclpy's handlers are off (SignalHandlerOptions.NO: they would
shut the ROS context down before the node could publish its final estimate), and Python leaves SIGINT ignored in a
process that a shell script started in the background (such a node would never hear Ctrl-C). The first signal ends
the spin loop; the stop then goes through bounded phases: the messages already received are processed (until none
is waiting, at most DRAIN_MAX_S: sensors that go on publishing are not waited for), the estimator's finish(), the
final estimate, calibration_out and stats_file (RosNode.shutdown), the subscribers' acknowledgements of the final
messages (at most DELIVER_MAX_S), and the ROS context closed. A second signal cuts it short: nothing more
processed, no finish(), no wait for acknowledgements; calibration_out is still written. Whatever a phase is doing
(an estimator call cannot be interrupted from Python), the kernel ends the process STOP_MAX_S after the first signal
(SIGALRM, exit status 142; calibration_out then holds its last write while running, core.py). The phases' times are
one log line.
"""

from __future__ import annotations

import atexit
import gc
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from gtsam_dvl.app.node.ros import RosNode, fast_repairs, import_ros, wait_for_acknowledgements
from gtsam_dvl.app.node.settings import load_settings
from gtsam_dvl.core.errors import GtsamDvlError

# at a stop: the messages already received processed for at most DRAIN_MAX_S, the subscribers' acknowledgements of
# the final messages awaited for at most DELIVER_MAX_S, the process ended by the kernel STOP_MAX_S after the signal
DRAIN_MAX_S = 5.0
DELIVER_MAX_S = 5.0
STOP_MAX_S = 30


class Stop:
    """SIGINT and SIGTERM as counted by the handler (module doc): the first requests the stop and arms the kernel's
    alarm, the second hurries it."""

    def __init__(self) -> None:
        self.signals = 0

    @property
    def requested(self) -> bool:
        return self.signals > 0

    @property
    def hurry(self) -> bool:
        return self.signals > 1

    def __call__(self, signum: int, frame: object) -> None:
        # only counts: the spin loop and the phases look, so no exception lands inside a callback half done
        self.signals += 1
        if self.signals == 1:
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.alarm(STOP_MAX_S)


@contextmanager
def stop_signals() -> Iterator[Stop]:
    """SIGINT and SIGTERM counted by a Stop while the node runs, the previous handlers back after it. Outside the
    main thread (where Python cannot install handlers: a test's node, stopped by `until`) a Stop nothing signals."""
    stop = Stop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    previous = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def drain(executor: Any, ros: RosNode, stop: Stop) -> int:
    """Process what DDS already delivered (a node behind a fast replay has a backlog) before finishing: until a spin
    finds nothing waiting, so that sensors publishing on are not waited for; at most DRAIN_MAX_S, nothing more once
    a second signal came. Returns the number of callbacks run."""
    end = time.monotonic() + DRAIN_MAX_S
    first = ros.callbacks
    while not stop.hurry and time.monotonic() < end:
        before = ros.callbacks
        executor.spin_once(timeout_sec=0.0)
        if ros.callbacks == before:
            break
    return ros.callbacks - first


def stop_node(executor: Any, ros: RosNode, stop: Stop) -> None:
    """The stop's phases (module doc), their times in one log line."""
    t0 = time.monotonic()
    n = drain(executor, ros, stop)
    t1 = time.monotonic()
    ros.shutdown(finish=not stop.hurry)
    t2 = time.monotonic()
    acked = wait_for_acknowledgements(ros.publishers(), DELIVER_MAX_S, lambda: stop.hurry)
    t3 = time.monotonic()
    ros.say(
        "info",
        f"stopped in {t3 - t0:.2f} s: {n} callbacks waiting run in {t1 - t0:.2f} s, finish and files "
        f"{t2 - t1:.2f} s, acknowledgements {t3 - t2:.2f} s"
        + ("" if acked else " (not all acknowledged)")
        + (" (cut short by a second signal)" if stop.hurry else ""),
    )


def new_executor(context: Any) -> Any:
    """rclpy's EventsExecutor (its dispatch in C++: about 20 us of CPU per message against 170 us for the
    SingleThreadedExecutor, measured on 10,000 IMU messages), else the SingleThreadedExecutor."""
    try:
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    except ImportError:
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)


def ros_arguments(
    params_file: Path | None, ros_args: Sequence[str] = (), name: str | None = None
) -> list[str]:
    """The arguments rclpy.init takes: --ros-args with the parameter file, the node's name and the caller's own
    ROS arguments (remappings, -p name:=value)."""
    args = ["--ros-args"]
    if params_file is not None:
        if not Path(params_file).is_file():
            raise GtsamDvlError(f"{params_file}: no such parameter file")
        args += ["--params-file", str(params_file)]
    if name:
        args += ["-r", f"__node:={name}"]
    extra = list(ros_args)
    if extra[:1] == ["--ros-args"]:
        extra = extra[1:]
    return args + extra


def make_node(
    context: Any,
    config: Path | str | None,
    params_file: Path | None,
    calibration: Path | None,
    name: str | None,
) -> RosNode:
    """The rclpy node with its parameters (from the context's arguments) and its NodeCore: the settings, the
    estimator's configuration and the prior calibration file read."""
    from rclpy.node import Node

    from gtsam_dvl.app.node.core import NodeCore

    with fast_repairs():  # DDS starts with the context's first node
        node = Node(
            name or "gtsam_dvl",
            context=context,
            allow_undeclared_parameters=True,
            automatically_declare_parameters_from_overrides=True,
        )
    try:
        params = {k: p.value for k, p in node.get_parameters_by_prefix("").items()}
        source = str(params_file) if params_file is not None else "parameters"
        settings, cfg = load_settings(config, params, source=source)
        settings = settings.model_copy(update={"node_name": node.get_name()})
        prior = None
        path = calibration or (Path(settings.calibration) if settings.calibration else None)
        if path is not None:
            from gtsam_dvl.io.calibration_file import read_calibration

            prior = read_calibration(path)
            if settings.vehicle and prior.vehicle and settings.vehicle != prior.vehicle:
                raise GtsamDvlError(
                    f"{path}: a calibration of vehicle {prior.vehicle!r}, not of {settings.vehicle!r}"
                )
        return RosNode(node, NodeCore(settings, cfg, calibration=prior))
    except BaseException:
        node.destroy_node()
        raise


def run_node(
    config: Path | str | None = None,
    params_file: Path | None = None,
    ros_args: Sequence[str] = (),
    calibration: Path | None = None,
    name: str | None = None,
    domain_id: int | None = None,
    echo: Callable[[str], None] = print,
    until: Callable[[], bool] | None = None,
) -> None:
    """Run the node (module doc). config: -c (TOML with [node], a configuration's name); params_file: a ROS
    parameter file (YAML); ros_args: further ROS arguments; calibration: a vehicle's calibration file as the prior
    (the parameter `calibration` otherwise); until: stop when it returns True (tests). After a stop signal the
    kernel's alarm stays armed past the return (module doc): this is the command's last act."""
    rclpy = import_ros()
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    # at the interpreter's exit its objects are frozen: its garbage collections over the libraries' objects
    # (scipy, gtsam, rclpy) took 1.7 s of the node's exit, 3 s on a loaded machine; frozen, 0.2 s
    atexit.register(gc.freeze)
    args = ros_arguments(params_file, ros_args, name)
    context = rclpy.Context()
    rclpy.init(
        args=args,
        context=context,
        domain_id=domain_id,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    with stop_signals() as stop:
        try:
            ros = make_node(context, config, params_file, calibration, name)
            try:
                s = ros.core.settings
                echo(
                    f"gtsam-dvl node {ros.node.get_fully_qualified_name()}: IMU {s.imu_topic}, DVL "
                    f"{s.dvl_topic} ({s.dvl_type.rsplit('/', 1)[-1]}), odometry on {s.odometry_topic} "
                    f"({s.map_frame} -> {s.base_frame}); Ctrl-C to stop"
                )
                executor = new_executor(context)
                executor.add_node(ros.node)
                try:
                    while (
                        context.ok() and not stop.requested and not (until is not None and until())
                    ):
                        executor.spin_once(timeout_sec=0.1)
                except (KeyboardInterrupt, ExternalShutdownException):
                    pass  # (Ctrl-C outside the main thread; the context shut down by another): stop below
                if context.ok():
                    stop_node(executor, ros, stop)
            finally:
                ros.node.destroy_node()
        finally:
            if context.ok():
                rclpy.shutdown(context=context)
