"""Honest about weak geometry: which calibration direction a log left leaning on its prior or tied to another
state, why (the motion), and which manoeuvre would separate them.

`assess_geometry(result)` reads the joint covariance of the shared states at the last state
(NavResult.shared_joint_cov, columns from core/states.py joint_states; the calibration block calib_joint_cov
when a result has only that, e.g. the online estimator's) in display units, the misalignment about body axes.
For each calibration direction (a state of the vehicle: scale, misalignment roll / pitch / yaw, time offset,
lever arm; SharedState.vehicle) it finds

- ratio = posterior sigma / prior sigma: above LEANS_ON_PRIOR the log taught it little, the estimate "leans on
  its prior";
- its strongest correlation with another state (bias or calibration); beyond CORRELATED the two trade against
  each other (scale against the horizontal accelerometer bias in a steady turn: a bias b along the turn's
  radius and a scale error k look alike when the speed v and the turn rate w stay constant, b = k v w);

and reports a Finding when either holds, with the motion the trajectory made (classify_motion: straight, steady
turn, varied; level or not) to say why and which manoeuvre separates them (straight: a turn separates the yaw
misalignment from the heading; steady turn: a speed change or an S-turn; no depth change: a descent or an
ascent separates the misalignment about the thrust axis).

Its severity: a weak direction whose one sigma moves this log's horizontal track by more than
MATTERS_FRACTION of the distance travelled is "warn" (the estimate is honest if its sigma covers the error,
but the position rests on the prior being right); a weak direction that hardly moves the track (the roll
misalignment of a level run: the DVL velocity has almost no component across the thrust axis) is a "note".
The track shift of direction c is sigma_c max_t |int_0^t g_c dt| over the horizontal map components, g_c the
velocity change one unit of c makes: n_v for the scale, n_R_b (a x b_v) for a misalignment about body axis a,
the velocity rate for the time offset, n_R_b (b_omega x a) for the lever arm along a.

Pure computation on a NavResult (analysis layer).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import block_diag

from gtsam_dvl.analysis.observability import fraction_text, number_text
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.states import SharedState, block_states, joint_states

# A calibration direction whose posterior sigma is above half its prior's "leans on its prior": the log gave it
# less information than the prior did (the observability verdict's DETERMINED threshold).
LEANS_ON_PRIOR = 0.5
# |correlation| above this: the two states trade against each other; the data fix only their combination
# (at 0.9 the combination's sigma is under half of either's, sqrt(1 - 0.9^2) = 0.44).
CORRELATED = 0.9
# Motion classes (classify_motion), on the states where the vehicle moves faster than MOVING_SPEED_M_S (the
# health check's "never moves" speed):
MOVING_SPEED_M_S = 0.1
# straight: the heading spans less than this; below it a turn teaches the yaw misalignment little (the DVL's
# velocity turns by at most sin(20 deg) = 0.34 of itself against the heading)
STRAIGHT_HEADING_DEG = 20.0
# the speed is "nearly constant" when its 5-95 % spread is below this fraction of its median (a speed change of
# 10 % over a 2 m/s run is 0.2 m/s, ten times the DVL noise)
STEADY_SPEED_SPREAD = 0.1
# a turn is "steady" when its rate's 5-95 % spread is below this fraction of its median rate, and at least
# MIN_TURN_RATE_DEG_S (a slower heading drift is a straight track's)
STEADY_TURN_SPREAD = 0.5
MIN_TURN_RATE_DEG_S = 0.1
# "no depth change" (level): the depth spans less than this (m), or the vertical speed stays below
# LEVEL_VERTICAL_SPEED_M_S (99th percentile: an estimate without a depth sensor drifts a few metres in height
# at mm/s, a descent is tenths of m/s); the misalignment about the thrust axis shows only in the vertical (and
# lateral) velocity
DEPTH_CHANGE_M = 2.0
LEVEL_VERTICAL_SPEED_M_S = 0.05
# a weak direction "matters" (warn) when one sigma of it moves the horizontal track by more than this fraction
# of the distance travelled (0.1 %: the accuracy of a good DVL-aided INS, 0.1-0.3 % of distance)
MATTERS_FRACTION = 1e-3

# the directions a depth change separates (their sentence says "with no depth change" on a level log)
DEPTH_COLUMNS = ("misalignment roll", "misalignment pitch")
# Directions a motion cannot determine at all, whatever an estimator's sigma says: on a straight track the yaw
# misalignment trades exactly with the direction of the velocity (nothing measures that direction). A smaller
# sigma there is not information: an EKF, linearised at a different estimate at every update, gains it spuriously
# (measured on straight-transect, 50 runs: the EKF's yaw sigma 0.21 deg, the batch smoother's 0.85 deg of the
# 1 deg prior, the EKF's estimate held at nominal). Reported with the prior's sigma.
UNDETERMINED = {("misalignment yaw", "straight")}
MANOEUVRES = {
    # (column, motion kind) -> the manoeuvre that separates it; (column, "") for any motion
    ("scale", "steady turn"): "a speed change or an S-turn",
    ("scale", "straight"): "a speed change or a turn",
    ("scale", ""): "speed changes and turns both ways",
    ("misalignment yaw", "straight"): "a turn",
    ("misalignment yaw", "steady turn"): "a speed change or an S-turn",
    ("misalignment yaw", ""): "turns both ways and speed changes",
    ("misalignment pitch", ""): "a depth change or a speed change",
    ("misalignment roll", "level"): "a depth change (a descent or an ascent)",
    ("misalignment roll", ""): "a depth change with the vehicle level (a descent or an ascent)",
    ("time offset", ""): "speed changes and turns (accelerations)",
    ("lever arm x", ""): "turns (rotation about the vertical)",
    ("lever arm y", ""): "turns (rotation about the vertical)",
    ("lever arm z", ""): "roll or pitch motion (turns about the vertical leave it unobserved)",
}


@dataclass
class MotionSummary:
    """What the trajectory did while moving: kind "straight", "steady turn", "varied" or "static"; whether it
    kept its depth (level); the heading's span (deg), the speed's median (m/s) and 5-95 % spread (fraction of
    the median), the turn rate's median (deg/s), the depth's span (m) and the horizontal distance (m)."""

    kind: str
    level: bool
    heading_change_deg: float = 0.0
    speed_m_s: float = 0.0
    speed_spread: float = 0.0
    turn_rate_deg_s: float = 0.0
    depth_change_m: float = 0.0
    distance_m: float = 0.0

    def during(self, depth: bool = False) -> str:
        """The motion in words, for a sentence: "during a steady turn", "on a straight track"; depth: say "with no
        depth change" when level."""
        text = {
            "straight": "on a straight track",
            "steady turn": "during a steady turn",
            "varied": "in this log's manoeuvres",
            "static": "on a static log",
        }[self.kind]
        if depth and self.level and self.kind != "static":
            text += " with no depth change"
        return text

    def line(self) -> str:
        """One console line."""
        if self.kind == "static":
            return "motion: static"
        return (
            f"motion: {self.kind}{', level' if self.level else ''} ({self.heading_change_deg:.0f} deg of heading, "
            f"turn rate {self.turn_rate_deg_s:+.2f} deg/s; speed {self.speed_m_s:.2f} m/s +- "
            f"{100 * self.speed_spread / 2:.0f} %; depth span {self.depth_change_m:.1f} m; "
            f"{self.distance_m:.0f} m travelled)"
        )


