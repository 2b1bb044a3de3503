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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.analysis.calibration_check import judge_calibration
from gtsam_dvl.analysis.geometry import assess_geometry
from gtsam_dvl.analysis.prior_check import check_priors
from gtsam_dvl.analysis.water_track import check_water_track
from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_exp, so3_log
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.ping_screen import frozen_runs
from gtsam_dvl.estimators.inputs.selection import ping_covariance, usable_pings
from gtsam_dvl.factors.dvl_model import dvl_model

# in order of severity: "warn" is an honest result that leans on its prior somewhere (weak geometry); --strict
# fails only on "degraded" and "failed"
STATUSES = ("ok", "warn", "degraded", "failed")

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
# More than this share of the DVL pings rejected: a good part of the log did not reach the estimator.
REJECTED_PINGS_DEGRADED = 0.05
# More than this share of a topic's messages dropped by --repair: the log is damaged, not just untidy.
REPAIRED_DEGRADED = 0.01
# IMU gaps are crossed by holding the last sample before them, with the motion model's uncertainty added
# (estimators/inputs/gaps.py): honest, but the trajectory across a gap longer than this is a guess the user should
# know about (a 100 Hz IMU dropping a few samples is harmless).
IMU_GAP_DEGRADED_S = 0.5
# The DVL may fall silent for a while (turns, bottom out of range); longer than this the trajectory is dead
# reckoned for long enough that the user should know where.
DVL_GAP_DEGRADED_S = 60.0

# Counters that are not rejections (the EKF's slow pings still update the navigation; keyframe thinning is
# by design).
_NOT_REJECTIONS = (
    "dvl_not_keyframe",
    "dvl_slow",
    "dvl_updates",
    "dvl_downweighted",
    "dvl_water_track",
    "dvl_before_imu",
    "dvl_after_imu",
)


@dataclass
class Health:
    """Status of one run ("ok", "warn", "degraded", "failed"), the warnings that set it (each says what to do),
    notes that do not change it, and the figures behind them."""

    status: str = "ok"
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    figures: dict[str, Any] = field(default_factory=dict)

    def flag(self, severity: str, text: str) -> None:
        """A finding: "note" (status unchanged), "warn", "degraded" or "failed" (status at least that)."""
        if severity == "note":
            self.notes.append(text)
            return
        self.warnings.append(text)
        if STATUSES.index(severity) > STATUSES.index(self.status):
            self.status = severity

    def as_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "figures": self.figures,
        }

    def lines(self) -> list[str]:
        """One line per warning and note, for a console."""
        return (
            [f"health: {self.status}"]
            + [f"  warning: {w}" for w in self.warnings]
            + [f"  note: {n}" for n in self.notes]
        )


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
    _check_counters(result, log, health)
    _check_noise_fit(result, health)
    if len(result.t):  # the weak calibration directions (analysis/geometry.py): "warn" or a note
        geometry = assess_geometry(result)
        health.figures["geometry"] = geometry.as_dict()
        for finding in geometry.findings:
            health.flag(finding.severity, finding.message)
    judge_calibration(
        result, health
    )  # against a calibration file's prior (analysis/calibration_check.py)
    return health


def _check_noise_fit(result: NavResult, health: Health) -> None:
    """A DVL noise fit that ended at a bound of [noise] is no fit: the DVL model does not fit its data at any
    noise level within ten times the stated one (a wrong mounting, a wrong topic, water track)."""
    noise = result.info.get("noise")
    for entry in (
        (noise.get(s) for s in ("dvl", "depth", "gnss")) if isinstance(noise, dict) else ()
    ):
        if isinstance(entry, dict) and entry.get(
            "at_bound"
        ):  # (the depth's and the fixes' fits likewise)
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


