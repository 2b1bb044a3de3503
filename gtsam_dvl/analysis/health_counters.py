"""The estimator's counters and records in the health check (analysis/health.py): DVL pings rejected or not used
and why, IMU samples dropped, the time offset's windows and bound, the pieces and IMU gaps.

Pure computation on NavResult and LogData: no files (analysis layer).
"""

from __future__ import annotations

import numpy as np

from gtsam_dvl.analysis.health_losses import DVL_GAP_DEGRADED_S, IMU_GAP_DEGRADED_S
from gtsam_dvl.analysis.health_verdict import Health
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.ping_screen import frozen_runs

# More than this share of the DVL pings rejected: a good part of the log did not reach the estimator.
REJECTED_PINGS_DEGRADED = 0.05

# Counters that are not rejections (the EKF's slow pings still update the navigation; keyframe thinning is
# by design).
NOT_REJECTIONS = (
    "dvl_not_keyframe",
    "dvl_slow",
    "dvl_updates",
    "dvl_downweighted",
    "dvl_water_track",
    "dvl_before_imu",
    "dvl_after_imu",
)


def check_counters(result: NavResult, log: LogData, health: Health) -> None:
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
        k: v for k, v in counters.items() if k.startswith("dvl_") and k not in NOT_REJECTIONS and v
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
    # the batch smoother's windows never agreed with its solution
    if centring.get("consistent") is False:
        health.flag(
            "degraded",
            f"the DVL time offset's IMU windows did not settle on the estimate (centred at "
            f"{centring['centre_s']:+.3f} s, estimate {centring['estimate_s']:+.3f} s, sigma "
            f"{centring['sigma_s']:.3f} s) after {centring['recentred']} re-centrings: the offset "
            "model is approximate here (sharp turns with a large offset)",
        )
    # the EKF held its offset state at the bound
    if bounded := counters.get("time_offset_bounded", 0):
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
    losses = result.info.get("screened_losses") or log.metadata.get("reader_losses") or {}
    # the reader's record says where the IMU data are missing, and its saturation record the gaps it made
    reader_saw = any("imu" in topic.lower() for topic in (losses.get("gaps") or {})) or bool(
        losses.get("saturation")
    )
    # an in-memory log: the reader's gap record is not there
    if gaps.get("count") and not reader_saw:
        text = (
            f"{gaps['count']} IMU gap(s), {gaps['total_s']:.2f} s in all, the longest {gaps['longest_s']:.2f} s, "
            "crossed by holding the last sample (the sigmas grow there)"
        )
        health.flag(
            "degraded" if gaps["longest_s"] > IMU_GAP_DEGRADED_S else "note",
            text + ("; check the IMU driver" if gaps["longest_s"] > IMU_GAP_DEGRADED_S else ""),
        )


def _offset_prior_centre(result: NavResult, config: EstimatorConfig) -> float:
    """The centre (s) of the time offset's prior the filter ran with: the configured one, or where the EKF's warm-up
    moved it (info["time_offset_prior"])."""
    recentred = result.info.get("time_offset_prior")
    if isinstance(recentred, dict) and "centre_s" in recentred:
        return float(recentred["centre_s"])
    return config.dvl.time_offset_prior_s


def _check_offset_clip(result: NavResult, clipped: int, health: Health) -> None:
    """The filters (EKF, online) centre the IMU windows of their time-offset model on the offset's estimate held
    within the prior +- 3 prior sigmas; `clipped` pings had their window held at that bound. "degraded" when the
    final estimate is beyond it (the late pings' model is approximate), a note when the estimate came back within
    (a transient: the bound held a filter that was still converging)."""
    config = result.estimator_config or EstimatorConfig()
    centre = _offset_prior_centre(result, config)
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
    centre = _offset_prior_centre(result, config)
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
