"""Observability from marginal covariances: which calibration and bias directions a log determined. Every
verdict on the shared states lives here; their rows, units, priors and targets come from the registry
(core/states.py).

The calibration and bias block's posterior covariance (from any estimator) is compared with its prior:
per state, ratio = posterior sigma / prior sigma; for directions, the eigen-decomposition of the
prior-whitened posterior covariance P0^-1/2 Sigma P0^-1/2, whose eigenvalues are squared ratios along
combinations of states (e.g. the misalignment about the thrust axis together with a bias). A ratio near 1
means the data said nothing about that direction; near 0, the data fixed it.

Verdicts per state, against a useful accuracy (the [observability] targets, core/config/sections.py ObservabilityConfig:
scale 0.1 %, misalignment 0.1 deg, biases half the paper's priors): "determined" when the posterior sigma is at or below
the target and the log informed the state (ratio <= NOT_DETERMINED); "weakly determined" when informed but above the
target; "not determined" when ratio > NOT_DETERMINED (the log gave it little; said when the prior alone already meets
the target). Directions and the lever arm are judged on the ratio: <= DETERMINED "determined". For states not determined
the information gained per hour of this log tells how long a similar mission would need to halve the prior sigma.

With [dvl] estimate_lever_arm the lever arm b_l (m, base_link) is judged per axis too (ObservabilityReport.
lever_arm, from NavResult.lever_arm_cov against [dvl] lever_arm_sigma_m), with a stricter threshold
(LEVER_DETERMINED): a metre-sized prior that only halves still leaves the DVL's velocity wrong by b_omega x
half a metre in turns. It enters the DVL model only as b_omega x b_l, so it is observable only from rotation:
its component along the rotation axis of every turn of the log is not (turns about the vertical leave b_l's z
undetermined, and a straight run determines none of it). It is not part of the direction analysis.

With [dvl] estimate_time_offset the DVL time offset is "determined" when its sigma falls below
TIME_OFFSET_DETERMINED of its prior's (time_offset_verdict, the summary's dvl_time_offset_s).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import block_diag

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.core.states import BY_NAME, SharedState, block_states
from gtsam_dvl.core.types import LogData, Mounting, Segment

DETERMINED = 0.5
NOT_DETERMINED = 0.9
# the lever arm's "determined": posterior sigma below a third of the prior's
LEVER_DETERMINED = 1.0 / 3.0
# the time offset's "determined": posterior sigma below a tenth of the prior's
TIME_OFFSET_DETERMINED = 0.1


def _rows(states: list[SharedState]) -> list[tuple[str, str, str]]:
    """(key, description, display unit) of each tangent component of the states, in their order."""
    return [
        (key, text, s.display_unit)
        for s in states
        for key, text in zip(s.component_names(), s.component_texts(), strict=True)
    ]


# the calibration block's components (core/states.py block_states): accelerometer and gyro bias, scale, misalignment
STATES = _rows(block_states())


def verdict_of(ratio: float) -> str:
    if ratio <= DETERMINED:
        return "determined"
    if ratio <= NOT_DETERMINED:
        return "weakly determined"
    return "not determined"


@dataclass
class StateVerdict:
    key: str
    description: str
    unit: str
    prior_sigma: float
    posterior_sigma: float
    ratio: float
    verdict: str
    # at this log's information rate; None when already determined
    hours_to_halve: float | None = None
    credited_segments: list[str] = field(default_factory=list)  # filled by attribute_segments

    target_sigma: float | None = None  # the useful accuracy it is judged against ([observability])
    subject: str = "log"  # what informed it: "log", or "plan" for the mission planner

    def sentence(self) -> str:
        s = (
            f"{self.description}: {self.verdict}; prior sigma {number_text(self.prior_sigma)} {self.unit}, "
            f"posterior {number_text(self.posterior_sigma)} {self.unit} ({fraction_text(self.ratio)} of the prior)"
        )
        if self.target_sigma is not None:
            s += f", target {number_text(self.target_sigma)} {self.unit}"
            if self.verdict == "not determined" and self.prior_sigma <= self.target_sigma:
                s += " (the prior alone meets it)"
        if self.credited_segments:
            s += f"; informed during {', '.join(self.credited_segments)}"
        if self.hours_to_halve is not None:
            s += (
                f"; at this {self.subject}'s rate a mission of {self.hours_to_halve:.1f} h would halve the prior "
                "sigma"
                if np.isfinite(self.hours_to_halve)
                else f"; this {self.subject} gives it no information"
            )
        return s


def fraction_text(ratio: float) -> str:
    """A posterior/prior ratio in words with significant digits: "26 %", "3.1 %", "1/640"."""
    if ratio >= 0.0995:
        return f"{100 * ratio:.0f} %"
    if ratio >= 0.01:
        return f"{100 * ratio:.2g} %"
    if ratio <= 0:
        return "0"
    n = 1.0 / ratio
    step = 10.0 ** max(np.floor(np.log10(n)) - 1, 0)  # two significant digits: 1/640, 1/1400
    return f"1/{int(round(n / step) * step)}"


def number_text(x: float) -> str:
    """A sigma for sentences: whole numbers from 100 up ("500,000", "780"), else three significant digits."""
    return f"{x:,.0f}" if abs(x) >= 100 else f"{x:.3g}"


@dataclass
class DirectionVerdict:
    ratio: float
    verdict: str
    weights: dict[
        str, float
    ]  # squared components of the unit eigenvector (prior-whitened), largest first

    def sentence(self) -> str:
        parts = ", ".join(f"{STATE_TEXT[k]} ({100 * w:.0f} %)" for k, w in self.weights.items())
        return f"{self.verdict} direction ({fraction_text(self.ratio)} of the prior): {parts}"


LEVER_ARM_STATES = _rows([BY_NAME["lever_arm"]])
LEVER_ARM_NOTE = (
    "the lever arm is observable only from rotation (it enters the DVL velocity as b_omega x b_l): "
    "a lever arm along the rotation axis of every turn is not, so turns about the vertical leave its "
    "z component undetermined and a run without turns determines none of it"
)

STATE_TEXT = {k: d for k, d, _ in STATES + LEVER_ARM_STATES}


@dataclass
class ObservabilityReport:
    states: list[StateVerdict]
    directions: list[DirectionVerdict]  # sorted from least to best determined
    duration_s: float
    # x, y, z with [dvl] estimate_lever_arm
    lever_arm: list[StateVerdict] = field(default_factory=list)
    time_offset: list[StateVerdict] = field(default_factory=list)  # with [dvl] estimate_time_offset

    def for_plan(self) -> ObservabilityReport:
        """The same report worded for a mission plan ("this plan's rate", not "this log's")."""
        for s in self.all_states():
            s.subject = "plan"
        return self

    def all_states(self) -> list[StateVerdict]:
        """Every estimated shared state's verdict: the calibration block's, the time offset's, the lever arm's."""
        return self.states + self.time_offset + self.lever_arm

    def state(self, key: str) -> StateVerdict:
        return next(s for s in self.all_states() if s.key == key)

    def lines(self) -> list[str]:
        out = ["Per state:"] + [f"  - {s.sentence()}" for s in self.states]
        if self.lever_arm:
            out.append("DVL lever arm (IMU -> DVL, base_link), estimated:")
            out += [f"  - {s.sentence()}" for s in self.lever_arm]
            if any(s.verdict != "determined" for s in self.lever_arm):
                out.append(f"  ({LEVER_ARM_NOTE})")
        if self.time_offset:
            out.append("DVL-IMU time offset, estimated:")
            out += [f"  - {s.sentence()}" for s in self.time_offset]
        return out + self.direction_lines()

    def direction_lines(self) -> list[str]:
        """The directions of the calibration and bias block not determined, or a line saying all are."""
        weak = [d for d in self.directions if d.verdict != "determined"]
        if not weak:
            return ["Every direction of the calibration and bias block is determined."]
        subject = self.states[0].subject if self.states else "log"
        return [f"Directions the {subject} did not fully determine (combinations of states):"] + [
            f"  - {d.sentence()}" for d in weak
        ]


def _user_units_jacobian(b_R_d: np.ndarray) -> np.ndarray:
    """d(user units)/d(tangent) of the calibration block (states.SharedState.display_jacobian): micro-g, deg/h,
    ppm, and degrees about body axes (body rotation = b_R_d * right tangent)."""
    return block_diag(
        *[
            s.display_jacobian(np.asarray(b_R_d) if s.kind == "rot3" else np.zeros(s.dim))
            for s in block_states()
        ]
    )


def prior_sigmas(config: EstimatorConfig) -> np.ndarray:
    """Prior sigmas of the block in user units (micro-g, deg/h, ppm, deg)."""
    return np.concatenate([s.prior_display_sigma(config) for s in block_states()])


def target_sigmas(config: EstimatorConfig) -> np.ndarray:
    """The [observability] targets in the order of STATES, user units (micro-g, deg/h, ppm, deg)."""
    return np.concatenate(
        [
            np.full(s.dim, s.target(config.observability) if s.target else np.nan, dtype=float)
            for s in block_states()
        ]
    )


def state_verdict(ratio: float, posterior: float, target: float) -> str:
    """The verdict of one state (module doc): informed (ratio <= NOT_DETERMINED) and at or below its target."""
    if ratio > NOT_DETERMINED:
        return "not determined"
    return "determined" if posterior <= target else "weakly determined"


def determined_threshold(prior: float, target: float) -> float:
    """The sigma at or below which a state is "determined" (state_verdict): the target, and informed."""
    return min(target, NOT_DETERMINED * prior)


def analyse(result: NavResult, config: EstimatorConfig | None = None) -> ObservabilityReport:
    """Per-state and per-direction verdicts from result.calib_joint_cov and the configuration's priors (and
    the lever arm's per axis from result.lever_arm_cov, the time offset's from its sigma, when estimated)."""
    if result.calib_joint_cov is None:
        raise ValueError("the result has no joint covariance of the calibration and bias block")
    if config is None:
        config = result_config(result)
    return analyse_block(
        result.calib_joint_cov,
        result.b_R_d,
        float(result.t[-1] - result.t[0]),
        config,
        result.lever_arm_cov,
        estimated_time_offset_sigma(result),
    )


def estimated_time_offset_sigma(result: NavResult) -> float | None:
    """The DVL time offset's posterior sigma (s) when the result estimated it, else None."""
    sigma = float(result.time_offset_sigma_s)
    return sigma if np.isfinite(sigma) else None


