"""Classify a log into the paper's segment types from its own data (no truth): static, Type I (constant
attitude with a varying specific force, found by the IO-DVLC detector), Type II (turning), cruise.

Thresholds (1 s windows): turning when the gyro rate exceeds TURN_RATE_DEG_S; static until the
alignment's static detection ends. Segments shorter than MIN_SEGMENT_S merge into their neighbour.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.core.config import AlignmentConfig
from gtsam_dvl.core.types import LogData, Segment
from gtsam_dvl.estimators.inputs.alignment import detect_static_end, window_means
from gtsam_dvl.estimators.inputs.mounting import imu_in_base_link
from gtsam_dvl.estimators.iodvlc import detect_type1_segments

TURN_RATE_DEG_S = 0.3
MIN_SEGMENT_S = 5.0


def classify_log(log: LogData) -> list[Segment]:
    """Segments covering the log: kinds static, type1 (with the specific-force axis in base_link), turn, cruise."""
    imu = imu_in_base_link(log.imu, log.mounting)
    ends, w_mean = window_means(imu.t, imu.b_omega)
    starts = ends - 1.0
    labels = np.where(
        np.degrees(np.linalg.norm(w_mean, axis=1)) > TURN_RATE_DEG_S, "turn", "cruise"
    ).astype(object)
    t_static = detect_static_end(imu, log.dvl, AlignmentConfig())
    labels[ends <= t_static] = "static"
    for k, seg in enumerate(detect_type1_segments(imu)):
        sel = (starts >= seg.start_s - 0.5) & (ends <= seg.end_s + 0.5) & (labels != "static")
        axis = "xyz"[int(np.argmax(np.abs(seg.axis)))]
        # '#k' keeps neighbours apart
        labels[sel] = f"type1 (specific-force rate along body {axis})#{k}"
    rows: list[dict[str, Any]] = []
    for s, e, lab in zip(starts, ends, labels, strict=True):
        if rows and rows[-1]["kind"] == lab:
            rows[-1]["end_s"] = float(e)
        else:
            rows.append({"start_s": float(s), "end_s": float(e), "kind": str(lab)})
    merged: list[dict[str, Any]] = []
    for row in rows:  # fold short blips into the previous segment
        if merged and row["end_s"] - row["start_s"] < MIN_SEGMENT_S:
            merged[-1]["end_s"] = row["end_s"]
        elif merged and merged[-1]["kind"] == row["kind"]:
            merged[-1]["end_s"] = row["end_s"]
        else:
            merged.append(row)
    for row in merged:
        row["kind"] = row["kind"].split("#")[0]
        row["type"] = (
            "I" if row["kind"].startswith("type1") else "II" if row["kind"] == "turn" else "-"
        )
    return [Segment.from_dict(row) for row in merged]
