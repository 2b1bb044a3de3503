"""Replaying a recorded log through the online estimator into the live view (`gtsam-dvl live LOG`).

replay_log pushes the log's messages in delivery order (core/message_order.py) at a chosen speed and publishes
each message and each completed epoch on a LiveView; serve_log reads the log, starts the view and replays it.
"""

from __future__ import annotations

import math
import threading
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.app.live.server import DEFAULT_PORT, LiveView, import_foxglove
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.message_order import log_messages
from gtsam_dvl.core.types import LogData

if TYPE_CHECKING:
    from gtsam_dvl.estimators.online import OnlineEstimate, OnlineEstimator
    from gtsam_dvl.io.read_options import ReadOptions


def parse_speed(text: str | float) -> float:
    """--speed: a positive factor of real time; 0, "max" or "inf": as fast as possible (math.inf)."""
    if isinstance(text, str) and text.strip().lower() in ("max", "inf", "0"):
        return math.inf
    try:
        speed = float(text)
    except ValueError:
        raise GtsamDvlError(
            f"--speed must be a number (times real time) or 'max', got {text!r}"
        ) from None
    if speed == 0 or speed == math.inf:
        return math.inf
    if not speed > 0:
        raise GtsamDvlError(f"--speed must be > 0 (times real time) or 'max', got {text!r}")
    return speed


@dataclass
class ReplayOutcome:
    """What replay_log did: the estimator (its result() and counters), epochs published, wall and log time (s) and
    their ratio: the numbers of the view's last status message (server.Progress)."""

    estimator: OnlineEstimator
    epochs_published: int
    wall_s: float
    log_s: float
    # analysis.health.Health of the run (replay_log with health=True and an epoch)
    health: Any = None
    real_time_factor: float | None = None  # log_s / wall_s (None: not both positive)

    def describe(self) -> str:
        rate = (
            f"{self.real_time_factor:.1f}x real time" if self.real_time_factor is not None else "-"
        )
        return (
            f"replayed {self.log_s:.0f} s of log in {self.wall_s:.1f} s ({rate}), {self.epochs_published} "
            f"epochs published, {self.estimator.epochs} states"
        )