def _state_verdict(
    key: str, text: str, unit: str, prior: float, post: float, duration_h: float, determined: float
) -> StateVerdict:
    """One state's verdict: ratio = posterior / prior sigma, "determined" at or below `determined`, and for
    the others the hours a similar mission would need to halve the prior sigma (as in analyse_block)."""
    ratio = float(min(post / prior, 1.0))
    verdict = (
        "determined"
        if ratio <= determined
        else "weakly determined"
        if ratio <= NOT_DETERMINED
        else "not determined"
    )
    hours = None
    if verdict != "determined":
        gained = 1.0 / post**2 - 1.0 / prior**2
        info_rate = gained / max(duration_h, 1e-9) if gained > 0.01 / prior**2 else 0.0
        hours = float(3.0 / prior**2 / info_rate) if info_rate > 0 else float("inf")
    return StateVerdict(key, text, unit, float(prior), float(post), ratio, verdict, hours)


def result_config(result: NavResult) -> EstimatorConfig:
    """The configuration the result was made with (GtsamDvlError if it does not read)."""
    if result.estimator_config is None:
        raise GtsamDvlError(
            "the result's configuration does not read (a result of another gtsam_dvl version)"
        )
    return result.estimator_config


def lever_arm_verdicts(
    lever_arm_cov: np.ndarray, prior_sigma_m: float, duration_s: float
) -> list[StateVerdict]:
    """Per base_link axis, whether the log determined the lever arm: its marginal sigma (from the 3x3
    covariance, m^2) against the prior's ([dvl] lever_arm_sigma_m), "determined" below LEVER_DETERMINED."""
    post = np.sqrt(np.diag(np.asarray(lever_arm_cov, dtype=float)))
    return [
        _state_verdict(
            key,
            text,
            unit,
            float(prior_sigma_m),
            float(post[i]),
            duration_s / 3600.0,
            LEVER_DETERMINED,
        )
        for i, (key, text, unit) in enumerate(LEVER_ARM_STATES)
    ]