def classify_motion(
    t: np.ndarray, n_R_b: np.ndarray, n_v: np.ndarray, n_p: np.ndarray
) -> MotionSummary:
    """The motion of a trajectory (map frame ENU; module constants): straight (heading span below
    STRAIGHT_HEADING_DEG, speed nearly constant), steady turn (turn rate nearly constant, speed nearly constant),
    varied (anything else), static (never faster than MOVING_SPEED_M_S)."""
    t, n_v, n_p = (
        np.asarray(t, dtype=float),
        np.asarray(n_v, dtype=float),
        np.asarray(n_p, dtype=float),
    )
    speed = np.linalg.norm(n_v, axis=1)
    moving = speed > MOVING_SPEED_M_S
    distance = (
        float(np.linalg.norm(np.diff(n_p[:, :2], axis=0), axis=1).sum()) if len(n_p) > 1 else 0.0
    )
    if moving.sum() < 3:
        return MotionSummary("static", True, distance_m=distance)
    heading = np.degrees(np.unwrap(np.arctan2(n_R_b[moving, 1, 0], n_R_b[moving, 0, 0])))
    rate = (
        np.gradient(heading, t[moving])
        if np.all(np.diff(t[moving]) > 0)
        else np.zeros(int(moving.sum()))
    )
    s5, s50, s95 = np.percentile(speed[moving], [5, 50, 95])
    r5, r50, r95 = np.percentile(rate, [5, 50, 95])
    span = float(heading.max() - heading.min())
    depth = float(np.ptp(n_p[moving, 2]))
    steady_speed = (s95 - s5) <= STEADY_SPEED_SPREAD * s50
    if span < STRAIGHT_HEADING_DEG and steady_speed:
        kind = "straight"
    elif (
        steady_speed
        and abs(r50) >= MIN_TURN_RATE_DEG_S
        and (r95 - r5) <= STEADY_TURN_SPREAD * abs(r50)
    ):
        kind = "steady turn"
    else:
        kind = "varied"
    level = (
        depth < DEPTH_CHANGE_M
        or float(np.percentile(np.abs(n_v[moving, 2]), 99)) < LEVEL_VERTICAL_SPEED_M_S
    )
    return MotionSummary(
        kind, level, span, float(s50), float((s95 - s5) / s50), float(r50), depth, distance
    )


