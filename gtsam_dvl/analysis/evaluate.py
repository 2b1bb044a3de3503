"""`evaluate`: a stored result against the truth over time, and what the log made observable.

Works without truth (a real log): then only the observability analysis, the segment classification, the
sigma timelines and, when the log has GNSS fixes, the errors at the held-out fixes and the surfacing error
(analysis/surfacing.py: metrics["gnss"]) are reported.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.analysis.metrics import trajectory_errors
from gtsam_dvl.analysis.observability import ObservabilityReport, analyse_block, attribute_segments, result_config
from gtsam_dvl.analysis.segments import classify_log
from gtsam_dvl.analysis.surfacing import SurfacingReport, surfacing_report
from gtsam_dvl.core.result import StoredResult
from gtsam_dvl.core.types import LogData, Segment


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
    gnss: SurfacingReport | None = None  # held-out GNSS fixes and the surfacing error (log with fixes)


def _within_3_sigma(err: np.ndarray, sig: np.ndarray) -> list[float]:
    """Per axis, the fraction of epochs with |error| <= 3 sigma (0.997 for a consistent Gaussian)."""
    return np.mean(np.abs(err) <= 3 * sig, axis=0).tolist()


def evaluate_result(stored: StoredResult, log: LogData | None) -> Evaluation:
    """Errors against the log's truth (if any), observability verdict, segments credited."""
    res = stored.result
    ev = Evaluation(res.estimator, res.t, res.attitude_sigma_deg, res.position_sigma_m, res.velocity_sigma_m_s)
    m: dict[str, Any] = {"estimator": res.estimator, "result": stored.path, "states": len(res.t),
                         "final": {k: stored.summary.get(k) for k in ("scale", "misalignment_deg",
                                                                      "gyro_bias_deg_per_h", "accel_bias_ug")}}
    if log is not None:
        ev.segments = log.segments or classify_log(log)
        m["segments_from"] = "simulation" if log.segments else "classified from IMU"
    if log is not None and log.truth is not None:
        errors = trajectory_errors(res, log.truth)
        ev.attitude_error_deg, ev.position_error_m, ev.velocity_error_m_s = (
            errors.attitude_deg, errors.position_m, errors.velocity_m_s)
        m["truth"] = {
            **errors.metrics(),
            "attitude_within_3_sigma": _within_3_sigma(ev.attitude_error_deg, ev.attitude_sigma_deg),
            "position_within_3_sigma": _within_3_sigma(ev.position_error_m, ev.position_sigma_m),
            "velocity_within_3_sigma": _within_3_sigma(ev.velocity_error_m_s, ev.velocity_sigma_m_s),
            "calibration_errors": stored.summary.get("errors", {}),
        }
    config = result_config(res)
    if log is not None and log.gnss is not None:
        ev.gnss = surfacing_report(res, log, config)
        if ev.gnss is not None:
            m["gnss"] = ev.gnss.as_dict()
    if res.calib_joint_cov is not None:
        ev.report = analyse_block(res.calib_joint_cov, res.b_R_d, float(res.t[-1] - res.t[0]), config,
                                  lever_arm_cov=res.lever_arm_cov)
        if res.timeline is not None and ev.segments:
            ev.shares = attribute_segments(ev.report, res.timeline, ev.segments)
        m["observability"] = [{"key": s.key, "verdict": s.verdict, "prior_sigma": s.prior_sigma,
                               "posterior_sigma": s.posterior_sigma, "ratio": s.ratio,
                               "credited_segments": s.credited_segments, "hours_to_halve": s.hours_to_halve}
                              for s in ev.report.states]
        m["verdict"] = ev.report.lines()
    ev.metrics = m
    return ev
