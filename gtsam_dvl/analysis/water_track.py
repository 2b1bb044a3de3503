"""Water-track pings in the health check: the stretches, their residuals against the estimated current, and false
bottom lock.

A water-track ping measures the velocity relative to the water (estimators/models/current.py): its residual is the
bottom-track residual (analysis/dvl_residuals.py, against the velocity over ground) plus the current seen in
dvl_link, k d_R_b n_R_b^T [c_east, c_north, 0]. This module

- counts the water-track pings and their stretches (runs of water-track pings without a bottom-track ping between
  them), and says whether they were used (with the current as a state) or refused;
- judges the used ones: their whitened residuals against the model with the estimated current, noise
  the noise they were given (selection.water_covariance) plus the current's own uncertainty ("warn" beyond
  WATER_RMS_WARN);
- flags false bottom lock: a bottom-track ping whose velocity disagrees with the velocity over ground (its whitened
  residual beyond FALSE_LOCK_CHI2) but agrees with the water track, i.e. with the vehicle's velocity relative to
  the water (residual within WATER_AGREES_CHI2 once the current is added), where the current is determined and
  large enough to tell the two apart (|c| above three sigmas of the ping): what a DVL that locked on a scattering
  layer, or on the water near the range limit, reports as bottom track.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult, WaterCurrentProfile
from gtsam_dvl.core.types import DvlData, LogData
from gtsam_dvl.estimators.inputs.selection import ping_covariance, water_covariance

# whitened RMS of the water-track residuals above which the current model does not fit
WATER_RMS_WARN = 2.0
# chi^2 (3 dof) 0.999 quantile: a bottom-track ping that disagrees with the ground
FALSE_LOCK_CHI2 = 16.27
WATER_AGREES_CHI2 = 7.81  # chi^2 (3 dof) 0.95 quantile: ...and agrees with the water track
STRETCH_GAP_S = 5.0  # water-track pings further apart than this are two stretches


def stretches(t: np.ndarray, water: np.ndarray) -> list[tuple[float, float, int]]:
    """(start s, end s, pings) of each run of water-track pings: consecutive in the log (no bottom-track ping
    between) and at most STRETCH_GAP_S apart."""
    out: list[tuple[float, float, int]] = []
    idx = np.flatnonzero(water)
    if not len(idx):
        return out
    start = prev = int(idx[0])
    for j in idx[1:].tolist():
        if j != prev + 1 or t[j] - t[prev] > STRETCH_GAP_S:
            out.append((float(t[start]), float(t[prev]), prev - start + 1))
            start = j
        prev = j
    out.append((float(t[start]), float(t[prev]), prev - start + 1))
    return out


def _current_at(profile: WaterCurrentProfile, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The estimated current [c_east, c_north, 0] (N, 3) at times t and its per-axis variance (N, 2), interpolated
    between the profile's states."""
    ts = np.asarray(profile.t_s, dtype=float)
    c = np.zeros((len(t), 3))
    var = np.zeros((len(t), 2))
    for a, (value, sigma) in enumerate(
        ((profile.east_m_s, profile.east_sigma_m_s), (profile.north_m_s, profile.north_sigma_m_s))
    ):
        c[:, a] = np.interp(t, ts, np.asarray(value, dtype=float))
        var[:, a] = np.interp(t, ts, np.asarray(sigma, dtype=float) ** 2)
    return c, var


def check_water_track(
    result: NavResult,
    log: LogData,
    config: EstimatorConfig,
    res: Any,
    figures: dict[str, Any],
    flag: Callable[[str, str], None],
) -> None:
    """The water-track findings of a run (module doc) into the health's figures ("water_track") and flags. res:
    analysis/dvl_residuals.py DvlResiduals of the run (its raw residuals, ping indices and water-track mask)."""
    dvl = log.dvl
    if dvl.water_track is None or not np.any(dvl.water_track):
        return
    water = np.asarray(dvl.water_track, dtype=bool)
    runs = stretches(np.asarray(dvl.t, dtype=float), water)
    profile = result.water_current
    span = ", ".join(f"{a:.0f}-{b:.0f} s ({n})" for a, b, n in runs[:5]) + (
        " ..." if len(runs) > 5 else ""
    )
    fig: dict[str, Any] = {
        "pings": int(water.sum()),
        "stretches": [list(r) for r in runs],
        "used": profile is not None,
    }
    figures["water_track"] = fig
    # refused: counted and judged by analysis/health_counters.py (dvl_water_track)
    if profile is None:
        return
    flag(
        "note",
        f"{int(water.sum())} water-track pings in {len(runs)} stretch(es) ({span}) used with the water "
        f"current as a state; the current: {profile.verdict}",
    )
    if res.residual_m_s is None or res.index is None or res.water is None or not len(res.index):
        return
    figs, warnings = _ping_findings(_PingsInCurrent.of(result, log, res, profile), result, config)
    fig.update(figs)
    for text in warnings:
        flag("warn", text)


