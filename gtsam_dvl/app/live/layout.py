"""The Foxglove layout of the live view: layout.json beside this module (installed with the package as
package data) is layout_json(), regenerated with `python -m gtsam_dvl.app.live --write-layout`;
`gtsam-dvl live --layout PATH` writes a copy of it (copy_layout).

A 3-D panel following base_link in map with the path, the odometry's covariance and the truth; Plot panels of
the calibration and the biases, each series drawn with its value - sigma and value + sigma; a Log panel and a
Raw Messages panel of the status.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

from gtsam_dvl.app.live.schemas import TOPICS
from gtsam_dvl.core.errors import GtsamDvlError

LAYOUT_NAME = "layout.json"  # package data of gtsam_dvl.app.live (pyproject.toml)
# in the source tree, for write_layout
LAYOUT_FILE = Path(__file__).resolve().with_name(LAYOUT_NAME)


def _series(
    topic: str, field_path: str, label: str, color: str, dashed: bool = False
) -> dict[str, Any]:
    s: dict[str, Any] = {
        "value": f"{topic}.{field_path}",
        "enabled": True,
        "timestampMethod": "receiveTime",
        "label": label,
        "color": color,
        "showLine": True,
    }
    if dashed:
        s["lineSize"] = 0.75
    return s


def _band_series(topic: str, path: str, label: str, color: str) -> list[dict[str, Any]]:
    return [
        _series(topic, f"{path}value", label, color),
        _series(topic, f"{path}lower", f"{label} - sigma", color, dashed=True),
        _series(topic, f"{path}upper", f"{label} + sigma", color, dashed=True),
    ]


def _plot(title: str, y_label: str, paths: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "paths": paths,
        "title": title,
        "yAxisLabel": y_label,
        "showLegend": True,
        "legendDisplay": "floating",
        "showXAxisLabels": True,
        "showYAxisLabels": True,
        "isSynced": True,
        "xAxisVal": "timestamp",
        "sidebarDimension": 240,
    }


AXIS_COLORS = ("#e6194b", "#3cb44b", "#4363d8")


ESTIMATE, TRUTH = (
    "#ff8c00ff",
    "#00b4ffff",
)  # the 3-D panel's colours (RGBA): the estimate orange, the truth blue


def _arrow(color: str, **covariance: Any) -> dict[str, Any]:
    """A pose topic in the 3-D panel: an arrow of one colour (and its covariance's settings, when given)."""
    return {
        "visible": True,
        "type": "arrow",
        **covariance,
        "color": color,
        "arrowScale": [4, 0.6, 0.6],
    }


def _line(color: str, width_m: float) -> dict[str, Any]:
    """A path topic in the 3-D panel: a line of one colour, width_m wide."""
    return {"visible": True, "type": "line", "lineWidth": width_m, "gradient": [color, color]}


def _three_d_panel() -> dict[str, Any]:
    """The 3-D panel: following base_link in map, the estimated pose with its covariance and path, the truth's,
    a 10 m grid."""
    T = TOPICS
    return {
        "followTf": "base_link",
        "followMode": "follow-position",
        "cameraState": {
            "distance": 80,
            "perspective": True,
            "phi": 55,
            "thetaOffset": 30,
            "target": [0, 0, 0],
            "targetOffset": [0, 0, 0],
            "targetOrientation": [0, 0, 0, 1],
            "fovy": 45,
            "near": 0.5,
            "far": 20000,
        },
        "scene": {"enableStats": False, "transforms": {"showLabel": True, "axisScale": 2}},
        "transforms": {"frame:map": {"visible": True}, "frame:base_link": {"visible": True}},
        "topics": {
            T["odometry"]: _arrow(ESTIMATE, showCovariance=True, covarianceColor="#ff8c0055"),
            T["path"]: _line(ESTIMATE, 0.4),
            T["truth"]: _arrow(TRUTH),
            T["truth_path"]: _line(TRUTH, 0.3),
        },
        "layers": {
            "grid": {
                "visible": True,
                "frameLocked": False,
                "label": "Grid (10 m)",
                "instanceId": "grid",
                "layerId": "foxglove.Grid",
                "frameId": "map",
                "size": 2000,
                "divisions": 200,
                "lineWidth": 1,
                "color": "#248eff40",
                "position": [0, 0, 0],
                "rotation": [0, 0, 0],
                "order": 1,
            }
        },
        "publish": {
            "type": "point",
            "poseTopic": "/move_base_simple/goal",
            "pointTopic": "/clicked_point",
            "poseEstimateTopic": "/initialpose",
            "poseEstimateXDeviation": 0.5,
            "poseEstimateYDeviation": 0.5,
            "poseEstimateThetaDeviation": 0.26179939,
        },
        "imageMode": {},
    }


def _plot_panels() -> dict[str, Any]:
    """The Plot panels by id: scale, misalignment, time offset, accelerometer and gyro biases, each series with
    its value - sigma and value + sigma."""
    T = TOPICS
    axes = ("x", "y", "z")
    return {
        "Plot!scale": _plot(
            "DVL scale (+- 1 sigma)",
            "scale factor (1 = perfect)",
            _band_series(T["scale"], "", "scale", "#ff8c00"),
        ),
        "Plot!misalignment": _plot(
            "DVL misalignment (+- 1 sigma)",
            "angle (deg)",
            [
                s
                for name, c in zip(("roll", "pitch", "yaw"), AXIS_COLORS, strict=True)
                for s in _band_series(T["misalignment"], f"{name}.", name, c)
            ],
        ),
        "Plot!time_offset": _plot(
            "DVL time offset (+- 1 sigma)",
            "dt_d (s)",
            _band_series(T["time_offset"], "", "time offset", "#911eb4"),
        ),
        "Plot!accel_bias": _plot(
            "Accelerometer bias (+- 1 sigma)",
            "bias (micro-g)",
            [
                s
                for a, c in zip(axes, AXIS_COLORS, strict=True)
                for s in _band_series(T["imu_bias"], f"accel_ug.{a}.", a, c)
            ],
        ),
        "Plot!gyro_bias": _plot(
            "Gyro bias (+- 1 sigma)",
            "bias (deg/h)",
            [
                s
                for a, c in zip(axes, AXIS_COLORS, strict=True)
                for s in _band_series(T["imu_bias"], f"gyro_deg_per_h.{a}.", a, c)
            ],
        ),
    }


def _arrangement() -> tuple[dict[str, Any], dict[str, Any]]:
    """Where the panels sit: the left column (3-D above the health log and the status), the right one (the
    plots). Returns (left, right)."""
    plots = {
        "first": {
            "first": "Plot!scale",
            "second": "Plot!misalignment",
            "direction": "column",
            "splitPercentage": 50,
        },
        "second": {
            "first": {
                "first": "Plot!time_offset",
                "second": "Plot!accel_bias",
                "direction": "column",
                "splitPercentage": 50,
            },
            "second": "Plot!gyro_bias",
            "direction": "column",
            "splitPercentage": 66,
        },
        "direction": "column",
        "splitPercentage": 40,
    }
    left = {
        "first": "3D!live",
        "second": {
            "first": "RosOut!health",
            "second": "RawMessages!status",
            "direction": "row",
            "splitPercentage": 60,
        },
        "direction": "column",
        "splitPercentage": 70,
    }
    return left, plots


def layout() -> dict[str, Any]:
    """The Foxglove layout of the installed layout.json (Layouts > Import from file): a 3-D panel following
    base_link in map with the estimated path, odometry covariance and truth; Plot panels of scale,
    misalignment, time offset and biases, each series drawn with its value - sigma and value + sigma; a Log
    panel of the health and a Raw Messages panel of the status."""
    T = TOPICS
    config_by_id: dict[str, Any] = {
        "3D!live": _three_d_panel(),
        **_plot_panels(),
        "RosOut!health": {"searchTerms": [], "minLogLevel": 1, "topicToRender": T["log"]},
        "RawMessages!status": {
            "topicPath": T["status"],
            "diffEnabled": False,
            "diffMethod": "custom",
            "diffTopicPath": "",
            "showFullMessageForDiff": False,
            "expansion": "all",
        },
    }
    left, plots = _arrangement()
    return {
        "configById": config_by_id,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": {"first": left, "second": plots, "direction": "row", "splitPercentage": 55},
    }


def layout_json() -> str:
    """layout() as the text of layout.json."""
    return json.dumps(layout(), indent=2) + "\n"


def write_layout(path: Path = LAYOUT_FILE) -> Path:
    """Write layout_json() to path (default: layout.json beside this module, in the source tree)."""
    path.write_text(layout_json())
    return path


def installed_layout() -> str:
    """The text of the layout file installed with the package (importlib.resources: a wheel, an editable install
    or a zip)."""
    return resources.files("gtsam_dvl.app.live").joinpath(LAYOUT_NAME).read_text(encoding="utf-8")


def copy_layout(path: Path) -> Path:
    """`gtsam-dvl live --layout PATH`: write a copy of the installed layout file to path, for Foxglove's Layouts >
    Import from file. Its folder must exist and an existing file is not overwritten (one-line GtsamDvlError)."""
    from gtsam_dvl.app.outputs import check_folders

    path = Path(path)
    check_folders({"--layout": path})
    text = installed_layout()
    try:
        with path.open("x", encoding="utf-8") as f:  # exclusive creation: never overwrites
            f.write(text)
    except FileExistsError:
        raise GtsamDvlError(
            f"{path}: exists; --layout does not overwrite a file, choose another path"
        ) from None
    except IsADirectoryError:
        raise GtsamDvlError(
            f"{path}: is a folder; --layout takes a file path (e.g. gtsam_dvl_live.json)"
        ) from None
    return path