@dataclass
class DvlResiduals:
    """Whitened DVL residuals of the usable pings within the result's span: per ping its time, squared whitened
    norm and degrees of freedom (3 for a 3-D velocity, the valid beams for beam factors)."""

    t: np.ndarray
    chi2: np.ndarray
    dof: np.ndarray
    unmatched: int  # states without a ping at their time
    # pings selected again here (selection.usable_pings): the result does not record its own (NavResult.dvl_pings)
    selected_again: int = 0
    # y - h(x) per ping, m/s in dvl_link, nan where the ping is not used (3-D velocity; None with beam factors);
    # a water-track ping's against the velocity over ground (analysis/water_track.py adds the current), not in chi2
    residual_m_s: np.ndarray | None = None
    index: np.ndarray | None = None  # each ping's index in the log's DVL data
    water: np.ndarray | None = None  # which are water-track pings

    def rms(self, mask: np.ndarray | None = None) -> float:
        c, d = (self.chi2, self.dof) if mask is None else (self.chi2[mask], self.dof[mask])
        return float(np.sqrt(c.sum() / d.sum())) if d.sum() > 0 else float("nan")


def dvl_residuals(result: NavResult, log: LogData, config: DvlConfig) -> DvlResiduals:
    """Residuals y - h(x) of every usable ping (NavResult.dvl_pings) between the result's first and last
    state: at a state's time the state's prediction, between states (keyframes, [solver] keyframe_spacing_s, or
    decimated pings) the states' predictions interpolated linearly in time (in dvl_link: the body-frame
    velocity stays smooth through turns; over 1 s in a 0.05 rad/s turn the chord error is below 1e-3 m/s).
    Whitened by the noise that ping was given: config.noise_m_s if > 0, else the message's covariance if
    positive definite, else config.default_noise_m_s (selection.ping_covariance); with config.use_beams, per
    beam with beam_noise_m_s; plus the correlated error's variance correlated_sigma_m_s^2 per axis. unmatched:
    the states without a ping at their time (DVL dropouts)."""
    dvl = log.dvl
    n = len(result.t)
    if not len(dvl) or not n:
        return DvlResiduals(np.asarray(result.t, dtype=float), np.zeros(n), np.zeros(n), n)
    j = np.clip(np.searchsorted(dvl.t, result.t), 0, len(dvl) - 1)
    prev = np.clip(j - 1, 0, len(dvl) - 1)
    j = np.where(np.abs(dvl.t[prev] - result.t) < np.abs(dvl.t[j] - result.t), prev, j)
    unmatched = int((np.abs(dvl.t[j] - result.t) >= 1e-6).sum())
    y_state = _state_predictions(result, log)
    t0, t1 = float(result.t[0]), float(result.t[-1])
    pings = result.dvl_pings
    selected_again = 0
    if pings is None or (len(pings) and int(pings.max()) >= len(dvl)):
        pings = usable_pings(dvl, log.imu, config, {})
        selected_again = len(pings)
    j = pings[(dvl.t[pings] >= t0 - 1e-6) & (dvl.t[pings] <= t1 + 1e-6)]
    t_p = np.clip(dvl.t[j], t0, t1)
    y_hat = np.stack([np.interp(t_p, result.t, y_state[:, k]) for k in range(3)], axis=1).reshape(
        -1, 3
    )
    gm_var = (
        config.correlated_sigma_m_s**2
    )  # the DVL's correlated error's variance (estimators/models/correlated.py)
    if config.use_beams and dvl.beams is not None:
        d_u, v, ok = dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j]
        ok = ok & np.isfinite(v) & np.isfinite(d_u).all(axis=2)
        r = np.where(ok, v - np.einsum("nbi,ni->nb", np.where(ok[..., None], d_u, 0.0), y_hat), 0.0)
        chi2 = (r**2).sum(axis=1) / (config.beam_sigma_m_s() ** 2 + gm_var)
        dof = ok.sum(axis=1).astype(float)
        return DvlResiduals(np.asarray(dvl.t[j], dtype=float), chi2, dof, unmatched, selected_again)
    return _velocity_residuals(log, config, j, y_hat, gm_var, unmatched, selected_again)


