"""The ROS 2 node's settings: topics, QoS, frames, the message window, health thresholds and files, and where the
estimator's configuration comes from.

Two sources, one layout. A `-c` TOML file is an estimator configuration (as for `smooth -c`) with an optional
[node] table holding these settings; a ROS parameter file (YAML, `--params FILE`, read by rcl itself so that the
usual `/**:` and node-name keys work) holds the same settings as the node's parameters, and the estimator
configuration under the `estimator.` prefix (`estimator.dvl.noise_m_s: 0.01`, `estimator.preset: paper`). The
parameters override the TOML file's keys. A named configuration (`-c paper`) works as for `smooth`.

Why a pydantic model (core/config/base.py ConfigModel) rather than ROS parameter declarations one by one: the
same one-line errors as every other configuration of the project, for either source ("node.yaml: [node]
reorder_window_s must be a number >= 0, got -1"), and one place that lists every setting with its unit.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import Field

from gtsam_dvl.analysis.live_health import LiveThresholds
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.config.base import ConfigModel, Flag, Integer, NonNegative, Positive
from gtsam_dvl.core.errors import GtsamDvlError

DVL_TYPES = (
    "geometry_msgs/msg/TwistWithCovarianceStamped",
    "geometry_msgs/msg/TwistStamped",
    "marine_acoustic_msgs/msg/Dvl",
)
Reliability = Literal["best_effort", "reliable"]
# the parameters every rclpy node declares itself
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")
# the health verdict's thresholds (analysis/live_health.py), whose defaults are the node's
HEALTH = LiveThresholds()


class QosSettings(ConfigModel):
    """QoS of a group of topics. Inputs default to best effort: a driver publishing with the sensor-data profile
    (best effort) is not heard by a reliable subscriber, while a best-effort subscriber hears both kinds."""

    SECTION: ClassVar[str] = "node.qos"

    reliability: Reliability = "best_effort"
    # messages queued per topic (1000: 5 s of a 200 Hz IMU)
    depth: Integer = Field(default=1000, ge=1)


class NodeSettings(ConfigModel):
    """Every setting of `gtsam-dvl node` (docs/ros2.md lists them with examples). Times in seconds; "sensor time"
    is the time of the header stamps (the IMU's clock), "wall time" the node's own steady clock."""

    SECTION: ClassVar[str] = "node"

    node_name: str = "gtsam_dvl"
    # inputs; "" turns an optional input off
    imu_topic: str = "/imu/data"
    dvl_topic: str = "/dvl/twist"
    dvl_type: Literal[
        "geometry_msgs/msg/TwistWithCovarianceStamped",
        "geometry_msgs/msg/TwistStamped",
        "marine_acoustic_msgs/msg/Dvl",
    ] = "geometry_msgs/msg/TwistWithCovarianceStamped"
    pressure_topic: str = "/depth/pressure"  # sensor_msgs/msg/FluidPressure
    # sensor_msgs/msg/NavSatFix: the map origin when the configuration has none
    gnss_topic: str = "/gnss/fix"
    tf_static_topic: str = "/tf_static"  # read when tf2_msgs is importable (docs/ros2.md)
    # outputs; "" turns an optional output off
    odometry_topic: str = "/gtsam_dvl/odometry"
    calibration_topic: str = "/gtsam_dvl/calibration"
    diagnostics_topic: str = "/diagnostics"
    path_topic: str = "/gtsam_dvl/path"
    # frames (REP-103/105): the Odometry's header and child frames; the sensors' own frames come from their messages
    map_frame: str = "map"
    base_frame: str = "base_link"
    qos_inputs: QosSettings = Field(default_factory=QosSettings)
    qos_outputs: QosSettings = Field(
        default_factory=lambda: QosSettings(reliability="reliable", depth=50)
    )
    # the nominal mounting when /tf_static does not give it: rotations (roll, pitch, yaw in deg, ZYX, of the sensor
    # frame in base_link) and positions in base_link (m)
    imu_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    imu_xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dvl_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    dvl_xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pressure_xyz_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # messages are held this long in sensor time (behind the newest stamp) and released in stamp order, so that
    # one arriving out of order or late within it is put in its place; later than that it is counted and dropped
    reorder_window_s: NonNegative = 0.05
    # with no new message for this long (wall time) every held message is released (a stalled IMU does not hold
    # the others back)
    flush_after_s: Positive = 0.5
    # a DVL, pressure or GNSS stamp further than this from the IMU's newest: not on the IMU's clock (dropped, said).
    # Generous: a node that falls behind a fast replay holds an IMU backlog of seconds, and offsets below it are
    # the DVL time offset's to estimate ([dvl] estimate_time_offset)
    clock_skew_s: Positive = 30.0
    # a stamp stepping forward by more than this (sensor time) from the stream's previous one: a stamp jump
    stamp_jump_s: Positive = 1.0
    # health (diagnostics): the DVL topic silent this long in sensor time: warn, then degraded; the IMU silent this
    # long in wall time: no estimate (stale)
    dvl_silent_warn_s: Positive = HEALTH.dvl_silent_warn_s
    dvl_silent_degraded_s: Positive = HEALTH.dvl_silent_degraded_s
    # pings arriving but none valid (no bottom lock) this long: warn at once, degraded after this
    bottom_lock_degraded_s: Positive = HEALTH.bottom_lock_degraded_s
    imu_silent_s: Positive = HEALTH.imu_silent_s
    diagnostics_period_s: Positive = 1.0  # wall time; a change of verdict is published at once
    path_period_s: NonNegative = 1.0  # wall time between two Path messages (0: none)
    # a vehicle calibration file as the prior (as smooth --calibration) and where the save service writes one
    calibration: str = ""
    calibration_out: str = ""
    # the vehicle's name in the file written (else the prior's, else the node's name)
    vehicle: str = ""
    # calibration_out is also written while running, so that a node killed keeps its calibration (core.py): when a
    # vehicle calibration state moved by more than this many of its sigmas since the last write, and at least this
    # often (sensor time)
    calibration_out_move_sigma: Positive = 0.1
    calibration_out_period_s: Positive = 60.0
    # at shutdown: finish() and publish the final estimate (and write calibration_out when set)
    finish_on_shutdown: Flag = True
    stats_file: str = ""  # JSON of per-epoch timings written at shutdown (bench/bench_node.py)

    def check(self) -> NodeSettings:
        if self.dvl_silent_degraded_s < self.dvl_silent_warn_s:
            raise GtsamDvlError(
                f"[node] dvl_silent_degraded_s ({self.dvl_silent_degraded_s:g}) must be >= "
                f"dvl_silent_warn_s ({self.dvl_silent_warn_s:g})"
            )
        if not self.imu_topic or not self.dvl_topic:
            raise GtsamDvlError(
                "[node] imu_topic and dvl_topic are needed (the estimator runs on IMU and DVL)"
            )
        return self


def nested(flat: Mapping[str, Any]) -> dict[str, Any]:
    """ROS parameters ("a.b.c": value, as rcl flattens a YAML file's nested keys) as nested dicts."""
    out: dict[str, Any] = {}
    for key, value in flat.items():
        parts = key.split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
            if not isinstance(d, dict):
                raise GtsamDvlError(f"parameter {key}: {p} is both a value and a table")
        d[parts[-1]] = list(value) if isinstance(value, (list, tuple)) else value
    return out


def _merged(base: Mapping[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = (
            _merged(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), Mapping) else v
        )
    return out


def load_settings(
    config: Path | str | None = None,
    parameters: Mapping[str, Any] | None = None,
    source: str = "parameters",
) -> tuple[NodeSettings, EstimatorConfig]:
    """The node's settings and the estimator's configuration from `-c` (a TOML file with an optional [node]
    table, a result's config.json or a configuration's name; None: the defaults) and the node's ROS parameters
    (flat, "estimator.<table>.<key>" for the configuration; they override the file's). One-line errors."""
    node: dict[str, Any] = {}
    estimator: dict[str, Any] = {}
    base: EstimatorConfig | None = None
    if config is not None:
        path = Path(config)
        if path.suffix.lower() == ".toml" and path.exists():
            try:
                data = tomllib.loads(path.read_text())
            except tomllib.TOMLDecodeError as exc:
                raise GtsamDvlError(f"{path}: not valid TOML ({exc})") from None
            node = data.pop("node", {})
            if not isinstance(node, dict):
                raise GtsamDvlError(f"{path}: [node] must be a table")
            estimator = data
        else:
            base = EstimatorConfig.load(config)
    params = nested(
        {
            k: v
            for k, v in (parameters or {}).items()
            if k not in RCLPY_PARAMETERS and not k.startswith("qos_overrides.")
        }
    )
    over = params.pop("estimator", {})
    if not isinstance(over, dict):
        raise GtsamDvlError(f"{source}: estimator must be a table of configuration sections")
    node = _merged(node, params)
    for key in ("qos_inputs", "qos_outputs"):
        if isinstance(node.get(key), dict):
            node[key] = QosSettings.checked(node[key], f"{source}: [node.{key}]")
    settings = NodeSettings.checked(node, f"{config}" if config and not params else source).check()
    if base is not None:
        estimator = _merged(base.to_dict(), {})
    estimator = _merged(estimator, over)
    cfg = EstimatorConfig.from_dict(estimator, source=str(config or source))
    return settings, cfg
