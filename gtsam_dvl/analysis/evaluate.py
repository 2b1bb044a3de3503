"""`evaluate`: a stored result against the truth over time, and what the log made observable.

The verdict reads like the mission planner's (observability.calibration_answer): a Yes/No headline on the DVL's
calibration, advice on what would determine what is missing, and every estimated shared state (core/states.py:
biases, scale, misalignment, and the time offset and lever arm when estimated) with the time its filtering sigma
reached "determined" when the result holds its filtering timeline. With truth, the errors against it: the
trajectory's, and the calibration's and biases' where the truth has them (unknown ones are left out).

Works without truth (a real log): then only the observability analysis, the segment classification, the
sigma timelines and, when the log has GNSS fixes, the errors at the held-out fixes and the surfacing error
(analysis/surfacing.py: metrics["gnss"]) are reported. The log given as truth must be the result's source
(source_mismatch).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

from gtsam_dvl.analysis.metrics import trajectory_errors, truth_errors
from gtsam_dvl.analysis.observability import (
    ObservabilityReport,
    analyse_block,
    attribute_segments,
    calibration_answer,
    determined_at,
    estimated_time_offset_sigma,
    result_config,
)
from gtsam_dvl.analysis.segments import classify_log
from gtsam_dvl.analysis.surfacing import SurfacingReport, surfacing_report
from gtsam_dvl.core.result import StoredResult
from gtsam_dvl.core.types import GeoOrigin, LogData, Segment


@dataclass
class Evaluation:
    estimator: str
    t: np.ndarray
    attitude_sigma_deg: np.ndarray  # (N, 3) map axes
    position_sigma_m: np.ndarray  # (N, 3) map axes
    velocity_sigma_m_s: np.ndarray  # (N, 3) map axes
    attitude_error_deg: np.ndarray | None = None  # (N, 3)
    position_error_m: np.ndarray | None = None  # (N, 3)
    velocity_error_m_s: np.ndarray | None = None  # (N, 3)
    report: ObservabilityReport | None = None
    segments: list[Segment] = field(default_factory=list)
    shares: dict[str, list[tuple[str, float]]] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=dict)
    # held-out GNSS fixes and the surfacing error (log with fixes)
    gnss: SurfacingReport | None = None
    # from the filtering timeline
    determined_at_s: dict[str, float | None] = field(default_factory=dict)
    truth_errors: dict[str, Any] | None = None  # metrics.truth_errors against the log's truth
    notes: list[str] = field(default_factory=list)  # printed after the verdict

    def lines(self) -> list[str]:
        """The verdict (headline, advice, every state), the directions not determined, the errors against the
        truth."""
        if self.report is None:
            out = ["no calibration covariance in this result"]
        else:
            out = (
                calibration_answer(self.report, self.determined_at_s, "log")
                + self.report.direction_lines()
            )
        return out + truth_error_lines(self.truth_errors or {}) + self.notes


def _finite(*values: Any) -> bool:
    try:
        return all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in values)
    except (TypeError, ValueError):
        return False


def _with_sigmas(values: Any, nsigma: Any, fmt: str, unit: str) -> str:
    """ "+0.010, -0.020 deg (+0.3, -0.5 sigma)"; the sigmas left out when not finite."""
    vals = ", ".join(format(float(v), fmt) for v in np.atleast_1d(values))
    if nsigma is not None and _finite(nsigma):
        return (
            f"{vals} {unit} ({', '.join(f'{float(n):+.1f}' for n in np.atleast_1d(nsigma))} sigma)"
        )
    return f"{vals} {unit}"


def truth_error_lines(errors: dict[str, Any]) -> list[str]:
    """The errors against the truth as printed lines (metrics.truth_errors' keys), only those the truth gives
    and finite: nothing for a log without truth, the trajectory's alone without a true calibration."""
    out = []
    if _finite(errors.get("final_horizontal_position_m")):
        pct = errors.get("final_horizontal_position_pct_distance")
        line = (
            f"vs truth: final horizontal position error {errors['final_horizontal_position_m']:.2f} m"
            + (f" ({pct:.3f} % of distance)" if _finite(pct) else "")
        )
        if _finite(errors.get("position_rmse_m")):
            line += f", position rms {errors['position_rmse_m']:.2f} m"
        if _finite(errors.get("attitude_rmse_deg")) and errors.get("attitude_rmse_deg"):
            line += (
                ", attitude rms about east/north/up "
                + ", ".join(f"{v:.3g}" for v in errors["attitude_rmse_deg"])
                + " deg"
            )
        out.append(line)
    parts = []
    for key, nsigma_key, name, fmt, unit, to_display in (
        ("scale_ppm", "scale_nsigma", "scale", "+.0f", "ppm", 1.0),
        (
            "misalignment_deg",
            "misalignment_nsigma",
            "misalignment roll/pitch/yaw",
            "+.3f",
            "deg",
            1.0,
        ),
        ("dvl_time_offset_s", "dvl_time_offset_nsigma", "time offset", "+.1f", "ms", 1e3),
        ("dvl_lever_arm_m", "dvl_lever_arm_nsigma", "lever arm x/y/z", "+.3f", "m", 1.0),
        ("gyro_bias_deg_per_h", "gyro_bias_nsigma", "gyro bias x/y/z", "+.4f", "deg/h", 1.0),
        ("accel_bias_ug", "accel_bias_nsigma", "accel bias x/y/z", "+.1f", "micro-g", 1.0),
    ):
        value = errors.get(key)
        if value is None or not np.size(value) or not _finite(value):
            continue
        shown = _with_sigmas(
            np.asarray(value, dtype=float) * to_display, errors.get(nsigma_key), fmt, unit
        )
        parts.append(f"{name} {shown}")
    if parts:
        out.append("vs truth: " + "; ".join(parts))
    return out


# a truth log's map origin farther than this from the source's: another dive
SOURCE_ORIGIN_M = 1000.0


def _utc(t_ns: float) -> str:
    return datetime.fromtimestamp(t_ns / 1e9, tz=UTC).strftime("%Y-%m-%d %H:%M:%S UTC")


def origin_distance_m(a: GeoOrigin, b: GeoOrigin) -> float:
    """Horizontal distance between two map origins on a sphere of the Earth's mean radius (haversine), m."""
    lat1, lat2 = np.radians(a.lat_deg), np.radians(b.lat_deg)
    h = (
        np.sin((lat2 - lat1) / 2) ** 2
        + np.cos(lat1) * np.cos(lat2) * np.sin(np.radians(b.lon_deg - a.lon_deg) / 2) ** 2
    )
    return float(2 * 6_371_000.0 * np.arcsin(np.sqrt(min(h, 1.0))))


def source_mismatch(stored: StoredResult, log: LogData, log_sha256: str) -> str:
    """Why `log` (whose content hashes to log_sha256) is not the result's source, "" when it is: its content
    differs from the source's recorded SHA-256 (the same content is the source, wherever it lies); its stamps do
    not overlap the result's; its map origin lies more than SOURCE_ORIGIN_M from the source's. A result that
    recorded no hash or origin is judged on what it recorded."""
    if stored.source_sha256 and log_sha256 == stored.source_sha256:
        return ""
    reasons = []
    if stored.source_sha256 and log_sha256:
        reasons.append(
            f"its content differs from that of the source {stored.source_log or 'log'} (SHA-256 "
            f"{log_sha256[:12]}... against {stored.source_sha256[:12]}...)"
        )
    res = stored.result
    starts = [float(x.t[0]) for x in (log.imu, log.dvl) if len(x.t)]
    ends = [float(x.t[-1]) for x in (log.imu, log.dvl) if len(x.t)]
    if starts and len(res.t):
        log_span = (log.t0_ns + min(starts) * 1e9, log.t0_ns + max(ends) * 1e9)
        res_span = (res.t0_ns + float(res.t[0]) * 1e9, res.t0_ns + float(res.t[-1]) * 1e9)
        if log_span[1] < res_span[0] or res_span[1] < log_span[0]:
            reasons.append(
                f"its stamps ({_utc(log_span[0])} to {_utc(log_span[1])}) do not overlap the result's "
                f"({_utc(res_span[0])} to {_utc(res_span[1])})"
            )
    if stored.source_origin and log.origin is not None:
        d = origin_distance_m(GeoOrigin.from_dict(stored.source_origin), log.origin)
        if d > SOURCE_ORIGIN_M:
            reasons.append(
                f"its map origin is {d / 1000:.1f} km from the source's (more than "
                f"{SOURCE_ORIGIN_M / 1000:.0f} km)"
            )
    return "; ".join(reasons)


def _within_3_sigma(err: np.ndarray, sig: np.ndarray) -> list[float]:
    """Per axis, the fraction of epochs with |error| <= 3 sigma (0.997 for a consistent Gaussian)."""
    return np.mean(np.abs(err) <= 3 * sig, axis=0).tolist()


def evaluate_result(stored: StoredResult, log: LogData | None) -> Evaluation:
    """Errors against the log's truth (if any), observability verdict, segments credited."""
    res = stored.result
    ev = Evaluation(
        res.estimator, res.t, res.attitude_sigma_deg, res.position_sigma_m, res.velocity_sigma_m_s
    )
    m: dict[str, Any] = {
        "estimator": res.estimator,
        "result": stored.path,
        "states": len(res.t),
        "final": {
            k: getattr(stored.summary, k).model_dump()
            for k in ("scale", "misalignment_deg", "gyro_bias_deg_per_h", "accel_bias_ug")
        },
    }
    if log is not None and not stored.source_sha256:
        ev.notes.append(
            f"the result records no content hash of its source log (written by an older gtsam_dvl): "
            f"{log.source or 'the log'} is taken as its source on its stamps and origin alone"
        )
    if log is not None:
        ev.segments = log.segments or classify_log(log)
        m["segments_from"] = "simulation" if log.segments else "classified from IMU"
    if log is not None and log.truth is not None:
        ev.truth_errors = truth_errors(res, log)
        errors = trajectory_errors(res, log.truth)
        ev.attitude_error_deg, ev.position_error_m, ev.velocity_error_m_s = (
            errors.attitude_deg,
            errors.position_m,
            errors.velocity_m_s,
        )
        m["truth"] = {
            **errors.metrics(),
            "attitude_within_3_sigma": _within_3_sigma(
                ev.attitude_error_deg, ev.attitude_sigma_deg
            ),
            "position_within_3_sigma": _within_3_sigma(ev.position_error_m, ev.position_sigma_m),
            "velocity_within_3_sigma": _within_3_sigma(
                ev.velocity_error_m_s, ev.velocity_sigma_m_s
            ),
            "calibration_errors": ev.truth_errors,
        }
    config = result_config(res)
    if log is not None and log.gnss is not None:
        ev.gnss = surfacing_report(res, log, config)
        if ev.gnss is not None:
            m["gnss"] = ev.gnss.as_dict()
    if res.calib_joint_cov is not None:
        ev.report = analyse_block(
            res.calib_joint_cov,
            res.b_R_d,
            float(res.t[-1] - res.t[0]),
            config,
            lever_arm_cov=res.lever_arm_cov,
            time_offset_sigma_s=estimated_time_offset_sigma(res),
        )
        if res.timeline is not None:
            ev.determined_at_s = determined_at(ev.report, res.timeline)
            if ev.segments:
                ev.shares = attribute_segments(ev.report, res.timeline, ev.segments)
        m["observability"] = [
            {
                "key": s.key,
                "verdict": s.verdict,
                "prior_sigma": s.prior_sigma,
                "posterior_sigma": s.posterior_sigma,
                "ratio": s.ratio,
                "unit": s.unit,
                "determined_at_s": ev.determined_at_s.get(s.key),
                "credited_segments": s.credited_segments,
                "hours_to_halve": s.hours_to_halve,
            }
            for s in ev.report.all_states()
        ]
        m["answer"] = calibration_answer(ev.report, ev.determined_at_s, "log")[0]
        m["verdict"] = ev.lines()
    ev.metrics = m
    return ev