def motion_of(result: NavResult) -> MotionSummary:
    """classify_motion on a result's estimated trajectory."""
    return classify_motion(result.t, result.n_R_b, result.n_v, result.n_p)


@dataclass
class Finding:
    """A weak calibration direction: its column (states.joint_columns), posterior / prior sigma ratio, the
    state it is most correlated with and the correlation (when beyond CORRELATED; "" and 0 otherwise), the
    motion, the manoeuvre that separates them, how far one sigma of it moves the horizontal track (m, and % of
    the distance), the severity ("warn" or "note") and the sentence."""

    column: str
    ratio: float
    partner: str
    correlation: float
    motion: str
    manoeuvre: str
    track_shift_m: float
    track_shift_pct: float
    severity: str
    message: str


@dataclass
class GeometryReport:
    motion: MotionSummary
    findings: list[Finding] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"motion": asdict(self.motion), "findings": [asdict(f) for f in self.findings]}


def _covariance(
    result: NavResult, config: EstimatorConfig
) -> tuple[np.ndarray, list[SharedState]] | None:
    """The joint covariance and its states: shared_joint_cov (with or without the states the EKF does not carry),
    else the calibration block; None when the result has neither."""
    if result.shared_joint_cov is not None:
        cov = np.asarray(result.shared_joint_cov, dtype=float)
        for states in (joint_states(config), joint_states(config, ekf=True)):
            if sum(s.dim for s in states) == cov.shape[0]:
                return cov, states
    if result.calib_joint_cov is not None:
        return np.asarray(result.calib_joint_cov, dtype=float), block_states()
    return None


def _track_shift(result: NavResult, state: SharedState) -> np.ndarray:
    """(dim,) the largest horizontal shift of the track (m) that one display unit of each of the state's
    components makes (module doc), 0 for a state that does not enter the DVL velocity this way (the biases)."""
    t = np.asarray(result.t, dtype=float)
    n = len(t)
    if n < 2:
        return np.zeros(state.dim)
    n_R_b, n_v = np.asarray(result.n_R_b), np.asarray(result.n_v)
    b_v = np.einsum("nji,nj->ni", n_R_b, n_v)
    axes = np.eye(3)
    if state.name == "scale":
        g = n_v[:, None, :]
    elif state.name == "misalignment":
        g = np.einsum("nij,naj->nai", n_R_b, np.cross(axes[None, :, :], b_v[:, None, :]))
    elif state.name == "time_offset":
        g = np.gradient(n_v, t, axis=0)[:, None, :]
    elif state.name == "lever_arm":
        b_omega = np.zeros((n, 3)) if result.b_omega is None else np.asarray(result.b_omega)
        g = np.einsum("nij,naj->nai", n_R_b, np.cross(b_omega[:, None, :], axes[None, :, :]))
    else:
        return np.zeros(state.dim)
    dt = np.diff(t)[:, None, None]
    shift = np.concatenate(
        [np.zeros((1,) + g.shape[1:]), np.cumsum(0.5 * (g[1:] + g[:-1]) * dt, axis=0)]
    )
    return np.linalg.norm(shift[:, :, :2], axis=2).max(axis=0) / state.to_display


def _words(state: SharedState, suffix: str) -> str:
    return f"{state.description} {suffix}".strip()