def time_offset_verdicts(
    sigma_s: float, config: EstimatorConfig, duration_s: float
) -> list[StateVerdict]:
    """The time offset's verdict (in ms) as a StateVerdict: its posterior sigma sigma_s (s) against the prior's
    ([dvl] time_offset_sigma_s), "determined" below TIME_OFFSET_DETERMINED of it."""
    state = BY_NAME["time_offset"]
    ((key, text, unit),) = _rows([state])
    prior = float(state.prior_display_sigma(config)[0])
    return [
        _state_verdict(
            key,
            text,
            unit,
            prior,
            sigma_s * state.to_display,
            duration_s / 3600.0,
            TIME_OFFSET_DETERMINED,
        )
    ]


def time_offset_verdict(result: NavResult) -> dict[str, Any]:
    """The estimated DVL-IMU time offset (s) with its sigma and whether the log determined it (its sigma below
    TIME_OFFSET_DETERMINED of the prior's, [dvl] time_offset_sigma_s): it is observable only from turns and
    accelerations (the velocity rate), so on a straight, steady run its sigma stays near the prior's."""
    state = BY_NAME["time_offset"]
    config = result.estimator_config if result.config else None
    prior = float(state.prior(config, Mounting()).sigma[0]) if config is not None else float("nan")
    est = result.calibration.get("time_offset")
    value, sigma = (
        (0.0, float("nan")) if est is None else (float(est.value[0]), float(est.sigma[0]))
    )
    determined = bool(sigma < TIME_OFFSET_DETERMINED * prior) if np.isfinite(prior) else None
    ms = state.to_display
    if determined:
        verdict = f"determined: sigma {sigma * ms:.1f} ms (prior {prior * ms:.0f} ms)"
    else:
        verdict = (
            f"not observable from this log: sigma {sigma * ms:.1f} ms, near the prior's "
            f"{prior * ms:.0f} ms (the offset shows only in turns and accelerations)"
        )
    return {
        "value": value,
        "sigma": sigma,
        "determined": determined,
        "verdict": verdict,
        "words": time_offset_words(value),
        "convention": TIME_OFFSET_CONVENTION,
    }


