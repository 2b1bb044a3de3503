"""The online estimator: an iSAM2 smoother fed message by message (estimator.py, and the modules it names), its
fixed-lag window (window.py) and its options and estimate types (types.py)."""

from gtsam_dvl.estimators.online.estimator import OnlineEstimator
from gtsam_dvl.estimators.online.feed import feed_log
from gtsam_dvl.estimators.online.types import (
    ONLINE_MODES,
    MessageDropped,
    OnlineConfig,
    OnlineEstimate,
    latency_stats,
)
from gtsam_dvl.estimators.online.whole_log import run_result, smooth_online
from gtsam_dvl.estimators.online.window import RelinearizationThresholds

__all__ = [
    "ONLINE_MODES",
    "MessageDropped",
    "OnlineConfig",
    "OnlineEstimate",
    "OnlineEstimator",
    "RelinearizationThresholds",
    "feed_log",
    "latency_stats",
    "run_result",
    "smooth_online",
]
