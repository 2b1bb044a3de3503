"""Where the EKF's warm-up window centres the time offset's prior (filter.py _warm_up; [ekf] recentre_time_offset).

The filter linearises the offset's model about its estimate, so a prior centred far from the truth (a DVL stamped
1 s early against the default 0 +- 0.5 s) costs it the first minutes. The warm-up window ([noise] warmup_s) is
filtered first and its estimate becomes the prior's centre, with the configured sigma kept. That estimate is only
as good as the window's filter: one that lost track (a disturbance it could not explain, e.g. a depth update forced
in once its gate reopened) puts into the offset whatever it absorbed, with a sigma as small as a good run's. So the
window's estimate moves the centre only when the window supports it (window_support):

- its own sigma: at most RECENTRE_DETERMINED of the prior's (the window determined the offset: a straight run at
  constant speed does not, and its window estimate is noise);
- its residuals: its DVL innovations at most WINDOW_RESIDUAL_MAX times the stated noise (the root of the mean NIS
  per degree of freedom, at the noise level of that pass, times that level over the stated one: a consistent
  filter's is 1 at a stated level that is right, below 1 at a stated level that is a datasheet's long-term figure);
- its gate: at most WINDOW_GATED_MAX of its pings gated (at the 0.99999 gate a filter that keeps track gates the
  outliers only);
- its bound: its offset never held at the prior's +- 3 sigma (an estimate there is the bound, not the data's).

Otherwise the prior stays where the configuration put it (a centre moved by an earlier pass goes back: that pass's
window is not evidence for the centre its successor contradicts), and the result says why (info
["time_offset_prior"]). The filter itself sees the same evidence over the whole log: its divergence watch catches an
offset held at its bound (divergence.py), and run_ekf then filters again at the configured prior."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult

# The warm-up passes stop recentring once the window's offset moves the prior's centre by less than this fraction
# of its sigma (0.05 x 0.5 s = 25 ms, about the window's own sigma of the offset).
RECENTRE_TOLERANCE = 0.05
# The window's offset recentres the prior only when the window determined it: its sigma at most this fraction of
# the prior's.
RECENTRE_DETERMINED = 0.5
# ... and only when the window's filter kept track: its DVL innovations at most this many times the stated noise
# (field-survey seed 3 with its first position pinned at a fix 5 m off in height: 7.8x, 461 of 594 pings gated, the
# offset at -1.45 s on a truth of +0.3 s; the same window with the fix's uncertainty: 1.0x, none gated, +0.32 s) ...
WINDOW_RESIDUAL_MAX = 2.0
# ... and at most this fraction of its pings gated.
WINDOW_GATED_MAX = 0.02


def with_offset_prior(config: EstimatorConfig, centre_s: float) -> EstimatorConfig:
    """config with [dvl] time_offset_prior_s at centre_s (the sigma kept)."""
    return config.model_copy(
        update={"dvl": config.dvl.model_copy(update={"time_offset_prior_s": float(centre_s)})}
    )


def window_support(
    window: NavResult, config: EstimatorConfig, stated_multiplier: float
) -> str | None:
    """None when the warm-up window (its result, filtered at config) supports its time offset estimate (module doc),
    else why not, in words. stated_multiplier: the DVL noise multiplier as configured (the stated level)."""
    dvl = config.dvl
    dt, sigma = float(window.time_offset_s), float(window.time_offset_sigma_s)
    if (
        not (np.isfinite(dt) and np.isfinite(sigma))
        or sigma > RECENTRE_DETERMINED * dvl.time_offset_sigma_s
    ):
        return (
            f"the warm-up window did not determine the offset (sigma {sigma:.3g} s of the prior's "
            f"{dvl.time_offset_sigma_s:g} s)"
        )
    counters, filt = window.info.get("counters", {}), window.info.get("filter", {})
    if bounded := int(counters.get("time_offset_bounded", 0)):
        return (
            f"the warm-up window's offset was held at its prior's bound ({bounded} update(s)): its {dt:+.3f} s "
            "is the bound's"
        )
    pings = max(int(counters.get("dvl_updates", 0)), 1)
    gated = int(counters.get("dvl_gated", 0))
    if gated > WINDOW_GATED_MAX * pings:
        return (
            f"the warm-up window's filter lost track ({gated} of its {pings} pings gated): its {dt:+.3f} s is what "
            "it absorbed"
        )
    nis = float(filt.get("mean_nis_per_dof", math.nan))
    level = math.sqrt(max(nis, 0.0)) * dvl.noise_multiplier / stated_multiplier
    if not math.isfinite(level) or level > WINDOW_RESIDUAL_MAX:
        return (
            f"the warm-up window's DVL innovations were {level:.1f}x their stated noise (more than "
            f"{WINDOW_RESIDUAL_MAX:g}x): its {dt:+.3f} s is what a filter that does not fit absorbed"
        )
    return None


def recentred_offset(
    config: EstimatorConfig,
    window: NavResult,
    info: dict[str, Any],
    passes: int,
    window_config: EstimatorConfig,
    stated_multiplier: float,
) -> tuple[EstimatorConfig, bool, bool]:
    """config with the time offset prior after one warm-up pass (module doc), whether its centre moved by more than
    RECENTRE_TOLERANCE prior sigmas (another pass needed) and whether the window supported its estimate (else the
    prior is back at the configured centre, and the passes stop recentring). window: the pass's result, filtered at
    window_config. info (the result's info["time_offset_prior"]) says where the centre is and why; "centre_s" only
    when the centre is the window's (analysis/health_counters.py reads it)."""
    dvl = config.dvl
    configured = float(info.setdefault("configured_s", dvl.time_offset_prior_s))
    why_not = window_support(window, window_config, stated_multiplier)
    info.update(window_sigma_s=float(window.time_offset_sigma_s), passes=passes)
    if why_not is not None:
        moved = dvl.time_offset_prior_s != configured
        info.pop("centre_s", None)
        info["why"] = f"time offset prior kept at {configured:+.3f} s: {why_not}"
        return with_offset_prior(config, configured), moved, False
    dt = float(window.time_offset_s)
    moved = abs(dt - dvl.time_offset_prior_s) > RECENTRE_TOLERANCE * dvl.time_offset_sigma_s
    info.update(
        centre_s=dt,
        why=f"time offset prior centred at {dt:+.3f} s, the warm-up window's estimate (configured "
        f"{configured:+.3f} s, sigma {dvl.time_offset_sigma_s:g} s kept)",
    )
    return with_offset_prior(config, dt), moved, True


def contradicted(result: NavResult, config: EstimatorConfig, info: dict[str, Any]) -> str | None:
    """Why the filtered log contradicts the centre the warm-up gave its time offset prior (info "centre_s", config's
    prior): the divergence watch found the offset held at that prior's bound (divergence.py), or it ended there
    (within a tenth of a prior sigma of +- 3 sigma, as analysis/health_counters.py judges it); None when the centre
    was not moved or the filter kept inside."""
    if "centre_s" not in info:
        return None
    dvl = config.dvl
    centre, sigma = dvl.time_offset_prior_s, dvl.time_offset_sigma_s
    caught = result.info.get("filter", {}).get("diverged_by") == "bound"
    if not caught and abs(result.time_offset_s - centre) < 3.0 * sigma - 0.1 * sigma:
        return None
    how = "held its offset at that prior's bound" if caught else "ended at that prior's bound"
    return (
        f"time offset prior kept at {info['configured_s']:+.3f} s: centred at {centre:+.3f} s by the warm-up "
        f"window, the filter {how} ({result.time_offset_s:+.3f} s at the end), so the log does not support that "
        "centre; filtered again at the configured prior"
    )
