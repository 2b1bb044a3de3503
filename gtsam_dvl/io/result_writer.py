"""Write an estimator's result as a ROS 2 MCAP (docs/conventions.md: /gtsam_dvl/* topics).

Covariances are converted from GTSAM's tangent spaces to ROS conventions by io/ros2/covariance.py: Odometry pose
covariance over (x, y, z, rot_x, rot_y, rot_z) in map axes, twist covariance in base_link.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.config.schema import SCHEMA_VERSION
from gtsam_dvl.core.result import NavResult, Timeline, misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw
from gtsam_dvl.core.summary import Summary
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.atomic import to_json
from gtsam_dvl.io.mcap.writer import McapLogWriter
from gtsam_dvl.io.read_options import ReadOptions
from gtsam_dvl.io.ros2 import messages
from gtsam_dvl.io.ros2.covariance import ros_pose_covariance, ros_twist_covariance

TOPICS = {
    "odometry": "/gtsam_dvl/odometry",
    "path": "/gtsam_dvl/path",
    "imu_bias": "/gtsam_dvl/imu_bias",
    "scale": "/gtsam_dvl/dvl_scale",
    "misalignment": "/gtsam_dvl/dvl_misalignment",
    "misalignment_rpy": "/gtsam_dvl/dvl_misalignment_rpy_deg",
    "misalignment_sigma": "/gtsam_dvl/dvl_misalignment_sigma_deg",
    "time_offset": "/gtsam_dvl/dvl_time_offset",  # s, only when estimated ([dvl] estimate_time_offset)
    # lever arm IMU -> DVL (m, base_link) as the position of a PoseWithCovarianceStamped with its 3x3 covariance,
    # only when estimated ([dvl] estimate_lever_arm)
    "lever_arm": "/gtsam_dvl/dvl_lever_arm",
    # the water current [east, north, 0] (m/s, map) at each state and its sigmas, when water-track pings were used
    # (estimators/models/current.py; NavResult.water_current)
    "water_current": "/gtsam_dvl/water_current",
    "water_current_sigma": "/gtsam_dvl/water_current_sigma",
}


TIMELINE_PREFIX = "/gtsam_dvl/filter"


def calibration_record(result: NavResult) -> dict[str, Any]:
    """What evaluation needs to redo the observability analysis without the graph."""
    return {
        "estimator": result.estimator,
        "scale": result.scale,
        "b_R_d": result.b_R_d,
        "b_R_d0": result.b_R_d0,
        "accel_bias_m_s2": result.accel_bias,
        "gyro_bias_rad_s": result.gyro_bias,
        "calib_joint_cov": result.calib_joint_cov,
        "calib_joint_cov_order": "accel bias (3, m/s^2), gyro bias (3, rad/s), scale (1), "
        "b_R_d right tangent (3, rad)",
        "t": [float(result.t[0]), float(result.t[-1])],
        "config": result.config,
        **(
            {
                "lever_arm_m": result.lever_arm_m,
                "lever_arm_cov": result.lever_arm_cov,
                "lever_arm_frame": "base_link, IMU -> DVL, m (covariance m^2)",
            }
            if result.lever_arm_m is not None
            else {}
        ),
    }


# NavResult's array fields, stored as they are in the attachment "states.npz" so that read_result gives back
# the NavResult that was written (the ROS topics carry the same numbers in ROS conventions, for ROS tools)
STATE_ARRAYS = (
    "t",
    "n_p",
    "n_R_b",
    "n_v",
    "pose_cov",
    "vel_cov",
    "accel_bias",
    "gyro_bias",
    "bias_cov",
    "b_R_d",
    "b_R_d_cov",
    "b_R_d0",
)
OPTIONAL_STATE_ARRAYS = (
    "b_omega",
    "pose_vel_cross",
    "calib_joint_cov",
    "shared_joint_cov",
    "lever_arm_m",
    "lever_arm_cov",
    "dvl_pings",
)


def states_npz_bytes(result: NavResult) -> bytes:
    arrays = {name: np.asarray(getattr(result, name)) for name in STATE_ARRAYS}
    arrays.update(
        {
            name: np.asarray(getattr(result, name))
            for name in OPTIONAL_STATE_ARRAYS
            if getattr(result, name) is not None
        }
    )
    arrays["scale"] = np.array([result.scale, result.scale_sigma])
    if np.isfinite(result.time_offset_sigma_s):
        arrays["time_offset_s"] = np.array([result.time_offset_s, result.time_offset_sigma_s])
    arrays["t0_ns"] = np.array([result.t0_ns], dtype=np.int64)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]  # numpy's stubs mistype **arrays
    return buf.getvalue()


def timeline_npz_bytes(timeline: Timeline) -> bytes:
    """A Timeline as .npz bytes (Timeline.from_arrays reads it back)."""
    buf = io.BytesIO()
    np.savez(buf, **timeline.as_arrays())  # type: ignore[arg-type]  # numpy's stubs mistype **arrays
    return buf.getvalue()


def write_timeline_topics(w: McapLogWriter, result: NavResult) -> None:
    """The filtering history as topics: estimate and sigma of scale, misalignment, biases; attitude sigma."""
    tl = result.timeline
    assert tl is not None
    p = TIMELINE_PREFIX
    w.add_scalar_with_variance(f"{p}/dvl_scale", tl.t, tl.scale, tl.scale_sigma**2, "dvl_link")
    w.add_vector3_stamped(f"{p}/dvl_misalignment_rpy_deg", tl.t, tl.misalignment_deg, "base_link")
    w.add_vector3_stamped(
        f"{p}/dvl_misalignment_sigma_deg", tl.t, tl.misalignment_sigma_deg, "base_link"
    )
    w.add_vector3_stamped(f"{p}/gyro_bias_deg_per_h", tl.t, tl.gyro_bias_deg_per_h, "imu_link")
    w.add_vector3_stamped(
        f"{p}/gyro_bias_sigma_deg_per_h", tl.t, tl.gyro_bias_sigma_deg_per_h, "imu_link"
    )
    w.add_vector3_stamped(f"{p}/accel_bias_ug", tl.t, tl.accel_bias_ug, "imu_link")
    w.add_vector3_stamped(f"{p}/accel_bias_sigma_ug", tl.t, tl.accel_bias_sigma_ug, "imu_link")
    w.add_vector3_stamped(f"{p}/attitude_sigma_deg", tl.t, tl.attitude_sigma_deg, "map")


def health_record(health: dict[str, Any], losses: dict[str, Any]) -> dict[str, str]:
    """The metadata record "gtsam_dvl_health" (strings only, as MCAP metadata is): status, warnings and notes
    (JSON lists), the figures behind them and the reader's losses (JSON)."""
    return {
        "status": str(health.get("status", "")),
        "warnings": to_json(health.get("warnings", [])),
        "notes": to_json(health.get("notes", [])),
        "figures": to_json(health.get("figures", {})),
        "losses": to_json(losses),
    }