@dataclass
class _Replay:
    """One replay's pushes (replay_log): each message pushed into the estimator when the wall clock reaches its
    stamp (speed: times real time; math.inf: no waiting), published on the view, and each epoch it completes."""

    log: LogData
    view: LiveView
    est: OnlineEstimator
    speed: float
    step_s: float
    clock: Callable[[], float]
    sleep: Callable[[float], None]
    t_first: float  # log time of the first message (s)
    wall0: float  # the clock at t_first (s)

    def pace(self, t: float) -> None:
        """Wait until the wall clock reaches log time t (s) at the replay's speed."""
        if math.isfinite(self.speed):
            wait = self.wall0 + (t - self.t_first) / self.speed - self.clock()
            if wait > 0:
                self.sleep(wait)

    def epoch_done(self, n: int) -> None:
        """After a push that completed n epochs: the latest estimate published, with the truth nearest to it."""
        est, view, truth = self.est, self.view, self.log.truth
        e = est.estimate()
        if n and e is not None:
            view.publish_epoch(
                e, counters=est.counters, latency_s=est.latencies_s[-1] if est.latencies_s else None
            )
            if truth is not None and len(truth):
                k = min(int(np.searchsorted(truth.t, e.t)), len(truth) - 1)
                if k > 0 and abs(truth.t[k - 1] - e.t) < abs(truth.t[k] - e.t):
                    k -= 1
                view.publish_truth(
                    float(truth.t[k]), truth.n_p[k], truth.n_q_b[k], truth.n_v[k], truth.b_omega[k]
                )

    def push_imu(self, a: int, b: int) -> None:
        """IMU samples a..b-1, in pieces of step_s log seconds at a finite speed (all at once otherwise)."""
        imu = self.log.imu
        step = (
            len(imu)
            if not math.isfinite(self.speed)
            else max(1, int(np.searchsorted(imu.t, imu.t[a] + self.step_s) - a))
        )
        for s in range(a, b, step):
            e = min(b, s + step)
            self.pace(float(imu.t[e - 1]))
            n = self.est.push_imu_batch(imu.t[s:e], imu.b_omega[s:e], imu.b_f[s:e])
            self.view.publish_imu(imu.t[s:e], imu.b_omega[s:e], imu.b_f[s:e])
            self.epoch_done(n)

    def push_depth(self, k: int) -> None:
        """Depth sample k."""
        from gtsam_dvl.estimators.online.feed import push_depth_sample

        depth = self.log.depth
        assert depth is not None
        self.pace(float(depth.t[k]))
        push_depth_sample(self.est, depth, k)
        pa = None if depth.pressure_pa is None else float(depth.pressure_pa[k])
        self.view.publish_depth(float(depth.t[k]), float(depth.depth_m[k]), pa)

    def push_dvl(self, j: int) -> None:
        """DVL ping j."""
        from gtsam_dvl.estimators.online.feed import push_dvl_ping

        dvl = self.log.dvl
        self.pace(float(dvl.t[j]))
        n = push_dvl_ping(self.est, dvl, j)
        self.view.publish_dvl(float(dvl.t[j]), dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
        self.epoch_done(n)

    def push_all(self, stop: threading.Event | None) -> OnlineEstimate | None:
        """Every message in delivery order, then finish(); the estimator's warnings logged at their group's ping
        (after finish(): unstamped). stop is honoured between groups. Returns finish()'s final estimate."""
        from gtsam_dvl.estimators.online import MessageDropped

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MessageDropped)
            seen = 0
            group_opens = True  # the next message opens a ping's group (IMU block, depth samples, ping) or the tail
            for m in log_messages(self.log):
                # stop is honoured between groups: a ping always goes in with the IMU before it
                if group_opens:
                    if stop is not None and stop.is_set():
                        break
                    group_opens = False
                if m.kind == "imu":
                    self.push_imu(m.start, m.stop)
                elif m.kind == "depth":
                    self.push_depth(m.start)
                else:
                    self.push_dvl(m.start)
                    for w in caught[seen:]:  # the group's warnings, stamped at its ping
                        self.view.log("warning", str(w.message), float(self.log.dvl.t[m.start]))
                    seen = len(caught)
                    group_opens = True
            final = self.est.finish()
            for w in caught[seen:]:
                self.view.log("warning", str(w.message))
        return final


def replay_log(
    log: LogData,
    view: LiveView,
    estimator: OnlineEstimator | None = None,
    *,
    speed: float = math.inf,
    step_s: float = 0.1,
    health: bool = True,
    stop: threading.Event | None = None,
    clock: Callable[[], float] = time.monotonic,
    sleep: Callable[[float], None] = time.sleep,
) -> ReplayOutcome:
    """Push a log's messages through the online estimator in delivery order (core/message_order.log_messages:
    the IMU samples up to each ping, then the depth samples up to it, then the ping; the rest; finish()),
    publishing each message as it is pushed and each epoch as it is completed (the estimate after the push, the
    latest when a push completes several), then the final estimate. speed: times real time (math.inf: as fast as
    possible); with a finite speed the IMU goes in pieces of step_s log seconds, each pushed when the wall clock
    reaches its last stamp. health: the log's health checks at the start and the run's (analysis/health.py
    assess_health) at the end on the log channel. stop: set to end the replay early, checked before each ping's
    group and before the messages after the last ping (finish() is still called). Warnings the estimator raises
    (MessageDropped) go to the log channel, stamped at the ping of their group (after finish(): at the last
    stamp). estimator None: OnlineEstimator.for_log(log)."""
    from gtsam_dvl.estimators.online import OnlineEstimator

    if not (speed > 0):
        raise GtsamDvlError(
            f"replay speed must be > 0 (math.inf: as fast as possible), got {speed}"
        )
    est = estimator if estimator is not None else OnlineEstimator.for_log(log)
    imu, dvl = log.imu, log.dvl
    if len(imu) == 0:
        raise GtsamDvlError(f"{log.source or 'log'}: no IMU samples to replay")
    if health:
        from gtsam_dvl.analysis.health import assess_log_health

        view.publish_health(assess_log_health(log), float(imu.t[0]))
    t_first = float(min(imu.t[0], dvl.t[0] if len(dvl) else imu.t[0]))
    # the epochs, log and wall time of the status messages and of the outcome
    progress = view.progress
    wall0 = progress.start(t_first, clock)
    replay = _Replay(log, view, est, speed, step_s, clock, sleep, t_first, wall0)
    final = replay.push_all(stop)
    run_health = None
    if final is not None:
        # freezes the progress's wall time
        view.publish_epoch(final, counters=est.counters, final=True)
        if health:
            from gtsam_dvl.analysis.health import assess_health

            run_health = assess_health(est.result(log.t0_ns), log)
            view.publish_health(run_health, final.t)
    elif health:
        view.log(
            "error", f"{log.source or 'log'}: no DVL epoch was processed (nothing to estimate)"
        )
    progress.finish()
    return ReplayOutcome(
        est, progress.epochs, progress.wall_s, progress.log_s, run_health, progress.real_time_factor
    )


