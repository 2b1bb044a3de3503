"""The DVL residuals of a run, recomputed from the result and the log with the model of docs/conventions.md,
y = k * b_R_d^T (n_R_b^T n_v + b_omega x b_l), whitened by the noise each ping was given: what the health check
(analysis/health.py) judges per window and analysis/water_track.py per water-track stretch. A filter's states with
the calibration they were estimated with (state_calibration).

Pure computation on NavResult and LogData: no files (analysis layer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_exp, so3_log
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.selection import ping_covariance, usable_pings
from gtsam_dvl.factors.dvl_model import dvl_model


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
    # d h / dt per ping, m/s^2 in dvl_link (3-D velocity only): the predicted DVL velocity's rate, which is the
    # time offset's Jacobian (a ping seen at t + delta measures h + delta * dh/dt; analysis/dvl_misfit.py)
    rate_m_s2: np.ndarray | None = None

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
    # the DVL's correlated error's variance (estimators/models/correlated.py)
    gm_var = config.correlated_sigma_m_s**2
    if config.use_beams and dvl.beams is not None:
        d_u, v, ok = dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j]
        ok = ok & np.isfinite(v) & np.isfinite(d_u).all(axis=2)
        r = np.where(ok, v - np.einsum("nbi,ni->nb", np.where(ok[..., None], d_u, 0.0), y_hat), 0.0)
        chi2 = (r**2).sum(axis=1) / (config.beam_sigma_m_s() ** 2 + gm_var)
        dof = ok.sum(axis=1).astype(float)
        return DvlResiduals(np.asarray(dvl.t[j], dtype=float), chi2, dof, unmatched, selected_again)
    out = _velocity_residuals(log, config, j, y_hat, gm_var, unmatched, selected_again)
    if n > 1:
        rate = np.gradient(y_state, result.t, axis=0)
        out.rate_m_s2 = np.stack([np.interp(t_p, result.t, rate[:, k]) for k in range(3)], axis=1)
    return out


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
