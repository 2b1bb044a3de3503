"""The posterior against the prior: is any shared state far outside what its prior allowed?

Every shared state (core/states.py STATES: IMU biases, DVL scale, misalignment, time offset, lever arm) that the
run estimated is compared with its prior, per component of the state's tangent, in prior sigmas:

    z_i = (estimate - prior mean)_i / prior sigma_i

for the misalignment with the rotation's local coordinates about body axes, e = Log(b_R_d b_R_d0^T) (R_c's rotation
vector, b_R_d0 the nominal mounting from /tf_static that centres the prior). |z_i| > PRIOR_NSIGMA_FAILED is not
a calibration but a sign that the prior's centre is wrong (a mounting in /tf_static off by tens of degrees, a
wrong sound speed) or that the data are (a saturated gyro read as a bias or a scale): the run is "failed", with a
warning that names the state, the distance and the likely cause. A random-walk bias (a variable per state) is not
checked: its prior holds at the first state only, the final value may wander away from it by design. Nor is a state
whose prior came from a vehicle's calibration file (analysis/calibration_check.py judges those).

Pure computation on NavResult and LogData (analysis layer).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import so3_log
from gtsam_dvl.core.states import STATES, SharedState
from gtsam_dvl.core.types import LogData

# A state drawn from its prior lies beyond 4 sigma with probability 6e-5 per component; a clean log's estimate,
# pulled towards the prior by it, even less often. Further out the prior's centre is wrong, or the data are.
PRIOR_NSIGMA_FAILED = 4.0


@dataclass
class PriorDistance:
    """One state's estimate against its prior: per tangent component the distance in prior sigmas (z) and the
    offset in the state's display unit (estimate - prior; for the misalignment the rotation vector of
    b_R_d b_R_d0^T about body axes, deg)."""

    state: SharedState
    z: np.ndarray
    offset_display: np.ndarray

    @property
    def worst(self) -> int:
        return int(np.argmax(np.abs(self.z)))

    def as_dict(self) -> dict[str, Any]:
        return {
            "components": self.state.component_names(),
            "nsigma": self.z.tolist(),
            "offset": self.offset_display.tolist(),
            "unit": self.state.display_unit,
        }


@dataclass
class PriorReport:
    """Every checked state's distance from its prior, and the findings (severity, text) for the health."""

    distances: dict[str, PriorDistance] = field(default_factory=dict)
    findings: list[tuple[str, str]] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {name: d.as_dict() for name, d in self.distances.items()}


def prior_distances(
    result: NavResult, log: LogData, config: EstimatorConfig
) -> dict[str, PriorDistance]:
    """The distance of each estimated shared state from its prior (module doc). The prior is the configuration's,
    around the mounting the result was made with (its b_R_d0 from /tf_static, the log's lever arm)."""
    mounting = dataclasses.replace(log.mounting, b_R_d0=np.asarray(result.b_R_d0, dtype=float))
    out: dict[str, PriorDistance] = {}
    # judged by calibration_check.py
    from_file = (result.info.get("calibration_prior") or {}).get("states", [])
    for s in STATES:
        est = result.calibration.get(s.name)
        if est is None or not s.enabled(config) or s.per_state(config) or s.name in from_file:
            continue
        prior = s.prior(config, mounting)
        # R_c's rotation vector about body axes (the prior's sigmas are about them)
        if s.kind == "rot3":
            offset = so3_log(
                np.asarray(est.value, dtype=float) @ np.asarray(prior.value, dtype=float).T
            )
        else:
            offset = np.asarray(est.value, dtype=float) - np.asarray(prior.value, dtype=float)
        offset = np.asarray(offset, dtype=float).reshape(s.dim)
        out[s.name] = PriorDistance(s, offset / prior.sigma, offset * s.to_display)
    return out


def check_priors(result: NavResult, log: LogData, config: EstimatorConfig) -> PriorReport:
    """The distances from the priors and a "failed" finding per state beyond PRIOR_NSIGMA_FAILED prior sigmas."""
    report = PriorReport(prior_distances(result, log, config))
    peak_rate_deg_s = _peak_rate_deg_s(log)
    straight = heading_span_deg(result) < STRAIGHT_SPAN_DEG
    for d in report.distances.values():
        k = d.worst
        if not abs(d.z[k]) > PRIOR_NSIGMA_FAILED:  # nan: judged elsewhere (non-finite estimates)
            continue
        s = d.state
        what = s.component_texts()[k]
        # the forward axis on one heading: the pitch coupling
        if straight and s.name == "accel_bias" and k == 0:
            report.findings.append(("degraded", _pitch_coupling(what, d, s)))
            continue
        text = (
            f"{what} is {abs(d.z[k]):.1f} prior sigmas from its prior ({_amount(s, d.offset_display[k])} off; "
            f"the prior allows {PRIOR_NSIGMA_FAILED:g} sigmas): {_cause(s, d, config, peak_rate_deg_s)}; do not "
            "use this result"
        )
        report.findings.append(("failed", text))
    return report