# the one definition of the time offset's sign (docs/conventions.md), in every message that shows one
TIME_OFFSET_CONVENTION = (
    "the DVL message stamped t measures the velocity at t + dt_d: dt_d > 0, the DVL's stamps "
    "are early; dt_d < 0, late"
)


def time_offset_words(dt_d_s: float) -> str:
    """The time offset dt_d (s) in words, the same everywhere (TIME_OFFSET_CONVENTION): "dt_d = +1.000 s: the
    DVL's stamps are 1.000 s early (each ping measures the velocity 1.000 s after its stamp)"."""
    if not np.isfinite(dt_d_s):
        return "dt_d unknown"
    size = f"{abs(dt_d_s):.3f} s"
    if size == "0.000 s":
        return "dt_d = 0.000 s: the DVL's stamps are on time (each ping measures the velocity at its stamp)"
    when, where = ("early", "after") if dt_d_s > 0 else ("late", "before")
    return (
        f"dt_d = {dt_d_s:+.3f} s: the DVL's stamps are {size} {when} (each ping measures the velocity {size} "
        f"{where} its stamp)"
    )


def lever_arm_verdict(result: NavResult, log: LogData | None = None) -> dict[str, Any]:
    """The estimated DVL lever arm b_l (IMU -> DVL, m, base_link) with its per-axis sigma and whether the log
    determined each axis (lever_arm_verdicts: posterior sigma below LEVER_DETERMINED of the prior's, [dvl]
    lever_arm_sigma_m), with the /tf_static value it started from when the log is given."""
    est = result.calibration.get("lever_arm")
    if est is None:
        raise ValueError("the result has no estimated lever arm ([dvl] estimate_lever_arm)")
    config = result.estimator_config if result.config else None
    prior = (
        float(BY_NAME["lever_arm"].prior_display_sigma(config)[0])
        if config is not None
        else float("nan")
    )
    out: dict[str, Any] = {
        "value": est.value.tolist(),
        "sigma": est.sigma.tolist(),
        "prior_sigma": prior,
        "frame": "base_link (x forward, y left, z up), from the IMU to the DVL, m",
    }
    if log is not None:
        out["tf_static"] = np.asarray(log.mounting.b_l, dtype=float).tolist()
    if not np.isfinite(prior):
        out.update(determined=None, verdict=None)
        return out
    duration = float(result.t[-1] - result.t[0]) if len(result.t) else 0.0
    verdicts = lever_arm_verdicts(est.cov, prior, duration)
    out["determined"] = [v.verdict == "determined" for v in verdicts]
    out["verdict"] = [
        f"{v.key[-1]}: {v.verdict} (sigma {v.posterior_sigma:.3f} m, prior {prior:.3g} m)"
        for v in verdicts
    ]
    if not all(out["determined"]):
        out["note"] = LEVER_ARM_NOTE
    return out


