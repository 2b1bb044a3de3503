"""The health of a running estimator, from what its input streams and counters show now (the ROS 2 node's
diagnostics). The same verdicts as analysis/health.py (Health: "ok", "warn", "degraded", "failed", with warnings
that say what to do), judged on the present instead of on a finished run:

- the estimator stopped (an exception inside it: the node keeps running and says so): "failed";
- the IMU silent (wall time: the IMU is the clock, so sensor time stops with it): "failed", no estimate;
- the DVL topic silent (sensor time, the IMU's newest stamp against the DVL's): "warn", then "degraded" (the
  trajectory is dead reckoned on the IMU and depth, its covariance growing); lost bottom lock (pings coming
  without a valid velocity) likewise, with its own, longer threshold, as a DVL gap in a log (health_losses.py
  DVL_GAP_DEGRADED_S): a vehicle over deep water loses lock by design, a driver that stops is a fault;
- stamps: a jump in a stream's stamps in the last RECENT_S, messages on another clock than the IMU's: "warn";
  messages late beyond the reorder window or duplicated, rejected pings and dropped samples: notes with counts;
- waiting for the map origin (no origin configured and no GNSS fix yet): "warn"; aligning: a note.

Pure computation on a LiveState snapshot (no ROS, no files), so that it is tested without a node.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from gtsam_dvl.analysis.health_counters import NOT_REJECTIONS
from gtsam_dvl.analysis.health_losses import DVL_GAP_DEGRADED_S
from gtsam_dvl.analysis.health_verdict import Health

RECENT_S = 60.0  # a stamp jump is reported this long (sensor time) after it


@dataclass
class LiveThresholds:
    """Seconds: the DVL silent (sensor time) before "warn" and "degraded", no bottom lock before "degraded", the
    IMU silent (wall time) before "failed"."""

    dvl_silent_warn_s: float = 2.0
    dvl_silent_degraded_s: float = 10.0
    bottom_lock_degraded_s: float = DVL_GAP_DEGRADED_S
    imu_silent_s: float = 0.5


@dataclass
class StreamState:
    """One input as the node sees it: topic, messages received, seconds since its newest stamp (sensor time, nan
    before any), messages dropped late, duplicated or on another clock, stamp jumps (count, largest s, seconds
    since the last one)."""

    topic: str
    received: int = 0
    silent_s: float = math.nan
    late: int = 0
    duplicates: int = 0
    off_clock: int = 0
    jumps: int = 0
    largest_jump_s: float = 0.0
    since_jump_s: float = math.inf


@dataclass
class LiveState:
    """A snapshot of the node: the estimator's phase ("waiting_origin", "aligning", "running", "stopped"), its
    stop (error text, seconds since it), the IMU's wall-time silence (s), the streams, the seconds without a valid
    ping while pings arrive (sensor time), the estimator's counters, epochs, and t (s, sensor time)."""

    phase: str = "aligning"
    streams: dict[str, StreamState] = field(default_factory=dict)
    imu_wall_silent_s: float = 0.0
    no_lock_s: float = 0.0
    stop_error: str = ""
    since_stop_s: float = math.inf
    counters: dict[str, int] = field(default_factory=dict)
    epochs: int = 0
    t: float = math.nan


def assess_live(state: LiveState, limits: LiveThresholds | None = None) -> Health:
    """The verdict on a running estimator (module doc); figures: the numbers behind it."""
    lim = limits or LiveThresholds()
    h = Health()
    h.figures = {
        "phase": state.phase,
        "epochs": state.epochs,
        "t_s": state.t,
        "imu_wall_silent_s": state.imu_wall_silent_s,
        "no_lock_s": state.no_lock_s,
    }
    _check_stop_and_imu(state, lim, h)
    _check_phase(state, h)
    _check_dvl(state, lim, h)
    _check_streams(state, h)
    _check_counters(state, h)
    return h


def _check_stop_and_imu(state: LiveState, lim: LiveThresholds, h: Health) -> None:
    """The estimator stopped, or the IMU silent in wall time (the IMU is the clock): "failed" either way."""
    if state.stop_error:
        h.flag(
            "failed",
            f"the estimator stopped {state.since_stop_s:.1f} s ago ({state.stop_error}): no estimate "
            "from here on; restart the node (and report the error with its log)",
        )
    imu = state.streams.get("imu")
    if imu is not None and (imu.received == 0 or state.imu_wall_silent_s > lim.imu_silent_s):
        what = (
            "no IMU message yet"
            if imu.received == 0
            else f"silent for {state.imu_wall_silent_s:.1f} s"
        )
        h.flag(
            "failed",
            f"IMU topic {imu.topic}: {what}: no estimate without it; check the IMU driver and the "
            "topic name and QoS (imu_topic, qos_inputs)",
        )


