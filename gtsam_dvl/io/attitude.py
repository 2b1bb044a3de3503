"""Attitude from the log: an IMU's own orientation or an attitude topic, as LogData.attitude (AttitudeData).

(Being written: read_attitude is the reader's hook.)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.core.types import AttitudeData, Mounting
from gtsam_dvl.io.storage.sources import Source


def read_attitude(src: Source, topic: str | None, imu_topic: str, raw: dict[str, Any], imu_arr: np.ndarray,
                  t0: int, mounting: Mounting, repair: bool, warnings: list[str],
                  dropped: dict[str, dict[str, int]]) -> AttitudeData | None:
    """The attitude of base_link in map (ENU). topic None: the IMU topic's own orientation (imu_arr, decoded
    sensor_msgs/msg/Imu messages) when its covariance says it is valid, else None; "" or "none": None; a topic
    name: that topic (its bodies in raw[topic]). t0: the log's time base (ns)."""
    return None