def _state_predictions(result: NavResult, log: LogData) -> np.ndarray:
    """The DVL velocity (N, 3) m/s in dvl_link the model predicts at each state (factors/dvl_model.py), with the
    calibration the estimator fitted (state_calibration)."""
    n = len(result.t)
    b_omega = result.b_omega if result.b_omega is not None else np.zeros((n, 3))
    # the model the estimator fitted: its lever arm when estimated, and the ping stamped t seen at t + dt_d (the
    # state's velocity interpolated there, its attitude turned by the body rate over dt_d); a filter's states with
    # the calibration it held at their time (state_calibration)
    k, b_R_d, dt_d, b_l = state_calibration(result, log)
    n_R_b, n_v = result.n_R_b, result.n_v
    if np.any(dt_d != 0.0) and n > 1:
        n_v = np.stack(
            [np.interp(result.t + dt_d, result.t, result.n_v[:, i]) for i in range(3)], axis=1
        )
        n_R_b = attitude_at(result.t, result.n_R_b, b_omega, result.t + dt_d)
        b_omega = np.stack(
            [np.interp(result.t + dt_d, result.t, b_omega[:, i]) for i in range(3)], axis=1
        )
    # for all states at once (h is linear in the scale)
    y_unit, _ = dvl_model(n_R_b, n_v, 1.0, b_R_d, b_omega, b_l, jacobians=False)
    return k[:, None] * y_unit


def _velocity_residuals(
    log: LogData,
    config: DvlConfig,
    j: np.ndarray,
    y_hat: np.ndarray,
    gm_var: float,
    unmatched: int,
    selected_again: int,
) -> DvlResiduals:
    """The residuals of the pings j on their 3-D velocities (predicted y_hat (len(j), 3)), whitened by the
    covariance each ping was given plus the correlated error's variance gm_var; the water-track pings kept aside,
    unjudged here (analysis/water_track.py judges them with the current)."""
    dvl = log.dvl
    d_y = dvl.d_v[j]
    water = (
        np.zeros(len(j), bool) if dvl.water_track is None else np.asarray(dvl.water_track, bool)[j]
    )
    seen = (dvl.valid[j] | water) & np.isfinite(d_y).all(axis=1)
    ok = seen & ~water
    r = np.where(ok[:, None], d_y - y_hat, 0.0)
    # the noise each ping was given by the estimators, and the correlated error they modelled beside it (its
    # estimate is not in the result: the residual holds it)
    cov = ping_covariance(config, dvl.d_cov[j]) + gm_var * np.eye(3)
    cov[~ok] = np.eye(3)
    chi2 = np.where(ok, np.einsum("ni,ni->n", r, np.linalg.solve(cov, r[..., None])[..., 0]), 0.0)
    return DvlResiduals(
        np.asarray(dvl.t[j], dtype=float),
        chi2,
        3.0 * ok,
        unmatched,
        selected_again,
        np.where(seen[:, None], d_y - y_hat, np.nan),
        j,
        water,
    )


def attitude_at(
    t: np.ndarray, n_R_b: np.ndarray, b_omega: np.ndarray, t_q: np.ndarray
) -> np.ndarray:
    """The attitude n_R_b (Q, 3, 3) at the times t_q from the states' (t (N,) sorted, n_R_b (N, 3, 3)): along the
    geodesic between the two states around each time (their relative rotation, scaled by the fraction of the
    interval), and beyond the first or last state turned by that state's body rate b_omega (N, 3) rad/s. The
    geodesic, not a state's rate times the offset: in a turn that starts within the second after a ping, the ping's
    own rate (near zero) would leave the attitude a second later up to 0.3 rad short, 0.5 m/s at 1.9 m/s, and the
    residuals of a correct fit 2.5 times the stated noise (realistic-turns, issue 31)."""
    t = np.asarray(t, dtype=float)
    t_q = np.asarray(t_q, dtype=float)
    a = np.clip(np.searchsorted(t, t_q, side="right") - 1, 0, len(t) - 2)
    span = t[a + 1] - t[a]
    f = np.where(span > 0, (t_q - t[a]) / np.where(span > 0, span, 1.0), 0.0)
    inside = (f >= 0.0) & (f <= 1.0)
    rel = np.einsum("nji,njk->nik", n_R_b[a], n_R_b[a + 1])  # n_R_b[a]^T n_R_b[a + 1]
    phi = so3_log(rel).reshape(-1, 3) * np.clip(f, 0.0, 1.0)[:, None]
    # beyond the ends: the nearest state turned by its own rate over the time from it
    end = np.where(t_q < t[0], 0, len(t) - 1)
    base = np.where(inside, a, end)
    phi = np.where(inside[:, None], phi, b_omega[end] * (t_q - t[end])[:, None])
    return np.einsum("nij,njk->nik", n_R_b[base], so3_exp(phi).reshape(-1, 3, 3))