def _check_phase(state: LiveState, h: Health) -> None:
    """Waiting for the map origin ("warn") or aligning (a note)."""
    if state.phase == "waiting_origin":
        h.flag(
            "warn",
            "waiting for the map origin: no GNSS fix yet and no estimator.alignment.origin_lat_deg "
            "(and lon, height) in the parameters; Earth rate and gravity need the latitude",
        )
    elif state.phase == "aligning":
        h.flag(
            "note",
            "aligning: the first estimate comes after [online] align_s of static IMU data (or at once "
            "with alignment.initial_attitude_deg)",
        )


def _check_dvl(state: LiveState, lim: LiveThresholds, h: Health) -> None:
    """The DVL silent or without bottom lock (sensor time, once the IMU runs): "warn", then "degraded"."""
    imu = state.streams.get("imu")
    dvl = state.streams.get("dvl")
    if dvl is not None and imu is not None and imu.received:
        silent = dvl.silent_s if dvl.received else math.inf
        where = f"DVL topic {dvl.topic}"
        if silent >= lim.dvl_silent_degraded_s:
            h.flag(
                "degraded",
                f"{where} silent for {_s(silent)} (sensor time): dead reckoning on the IMU (and depth) "
                "since, the position sigma growing; check the DVL driver",
            )
        elif silent >= lim.dvl_silent_warn_s:
            h.flag(
                "warn",
                f"{where} silent for {_s(silent)} (sensor time): dead reckoning on the IMU meanwhile",
            )
        if state.no_lock_s >= lim.bottom_lock_degraded_s:
            h.flag(
                "degraded",
                f"no bottom lock for {state.no_lock_s:.1f} s (pings without a valid velocity): dead "
                "reckoning on the IMU (and depth) for long; the position sigma grows",
            )
        elif state.no_lock_s >= lim.dvl_silent_warn_s:
            h.flag(
                "warn",
                f"no bottom lock for {state.no_lock_s:.1f} s (pings without a valid velocity): dead "
                "reckoning on the IMU (and depth) until the DVL finds the bottom",
            )


def _check_streams(state: LiveState, h: Health) -> None:
    """Each stream's recent stamp jumps and off-clock messages ("warn"), late and duplicate ones (a note)."""
    for s in state.streams.values():
        if s.jumps and s.since_jump_s < RECENT_S:
            h.flag(
                "warn",
                f"{s.topic}: stamp jump of {s.largest_jump_s:.3f} s {s.since_jump_s:.1f} s ago "
                f"({s.jumps} in all): a clock step or a gap in the driver's stamps",
            )
        if s.off_clock:
            h.flag(
                "warn",
                f"{s.topic}: {s.off_clock} message(s) stamped far from the IMU's clock, dropped: stamp "
                "every sensor on one clock (or raise clock_skew_s)",
            )
        if s.late or s.duplicates:
            h.flag(
                "note",
                f"{s.topic}: {s.late} message(s) later than the reorder window and {s.duplicates} "
                "duplicate(s), dropped",
            )


def _check_counters(state: LiveState, h: Health) -> None:
    """The estimator's counters: rejected pings and dropped IMU samples, a note each."""
    # the pings the estimator could not use, counted as assess_health counts them (keyframe thinning and slow
    # pings are not rejections); the ones without a valid velocity are the bottom lock's, said above
    rejected = {
        k: v
        for k, v in state.counters.items()
        if k.startswith("dvl_") and v and k not in NOT_REJECTIONS and k != "dvl_unusable"
    }
    if rejected:
        h.flag(
            "note",
            "DVL pings rejected: "
            + ", ".join(
                f"{v} {k.removeprefix('dvl_').replace('_', ' ')}"
                for k, v in sorted(rejected.items())
            ),
        )
    dropped = {
        k: v for k, v in state.counters.items() if k.startswith("imu_") and k != "imu_gaps" and v
    }
    if dropped:
        h.flag(
            "note",
            "IMU samples dropped: "
            + ", ".join(
                f"{v} {k.removeprefix('imu_').replace('_', ' ')}"
                for k, v in sorted(dropped.items())
            ),
        )


def _s(x: float) -> str:
    return "ever (no message yet)" if not math.isfinite(x) else f"{x:.1f} s"


def summary_values(health: Health) -> dict[str, Any]:
    """The verdict as flat key-values (diagnostic_msgs/KeyValue): status, each warning and note numbered."""
    out: dict[str, Any] = {"status": health.status}
    out.update({f"warning {i + 1}": w for i, w in enumerate(health.warnings)})
    out.update({f"note {i + 1}": n for i, n in enumerate(health.notes)})
    return out