def _ping_findings(
    pings: _PingsInCurrent, result: NavResult, config: EstimatorConfig
) -> tuple[dict[str, Any], list[str]]:
    """The run's pings against the estimated current: the water-track pings' whitened residuals (figure
    "whitened_rms", a warning beyond WATER_RMS_WARN) and the bottom-track pings in false lock (figure
    "false_lock_pings", a warning when any). Returns the figures and the warnings."""
    figs: dict[str, Any] = {}
    warnings = []
    seen = np.isfinite(pings.r).all(axis=1)
    wt = pings.water & seen
    if wt.any():
        figs["whitened_rms"] = rms = pings.water_rms(result, config, wt)
        if rms > WATER_RMS_WARN:
            warnings.append(
                f"water-track residuals {rms:.1f}x their noise (the messages' covariance or [current] "
                "water_track_sigma_m_s) with the estimated current: the current "
                "changes faster than its random walk allows ([current] time_rw_m_s_per_sqrt_s, "
                "depth_rw_m_s_per_sqrt_m) or the water-track noise is larger"
            )
    bt = ~pings.water & seen
    if bt.any():
        false_lock = pings.false_lock(config, bt)
        figs["false_lock_pings"] = int(false_lock.sum())
        if false_lock.any():
            times = pings.t_p[bt][false_lock]
            warnings.append(
                f"{int(false_lock.sum())} bottom-track pings ({times[0]:.0f}-{times[-1]:.0f} s) "
                "disagree with the velocity over ground and agree with the water track (velocity "
                "relative to the water): a false bottom lock (a scattering layer, or the water near "
                "the DVL's range limit); their factors were down-weighted by the robust kernel, check "
                "the DVL's altitude there"
            )
    return figs, warnings


def _current_seen(
    result: NavResult, t_p: np.ndarray, c: np.ndarray, var_c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The current c (N, 3) m/s in the map frame, variance var_c (N, 2) (east, north), as the DVL sees it at the
    pings' times t_p: in dvl_link (N, 3) and its covariance (N, 3, 3)."""
    # the current seen in dvl_link at each ping: k d_R_b n_R_b^T c, with the nearest state's attitude
    state = np.clip(np.searchsorted(result.t, t_p), 0, len(result.t) - 1)
    n_R_b = np.asarray(result.n_R_b)[state]
    d_R_n = np.einsum(
        "ij,njk->nik",
        float(result.scale) * np.asarray(result.b_R_d).T,
        np.transpose(n_R_b, (0, 2, 1)),
    )
    c_d = np.einsum("nij,nj->ni", d_R_n, c)
    # its covariance from the current's (east, north)
    cov_c = np.einsum("nia,na,nja->nij", d_R_n[:, :, :2], var_c, d_R_n[:, :, :2])
    return c_d, cov_c


def _chi2(r: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """r_i^T cov_i^-1 r_i of each residual r (N, 3) with its covariance cov (N, 3, 3)."""
    return np.einsum("ni,ni->n", r, np.linalg.solve(cov, r[..., None])[..., 0])


@dataclass
class _PingsInCurrent:
    """The run's pings (dvl: the log's; r: their raw residuals (N, 3) m/s, idx: their indices in dvl, water: the
    water-track ones) at their times t_p (s) with the estimated current: c (N, 3) m/s in the map frame, its
    variance var_c (N, 2) (east, north), and as the DVL sees it, c_d (N, 3) in dvl_link with covariance cov_c
    (N, 3, 3)."""

    dvl: DvlData
    r: np.ndarray
    idx: np.ndarray
    water: np.ndarray
    t_p: np.ndarray
    c: np.ndarray
    var_c: np.ndarray
    c_d: np.ndarray
    cov_c: np.ndarray

    @classmethod
    def of(
        cls, result: NavResult, log: LogData, res: Any, profile: WaterCurrentProfile
    ) -> _PingsInCurrent:
        """The pings of res (DvlResiduals) with result's current profile."""
        t_p = np.asarray(log.dvl.t[res.index], dtype=float)
        c, var_c = _current_at(profile, t_p)
        c_d, cov_c = _current_seen(result, t_p, c, var_c)
        return cls(log.dvl, res.residual_m_s, res.index, res.water, t_p, c, var_c, c_d, cov_c)

    def water_rms(self, result: NavResult, config: EstimatorConfig, wt: np.ndarray) -> float:
        """The whitened RMS of the water-track pings' (mask wt) residuals under the water-track model, whitened
        by their noise and the current's."""
        dvl, idx = self.dvl, self.idx
        # y - (h_ground - current seen): the water-track model's residual
        r_w = self.r[wt] + self.c_d[wt]
        if (k_w := result.calibration.get("water_scale")) is not None:
            # their own scale: y - (k_w / k) h_water
            y = np.asarray(dvl.d_v[idx[wt]], dtype=float)
            r_w = y - (y - r_w) * float(k_w.value[0]) / float(result.scale)
        chi2 = _chi2(r_w, water_covariance(config, dvl.d_cov[idx[wt]]) + self.cov_c[wt])
        return float(np.sqrt(chi2.sum() / (3 * len(chi2))))

    def false_lock(self, config: EstimatorConfig, bt: np.ndarray) -> np.ndarray:
        """Which bottom-track pings (mask bt) disagree with the velocity over ground and agree with the water
        track, where the current is large (beyond three sigmas of the ping) and determined (its sigma below
        half its prior's)."""
        determined = np.sqrt(self.var_c.max(axis=1)) < 0.5 * config.current.prior_sigma_m_s
        cov_g = ping_covariance(config.dvl, self.dvl.d_cov[self.idx[bt]])
        r_g = self.r[bt]
        chi2_g = _chi2(r_g, cov_g)
        chi2_w = _chi2(r_g + self.c_d[bt], cov_g + self.cov_c[bt])
        c = self.c[bt, :2]
        big = np.linalg.norm(c, axis=1) > 3.0 * np.sqrt(np.trace(cov_g, axis1=1, axis2=2) / 3.0)
        return (chi2_g > FALSE_LOCK_CHI2) & (chi2_w < WATER_AGREES_CHI2) & big & determined[bt]
