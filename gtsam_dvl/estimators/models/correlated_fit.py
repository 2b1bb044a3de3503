"""The DVL's correlated error (estimators/models/correlated.py) fitted from the data in the batch smoother's noise loop
([noise] fit_correlated; estimators/batch/smoother.py fit_dvl_noise).

At a solution, each bottom-track ping's residual in dvl_link axes with the estimated correlated error added back,
y - h(x) = (y - h(x) - E(i)) + E(i), is what a model without E would see: the white ping noise plus the part of
the DVL's slow error that the rest of the solution does not follow. A white plus first-order Gauss-Markov fit of
its autocovariance, the three axes pooled (core/sensor_noise.py gauss_markov_fit, with the removed mean allowed
for), gives a level sg (m/s) and a time constant tau (s); they replace [dvl] correlated_sigma_m_s and
correlated_tau_s, clipped to [noise] correlated_min/max_sigma_m_s and correlated_min/max_tau_s, the prior and
links of E are made again and the log solved again, until neither changes by more than [noise]
correlated_tolerance (the DVL's variance component is fitted in the same loop from the same solutions).

A fit whose Gauss-Markov part is not significant (core/sensor_noise.py: sg^2 within three sampling sigmas of
zero) changes nothing: the level last used holds. Not significant means not seen, not absent: on a log of IMU and
DVL alone the navigation solution follows the DVL's slow error (an error of 2 mm/s over 60 s needs an
acceleration of a few micro-g, below what a tilt drift of a thousandth of a degree makes), so the residuals lose
most of it whatever its level, and a fit taken at its word would drive the model to white and the position sigma
to the paper's (measured on straight-transect and steady-turn: docs/command-line.md). What the residuals show
is a lower bound of the level. Position fixes help only when they resolve the error's integral: 2 mm/s over
60 s moves the position by about sigma tau = 0.12 m per time constant, far below a 2 m GNSS fix, within an RTK
fix's reach (not measured).

Pings left out of the fit: the water-track rows (their error holds the current's), the rows beyond the robust
kernel's threshold at a median-based scale, and every row of beam factors (each beam sees d_u . E: not fitted;
the configured level holds). The online estimator and the EKF hold the configured level and say so
(held_correlated_level).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from scipy.stats import chi2

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.sensor_noise import MIN_LAGS, GaussMarkovFit, gauss_markov_fit
from gtsam_dvl.core.states import correlated_error
from gtsam_dvl.estimators.models import correlated


def fit_enabled(config: EstimatorConfig) -> bool:
    """Whether the batch smoother fits the correlated error: [noise] from_data and fit_correlated, the error
    modelled ([dvl] correlated_sigma_m_s > 0: its states exist) and the pings' 3-D velocity factors (not beams)."""
    n = config.noise
    return (
        n.from_data and n.fit_correlated and correlated_error(config) and not config.dvl.use_beams
    )


def with_level(config: EstimatorConfig, sigma_m_s: float, tau_s: float) -> EstimatorConfig:
    """config with [dvl] correlated_sigma_m_s and correlated_tau_s set."""
    return config.model_copy(
        update={
            "dvl": config.dvl.model_copy(
                update={"correlated_sigma_m_s": float(sigma_m_s), "correlated_tau_s": float(tau_s)}
            )
        }
    )


def replace_factors(
    graph: gtsam.NonlinearFactorGraph, slots: range, config: EstimatorConfig, t_states: np.ndarray
) -> None:
    """The prior and links of E made again at config's level and time constant, into their slots
    (LogGraph.factor_slots["dvl_error"]: the prior first, then the links in state order)."""
    factors = correlated.factors(config, t_states)
    if len(factors) != len(slots):
        raise GtsamDvlError(
            f"correlated error fit: {len(factors)} factors made again for {len(slots)} slots"
        )
    for i, f in zip(slots, factors, strict=True):
        graph.replace(i, f)


def residual_series(bulk: Any, values: gtsam.Values) -> tuple[np.ndarray, np.ndarray]:
    """The bottom-track rows' ping stamps (N,) s and their residuals h(x) - y with the estimated E taken out of h
    (N, 3) m/s, dvl_link (module doc); nan on the rows beyond the robust kernel's threshold at a median-based
    scale. bulk: the graph's BulkDvl (estimators/graph/bulk.py), 3-D rows."""
    ew = bulk.whitened_errors(values)
    e = np.linalg.solve(bulk.whiten, ew[..., None])[..., 0]  # the unwhitened error h + E - y
    d_e = bulk._correlated_errors(values)
    r = e - d_e if d_e is not None else e
    x2 = np.einsum("ni,ni->n", ew, ew)
    s0 = float(np.median(x2) / chi2.median(ew.shape[1])) if len(x2) else 1.0
    bad = x2 > bulk.robust_k**2 * max(s0, 1e-300)
    if bulk.water is not None:
        bad |= bulk.water
    r = np.where(bad[:, None], np.nan, r)
    return np.asarray(bulk.t_ping, dtype=float), r