def analyse_block(
    calib_joint_cov: np.ndarray,
    b_R_d: np.ndarray,
    duration_s: float,
    config: EstimatorConfig,
    lever_arm_cov: np.ndarray | None = None,
    time_offset_sigma_s: float | None = None,
) -> ObservabilityReport:
    """The analysis on the block's covariance itself ([accel bias, gyro bias, scale, b_R_d right tangent],
    SI units), e.g. as stored in a result log; lever_arm_cov (3x3, m^2), when the lever arm was estimated,
    adds its per-axis verdicts, time_offset_sigma_s (s), when the time offset was, its verdict."""
    J = _user_units_jacobian(np.asarray(b_R_d))
    cov = J @ np.asarray(calib_joint_cov) @ J.T
    p0 = prior_sigmas(config)
    targets = target_sigmas(config)
    post = np.sqrt(np.diag(cov))
    duration_h = duration_s / 3600.0
    states = []
    for i, (key, text, unit) in enumerate(STATES):
        ratio = float(min(post[i] / p0[i], 1.0))
        verdict = state_verdict(ratio, float(post[i]), float(targets[i]))
        hours = None
        if verdict == "not determined":
            # information gained below 1 % of the prior's: numerically nothing, so no extrapolation
            gained = 1.0 / post[i] ** 2 - 1.0 / p0[i] ** 2
            info_rate = gained / max(duration_h, 1e-9) if gained > 0.01 / p0[i] ** 2 else 0.0
            hours = float(3.0 / p0[i] ** 2 / info_rate) if info_rate > 0 else float("inf")
        states.append(
            StateVerdict(
                key,
                text,
                unit,
                float(p0[i]),
                float(post[i]),
                ratio,
                verdict,
                hours,
                target_sigma=float(targets[i]),
            )
        )
    white = cov / np.outer(p0, p0)
    evals, evecs = np.linalg.eigh(0.5 * (white + white.T))
    directions = []
    for j in np.argsort(-evals):
        ratio = float(np.sqrt(min(max(evals[j], 0.0), 1.0)))
        w = evecs[:, j] ** 2
        order = [k for k in np.argsort(-w) if w[k] >= 0.1]
        directions.append(
            DirectionVerdict(ratio, verdict_of(ratio), {STATES[k][0]: float(w[k]) for k in order})
        )
    lever = (
        []
        if lever_arm_cov is None
        else lever_arm_verdicts(
            lever_arm_cov, float(BY_NAME["lever_arm"].prior_display_sigma(config)[0]), duration_s
        )
    )
    offset = (
        []
        if time_offset_sigma_s is None
        else time_offset_verdicts(time_offset_sigma_s, config, duration_s)
    )
    return ObservabilityReport(states, directions, duration_s, lever, offset)


def _timeline_sigmas(timeline: Timeline) -> np.ndarray:
    """(N, 10) sigmas in the order of STATES, user units (scale in ppm)."""
    return np.column_stack(
        [
            timeline.accel_bias_sigma_ug,
            timeline.gyro_bias_sigma_deg_per_h,
            timeline.scale_sigma * 1e6,
            timeline.misalignment_sigma_deg,
        ]
    )


def attribute_segments(
    report: ObservabilityReport,
    timeline: Timeline,
    segments: list[Segment],
    min_share: float = 0.25,
) -> dict[str, list[tuple[str, float]]]:
    """Which segments made each state observable: the share of the total fall of log(sigma) (prior to
    final) that happened inside each segment. Segments with at least min_share are credited on the
    report's states (StateVerdict.credited_segments); returns every state's shares, largest first."""
    sig = _timeline_sigmas(timeline)
    p0 = np.array([s.prior_sigma for s in report.states])
    # the prior is the sigma before the first epoch
    log_sig = np.log(np.minimum(np.vstack([p0, sig]), p0))
    t = np.concatenate([[timeline.t[0] - 1e-9], timeline.t])
    total = log_sig[0] - log_sig[-1]
    shares: dict[str, list[tuple[str, float]]] = {}
    for j, state in enumerate(report.states):
        rows = []
        for seg in segments:
            a = int(np.searchsorted(t, seg.start_s, side="right")) - 1
            b = int(np.searchsorted(t, seg.end_s, side="right")) - 1
            if b <= a or total[j] <= 1e-6:
                continue
            share = float((log_sig[max(a, 0), j] - log_sig[b, j]) / total[j])
            label = f"{seg.label()} (type {seg.type})"
            rows.append((label, share))
        rows.sort(key=lambda r: -r[1])
        shares[state.key] = rows
        if state.verdict != "not determined":
            state.credited_segments = [label for label, share in rows if share >= min_share]
    return shares


