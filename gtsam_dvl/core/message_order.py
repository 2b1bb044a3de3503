"""The order in which a recorded log's messages reach an online estimator: one iterator for every replay.

feed_log (estimators/online) and the live view's replay (app/live) both push a log through the online
estimator as a vehicle would have delivered it: the IMU samples up to each ping's stamp as one block, then the
depth samples up to that stamp, then the ping (a sample stamped like the ping comes before it); after the last
ping the remaining depth samples, then the remaining IMU samples. Only index ranges are yielded: the consumer
reads the arrays of LogData and decides how to push and publish them (e.g. the live replay cuts an IMU block
into pieces to pace it against the wall clock).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Literal, NamedTuple

import numpy as np

from gtsam_dvl.core.types import LogData

MessageKind = Literal["imu", "depth", "dvl"]


class LogMessage(NamedTuple):
    """Messages [start, stop) of one stream: a block of IMU samples, one depth sample or one ping."""

    kind: MessageKind
    start: int
    stop: int


def log_messages(log: LogData) -> Iterator[LogMessage]:
    """The log's messages in delivery order (module doc). Every IMU sample, depth sample and ping is yielded
    exactly once; IMU blocks are never empty."""
    imu_t, dvl_t = log.imu.t, log.dvl.t
    depth_t = np.zeros(0) if log.depth is None else log.depth.t
    ends = np.searchsorted(imu_t, dvl_t, side="right")
    start, k = 0, 0
    n_depth = len(depth_t)
    for j in range(len(dvl_t)):
        end = int(ends[j])
        if end > start:
            yield LogMessage("imu", start, end)
            start = end
        while k < n_depth and depth_t[k] <= dvl_t[j]:
            yield LogMessage("depth", k, k + 1)
            k += 1
        yield LogMessage("dvl", j, j + 1)
    while k < n_depth:
        yield LogMessage("depth", k, k + 1)
        k += 1
    if start < len(imu_t):
        yield LogMessage("imu", start, len(imu_t))