def file_sha256(path: Path | str) -> str:
    """The SHA-256 of a log's content, hex: of the file, or of a rosbag2 folder's files (their paths relative to
    it and their bytes, in sorted order); "" when there is no such file or folder."""
    path = Path(path)
    files = (
        [path]
        if path.is_file()
        else sorted(p for p in path.rglob("*") if p.is_file())
        if path.is_dir()
        else []
    )
    if not files:
        return ""
    digest = hashlib.sha256()
    for f in files:
        if path.is_dir():
            digest.update(f.relative_to(path).as_posix().encode() + b"\0")
        with f.open("rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                digest.update(chunk)
    return digest.hexdigest()


def source_record(
    log: LogData, result_path: Path | str, read_options: ReadOptions | None
) -> dict[str, str]:
    """Where the result came from, for the metadata record "gtsam_dvl_result": the source log's absolute path,
    its path relative to the folder of the result file (so that the two can move together), the SHA-256 of its
    content (file_sha256: `evaluate --truth` checks that it is given the source), the map origin it read (JSON,
    "" when the log records none) and the reading options (JSON, ReadOptions.record(): imu_topic, dvl_topic,
    salvage, repair and the others that differ from their defaults; None: the defaults)."""
    options = (read_options or ReadOptions()).record()
    origin = to_json(log.origin.as_dict()) if log.origin is not None else ""
    if not log.source:
        return {
            "source_log": "",
            "source_log_relative": "",
            "source_sha256": "",
            "source_origin": origin,
            "read_options": to_json(options),
        }
    source = Path(log.source).resolve()
    try:
        relative = os.path.relpath(source, Path(result_path).resolve().parent)
    except ValueError:  # another drive (Windows): no relative path
        relative = ""
    return {
        "source_log": str(source),
        "source_log_relative": relative,
        "source_sha256": file_sha256(source),
        "source_origin": origin,
        "read_options": to_json(options),
    }


def write_result_log(
    path: Path | str,
    result: NavResult,
    log: LogData,
    summary: dict[str, Any],
    read_options: ReadOptions | None = None,
    result_path: Path | str | None = None,
) -> Path:
    """Estimates with marginal covariances, path, biases and calibration, plus the summary and the
    effective configuration (metadata record and config.json attachment) and the run's health (metadata
    record "gtsam_dvl_health", and in summary.json). The record "gtsam_dvl_result" also names the source log
    (absolute, and relative to result_path's folder: the final name when path is a temporary file), the
    options it was read with and the schema_version (core/config/schema.py). Written atomically. summary: the
    summary's JSON dict (analysis/metrics.py summary), checked against its model (core/summary.py Summary: a
    pydantic ValidationError, a programming error, before anything is written)."""
    Summary.model_validate(summary)
    path = Path(path)
    t = result.t
    mis_rpy, mis_cov = misalignment_rpy_and_cov(result.b_R_d, result.b_R_d0, result.b_R_d_cov)
    R_c = result.b_R_d @ result.b_R_d0.T
    with McapLogWriter(path, t0_ns=result.t0_ns) as w:
        _write_trajectory(w, result, log)
        _write_calibration_topics(w, result)
        cov_c = np.zeros((6, 6))
        cov_c[3:, 3:] = result.b_R_d @ result.b_R_d_cov @ result.b_R_d.T  # body axes, rad^2
        w.add_pose_with_covariance(
            TOPICS["misalignment"],
            t[-1:],
            np.zeros((1, 3)),
            matrix_to_quat_xyzw(R_c)[None],
            cov_c[None],
            "base_link",
        )
        w.add_vector3_stamped(TOPICS["misalignment_rpy"], t[-1:], mis_rpy[None], "base_link")
        w.add_vector3_stamped(
            TOPICS["misalignment_sigma"], t[-1:], np.sqrt(np.diag(mis_cov))[None], "base_link"
        )
        if (wc := result.water_current) is not None and len(wc.t_s):
            t_c = np.asarray(wc.t_s, dtype=float)
            zero = np.zeros(len(t_c))
            w.add_vector3_stamped(
                TOPICS["water_current"],
                t_c,
                np.stack([wc.east_m_s, wc.north_m_s, zero], axis=1),
                "map",
            )
            w.add_vector3_stamped(
                TOPICS["water_current_sigma"],
                t_c,
                np.stack([wc.east_sigma_m_s, wc.north_sigma_m_s, zero], axis=1),
                "map",
            )
        if result.timeline is not None:
            write_timeline_topics(w, result)
            w.add_attachment(
                "timeline.npz", timeline_npz_bytes(result.timeline), "application/x-npz"
            )
        _write_records(w, result, summary, source_record(log, result_path or path, read_options))
    return path


def _write_trajectory(w: McapLogWriter, result: NavResult, log: LogData) -> None:
    """The mounting (/tf_static), the odometry with its covariances (ROS conventions), the path (one message per
    piece of a log smoothed in pieces) and the IMU biases."""
    t = result.t
    n = len(t)
    n_q_b = matrix_to_quat_xyzw(result.n_R_b)
    b_v, twist_cov = ros_twist_covariance(
        result.n_R_b, result.n_v, result.pose_cov, result.vel_cov, result.pose_vel_cross
    )
    b_omega = result.b_omega if result.b_omega is not None else np.zeros((n, 3))
    m = log.mounting
    w.add_tf_static(
        "/tf_static",
        float(t[0]),
        [
            ("base_link", "imu_link", m.b_R_imu, m.b_p_imu),
            ("base_link", "dvl_link", m.b_R_d0, m.b_p_dvl),
        ],
    )
    odometry = messages.odometry(
        w.stamps_ns(t),
        result.n_p,
        n_q_b,
        b_v,
        b_omega,
        ros_pose_covariance(result.n_R_b, result.pose_cov),
        twist_cov,
    )
    w.add_structured(TOPICS["odometry"], messages.ODOMETRY, odometry)
    # one Path message per piece of a log smoothed at its long IMU gaps (estimators/batch/pieces.py), so that no
    # line crosses a break; else one of the whole trajectory
    starts = [int(p["start_index"]) for p in result.info.get("pieces") or []] or [0]
    for a, b in zip(starts, starts[1:] + [n], strict=True):
        w.add_path(TOPICS["path"], t[a:b], result.n_p[a:b], n_q_b[a:b])
    ones = np.ones(n)
    bias_cov = np.broadcast_to(result.bias_cov, (n, 6, 6))
    bias = messages.six_dof_with_covariance(
        messages.ACCEL_COV,
        w.stamps_ns(t),
        np.outer(ones, result.accel_bias),
        np.outer(ones, result.gyro_bias),
        bias_cov,
        "imu_link",
    )
    w.add_structured(TOPICS["imu_bias"], messages.ACCEL_COV, bias)


def _write_calibration_topics(w: McapLogWriter, result: NavResult) -> None:
    """The DVL scale, and when estimated its time offset and lever arm, each one message at the last state."""
    t = result.t
    scalars = [("scale", result.scale, result.scale_sigma)]
    if np.isfinite(result.time_offset_sigma_s):
        scalars.append(("time_offset", result.time_offset_s, result.time_offset_sigma_s))
    for topic, value, sigma in scalars:
        w.add_scalar_with_variance(
            TOPICS[topic], t[-1:], np.array([value]), np.array([sigma**2]), "dvl_link"
        )
    if result.lever_arm_m is not None and result.lever_arm_cov is not None:
        cov_l = np.zeros((6, 6))
        cov_l[:3, :3] = result.lever_arm_cov  # m^2, base_link; the rotation block is not estimated
        w.add_pose_with_covariance(
            TOPICS["lever_arm"],
            t[-1:],
            result.lever_arm_m[None],
            np.array([[0.0, 0.0, 0.0, 1.0]]),
            cov_l[None],
            "base_link",
        )


def _write_records(
    w: McapLogWriter, result: NavResult, summary: dict[str, Any], source: dict[str, str]
) -> None:
    """The metadata records ("gtsam_dvl_result" with the source record and the schema_version,
    "gtsam_dvl_health") and the attachments read_result reads back: calibration.json, config.json (the effective
    configuration), summary.json, states.npz and result.json."""
    w.add_attachment(
        "calibration.json", to_json(calibration_record(result)).encode(), "application/json"
    )
    w.add_metadata(
        "gtsam_dvl_result",
        {
            "estimator": result.estimator,
            "summary": to_json(summary),
            **source,
            "schema_version": str(SCHEMA_VERSION),
        },
    )
    if (health := summary.get("health")) is not None:
        w.add_metadata("gtsam_dvl_health", health_record(health, summary.get("losses", {})))
    w.add_attachment(
        "config.json",
        json.dumps(
            {
                "schema_version": SCHEMA_VERSION,
                "estimator": result.estimator,
                "config": result.config,
            },
            default=str,
            indent=2,
        ).encode(),
        "application/json",
    )
    w.add_attachment("summary.json", to_json(summary).encode(), "application/json")
    w.add_attachment("states.npz", states_npz_bytes(result), "application/x-npz")
    w.add_attachment(
        "result.json",
        to_json(
            {
                "estimator": result.estimator,
                # (the water current's profile in the file's info, as before it was a field: io/result_reader.py)
                "info": result.info
                if result.water_current is None
                else {**result.info, "water_current": result.water_current.as_dict()},
                "timing_s": result.timing_s,
                "config": result.config,
            }
        ).encode(),
        "application/json",
    )
