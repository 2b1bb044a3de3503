"""Replaying a recorded log into an online estimator, message by message, in the order a vehicle delivers them
(core/message_order.log_messages)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gtsam_dvl.core.message_order import log_messages
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.types import DepthData, DvlData, LogData

if TYPE_CHECKING:  # (estimator.py imports feed_log from here: the annotations only)
    from gtsam_dvl.estimators.online.estimator import OnlineEstimator


def push_depth_sample(sink: OnlineEstimator, depth: DepthData, k: int) -> None:
    """Depth sample k of a log: its pressure and variance when the log has them, else its depth."""
    if depth.pressure_pa is not None:
        var = (
            math.nan
            if depth.pressure_variance_pa2 is None
            else float(depth.pressure_variance_pa2[k])
        )
        sink.push_depth(
            float(depth.t[k]), pressure_pa=float(depth.pressure_pa[k]), pressure_variance_pa2=var
        )
    else:
        sink.push_depth(float(depth.t[k]), float(depth.depth_m[k]), float(depth.variance_m2[k]))


def push_dvl_ping(sink: OnlineEstimator, dvl: DvlData, j: int) -> int:
    """Ping j of a log, with its beams and water-track flag when the log has them; returns the epochs completed."""
    beams = None if dvl.beams is None else (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
    return sink.push_dvl(
        dvl.t[j],
        dvl.d_v[j],
        dvl.d_cov[j],
        bool(dvl.valid[j]),
        beams,
        water_track=dvl.water_track is not None and bool(dvl.water_track[j]),
    )


class _AttitudeFeed:
    """The log's attitude samples (LogData.attitude: the IMU's own orientation or an attitude topic, base_link in
    map) pushed after the IMU samples up to their stamps, until the estimator has aligned (it uses them for the
    initial attitude only: online/alignment_wait.py)."""

    def __init__(self, log: LogData) -> None:
        self.att, self.k = log.attitude, 0

    def push_up_to(self, sink: OnlineEstimator, t: float) -> None:
        att = self.att
        while att is not None and self.k < len(att) and att.t[self.k] <= t:
            if sink.smoother is not None:
                self.att = None
                return
            sink.push_attitude(float(att.t[self.k]), att.n_q_b[self.k], att.cov_rad2[self.k])
            self.k += 1


class _GnssFeed:
    """The log's GNSS fixes pushed after the IMU samples up to their stamps (and the rest at the end)."""

    def __init__(self, log: LogData) -> None:
        self.gnss, self.k = log.gnss, 0

    def push_up_to(self, sink: OnlineEstimator, t: float) -> None:
        g = self.gnss
        while g is not None and self.k < len(g) and g.t[self.k] <= t:
            k = self.k
            sink.push_gnss(
                float(g.t[k]),
                g.lat_deg[k],
                g.lon_deg[k],
                g.height_m[k],
                g.cov_enu_m2[k],
                g.status[k],
            )
            self.k += 1


def feed_log(estimator: OnlineEstimator, log: LogData, progress: ProgressFn | None = None) -> None:
    """Push a log's messages in delivery order (log_messages: the IMU samples up to each ping's stamp as one
    batch, then the log's attitude samples (until the estimator has aligned) and GNSS fixes up to it, then the
    depth samples up to it, then the ping, a sample stamped like the ping first; then the rest), then finish().
    progress: 0.95 j / M after ping j of M, every M / 100 pings."""
    imu, dvl, depth = log.imu, log.dvl, log.depth
    n = len(dvl)
    step = max(1, n // 100)
    attitude, fixes = _AttitudeFeed(log), _GnssFeed(log)
    for m in log_messages(log):
        if m.kind == "imu":
            estimator.push_imu_batch(
                imu.t[m.start : m.stop], imu.b_omega[m.start : m.stop], imu.b_f[m.start : m.stop]
            )
            attitude.push_up_to(estimator, float(imu.t[m.stop - 1]))
            fixes.push_up_to(estimator, float(imu.t[m.stop - 1]))
        elif m.kind == "depth":
            assert depth is not None  # log_messages yields depth samples of a log that has them
            push_depth_sample(estimator, depth, m.start)
        else:
            j = m.start
            push_dvl_ping(estimator, dvl, j)
            if progress is not None and j % step == 0:
                progress(0.95 * j / n)
    fixes.push_up_to(estimator, math.inf)
    estimator.finish()
