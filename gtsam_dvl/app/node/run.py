"""`gtsam-dvl node`: read the settings, start rclpy, spin the node until Ctrl-C or SIGTERM, then finish.

rclpy's own signal handlers are off (SignalHandlerOptions.NO): they would shut the ROS context down before the node
could publish its final estimate. Ctrl-C arrives as KeyboardInterrupt and SIGTERM as the command line's Terminated
(app/cli_options.py), both in the spin loop; the node then finishes (RosNode.shutdown), waits until its subscribers
acknowledged the final messages (ros.py wait_for_acknowledgements), and closes.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from gtsam_dvl.app.cli_options import Terminated
from gtsam_dvl.app.node.ros import RosNode, fast_repairs, import_ros, wait_for_acknowledgements
from gtsam_dvl.app.node.settings import load_settings
from gtsam_dvl.core.errors import GtsamDvlError

# after the final messages, before the context closes: at most this long for the subscribers' acknowledgements
DELIVER_MAX_S = 5.0
# at a stop, the messages already received are processed until none came for this long
DRAIN_QUIET_S = 0.3
DRAIN_MAX_S = 10.0


def drain(executor: Any, ros: RosNode) -> None:
    """Process the messages DDS already delivered (a node behind a fast replay has a backlog) before finishing:
    until nothing new came for DRAIN_QUIET_S, at most DRAIN_MAX_S."""
    streams = ros.core.buffer.streams
    end = time.monotonic() + DRAIN_MAX_S
    count, quiet = -1, time.monotonic()
    while time.monotonic() < end and time.monotonic() - quiet < DRAIN_QUIET_S:
        executor.spin_once(timeout_sec=0.02)
        n = sum(s.received for s in streams.values())
        if n != count:
            count, quiet = n, time.monotonic()


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
    (the parameter `calibration` otherwise); until: stop when it returns True (tests)."""
    rclpy = import_ros()
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    args = ros_arguments(params_file, ros_args, name)
    context = rclpy.Context()
    rclpy.init(
        args=args,
        context=context,
        domain_id=domain_id,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    node: Any = None
    ros: RosNode | None = None
    try:
        from rclpy.node import Node

        with fast_repairs():  # DDS starts with the context's first node
            node = Node(
                name or "gtsam_dvl",
                context=context,
                allow_undeclared_parameters=True,
                automatically_declare_parameters_from_overrides=True,
            )
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
        from gtsam_dvl.app.node.core import NodeCore

        ros = RosNode(node, NodeCore(settings, cfg, calibration=prior))
        echo(
            f"gtsam-dvl node {node.get_fully_qualified_name()}: IMU {settings.imu_topic}, DVL {settings.dvl_topic} "
            f"({settings.dvl_type.rsplit('/', 1)[-1]}), odometry on {settings.odometry_topic} "
            f"({settings.map_frame} -> {settings.base_frame}); Ctrl-C to stop"
        )
        executor = new_executor(context)
        executor.add_node(node)
        try:
            while context.ok() and not (until is not None and until()):
                executor.spin_once(timeout_sec=0.1)
        except (KeyboardInterrupt, ExternalShutdownException, Terminated):
            pass  # the normal ways to stop a node: finish below
        finally:
            if context.ok():
                drain(executor, ros)
                ros.shutdown()
                wait_for_acknowledgements(ros.publishers(), DELIVER_MAX_S)
    finally:
        if node is not None:
            node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)