def serve_log(
    log_path: Path,
    *,
    speed: str | float = 1.0,
    port: int = DEFAULT_PORT,
    host: str = "127.0.0.1",
    config_path: Path | None = None,
    read_options: ReadOptions | None = None,
    wait: bool = False,
    linger: bool = True,
    echo: Callable[[str], None] = print,
    layout_path: Path | None = None,
    calibration_path: Path | None = None,
) -> ReplayOutcome:
    """`gtsam-dvl live`: read the log, serve the view on host:port, replay the log through the online estimator at
    speed (parse_speed), print the outcome and the run's health; then, with linger, keep serving until Ctrl-C.
    wait: start the replay only once a client subscribes. layout_path: the layout file written for this run (the
    console names it; None: it says how to write one). calibration_path: a vehicle's calibration file as the
    prior (app/calibration_files.py). The foxglove package is checked before anything else."""
    import_foxglove()
    factor = parse_speed(speed)
    from gtsam_dvl.app.commands import load_log
    from gtsam_dvl.core.config import EstimatorConfig, estimator_overrides
    from gtsam_dvl.estimators.online import OnlineEstimator

    # a bad -c fails before the log is read
    config = EstimatorConfig.load(config_path) if config_path else None
    log = load_log(log_path, read_options)
    if config_path:  # the log's scenario's [estimator] table below the -c configuration
        config = EstimatorConfig.load(config_path, under=estimator_overrides(log.metadata))
    config = config or EstimatorConfig.for_log(log.metadata)
    prior = None
    if calibration_path is not None:  # the vehicle's calibration as the prior, inflated for its age
        from gtsam_dvl.app.calibration_files import calibration_prior

        prior, _ = calibration_prior(calibration_path, log, config)
    estimator = OnlineEstimator.for_log(log, config, calibration=prior)
    with LiveView(port, host=host, t0_ns=log.t0_ns, mounting=log.mounting) as view:
        layout = layout_path or "the file that `gtsam-dvl live --layout gtsam_dvl_live.json` writes"
        others = f" (from other machines: {', '.join(view.urls[1:])})" if len(view.urls) > 1 else ""
        echo(
            f"live view on {view.url}{others}: in Foxglove, Open connection > Foxglove WebSocket > {view.url}, "
            f"and Layouts > Import from file > {layout}"
        )
        outcome: ReplayOutcome | None = None
        try:
            if wait:
                echo("waiting for a client to subscribe (Ctrl-C to stop)")
                while not view.wait_for_subscribers(timeout_s=1.0):
                    pass
            pace = "as fast as possible" if math.isinf(factor) else f"at {factor:g}x real time"
            echo(
                f"replaying {Path(log_path).name} {pace} through the online estimator "
                f"({estimator.options.mode.replace('_', '-')})"
            )
            outcome = replay_log(log, view, estimator, speed=factor)
            echo(outcome.describe())
            if outcome.health is not None:
                echo("\n".join(outcome.health.lines()))
            if linger:
                echo(f"replay done; still serving on {view.url} (Ctrl-C to stop)")
                while True:
                    time.sleep(0.5)
        except KeyboardInterrupt:
            echo("live view stopped")
    return outcome or ReplayOutcome(estimator, 0, 0.0, 0.0)
