"""Comparisons of two estimators' results for the tests."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.result import NavResult


def changes_in_sigmas(
    a: NavResult, b: NavResult, *, final_position: bool = False
) -> dict[str, np.ndarray]:
    """(a - b) / b's sigma for the final calibration: scale, misalignment (deg), accelerometer bias (micro-g),
    gyro bias (deg/h), and with final_position the final position (m, map axes)."""
    out = {
        "scale": np.array([(a.scale - b.scale) / b.scale_sigma]),
        "misalignment": (a.misalignment_deg - b.misalignment_deg) / b.misalignment_sigma_deg,
        "accel bias": (a.accel_bias_ug - b.accel_bias_ug) / b.accel_bias_sigma_ug,
        "gyro bias": (a.gyro_bias_deg_per_h - b.gyro_bias_deg_per_h) / b.gyro_bias_sigma_deg_per_h,
    }
    if final_position:
        out["final position"] = (a.n_p[-1] - b.n_p[-1]) / b.position_sigma_m[-1]
    return out
