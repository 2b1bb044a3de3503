"""Results for the tests: two estimators' results compared, and hand-made results (a vehicle at rest, final
estimates at their nominal values)."""

from __future__ import annotations

from typing import Any

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


def resting_result(t: np.ndarray, **fields: Any) -> NavResult:
    """A batch smoother's NavResult at the times t (s): at rest at the map origin, level, unit pose and velocity
    covariances, the nominal DVL mounting the identity; the other fields as given."""
    n = len(t)
    return NavResult(
        "batch",
        t,
        np.zeros((n, 3)),
        np.tile(np.eye(3), (n, 1, 1)),
        np.zeros((n, 3)),
        np.tile(np.eye(6), (n, 1, 1)),
        np.tile(np.eye(3), (n, 1, 1)),
        b_R_d0=np.eye(3),
        **fields,
    )


def nominal_estimates(bias_var: float) -> dict[str, Any]:
    """NavResult's final-estimate fields at their nominal values: zero biases (their covariance bias_var times
    the identity), the scale 1 +- 1e-4, the mounting the identity (its covariance 1e-8 rad^2 per axis)."""
    return {
        "accel_bias": np.zeros(3),
        "gyro_bias": np.zeros(3),
        "bias_cov": np.eye(6) * bias_var,
        "scale": 1.0,
        "scale_sigma": 1e-4,
        "b_R_d": np.eye(3),
        "b_R_d_cov": np.eye(3) * 1e-8,
    }