# A run whose heading spans less than this is straight: its forward accelerometer bias and its pitch (and the
# DVL's pitch misalignment) trade against each other through gravity, g * d_pitch = d_bias, and only the priors and
# the small pitch motions tell them apart.
STRAIGHT_SPAN_DEG = 20.0


def heading_span_deg(result: NavResult) -> float:
    """The span of the estimated heading over the run (deg; the yaw of n_R_b, unwrapped)."""
    R = np.asarray(result.n_R_b, dtype=float)
    if not len(R):
        return float("nan")
    yaw = np.unwrap(np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    return float(np.degrees(yaw.max() - yaw.min()))


def _pitch_coupling(what: str, d: PriorDistance, s: SharedState) -> str:
    """The warning for a forward accelerometer bias far from its prior on a straight run (STRAIGHT_SPAN_DEG)."""
    # a bias of 1 micro-g is a pitch of 1e-6 rad
    pitch_deg = float(np.degrees(d.offset_display[0] * 1e-6))
    return (
        f"{what} is {abs(d.z[0]):.1f} prior sigmas from its prior ({_amount(s, d.offset_display[0])} off) on a "
        f"straight run: on one heading the forward accelerometer bias trades against the pitch (a pitch or DVL "
        f"pitch-misalignment error of {pitch_deg:+.3f} deg reads as this bias); not determined by this run, "
        "treat the along-track bias and the pitch with caution (a turn or a depth change separates them)"
    )


def _amount(s: SharedState, value: float) -> str:
    if s.name == "scale":
        return f"{value:+,.0f} ppm"
    if s.name == "time_offset":
        return f"{value / 1e3:+.3f} s"
    return f"{value:+.3g} {s.display_unit}"


def _peak_rate_deg_s(log: LogData) -> float:
    w = np.asarray(log.imu.b_omega, dtype=float)
    if not len(w):
        return float("nan")
    return float(np.degrees(np.nanmax(np.linalg.norm(w, axis=1))))


def _cause(
    s: SharedState, d: PriorDistance, config: EstimatorConfig, peak_rate_deg_s: float
) -> str:
    """The likely cause of a state far from its prior, and what to do, in words that name existing settings."""
    saturation = (
        f"IMU saturation? (an IMU axis clipping at its range, the gyro in fast turns, reads as a wrong "
        f"bias or scale; the peak body rate in this log is {peak_rate_deg_s:.1f} deg/s)"
    )
    if s.name == "misalignment":
        angle = float(np.linalg.norm(d.offset_display))
        return (
            f"the DVL mounting in /tf_static (base_link -> dvl_link) is off by {angle:.1f} deg; correct the "
            "mounting, or widen [priors] misalignment_sigma_deg if the DVL is mounted that loosely"
        )
    if s.name == "scale":
        return (
            "check the DVL's scale or its sound-speed setting (a speed of sound set wrong scales every "
            f"velocity), or widen [priors] scale_sigma; or {saturation}"
        )
    if s.name == "gyro_bias":
        return f"{saturation}; or a gyro bias beyond [imu] gyro_bias_sigma_deg_per_h"
    if s.name == "accel_bias":
        return (
            f"an accelerometer bias beyond [imu] accel_bias_sigma_ug, or a wrong IMU mounting in /tf_static; "
            f"or {saturation}"
        )
    if s.name == "time_offset":
        dt = float(d.offset_display[0]) / 1e3 + config.dvl.time_offset_prior_s
        sign = "early" if dt > 0 else "late"
        return (
            f"the time offset is beyond its prior (the DVL stamps {sign} by {abs(dt):.3f} s); set "
            "[dvl] time_offset_prior_s near it or widen [dvl] time_offset_sigma_s"
        )
    if s.name == "lever_arm":
        return (
            f"the DVL lever arm in /tf_static is off by {float(np.linalg.norm(d.offset_display)):.2f} m; "
            "correct the mounting, or widen [dvl] lever_arm_sigma_m"
        )
    return f"the prior of the {s.description} does not fit this log"