def is_filtered(result: NavResult) -> bool:
    """Whether the trajectory is a filter's (the EKF's, the online estimator's): each state as estimated when its
    ping was processed, with the calibration of that time (its timeline), not the final one."""
    return result.estimator == "ekf" or str(result.info.get("trajectory", "")).startswith(
        "filtered"
    )


def state_calibration(
    result: NavResult, log: LogData
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per state: the scale (N,), b_R_d (N, 3, 3), the time offset dt_d (N,) s and the lever arm b_l (N, 3) m of
    the model the state was estimated with. A smoother's states share the final calibration; a filter's (is_filtered)
    were estimated with the calibration of their time, which its timeline records: judged with the final one, a
    filter's early states, whose calibration was still converging (an in-motion alignment, a descent), would show
    residuals of the calibration's later change, not of the data. What the timeline lacks is the final value."""
    n = len(result.t)
    k = np.full(n, float(result.scale))
    b_R_d = np.broadcast_to(np.asarray(result.b_R_d, dtype=float), (n, 3, 3)).copy()
    dt_d = np.full(n, float(result.time_offset_s) if np.isfinite(result.time_offset_s) else 0.0)
    b_l = np.broadcast_to(
        np.asarray(
            result.lever_arm_m if result.lever_arm_m is not None else log.mounting.b_l, dtype=float
        ),
        (n, 3),
    ).copy()
    tl = result.timeline
    if tl is None or not is_filtered(result) or not len(tl.t) or not n:
        return k, b_R_d, dt_d, b_l
    # the timeline's entry at or before each state (a state before the first entry: the first)
    i = np.clip(np.searchsorted(tl.t, result.t + 1e-9, side="right") - 1, 0, len(tl.t) - 1)
    k = np.asarray(tl.scale, dtype=float)[i]
    R_c = np.stack(
        [rpy_deg_to_matrix(rpy) for rpy in np.asarray(tl.misalignment_deg, dtype=float)[i]]
    )
    b_R_d = R_c @ np.asarray(result.b_R_d0, dtype=float)
    if tl.time_offset_s is not None:
        dt_d = np.asarray(tl.time_offset_s, dtype=float)[i]
    if tl.lever_arm_m is not None:
        b_l = np.asarray(tl.lever_arm_m, dtype=float)[i]
    return k, b_R_d, dt_d, b_l


def _check_dvl_residuals(
    result: NavResult, log: LogData, config: EstimatorConfig, health: Health
) -> None:
    """The DVL residuals of the run (dvl_residuals) into figures "dvl_residuals" and flags: windows and stretches
    above their noise, the whole log's fit; the water-track pings judged apart (analysis/water_track.py)."""
    res = dvl_residuals(result, log, config.dvl)
    check_water_track(
        result, log, config, res, health.figures, health.flag
    )  # (analysis/water_track.py)
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


def _check_counters(result: NavResult, log: LogData, health: Health) -> None:
    """The estimator's counters (NavResult.info "counters") and records into figures "counters" and flags:
    rejected pings and dropped IMU samples, the time offset's windows and bound, the pieces and IMU gaps."""
    counters = {
        k: int(v)
        for k, v in result.info.get("counters", {}).items()
        if isinstance(v, (int, np.integer))
    }
    _check_rejections(counters, log, health)
    _check_time_offset(result, counters, health)
    _check_imu_gaps(result, log, health)


def _check_rejections(counters: dict[str, int], log: LogData, health: Health) -> None:
    """The DVL pings rejected and the IMU samples dropped (figures "counters"), a note or "degraded" flag each."""
    rejected = {
        k: v for k, v in counters.items() if k.startswith("dvl_") and k not in _NOT_REJECTIONS and v
    }
    dropped = {k: v for k, v in counters.items() if k.startswith("imu_") and k != "imu_gaps" and v}
    n_pings = max(len(log.dvl), 1)
    share = sum(rejected.values()) / n_pings
    health.figures["counters"] = {
        "dvl_rejected": rejected,
        "dvl_rejected_share": share,
        "imu_dropped": dropped,
        "dvl_downweighted": counters.get("dvl_downweighted", 0),
    }
    if rejected:
        why = ", ".join(
            f"{v} {k.removeprefix('dvl_').replace('_', ' ')}" for k, v in sorted(rejected.items())
        )
        text = f"{sum(rejected.values())} of {len(log.dvl)} DVL pings rejected ({why})"
        if share > REJECTED_PINGS_DEGRADED:
            health.flag(
                "degraded",
                f"{text}: a good part of the log was not used; check the DVL's valid flags and "
                "[dvl] max_speed_m_s",
            )
        else:
            health.flag("note", text)
    _check_unused_pings(counters, log, health)
    if dropped:
        why = ", ".join(
            f"{v} {k.removeprefix('imu_').replace('_', ' ')}" for k, v in sorted(dropped.items())
        )
        health.flag(
            "degraded",
            f"the estimator dropped {sum(dropped.values())} IMU sample(s) ({why}): the IMU "
            "stream has holes; read the log with --repair to see where",
        )


def _check_time_offset(result: NavResult, counters: dict[str, int], health: Health) -> None:
    """The time offset's IMU windows: held at the filters' bound (clipped), never settled on the batch solution
    (centring), the EKF's offset state held at its bound (bounded)."""
    clipped = counters.get("time_offset_window_clipped", 0)
    health.figures["counters"]["time_offset_window_clipped"] = clipped
    if clipped:
        _check_offset_clip(result, clipped, health)
    centring = result.info.get("time_offset_centring") or {}
    if (
        centring.get("consistent") is False
    ):  # the batch smoother's windows never agreed with its solution
        health.flag(
            "degraded",
            f"the DVL time offset's IMU windows did not settle on the estimate (centred at "
            f"{centring['centre_s']:+.3f} s, estimate {centring['estimate_s']:+.3f} s, sigma "
            f"{centring['sigma_s']:.3f} s) after {centring['recentred']} re-centrings: the offset "
            "model is approximate here (sharp turns with a large offset)",
        )
    if bounded := counters.get(
        "time_offset_bounded", 0
    ):  # the EKF held its offset state at the bound
        health.figures["counters"]["time_offset_bounded"] = bounded
        _check_offset_bound(result, bounded, health)


def _check_imu_gaps(result: NavResult, log: LogData, health: Health) -> None:
    """The log smoothed in pieces cut at IMU gaps, or gaps crossed by holding the last sample (those the reader
    did not record already)."""
    if breaks := result.info.get("breaks"):  # estimators/batch/pieces.py
        health.flag(
            "degraded",
            f"smoothed as {len(breaks) + 1} pieces, cut at IMU gaps longer than imu.max_gap_s ("
            + ", ".join(f"{b['gap_start_s']:.1f}-{b['gap_end_s']:.1f} s" for b in breaks)
            + "): the DVL calibration is the pieces' joint one; each later piece is aligned in motion and "
            "its position placed by dead reckoning across the gap; check the IMU driver"
            + "".join(
                f"; piece {p['piece']} left out: {p['error']}"
                for p in result.info.get("pieces_left_out") or []
            ),
        )
    gaps = result.info.get("imu_gaps") or {}
    losses = log.metadata.get("reader_losses") or result.info.get("screened_losses") or {}
    # the reader's record says where the IMU data are missing, and its saturation record the gaps it made
    reader_saw = any("imu" in topic.lower() for topic in (losses.get("gaps") or {})) or bool(
        losses.get("saturation")
    )
    if (
        gaps.get("count") and not reader_saw
    ):  # an in-memory log: the reader's gap record is not there
        text = (
            f"{gaps['count']} IMU gap(s), {gaps['total_s']:.2f} s in all, the longest {gaps['longest_s']:.2f} s, "
            "crossed by holding the last sample (the sigmas grow there)"
        )
        health.flag(
            "degraded" if gaps["longest_s"] > IMU_GAP_DEGRADED_S else "note",
            text + ("; check the IMU driver" if gaps["longest_s"] > IMU_GAP_DEGRADED_S else ""),
        )


def _check_offset_clip(result: NavResult, clipped: int, health: Health) -> None:
    """The filters (EKF, online) centre the IMU windows of their time-offset model on the offset's estimate held
    within the prior +- 3 prior sigmas; `clipped` pings had their window held at that bound. "degraded" when the
    final estimate is beyond it (the late pings' model is approximate), a note when the estimate came back within
    (a transient: the bound held a filter that was still converging)."""
    config = result.estimator_config or EstimatorConfig()
    recentred = result.info.get(
        "time_offset_prior"
    )  # the EKF's warm-up may move the prior's centre
    centre = (
        float(recentred["centre_s"])
        if isinstance(recentred, dict) and "centre_s" in recentred
        else (config.dvl.time_offset_prior_s)
    )
    bound = 3.0 * config.dvl.time_offset_sigma_s
    text = (
        f"the DVL time offset's estimate went beyond its prior +- 3 sigma ({centre:+.3f} +- {bound:.3f} s): the "
        f"IMU windows of its offset model were held at that bound for {clipped} ping(s)"
    )
    if abs(result.time_offset_s - centre) > bound:
        health.flag(
            "degraded",
            f"{text}, to the end ({result.time_offset_s:+.3f} s), so the offset model is "
            "approximate; set [dvl] time_offset_prior_s near the estimate or widen [dvl] "
            "time_offset_sigma_s",
        )
    else:
        health.flag(
            "note",
            f"{text}, while the filter converged (it ended within, at {result.time_offset_s:+.3f} s)",
        )


def _check_offset_bound(result: NavResult, bounded: int, health: Health) -> None:
    """The EKF holds its time-offset state within the prior +- 3 prior sigmas (a filter chasing its own error runs
    the offset away); held there at the end, the stamps are beyond the prior: "failed", as prior_check would say of
    an unbounded estimate that far."""
    config = result.estimator_config or EstimatorConfig()
    recentred = result.info.get("time_offset_prior")
    centre = (
        float(recentred["centre_s"])
        if isinstance(recentred, dict) and "centre_s" in recentred
        else (config.dvl.time_offset_prior_s)
    )
    bound = 3.0 * config.dvl.time_offset_sigma_s
    # at the bound: within a tenth of a prior sigma of it (an update after the last hold moves it a little inward)
    if abs(result.time_offset_s - centre) >= bound - 0.1 * config.dvl.time_offset_sigma_s:
        health.flag(
            "failed",
            f"DVL-IMU time offset is held at its bound ({result.time_offset_s:+.3f} s, the prior "
            f"{centre:+.3f} +- 3 x {config.dvl.time_offset_sigma_s:g} s) to the end, after "
            f"{bounded} ping(s) pushed it beyond its prior: set [dvl] time_offset_prior_s near the "
            "DVL's real offset or widen [dvl] time_offset_sigma_s; do not use this result",
        )
    else:
        health.flag(
            "note",
            f"the EKF held its DVL time offset at its prior's bound (+- 3 sigma) for {bounded} "
            f"update(s) while it converged (it ended within, at {result.time_offset_s:+.3f} s)",
        )


def _check_unused_pings(counters: dict[str, int], log: LogData, health: Health) -> None:
    """The pings not used for no fault of their own (water track, outside the IMU's span) and the frozen DVL
    output (ping_screen.frozen_runs), each in its own words."""
    n_pings = max(len(log.dvl), 1)
    if water := counters.get("dvl_water_track", 0):
        text = (
            f"{water} of {len(log.dvl)} DVL pings are water track (velocity relative to the water, not over "
            'ground): refused ([current] water_track = "refuse"; "auto" uses them with the current as a state)'
        )
        many = water / n_pings > REJECTED_PINGS_DEGRADED
        health.flag(
            "degraded" if many else "note",
            text
            + (
                "; the DVL had no bottom lock there, so the trajectory is dead reckoned on the IMU"
                if many
                else ""
            ),
        )
    before, after = counters.get("dvl_before_imu", 0), counters.get("dvl_after_imu", 0)
    if before + after > 1:  # one ping at the IMU's first stamp: the sensors started together
        health.flag(
            "note",
            f"{before + after} DVL pings outside the IMU's time span ({before} at or before its "
            f"first sample, {after} after its last): not used",
        )
    if repeated := counters.get("dvl_repeated", 0):
        runs = frozen_runs(log.dvl)
        longest = max(runs, key=lambda r: r[2]) if runs else None
        text = (
            (
                f"DVL output frozen: {longest[2]} pings repeated bit for bit between {longest[0]:.0f} and "
                f"{longest[1]:.0f} s"
                + (f" ({repeated} in {len(runs)} stretches)" if len(runs) > 1 else "")
                + ", dropped; check the DVL"
            )
            if longest
            else (
                f"DVL output frozen: {repeated} pings repeated bit for bit while the IMU showed motion, dropped"
            )
        )
        long = longest is not None and longest[1] - longest[0] > DVL_GAP_DEGRADED_S
        health.flag(
            "degraded" if long or repeated / n_pings > REJECTED_PINGS_DEGRADED else "warn", text
        )


def _check_losses(log: LogData, health: Health, screened: dict[str, Any] | None = None) -> None:
    """The reader's losses, or for a log that did not come through it those the estimator's own screen found
    (estimators/inputs/gaps.py screened_in_memory: result.info["screened_losses"])."""
    losses = log.metadata.get("reader_losses") or screened or {}
    health.figures["losses"] = loss_figures(losses)
    for severity, text in loss_findings(losses):
        health.flag(severity, text)
    known = ("salvage:", "gap(s) in the data", ": dropped ", "the IMU saturated", "clock step at")
    for w in log.metadata.get("reader_warnings", []):
        if not any(k in w for k in known):  # the losses are said above, from the structured record
            health.flag("note", f"reader: {w}")


def loss_figures(losses: dict[str, Any]) -> dict[str, Any]:
    """The numbers of the reader's losses: messages lost per topic, seconds of data missing per topic (gaps in
    the stamps), chunks lost, whether the file was cut short and where its data end."""
    salv = losses.get("salvage") or {}
    return {
        "messages_lost": dict(losses.get("messages_lost", {})),
        "seconds_missing": {t: g["seconds"] for t, g in (losses.get("gaps") or {}).items()},
        "chunks_lost": salv.get("chunks_lost", 0),
        "truncated": bool(salv.get("truncated")),
        "data_end_s": min(
            (c["data_end_s"] for c in salv.get("truncated", []) if c["data_end_s"] is not None),
            default=None,
        ),
    }


def loss_lines(losses: dict[str, Any]) -> list[str]:
    """What the reader lost (LogData.metadata["reader_losses"]), one line per finding; [] if nothing."""
    return [text for _, text in loss_findings(losses)]


def loss_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """(severity, text) per loss: salvaged chunks, a cut-off file, messages dropped by --repair per topic, gaps
    in a topic's stamps, IMU saturation, clock steps. Severity "degraded" when the loss harms the result, else
    "note"."""
    return [
        *_salvage_findings(losses),
        *_repair_findings(losses),
        *_gap_findings(losses),
        *_saturation_findings(losses),
        *_clock_step_findings(losses),
    ]


def _salvage_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The chunks --salvage dropped and a file cut short: both degrade the result."""
    out: list[tuple[str, str]] = []
    salv = losses.get("salvage") or {}
    if salv.get("chunks_lost"):
        per = ", ".join(
            f"{t} {n}" for t, n in sorted(salv.get("messages_lost_per_topic", {}).items())
        )
        spans = salv.get("lost_spans_s", [])
        when = (
            (
                f", log time {min(s[0] for s in spans):.1f} to {max(s[1] for s in spans):.1f} s "
                f"({salv.get('seconds_lost', 0.0):.1f} s of data)"
            )
            if spans
            else ""
        )
        at_least = "" if salv.get("messages_lost_exact") else "at least "
        out.append(
            (
                "degraded",
                f"--salvage dropped {salv['chunks_lost']} damaged chunk(s) with {at_least}"
                f"{salv.get('messages_lost', 0)} message(s)"
                + (f" ({per})" if per else "")
                + when
                + ": the result has no data there",
            )
        )
    for cut in salv.get("truncated", []):
        end = cut.get("data_end_s")
        out.append(
            (
                "degraded",
                f"the log file is cut short at byte {cut['at_byte']}: nothing after "
                + (f"{end:.1f} s" if end is not None else "its start")
                + " could be read and how much more it held is unknown; the result ends there",
            )
        )
    return out


def _repair_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The messages --repair dropped per topic: "degraded" beyond REPAIRED_DEGRADED of the topic."""
    out: list[tuple[str, str]] = []
    for topic, d in sorted((losses.get("repair") or {}).items()):
        if d.get("of") and d["dropped"] / d["of"] > REPAIRED_DEGRADED:
            out.append(
                ("degraded", _repair_line(topic, d) + ": the log is damaged, check the recording")
            )
        else:
            out.append(("note", _repair_line(topic, d)))
    return out


def _gap_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The gaps in each topic's stamps: "degraded" when the longest is beyond the IMU's or the DVL's limit."""
    out: list[tuple[str, str]] = []
    for topic, g in sorted((losses.get("gaps") or {}).items()):
        imu = "imu" in topic.lower()
        if imu and g["longest_s"] > IMU_GAP_DEGRADED_S:
            out.append(
                (
                    "degraded",
                    _gap_line(topic, g) + ": the IMU has holes, crossed by holding the last "
                    "sample (the sigmas grow there); check the IMU driver",
                )
            )
        elif not imu and g["longest_s"] > DVL_GAP_DEGRADED_S:
            out.append(
                ("degraded", _gap_line(topic, g) + ": dead reckoning on the IMU alone there")
            )
        else:
            out.append(("note", _gap_line(topic, g)))
    return out


def _saturation_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The IMU's saturated stretches per topic (dropped and crossed as gaps): each degrades the result."""
    out: list[tuple[str, str]] = []
    for topic, report in sorted((losses.get("saturation") or {}).items()):
        axes = ", ".join(
            f"{a['sensor']} {a['axis']} at {a['limit']:+.4g} "
            f"{'rad/s' if a['sensor'] == 'gyro' else 'm/s^2'}"
            for a in report["axes"]
        )
        a, b = (
            max(report["spans_s"], key=lambda s: s[1] - s[0])
            if report["spans_s"]
            else (float("nan"),) * 2
        )
        out.append(
            (
                "degraded",
                f"{topic}: the IMU saturated ({axes}): {report['samples']} samples at the range "
                f"limit in {report['stretches']} stretch(es), the longest {a:.2f} to {b:.2f} s, "
                "dropped and crossed as IMU gaps, holding the last sample before (the sigmas grow "
                "there); an IMU with a larger range avoids it",
            )
        )
    return out


def _clock_step_findings(losses: dict[str, Any]) -> list[tuple[str, str]]:
    """The clock steps --repair shifted the stamps across: notes."""
    out: list[tuple[str, str]] = []
    for topic, steps in sorted((losses.get("clock_steps") or {}).items()):
        for c in steps:
            back = c["jump_s"] < 0
            out.append(
                (
                    "note",
                    f"{topic}: clock step at {c['at_s']:.3f} s (the stamps jump {'back ' * back}by "
                    f"{abs(c['jump_s']):.3f} s while the samples run on): --repair shifted the later "
                    f"stamps {'forward' if back else 'back'} by {abs(c['step_s']):.3f} s",
                )
            )
    return out


def _repair_line(topic: str, d: dict[str, int]) -> str:
    why = ", ".join(
        f"{d[k]} {name}"
        for k, name in (
            ("nan", "with NaN"),
            ("duplicate", "duplicate stamp(s)"),
            ("backwards", "going back in time"),
        )
        if d.get(k)
    )
    return f"--repair dropped {d['dropped']} of {d.get('of', '?')} {topic} message(s) ({why})"


def _gap_line(topic: str, g: dict[str, Any]) -> str:
    a, b = (
        max(g["spans_s"], key=lambda s: s[1] - s[0])
        if g.get("spans_s")
        else (float("nan"), float("nan"))
    )
    return f"{topic}: {g['seconds']:.1f} s of data missing in {g['count']} gap(s) (longest {a:.1f} to {b:.1f} s)"
