"""The ROS 2 node's tests and benchmark (bench/bench_node.py): a short simulated log whose DVL topic stops for a
while, its configuration and parameter files, the subprocess commands, the environment that keeps DDS on this
machine, and the Listener that receives what the node publishes."""

from __future__ import annotations

import dataclasses
import math
import os
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.types import BeamData, LogData
from gtsam_dvl.io.ros2.covariance import ros_pose_covariance
from tests.support.scenarios import simulate_variant

# paper-3d-short cut down: 45 s static (the online alignment's 35 s and its margin), the surge, the descent
SEGMENTS: list[dict[str, Any]] = [
    {"kind": "static", "duration_s": 45.0},
    {"kind": "level", "duration_s": 15.0, "speed_end_m_s": 2.0},
    {"kind": "level", "duration_s": 45.0, "speed_bump_m_s": 0.5},
    {"kind": "descent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
]
GAP_S = (115.0, 135.0)  # the DVL topic silent for 20 s


def without_pings(log: LogData, start: float, stop: float) -> LogData:
    """The log with the DVL pings in [start, stop) removed (the topic stops; the IMU goes on)."""
    d, b = log.dvl, log.dvl.beams
    keep = ~((d.t >= start) & (d.t < stop))
    log.dvl = dataclasses.replace(
        d,
        t=d.t[keep],
        d_v=d.d_v[keep],
        d_cov=d.d_cov[keep],
        valid=d.valid[keep],
        beams=None if b is None else BeamData(b.d_u[keep], b.v[keep], b.range[keep], b.valid[keep]),
        water_track=None if d.water_track is None else d.water_track[keep],
        altitude=None if d.altitude is None else d.altitude[keep],
    )
    return log


def gap_log(seed: int = 3, imu_hz: float = 100.0, dvl_hz: float = 2.0) -> LogData:
    """The test log: SEGMENTS at imu_hz / dvl_hz, the DVL silent over GAP_S."""
    log = simulate_variant(seed, segments=SEGMENTS, rates={"imu_hz": imu_hz, "dvl_hz": dvl_hz})
    return without_pings(log, *GAP_S)


def config_toml(log: LogData, extra: str = "") -> str:
    """The estimator configuration of the node and of the reference run: the paper's (noise as stated: a node has
    no whole log to take it from), the log's origin, water track refused (a node's "auto" uses it)."""
    assert log.origin is not None
    return (
        f'preset = "paper"\n[alignment]\norigin_lat_deg = {log.origin.lat_deg!r}\n'
        f"origin_lon_deg = {log.origin.lon_deg!r}\norigin_height_m = {log.origin.height_m!r}\n"
        f'[online]\nalign_s = 35.0\n[current]\nwater_track = "refuse"\n{extra}'
    )


def params_yaml(**settings: Any) -> str:
    """A ROS parameter file for every node (/**) with these settings (nested dicts: sub-tables)."""

    def lines(d: dict[str, Any], indent: int) -> list[str]:
        out = []
        for k, v in d.items():
            if isinstance(v, dict):
                out += [" " * indent + f"{k}:", *lines(v, indent + 2)]
            else:
                value = (
                    f'"{v}"'
                    if isinstance(v, str)
                    else str(v).lower()
                    if isinstance(v, bool)
                    else repr(v)
                )
                out.append(" " * indent + f"{k}: {value}")
        return out

    return "\n".join(["/**:", "  ros__parameters:", *lines(settings, 4)]) + "\n"


def ros_env(domain_id: int | None = None) -> dict[str, str]:
    """The environment of the node's processes: a domain of their own (no other test's or user's traffic), and DDS
    discovery on this machine only."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id if domain_id is not None else random.randint(1, 100))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def cli(*args: str | Path) -> list[str]:
    """The command line `gtsam-dvl ARGS` as this interpreter runs it."""
    return [sys.executable, "-c", "from gtsam_dvl.app.cli import main; main()", *map(str, args)]


def sigma_distance(
    p: np.ndarray, ref: np.ndarray, n_R_b: np.ndarray, pose_cov: np.ndarray
) -> float:
    """The largest per-axis difference (map axes) of position p from the reference ref, in the reference's sigmas
    (its GTSAM pose covariance turned into map axes: io/ros2/covariance.py)."""
    sig = np.sqrt(np.diag(ros_pose_covariance(n_R_b, pose_cov))[:3])
    return float(np.max(np.abs(np.asarray(p) - np.asarray(ref)) / sig))


class Listener:
    """An rclpy node of this process in the DDS domain of env (ros_env) whose subscriptions keep what arrives, each
    with its arrival time (steady clock, s), spun (spin_until) while the node and the player run in theirs."""

    def __init__(self, name: str, env: dict[str, str]) -> None:
        import rclpy
        from rclpy.node import Node

        from gtsam_dvl.app.node.run import new_executor

        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=int(env["ROS_DOMAIN_ID"]))
        self.node = Node(name, context=self.context)
        self.executor = new_executor(self.context)
        self.executor.add_node(self.node)

    def record(
        self, message_type: Any, topic: str, depth: int = 1000, raw: bool = False
    ) -> list[tuple[float, Any]]:
        """The list that (arrival time, message) pairs of topic are appended to (raw: the serialized bytes)."""
        received: list[tuple[float, Any]] = []
        self.node.create_subscription(
            message_type, topic, lambda m: received.append((time.monotonic(), m)), depth, raw=raw
        )
        return received

    def spin_until(self, done: Callable[[], bool], deadline: float = math.inf) -> None:
        """Receive until done() or the deadline (steady clock, s)."""
        while not done() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
