"""`gtsam-dvl info`: a few lines about a log (what a navigator wants to know before processing it), or about a
result of `smooth -o` (its source log, how it was read, and the estimator's summary as smooth printed it)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from gtsam_dvl.app.commands import load_log
from gtsam_dvl.app.summary_lines import summary_lines
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.summary import parse_summary
from gtsam_dvl.core.types import LogData

if TYPE_CHECKING:
    from gtsam_dvl.io.read_options import ReadOptions


def describe_log(log_path: Path, read_options: ReadOptions | None = None) -> str:
    """A few lines about a log: what a navigator wants to know before processing it."""
    log = load_log(log_path, read_options)
    return "\n".join(
        [
            f"{log_path}",
            *_sensor_lines(log),
            *_frame_lines(log),
            *_stamp_lines(log),
            *_truth_lines(log),
        ]
        + [f"  warning: {warning}" for warning in log.metadata.get("reader_warnings", [])]
    )


def _sensor_lines(log: LogData) -> list[str]:
    """describe_log's lines on the sensors: message counts, the DVL's beams, water track and altitude, the rates."""
    imu, dvl = log.imu, log.dvl
    imu_hz = 1.0 / np.median(np.diff(imu.t))
    lines = [
        f"  duration {imu.t[-1] - imu.t[0]:.1f} s, IMU {len(imu)} msgs ({imu_hz:.1f} Hz), "
        f"DVL {len(dvl)} msgs ({int(dvl.valid.sum())} valid 3-D)",
    ]
    if dvl.beams is not None:
        lines.append(
            f"  DVL beams: {dvl.beams.v.shape[1]}, valid beam measurements {int(dvl.beams.valid.sum())}"
        )
    if dvl.water_track is not None and dvl.water_track.any():
        lines.append(
            f"  DVL water track (velocity relative to the water): {int(dvl.water_track.sum())} pings"
        )
    if dvl.altitude is not None and np.isfinite(dvl.altitude).any():
        alt = dvl.altitude[np.isfinite(dvl.altitude)]
        lines.append(
            f"  DVL altitude {alt.min():.1f}-{alt.max():.1f} m ({len(alt)} pings with one)"
        )
    dvl_hz = 1.0 / np.median(np.diff(dvl.t)) if len(dvl) > 1 else float("nan")
    lines.append(
        f"  rates: IMU {imu_hz:.1f} Hz, DVL {dvl_hz:.2f} Hz"
        + (
            f", depth {1.0 / np.median(np.diff(log.depth.t)):.2f} Hz ({len(log.depth)} msgs)"
            if log.depth is not None and len(log.depth) > 1
            else ", no depth"
        )
        + (f", GNSS {len(log.gnss)} msgs" if log.gnss is not None else ", no GNSS")
    )
    return lines


def _frame_lines(log: LogData) -> list[str]:
    """describe_log's lines on the frames: the map origin and the sensors' mounting."""
    from gtsam_dvl.core.rotations import matrix_to_rpy_deg

    lines = []
    o = log.origin
    lines.append(
        f"  map origin: lat {o.lat_deg:.7f} deg, lon {o.lon_deg:.7f} deg, height {o.height_m:.2f} m"
        if o is not None
        else "  map origin: none in the log (give --gnss-topic or alignment.origin_lat_deg)"
    )
    m = log.mounting
    lines.append(
        "  mounting (base_link <- sensor, roll/pitch/yaw deg): IMU "
        + " ".join(f"{v:+.2f}" for v in matrix_to_rpy_deg(m.b_R_imu))
        + ", DVL "
        + " ".join(f"{v:+.2f}" for v in matrix_to_rpy_deg(m.b_R_d0))
        + f"; lever arm IMU->DVL {np.round(m.b_l, 4).tolist()} m"
    )
    return lines


def _stamp_lines(log: LogData) -> list[str]:
    """describe_log's lines on the stamps: the DVL's phase against the IMU's, and the gaps the reader found."""
    imu, dvl = log.imu, log.dvl
    lines = []
    # stamps: where the DVL's fall between IMU samples, and the first stamps' offset (a hint of unsynchronised
    # clocks; the DVL-IMU time offset itself is only seen by the estimator, from the motion)
    if len(dvl) and len(imu) > 1:
        period = float(np.median(np.diff(imu.t)))
        phase = np.mod(dvl.t - imu.t[0], period) / period
        lines.append(
            f"  stamps: first DVL {dvl.t[0] - imu.t[0]:+.3f} s after the first IMU sample; DVL stamps fall "
            f"at {np.median(phase):.2f} of an IMU period (median)"
        )
    gaps = log.metadata.get("reader_losses", {}).get("gaps", {})
    lines.append(
        "  gaps: none"
        if not gaps
        else "  gaps: "
        + "; ".join(
            f"{topic} {g['count']} ({g['seconds']:.1f} s, longest {g['longest_s']:.2f} s)"
            for topic, g in gaps.items()
        )
    )
    return lines


def _truth_lines(log: LogData) -> list[str]:
    """describe_log's lines on a simulated log's truth: its calibration and its motion."""
    lines = []
    cal = log.true_calibration
    if cal is not None:
        lines.append(
            f"  truth: scale {cal.scale}, misalignment [roll, pitch, yaw] {list(cal.misalignment_deg)} deg"
        )
    if log.truth is not None and len(log.truth) > 1:
        tr = log.truth
        path_m = float(np.sum(np.linalg.norm(np.diff(tr.n_p, axis=0), axis=1)))
        up = tr.n_p[:, 2]
        lines.append(
            f"  truth: {path_m / 1000:.3f} km travelled in {tr.t[-1] - tr.t[0]:.0f} s; height in map from "
            f"{up.min():+.2f} to {up.max():+.2f} m (start {up[0]:+.2f} m); peak sink "
            f"{max(0.0, -float(tr.n_v[:, 2].min())):.2f} m/s, "
            f"peak rise {max(0.0, float(tr.n_v[:, 2].max())):.2f} m/s"
        )
    return lines


def describe_result(path: Path) -> str | None:
    """What `info` prints for a result of `smooth -o` (None: the file is not one): that it is a result, its source
    log and how it was read, then the estimator's summary as smooth printed it (calibration, noise, health)."""
    import json

    from gtsam_dvl.io.result_writer import TOPICS
    from gtsam_dvl.io.storage.sources import open_source

    try:
        src = open_source(Path(path))
    except (GtsamDvlError, OSError):
        return None  # not a readable MCAP: describe_log says why
    if TOPICS["odometry"] not in src.topics or "summary.json" not in src.attachments:
        return None
    try:
        summary = json.loads(src.attachments["summary.json"][1])
        record = src.metadata.get("gtsam_dvl_result", {})
        options = json.loads(record["read_options"]) if record.get("read_options") else {}
        given = ", ".join(f"{k} {v}" for k, v in options.items() if v not in (None, False, ""))
        # (core/summary.py: an older summary migrated; one that does not fit is one error line)
        body = summary_lines(parse_summary(summary, str(path)))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise GtsamDvlError(
            f"{path}: a gtsam_dvl result whose summary cannot be read ({type(exc).__name__}: "
            f"{exc}); smooth the log again"
        ) from None
    lines = [
        f"{path}: a gtsam_dvl result ({summary.get('estimator', '?')}); `gtsam-dvl evaluate {path} -o DIR` "
        "evaluates it",
        f"  source log: {record.get('source_log') or 'not recorded'}"
        + (f" (read with {given})" if given else ""),
    ]
    return "\n".join(lines + body)
