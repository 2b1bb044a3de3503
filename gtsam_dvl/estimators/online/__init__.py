"""The online estimator: an iSAM2 smoother fed message by message (estimator.py), its fixed-lag window
(window.py) and its options and estimate types (types.py)."""

from gtsam_dvl.estimators.online.estimator import OnlineEstimator, feed_log, smooth_online
from gtsam_dvl.estimators.online.types import (
    MODES,
    MessageDropped,
    OnlineConfig,
    OnlineEstimate,
    latency_stats,
)
from gtsam_dvl.estimators.online.window import RelinearizationThresholds

__all__ = ["MODES", "MessageDropped", "OnlineConfig", "OnlineEstimate", "OnlineEstimator", "RelinearizationThresholds",
           "feed_log", "latency_stats", "smooth_online"]
