"""Self-diagnosis of a run: is this result to be trusted, and if not, what to do about it.

`assess_health(result, log)` looks at what every run leaves behind and turns it into a status ("ok", "warn",
"degraded" or "failed"), warnings in words that say what to do, and the figures behind them:

- the solver (batch: did Gauss-Newton converge; the normalised chi^2 of the final solution, chi^2 / dof,
  whose expectation is 1 when the noise model fits; EKF: the mean normalised innovation squared per degree
  of freedom, with the same expectation);
- every estimated shared state against its prior (analysis/prior_check.py): beyond 4 prior sigmas "failed",
  naming the state, the distance and the likely cause; a calibration file's states against it (calibration_check);
- the DVL residuals, recomputed here from the result and the log with the model of docs/conventions.md,
  y = k * b_R_d^T (n_R_b^T n_v + b_omega x b_l), whitened by the noise each ping was given (the rule of
  FactorMaker.dvl_noise): their RMS overall and per time window (about 1 when the model fits; a window far
  above it is a stretch where the DVL measured something else, e.g. water track after losing the bottom). A
  filter's states (EKF, online) with the calibration they were estimated with (state_calibration); without a
  chi^2 from the solver (online) the residuals' mean square is judged as one;
- whether the log moves at all (nothing is calibratable on a static log);
- the estimator's counters (DVL pings rejected by reason, messages dropped);
- the reader's losses (LogData.metadata["reader_losses"]: what --salvage and --repair dropped, gaps in the
  stamps) and its other warnings;
- the geometry (analysis/geometry.py): a calibration direction that leans on its prior or trades against
  another state, with the manoeuvre that would separate them. "warn" when it moves this log's track by more than
  geometry.MATTERS_FRACTION of the distance, else a note: not "degraded", since the estimate stays honest while
  its sigma covers the error; it says the result rests on the prior there.

Pure computation on NavResult and LogData: no files (analysis layer).

The residuals are computed in analysis/dvl_residuals.py, the counters judged in analysis/health_counters.py, the
reader's losses in analysis/health_losses.py; the verdict is analysis/health_verdict.py's Health. Their public
names are importable from here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.analysis.calibration_check import judge_calibration
from gtsam_dvl.analysis.dvl_misfit import check_dvl_misfit
from gtsam_dvl.analysis.dvl_residuals import (
    DvlResiduals,
    attitude_at,
    dvl_residuals,
    is_filtered,
    state_calibration,
)
from gtsam_dvl.analysis.geometry import assess_geometry
from gtsam_dvl.analysis.health_counters import (
    NOT_REJECTIONS,
    REJECTED_PINGS_DEGRADED,
    check_counters,
)
from gtsam_dvl.analysis.health_losses import (
    DVL_GAP_DEGRADED_S,
    IMU_GAP_DEGRADED_S,
    REPAIRED_DEGRADED,
    loss_figures,
    loss_findings,
    loss_lines,
)
from gtsam_dvl.analysis.health_verdict import STATUSES, Health
from gtsam_dvl.analysis.prior_check import check_priors
from gtsam_dvl.analysis.water_track import check_water_track
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData

__all__ = [
    "CHI2_PER_DOF_DEGRADED",
    "CHI2_PER_DOF_FAILED",
    "CHI2_PER_DOF_LOW",
    "DVL_GAP_DEGRADED_S",
    "IMU_GAP_DEGRADED_S",
    "MAX_WINDOW_WARNINGS",
    "NEVER_MOVES_SPEED_M_S",
    "NOT_REJECTIONS",
    "REJECTED_PINGS_DEGRADED",
    "REPAIRED_DEGRADED",
    "RESIDUAL_OVERALL_DEGRADED",
    "RESIDUAL_WINDOW_DEGRADED",
    "RESIDUAL_WINDOW_MIN_PINGS",
    "RESIDUAL_WINDOW_S",
    "STATUSES",
    "DvlResiduals",
    "Health",
    "assess_health",
    "assess_log_health",
    "attitude_at",
    "dvl_residuals",
    "is_filtered",
    "loss_figures",
    "loss_findings",
    "loss_lines",
    "state_calibration",
]

# Thresholds, and why.
# chi^2 / dof has expectation 1 and, for the thousands of degrees of freedom of a log, a spread of
# sqrt(2 / dof) ~ 0.02; the clean paper runs give 1.0-1.1. Twice its expectation is far outside chance: the noise
# model does not fit (understated noise, a bad stretch of data, a wrong lever arm or mounting).
CHI2_PER_DOF_DEGRADED = 2.0
# Beyond this the solution is dominated by misfit: its covariances mean nothing.
CHI2_PER_DOF_FAILED = 100.0
# Below this the stated noise is far too large (the estimate is fine, its sigmas too pessimistic): a note.
CHI2_PER_DOF_LOW = 0.25
# DVL residual windows: 30 s holds 30 pings at 1 Hz (90 degrees of freedom), so a window RMS of whitened
# residuals has a spread of about 0.07 around its expectation (<= 1: smoothed residuals are smaller than the
# noise). 3x the stated noise is a bias of several sigma held over the window, not chance.
RESIDUAL_WINDOW_S = 30.0
RESIDUAL_WINDOW_DEGRADED = 3.0
RESIDUAL_WINDOW_MIN_PINGS = 5  # fewer pings in a window: too few to judge it
# The whole log's RMS: 2x the stated noise over thousands of pings means the noise is understated throughout.
RESIDUAL_OVERALL_DEGRADED = 2.0
MAX_WINDOW_WARNINGS = 5  # more bad windows are summarised in one line
# A log whose DVL speed stays below this (95th percentile) never moves: scale and misalignment enter the DVL
# model multiplied by the velocity, so nothing about them can be learnt (the DVL noise is 0.01-0.03 m/s).
NEVER_MOVES_SPEED_M_S = 0.1


def assess_health(result: NavResult, log: LogData) -> Health:
    """The health of a run (module doc)."""
    health = assess_log_health(log, result.info.get("screened_losses"))
    # the configuration the result was made with, at the noise levels it used (the IMU quantisation floor and
    # the fitted DVL noise of info["noise"]); a result of another version: judged with the default noise rule
    config = result.noise_config or EstimatorConfig()
    _check_finite(result, health)
    _check_solver(result, health)
    # every estimated shared state against its prior (analysis/prior_check.py): "failed" beyond
    # prior_check.PRIOR_NSIGMA_FAILED prior sigmas, naming the state and the likely cause
    priors = check_priors(result, log, result.estimator_config or EstimatorConfig())
    health.figures["prior_nsigma"] = priors.as_dict()
    for severity, text in priors.findings:
        health.flag(severity, text)
    if len(result.t):
        _check_dvl_residuals(result, log, config, health)
    check_counters(result, log, health)
    _check_noise_fit(result, health)
    if len(result.t):  # the weak calibration directions (analysis/geometry.py): "warn" or a note
        geometry = assess_geometry(result)
        health.figures["geometry"] = geometry.as_dict()
        for finding in geometry.findings:
            health.flag(finding.severity, finding.message)
    # against a calibration file's prior (analysis/calibration_check.py)
    judge_calibration(result, health)
    return health


def _check_noise_fit(result: NavResult, health: Health) -> None:
    """A DVL noise fit that ended at a bound of [noise] is no fit: the DVL model does not fit its data at any
    noise level within ten times the stated one (a wrong mounting, a wrong topic, water track)."""
    noise = result.info.get("noise")
    for entry in (
        (noise.get(s) for s in ("dvl", "depth", "gnss")) if isinstance(noise, dict) else ()
    ):
        # (the depth's and the fixes' fits likewise)
        if isinstance(entry, dict) and entry.get("at_bound"):
            health.flag("degraded", str(entry.get("why")))


def assess_log_health(log: LogData, screened: dict[str, Any] | None = None) -> Health:
    """The checks that need only the log: does it move, what did the reader lose (also for results that are
    not a NavResult, such as IO-DVLC's); screened: what an estimator's own screen of a log that did not come
    through the reader found (its result's info["screened_losses"])."""
    health = Health()
    _check_motion(log, health)
    _check_losses(log, health, screened)
    return health


# ----- checks ----------------------------------------------------------------------------------------------


def _check_finite(result: NavResult, health: Health) -> None:
    arrays = {
        "position": result.n_p,
        "velocity": result.n_v,
        "attitude": result.n_R_b,
        "position covariance": result.pose_cov,
        "calibration": np.r_[result.scale, result.scale_sigma],
        "misalignment covariance": result.b_R_d_cov,
        "bias covariance": result.bias_cov,
    }
    bad = [
        name for name, a in arrays.items() if not np.all(np.isfinite(np.asarray(a, dtype=float)))
    ]
    health.figures["non_finite"] = bad
    if not len(result.t):
        health.flag(
            "failed",
            "the estimator produced no state: check that the log has usable DVL pings during "
            "the IMU's time span",
        )
    elif bad:
        health.flag(
            "failed",
            f"the estimate contains NaN or infinity ({', '.join(bad)}): do not use it; rerun "
            "with --debug and report the log",
        )


def _check_solver(result: NavResult, health: Health) -> None:
    solver = result.info.get("solver")
    filt = result.info.get("filter")
    figures: dict[str, Any] = {}
    if isinstance(solver, dict):
        figures["converged"] = bool(solver.get("converged", True))
        figures["iterations"] = solver.get("iterations")
        if not figures["converged"]:
            health.flag(
                "degraded",
                f"the solver did not converge in {solver.get('iterations')} iterations: the "
                "estimate may not be the optimum; raise [solver] max_iterations or check the "
                "alignment and the DVL data",
            )
        final_error, dof = solver.get("final_error"), solver.get("dof")
        if final_error is not None and dof:
            figures["chi2"] = 2.0 * float(final_error)
            figures["dof"] = int(dof)
            figures["chi2_per_dof"] = figures["chi2"] / int(dof)
        elif final_error is not None and not np.isfinite(final_error):
            figures["chi2_per_dof"] = float("inf")
    elif isinstance(filt, dict) and filt.get("mean_nis_per_dof") is not None:
        figures["chi2_per_dof"] = float(filt["mean_nis_per_dof"])
        figures["chi2_kind"] = "mean normalised innovation squared per degree of freedom (EKF)"
    health.figures["solver"] = figures
    ratio = figures.get("chi2_per_dof")
    if ratio is None:
        return
    what = "normalised chi^2" if "chi2_kind" not in figures else "normalised innovation squared"
    if not np.isfinite(ratio) or ratio > CHI2_PER_DOF_FAILED:
        health.flag(
            "failed",
            f"{what} is {ratio:.3g} (expected 1): the model does not fit the data at all; do not "
            "use this result; check the topics, the mounting (/tf_static) and the DVL noise",
        )
    elif ratio > CHI2_PER_DOF_DEGRADED:
        health.flag(
            "degraded",
            f"{what} is {ratio:.2f} (expected 1): the noise model does not fit; look at the DVL "
            "residual windows below, or set [dvl] noise_m_s to the DVL's real noise",
        )
    elif ratio < CHI2_PER_DOF_LOW:
        health.flag(
            "note",
            f"{what} is {ratio:.2f} (expected 1): the stated noise is larger than the data's; the "
            "sigmas are pessimistic",
        )


def _check_dvl_residuals(
    result: NavResult, log: LogData, config: EstimatorConfig, health: Health
) -> None:
    """The DVL residuals of the run (dvl_residuals) into figures "dvl_residuals" and flags: windows and stretches
    above their noise, the whole log's fit; the water-track pings judged apart (analysis/water_track.py)."""
    res = dvl_residuals(result, log, config.dvl)
    # (analysis/water_track.py)
    check_water_track(result, log, config, res, health.figures, health.flag)
    used = res.dof > 0
    figures: dict[str, Any] = {
        "pings": int(used.sum()),
        "states_without_ping": res.unmatched,
        "whitened_rms": res.rms() if used.any() else None,
        "window_s": RESIDUAL_WINDOW_S,
        "windows": [],
    }
    health.figures["dvl_residuals"] = figures
    if res.selected_again:
        figures["pings_selected_again"] = res.selected_again
        health.flag(
            "note",
            f"the result does not record which DVL pings its estimator used (a result file without "
            f"them): the residuals are of the {res.selected_again} pings selected again with its "
            "configuration",
        )
    if not used.any():
        health.flag(
            "degraded",
            "no DVL ping could be compared with the estimate: check the DVL topic and its "
            "valid flags",
        )
        return
    spans = _bad_spans(res, figures)
    _flag_bad_spans(spans, config.dvl.robust, health)
    _judge_overall_residuals(figures["whitened_rms"], spans, health)
    # a fitted level far above the stated one, a time offset left in the residuals (analysis/dvl_misfit.py)
    check_dvl_misfit(result, log, config.dvl, res, health)


def _bad_spans(res: DvlResiduals, figures: dict[str, Any]) -> list[tuple[float, float, float]]:
    """The residuals' whitened RMS per RESIDUAL_WINDOW_S window (into figures "windows"), and the stretches of
    adjacent windows above RESIDUAL_WINDOW_DEGRADED (into figures "bad_windows"): (start s, end s, RMS) each."""
    used = res.dof > 0
    start = np.floor(res.t[used][0] / RESIDUAL_WINDOW_S) * RESIDUAL_WINDOW_S
    index = np.floor((res.t - start) / RESIDUAL_WINDOW_S).astype(int)
    bad: list[tuple[float, float, float]] = []
    for k in np.unique(index[used]).tolist():
        mask = used & (index == k)
        a = float(start + k * RESIDUAL_WINDOW_S)
        rms = res.rms(mask)
        figures["windows"].append(
            {
                "start_s": a,
                "end_s": a + RESIDUAL_WINDOW_S,
                "pings": int(mask.sum()),
                "whitened_rms": rms,
            }
        )
        if mask.sum() >= RESIDUAL_WINDOW_MIN_PINGS and rms > RESIDUAL_WINDOW_DEGRADED:
            bad.append((a, a + RESIDUAL_WINDOW_S, rms))
    spans = _merge_windows(bad, res)
    figures["bad_windows"] = [
        {"start_s": a, "end_s": b, "whitened_rms": rms} for a, b, rms in spans
    ]
    return spans


def _flag_bad_spans(spans: list[tuple[float, float, float]], robust: str, health: Health) -> None:
    """One "degraded" flag per bad stretch, the first MAX_WINDOW_WARNINGS by name and the rest in one line."""
    advice = _kernel_advice(robust)
    for a, b, rms in spans[:MAX_WINDOW_WARNINGS]:
        health.flag(
            "degraded",
            f"DVL residuals {rms:.1f}x their stated noise between {a:.0f} and {b:.0f} s: "
            "bottom lock lost? Check the DVL's bottom-track status and valid flags there" + advice,
        )
    if len(spans) > MAX_WINDOW_WARNINGS:
        rest = spans[MAX_WINDOW_WARNINGS:]
        health.flag(
            "degraded",
            f"and {len(rest)} more stretches of DVL residuals above "
            f"{RESIDUAL_WINDOW_DEGRADED:g}x their noise ({rest[0][0]:.0f} to {rest[-1][1]:.0f} s)",
        )


def _judge_overall_residuals(
    overall: float, spans: list[tuple[float, float, float]], health: Health
) -> None:
    """The whole log's whitened RMS: "failed" when its square is beyond CHI2_PER_DOF_FAILED and the solver gave
    no chi^2 of its own, "degraded" when above RESIDUAL_OVERALL_DEGRADED with no bad stretch to explain it."""
    if (
        health.figures.get("solver", {}).get("chi2_per_dof") is None
        and overall**2 > CHI2_PER_DOF_FAILED
    ):
        # no chi^2 from the solver (online): the residuals' mean square is its chi^2 / dof, judged alike
        health.flag(
            "failed",
            f"DVL residuals are {overall:.1f}x their stated noise over the whole log (chi^2 / dof "
            f"{overall**2:.3g}, expected 1): the model does not fit the data at all; do not use this "
            "result; check the topics, the mounting (/tf_static) and the DVL noise",
        )
    elif overall > RESIDUAL_OVERALL_DEGRADED and not spans:
        health.flag(
            "degraded",
            f"DVL residuals are {overall:.1f}x their stated noise over the whole log: the DVL "
            "noise is understated (set [dvl] noise_m_s), or the mounting or lever arm is wrong",
        )


def _kernel_advice(robust: str) -> str:
    """What a stronger robust kernel would do for a bad stretch, naming the next one of [dvl] robust ("" when the
    strongest, cauchy, is on already)."""
    if robust == "none":
        return '; or rerun with [dvl] robust = "huber" (the default) to down-weight such pings'
    if robust == "huber":
        return '; or rerun with [dvl] robust = "cauchy", which gives gross outliers less weight than huber'
    return ""


def _merge_windows(
    bad: list[tuple[float, float, float]], res: DvlResiduals
) -> list[tuple[float, float, float]]:
    """Adjacent bad windows as one span, with the RMS over the span's pings."""
    spans: list[tuple[float, float, float]] = []
    for a, b, _ in bad:
        if spans and abs(spans[-1][1] - a) < 1e-9:
            spans[-1] = (spans[-1][0], b, 0.0)
        else:
            spans.append((a, b, 0.0))
    used = res.dof > 0
    return [(a, b, res.rms(used & (res.t >= a) & (res.t < b))) for a, b, _ in spans]


def _check_motion(log: LogData, health: Health) -> None:
    dvl = log.dvl
    ok = dvl.valid & np.isfinite(dvl.d_v).all(axis=1) if len(dvl) else np.zeros(0, bool)
    speed = float(np.percentile(np.linalg.norm(dvl.d_v[ok], axis=1), 95)) if ok.any() else 0.0
    health.figures["dvl_speed_p95_m_s"] = speed
    if speed < NEVER_MOVES_SPEED_M_S:
        health.flag(
            "degraded",
            f"nothing calibratable: the log never moves (95 % of the DVL speeds are below "
            f"{NEVER_MOVES_SPEED_M_S:g} m/s), so the DVL scale and misalignment keep their priors; "
            "calibrate on a log with motion (see `gtsam-dvl plan`)",
        )


def _check_losses(log: LogData, health: Health, screened: dict[str, Any] | None = None) -> None:
    """The reader's losses, or those the estimator's own screen found or amended (estimators/inputs/gaps.py
    screened_in_memory: result.info["screened_losses"]; a clock step the DVL showed in a log read from a file)."""
    losses = screened or log.metadata.get("reader_losses") or {}
    health.figures["losses"] = loss_figures(losses)
    for severity, text in loss_findings(losses):
        health.flag(severity, text)
    known = ("salvage:", "gap(s) in the data", ": dropped ", "the IMU saturated", "clock step at")
    for w in log.metadata.get("reader_warnings", []):
        if not any(k in w for k in known):  # the losses are said above, from the structured record
            health.flag("note", f"reader: {w}")
