"""What the online estimator's fixed-lag window leaves alive: a run over a log with weak references to what it
made (memory.track_returns), counted with the estimator held after the run and once it is gone. Shared by the
tests of the IMU factors (test_online_memory.py) and of the keyframe factors (test_online_keyframes.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.online import OnlineEstimator, feed_log
from gtsam_dvl.estimators.online.window import IncrementalSmoother
from tests.support.memory import Made


@dataclass
class WindowCounts:
    """Per kind of object tracked: how many the run made, how many were alive after it (the estimator held) and
    once the estimator was deleted; in_window: the window's size they are judged against."""

    in_window: int
    made: dict[str, int]
    alive: dict[str, int]
    alive_after: dict[str, int]


def run_window(
    log: LogData,
    config: EstimatorConfig,
    tracked: dict[str, Made],
    window_size: Callable[[IncrementalSmoother], int],
) -> WindowCounts:
    """Run the fixed-lag online estimator over the log message by message and count what the tracked methods
    made (tracked: kind -> its Made, set up before the run). window_size(smoother): the window's size, e.g. its
    states. Prints the counts."""
    est = OnlineEstimator.for_log(log, config)
    feed_log(est, log)
    assert est.smoother is not None
    counts = WindowCounts(
        window_size(est.smoother),
        {kind: len(m) for kind, m in tracked.items()},
        {kind: m.alive() for kind, m in tracked.items()},
        {},
    )
    print(
        "\n"
        + "; ".join(
            f"{counts.made[kind]} {kind} made, {counts.alive[kind]} alive after the run"
            for kind in tracked
        )
        + f"; {counts.in_window} in the window, {est.smoother.rebases} rebases"
    )
    del est
    counts.alive_after.update({kind: m.alive() for kind, m in tracked.items()})
    return counts