@dataclass(frozen=True)
class LevelFit:
    """One fit of the level and time constant: the values the model takes next (clipped, or the current ones when
    the fit is not significant), whether either hit a bound, and the fit itself."""

    sigma_m_s: float
    tau_s: float
    at_bound: bool
    significant: bool
    fit: GaussMarkovFit | None  # None: too few rows
    rows: int  # the residual rows fitted (3 per ping)

    def moves(self, sigma_m_s: float, tau_s: float, tolerance: float) -> bool:
        """Whether the model at (sigma_m_s, tau_s) needs another solve at this fit's values."""
        return (
            abs(self.sigma_m_s / sigma_m_s - 1.0) > tolerance
            or abs(self.tau_s / tau_s - 1.0) > tolerance
        )


def fit_level(t: np.ndarray, r: np.ndarray, config: EstimatorConfig) -> LevelFit:
    """The level and time constant from the residual series (residual_series) at config's current ones (module
    doc): the ping spacing is the median of the stamps' differences."""
    n, dvl = config.noise, config.dvl
    current = (dvl.correlated_sigma_m_s, dvl.correlated_tau_s)
    ok = np.isfinite(r).all(axis=1) & np.isfinite(t)
    dt = np.diff(np.unique(t[ok]))
    rows = 3 * int(ok.sum())
    if ok.sum() < max(2 * MIN_LAGS, n.min_rows // 3) or not len(dt):
        return LevelFit(*current, False, False, None, rows)
    fit = gauss_markov_fit(t[ok], r[ok], float(np.median(dt)), mean_corrected=True)
    if not fit.significant:
        return LevelFit(*current, False, False, fit, rows)
    lo_s, hi_s = n.correlated_min_sigma_m_s, n.correlated_max_sigma_m_s
    lo_t, hi_t = n.correlated_min_tau_s, n.correlated_max_tau_s
    sigma = min(max(fit.gm_sigma, lo_s), hi_s)
    tau = min(max(fit.gm_tau_s, lo_t), hi_t)
    if sigma <= 0.0:  # (a lower bound of 0: the states' prior needs a level)
        return LevelFit(*current, True, True, fit, rows)
    return LevelFit(sigma, tau, sigma != fit.gm_sigma or tau != fit.gm_tau_s, True, fit, rows)


def fit_report(
    configured: EstimatorConfig, used: EstimatorConfig, last: LevelFit, passes: int, how: str
) -> dict[str, Any]:
    """report.dvl_correlated of the batch fit: the level and time constant configured and used, the last fit's
    figures, the passes, whether at a bound, and the line."""
    c, u, n, rows = configured.dvl, used.dvl, used.noise, last.rows
    out: dict[str, Any] = {
        "configured": {"sigma_m_s": c.correlated_sigma_m_s, "tau_s": c.correlated_tau_s},
        "sigma_m_s": u.correlated_sigma_m_s,
        "tau_s": u.correlated_tau_s,
        "rows": rows,
        "passes": passes,
        "at_bound": last.at_bound,
        "significant": last.significant,
        "how": how,
    }
    f = last.fit
    if f is not None:
        out["fit"] = {
            "gm_sigma_m_s": f.gm_sigma,
            "gm_tau_s": f.gm_tau_s,
            "white_sigma_m_s": f.white_sigma,
            "gm_sigma_noise_m_s": f.gm_sigma_noise,
            "samples": f.samples,
        }
    level = f"{u.correlated_sigma_m_s * 1e3:.3g} mm/s over {u.correlated_tau_s:.3g} s"
    if f is None:
        out["why"] = (
            f"DVL correlated error not fitted: {rows} usable residual rows; the configured {level} "
            "holds"
        )
    elif (
        u.correlated_sigma_m_s == c.correlated_sigma_m_s
        and u.correlated_tau_s == c.correlated_tau_s
        and not last.significant
    ):
        out["why"] = (
            f"DVL correlated error as configured ({level}): the residuals show no significant "
            f"correlated part ({f.gm_sigma * 1e3:.2g} +- {f.gm_sigma_noise * 1e3:.2g} mm/s, {rows} rows, "
            "the estimated error added back); the navigation solution follows a slow DVL error, so "
            "that is not its absence"
        )
    else:
        out["why"] = (
            f"DVL correlated error fitted from {rows} residual rows ({how}): {level} (configured "
            f"{c.correlated_sigma_m_s * 1e3:.3g} mm/s over {c.correlated_tau_s:.3g} s)"
        )
        if not last.significant:
            out["why"] += "; the last fit was not significant: the level before it holds"
        if last.at_bound:
            out["why"] += (
                f", at a bound of [noise] (level {n.correlated_min_sigma_m_s * 1e3:g}-"
                f"{n.correlated_max_sigma_m_s * 1e3:g} mm/s, tau {n.correlated_min_tau_s:g}-"
                f"{n.correlated_max_tau_s:g} s)"
            )
    return out


def held_correlated_level(config: EstimatorConfig, estimator: str) -> dict[str, Any]:
    """report.dvl_correlated of an estimator that holds the configured level (the online estimator, the EKF): said
    when [noise] would fit it in the batch smoother; else {}."""
    if not fit_enabled(config):
        return {}
    d = config.dvl
    return {
        "configured": {"sigma_m_s": d.correlated_sigma_m_s, "tau_s": d.correlated_tau_s},
        "sigma_m_s": d.correlated_sigma_m_s,
        "tau_s": d.correlated_tau_s,
        "held": True,
        "why": f"DVL correlated error as configured ({d.correlated_sigma_m_s * 1e3:.3g} mm/s over "
        f"{d.correlated_tau_s:.3g} s): the {estimator} holds it (the batch smoother fits it from the "
        "residuals)",
    }
