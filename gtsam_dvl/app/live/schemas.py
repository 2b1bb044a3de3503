"""The topics of the live view and the JSON schemas of its JSON topics, with the helpers that fill them.

Every JSON value is in SI or the unit its name says; a value without a sigma (not estimated, no covariance) is
null, so that Foxglove's Plot panel leaves a gap instead of drawing a wrong band (band()).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

# the topic of each published stream by key (the package doc says what each carries)
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


def _number(description: str) -> dict[str, Any]:
    return {"type": ["number", "null"], "description": description}


def _band(unit: str) -> dict[str, Any]:
    """A value with its sigma and the band value -+ sigma (null when unknown)."""
    return {
        "type": "object",
        "properties": {
            "value": _number(f"estimate, {unit}"),
            "sigma": _number(f"marginal 1-sigma, {unit}"),
            "lower": _number(f"value - sigma, {unit}"),
            "upper": _number(f"value + sigma, {unit}"),
        },
    }


def _object(title: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {
        "title": title,
        "type": "object",
        "properties": {
            "t_s": _number("log time of the epoch, s since the log's t0"),
            "final": {"type": "boolean", "description": "after finish(): the final estimate"},
            **properties,
        },
    }


def _axes(unit: str, names: tuple[str, ...] = ("x", "y", "z")) -> dict[str, Any]:
    return {"type": "object", "properties": {n: _band(unit) for n in names}}


# the JSON schema of each JSON topic, by its TOPICS key
SCHEMAS: dict[str, dict[str, Any]] = {
    "scale": _object("gtsam_dvl.live.Scale", _band("DVL scale factor (1 = perfect)")["properties"]),
    "misalignment": _object(
        "gtsam_dvl.live.MisalignmentDeg", _axes("deg", ("roll", "pitch", "yaw"))["properties"]
    ),
    "time_offset": _object(
        "gtsam_dvl.live.TimeOffset",
        {
            **_band("s (dt_d > 0: the DVL's stamps are early)")["properties"],
            "estimated": {"type": "boolean", "description": "false: not estimated, held at 0"},
        },
    ),
    "imu_bias": _object(
        "gtsam_dvl.live.ImuBias",
        {"accel_ug": _axes("micro-g, imu_link"), "gyro_deg_per_h": _axes("deg/h, imu_link")},
    ),
    "status": _object(
        "gtsam_dvl.live.Status",
        {
            "epochs": {
                "type": "integer",
                "description": "epochs published (the final estimate included)",
            },
            "counters": {"type": "object", "additionalProperties": {"type": "integer"}},
            "latency_ms": _number("the last epoch's update, ms"),
            "wall_s": _number("wall time since the start (of the replay, or the first message), s"),
            "log_s": _number("log time pushed since the start, s"),
            "real_time_factor": _number("log_s / wall_s"),
        },
    ),
    "imu": {
        "title": "gtsam_dvl.live.Imu",
        "type": "object",
        "properties": {
            "t_s": _number("s"),
            "b_omega_rad_s": _axes("rad/s, imu_link"),
            "b_f_m_s2": _axes("specific force, m/s^2, imu_link"),
        },
    },
    "dvl": {
        "title": "gtsam_dvl.live.Dvl",
        "type": "object",
        "properties": {
            "t_s": _number("s"),
            "valid": {"type": "boolean"},
            "d_v_m_s": _axes("m/s, dvl_link"),
            "sigma_m_s": _axes("m/s, from the message's covariance (null: none)"),
            "speed_m_s": _number("norm of d_v, m/s"),
        },
    },
    "depth": {
        "title": "gtsam_dvl.live.Depth",
        "type": "object",
        "properties": {
            "t_s": _number("s"),
            "depth_m": _number("m below the surface, positive down"),
            "pressure_pa": _number("absolute pressure, Pa (null: a depth topic)"),
        },
    },
}


def num(x: float) -> float | None:
    """A JSON number, None (null) for NaN or infinity (JSON has neither)."""
    x = float(x)
    return x if math.isfinite(x) else None


def band(value: float, sigma: float) -> dict[str, float | None]:
    """{value, sigma, lower, upper} with lower/upper = value -+ sigma (null where unknown)."""
    ok = math.isfinite(value) and math.isfinite(sigma)
    return {
        "value": num(value),
        "sigma": num(sigma),
        "lower": num(value - sigma) if ok else None,
        "upper": num(value + sigma) if ok else None,
    }


def xyz(
    v: np.ndarray, sigma: np.ndarray | None = None, names: tuple[str, ...] = ("x", "y", "z")
) -> dict[str, Any]:
    """{name: value} per axis, or {name: band(value, sigma)} with sigma."""
    if sigma is None:
        return {n: num(v[k]) for k, n in enumerate(names)}
    return {n: band(float(v[k]), float(sigma[k])) for k, n in enumerate(names)}


def sqrt_diag(P: np.ndarray) -> np.ndarray:
    """The square roots of a covariance's diagonal (sigmas); NaN where a variance is negative."""
    d = np.diag(np.asarray(P, dtype=float))
    return np.sqrt(np.where(d >= 0, d, np.nan))
