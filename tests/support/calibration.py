"""A vehicle calibration at a simulated log's truth and the short logs that inform it (or not), shared by the
calibration-file tests (tests/estimators/test_calibration_prior.py, tests/app/test_calibration_files.py,
tests/analysis/test_calibration_check.py)."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.types import LogData

STATIC = [{"kind": "static", "duration_s": 60.0}]
# 60 s static, a surge and a descent: the scale and misalignment informed, to a few tenths of a percent / degree
MOVING = STATIC + [
    {"kind": "level", "duration_s": 15.0, "speed_end_m_s": 2.0},
    {"kind": "level", "duration_s": 45.0, "speed_bump_m_s": 0.5},
    {"kind": "descent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
]


def calibration_at_truth(log: LogData, scale_off: float = 0.0) -> VehicleCalibration:
    """A calibration at the log's true scale (times 1 + scale_off), misalignment and time offset: scale 500 ppm,
    misalignment 0.05 / 0.05 / 0.1 deg, time offset 5 ms, the scale and yaw correlated (0.5)."""
    truth = log.true_calibration
    assert truth is not None
    sig = np.array([5e-4, *np.radians([0.05, 0.05, 0.1]), 5e-3])
    corr = np.eye(5)
    corr[0, 3] = corr[3, 0] = 0.5
    values = {
        "scale": np.array([truth.scale * (1.0 + scale_off)]),
        "misalignment": truth.b_R_d(log.mounting.b_R_d0),
        "time_offset": np.array([truth.time_offset_s]),
    }
    return VehicleCalibration(
        "auv-7",
        "2023-11-01T00:00:00Z",
        ("scale", "misalignment", "time_offset"),
        values,
        np.outer(sig, sig) * corr,
    )