def assess_geometry(
    result: NavResult, motion: MotionSummary | None = None, config: EstimatorConfig | None = None
) -> GeometryReport:
    """The weak calibration directions of a result (module doc). motion: the log's (default: classify_motion on
    the result's trajectory); config: the priors (default: the result's configuration)."""
    motion = motion if motion is not None else motion_of(result)
    report = GeometryReport(motion)
    config = config or result.estimator_config or EstimatorConfig()
    found = _covariance(result, config)
    if found is None or motion.kind == "static" or not len(result.t):
        return report
    cov, states = found
    # display units, the misalignment about body axes (its right tangent turned by b_R_d)
    J = block_diag(
        *[
            s.display_jacobian(np.asarray(result.b_R_d) if s.kind == "rot3" else np.zeros(s.dim))
            for s in states
        ]
    )
    cov = J @ cov @ J.T
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    prior = np.concatenate([s.prior_display_sigma(config) for s in states])
    corr = cov / np.outer(np.where(sigma > 0, sigma, 1.0), np.where(sigma > 0, sigma, 1.0))
    columns = [
        (s, suffix, f"{s.name.replace('_', ' ')} {suffix}".strip())
        for s in states
        for suffix, _ in s.components
    ]
    shifts = np.concatenate([_track_shift(result, s) for s in states])
    # a state whose prior is a vehicle's calibration file leans on it by design (analysis/calibration_check.py)
    from_file = (result.info.get("calibration_prior") or {}).get("states", [])
    for c, (state, _, name) in enumerate(columns):
        if not state.vehicle or not prior[c] > 0 or state.name in from_file:
            continue
        ratio = float(sigma[c] / prior[c])
        others = np.abs(np.where(np.arange(len(columns)) == c, 0.0, corr[c]))
        j = int(np.argmax(others))
        rho = float(corr[c, j])
        claimed = (name, motion.kind) in UNDETERMINED and ratio <= LEANS_ON_PRIOR
        if ratio <= LEANS_ON_PRIOR and abs(rho) <= CORRELATED and not claimed:
            continue
        # a sigma the motion cannot support is judged at the prior's
        s_c = float(prior[c]) if claimed else float(sigma[c])
        report.findings.append(
            _finding(
                name,
                ratio,
                columns[j] if abs(rho) > CORRELATED else None,
                rho,
                motion,
                s_c * float(shifts[c]),
                state,
                float(sigma[c]),
                claimed,
            )
        )
    return report


def _finding(
    name: str,
    ratio: float,
    partner: tuple[SharedState, str, str] | None,
    rho: float,
    motion: MotionSummary,
    shift_m: float,
    state: SharedState,
    sigma: float,
    claimed: bool = False,
) -> Finding:
    kind = "level" if name == "misalignment roll" and motion.level else motion.kind
    manoeuvre = MANOEUVRES.get((name, kind)) or MANOEUVRES.get((name, ""), "more varied motion")
    head = (
        f"{name} leans on its prior"
        if ratio > LEANS_ON_PRIOR
        else f"{name} is tied to another state"
    )
    if claimed:
        head = f"{name} cannot be determined"
    during = motion.during(depth=name in DEPTH_COLUMNS)
    verb = "separates" if manoeuvre.startswith(("a ", "an ")) else "separate"
    if partner is not None:
        text = (
            f"{head}: correlated {rho:.2f} with {_words(partner[0], partner[1])} {during}; "
            f"{manoeuvre} {verb} them"
        )
    else:
        text = f"{head} {during}; {manoeuvre} {verb} it" + (
            " from the heading" if name == "misalignment yaw" and motion.kind == "straight" else ""
        )
    pct = 100.0 * shift_m / motion.distance_m if motion.distance_m > 0 else 0.0
    matters = motion.distance_m > 0 and shift_m > MATTERS_FRACTION * motion.distance_m
    if claimed:
        text += (
            f" (its sigma, {number_text(sigma)} {state.display_unit}, {fraction_text(ratio)} of the prior's, "
            f"claims information this motion does not hold: a filter's linearisation gains it spuriously; one "
            f"prior sigma moves the track by up to {shift_m:.2g} m, {pct:.2g} % of the {motion.distance_m:.0f} m "
            f"travelled)"
        )
    else:
        text += (
            f" (sigma {number_text(sigma)} {state.display_unit}, {fraction_text(ratio)} of the prior's; one "
            f"sigma moves the track by up to {shift_m:.2g} m, {pct:.2g} % of the {motion.distance_m:.0f} m "
            f"travelled" + ("" if matters else ": little for this log") + ")"
        )
    return Finding(
        name,
        ratio,
        "" if partner is None else partner[2],
        rho if partner is not None else 0.0,
        motion.kind,
        manoeuvre,
        shift_m,
        pct,
        "warn" if matters else "note",
        text,
    )