def determined_at(report: ObservabilityReport, timeline: Timeline) -> dict[str, float | None]:
    """Time (s) at which each state's filtering sigma first falls to its "determined" threshold
    (determined_threshold: its target, and informed; for the time offset and the lever arm TIME_OFFSET_DETERMINED
    and LEVER_DETERMINED of the prior's; None: never, or not in the timeline)."""
    sig = _timeline_sigmas(timeline)
    out: dict[str, float | None] = {}
    for j, state in enumerate(report.states):
        target = (
            state.target_sigma if state.target_sigma is not None else DETERMINED * state.prior_sigma
        )
        below = np.flatnonzero(sig[:, j] <= determined_threshold(state.prior_sigma, target))
        out[state.key] = float(timeline.t[below[0]]) if below.size else None
    for verdicts, sigmas, fraction, name in (
        (report.time_offset, timeline.time_offset_sigma_s, TIME_OFFSET_DETERMINED, "time_offset"),
        (report.lever_arm, timeline.lever_arm_sigma_m, LEVER_DETERMINED, "lever_arm"),
    ):
        if not verdicts:
            continue
        display = (
            np.asarray(sigmas, dtype=float).reshape(len(timeline.t), -1) * BY_NAME[name].to_display
            if sigmas is not None
            else None
        )
        for j, state in enumerate(verdicts):
            below = (
                np.flatnonzero(display[:, j] <= fraction * state.prior_sigma)
                if display is not None
                else np.array([], dtype=int)
            )
            out[state.key] = float(timeline.t[below[0]]) if below.size else None
    return out


# the DVL's calibration (the vehicle's states, core/states.py) in a verdict's headline, with their words
_DVL_PARTS = (
    ("scale", "scale"),
    ("misalignment", "all three misalignment angles"),
    ("time_offset", "the time offset"),
    ("lever_arm", "the lever arm"),
)


def _of_state(key: str, name: str) -> bool:
    return key == name or key.startswith(name + "_")


def calibration_answer(
    report: ObservabilityReport, determined_at_s: dict[str, float | None], subject: str = "log"
) -> list[str]:
    """The verdict in a navigator's words: a Yes/No headline on the DVL's calibration (scale, misalignment, and
    the time offset and lever arm when estimated: the vehicle's states, core/states.py), advice on what would
    determine what is missing, then every state's sentence with the time it was determined at (when known).
    subject "plan" (the mission planner: "this plan calibrates ... into the mission") or "log" (`evaluate`)."""
    plan = subject == "plan"
    vehicle = [s.name for s in BY_NAME.values() if s.vehicle]
    dvl = [v for v in report.all_states() if any(_of_state(v.key, name) for name in vehicle)]
    missing = [v for v in dvl if v.verdict != "determined"]
    lines = []
    if not missing:
        present = [words for name, words in _DVL_PARTS if any(_of_state(v.key, name) for v in dvl)]
        what = present[0] if len(present) == 1 else ", ".join(present[:-1]) + " and " + present[-1]
        times = [determined_at_s.get(v.key) for v in dvl]
        when = ""
        if dvl and all(t is not None for t in times):
            last = max(t for t in times if t is not None)
            when = (
                f"; the last of them is determined {last:.0f} s into the mission"
                if plan
                else f"; the last of them was determined {last:.0f} s into the log"
            )
        lines.append(
            f"Yes: this {subject} {'calibrates' if plan else 'calibrated'} the DVL ({what}){when}."
        )
    else:
        groups = [
            f"{'; '.join(v.description for v in missing if v.verdict == verdict)} {verdict}"
            for verdict in ("not determined", "weakly determined")
            if any(v.verdict == verdict for v in missing)
        ]
        lines.append(f"No: this {subject} leaves {', and '.join(groups)}.")
        keys = {v.key for v in missing}
        if "misalignment_roll" in keys:
            lines.append(
                "  The misalignment about the thrust axis needs a specific-force change off that axis: "
                + (
                    "add a descent or ascent (ballast) with constant attitude."
                    if plan
                    else "a dive with a descent or ascent (ballast) at constant attitude determines it."
                )
            )
        if "time_offset" in keys:
            lines.append(
                "  The time offset shows only in turns and accelerations: "
                + (
                    "add turns or speed changes."
                    if plan
                    else "a dive with more turns or speed changes determines it."
                )
            )
        if any(_of_state(k, "lever_arm") for k in keys):
            lines.append(f"  {LEVER_ARM_NOTE[0].upper()}{LEVER_ARM_NOTE[1:]}.")
    for v in report.all_states():
        when_s = determined_at_s.get(v.key)
        lines.append(
            f"  {v.sentence()}" + (f"; determined at {when_s:.0f} s" if when_s is not None else "")
        )
    return lines
