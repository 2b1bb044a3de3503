"""GNSS fixes (sensor_msgs/msg/NavSatFix) read into GnssData, and written back.

A fix's status and covariance are kept as the message has them: status < 0 (STATUS_NO_FIX) or a non-finite
latitude/longitude marks a message that is not a fix; position_covariance_type 0 (unknown) gives a NaN
covariance. Which fixes are used, and how (map origin, position aiding at the surface, held out for the
surfacing error), is decided by estimators/inputs/gnss.py, not here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.core.types import GeoOrigin, GnssData
from gtsam_dvl.io.ros2 import cdr
from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.decode import decode, first_string
from gtsam_dvl.io.stamps import check_stamps
from gtsam_dvl.io.storage.sources import Source

NAVSATFIX_TYPE = "sensor_msgs/msg/NavSatFix"
GNSS_TOPIC = "/gnss/fix"
STATUS_NO_FIX = -1


def read_gnss(
    src: Source,
    topic: str,
    bodies: Any,
    t0: int,
    repair: bool,
    warnings: list[str],
    dropped: dict[str, dict[str, int]],
) -> GnssData:
    """GnssData of a NavSatFix topic. Stamps are checked like every topic's (duplicates and backwards
    stamps raise, or are dropped with ``repair``); messages that are not fixes are kept with their status
    (the estimators skip them and count them)."""
    arr = decode(src.path, topic, NAVSATFIX_TYPE, bodies)
    ns = stamps_ns(arr)
    keep = check_stamps(src.path, topic, ns, t0, None, repair, warnings, dropped)
    return gnss_from_messages(arr[keep], ns[keep], t0)


def gnss_from_messages(arr: np.ndarray, ns: np.ndarray, t0: int) -> GnssData:
    """GnssData of decoded NavSatFix messages stamped ns (ns, t relative to t0 ns): the one mapping of a fix (a
    covariance of type 0 unknown, a non-finite position no fix), for the reader and the ROS 2 node (app/node)."""
    cov = arr["position_covariance"].astype(float).reshape(-1, 3, 3).copy()
    cov[arr["position_covariance_type"] == 0] = np.nan
    status = arr["status"].astype(int)
    lat, lon = arr["latitude"].astype(float), arr["longitude"].astype(float)
    status = np.where(np.isfinite(lat) & np.isfinite(lon), status, STATUS_NO_FIX)
    return GnssData(
        (ns - t0) / 1e9,
        lat,
        lon,
        arr["altitude"].astype(float),
        cov,
        status,
        first_string(arr) or "gnss_link",
    )


def good_fixes(gnss: GnssData) -> np.ndarray:
    """Mask of the messages that are fixes: status >= 0 and a finite latitude, longitude and height."""
    return np.asarray(
        (gnss.status >= 0)
        & np.isfinite(gnss.lat_deg)
        & np.isfinite(gnss.lon_deg)
        & np.isfinite(gnss.height_m)
    )


def first_fix_time(gnss: GnssData) -> float:
    """Time (s) of the first good fix (NaN without one)."""
    good = np.flatnonzero(good_fixes(gnss))
    return float(gnss.t[good[0]]) if len(good) else float("nan")


def first_fix_origin(gnss: GnssData) -> GeoOrigin | None:
    """The first good fix as a map origin (None without one). The origin is the antenna's position at that
    fix; the estimators place the first state relative to it (estimators/inputs/gnss.py)."""
    good = np.flatnonzero(good_fixes(gnss))
    if not len(good):
        return None
    i = int(good[0])
    return GeoOrigin(float(gnss.lat_deg[i]), float(gnss.lon_deg[i]), float(gnss.height_m[i]))


def navsatfix_messages(gnss: GnssData, stamps_ns_: np.ndarray) -> np.ndarray:
    """NavSatFix messages (structured array for the MCAP writer) of gnss at the given stamps (ns). A NaN
    covariance is written as position_covariance_type 0 (unknown), else 3 (known)."""
    arr = cdr.new_messages(cdr.NAVSATFIX, {"frame_id": gnss.frame_id}, len(gnss))
    cdr.set_stamps(arr, stamps_ns_)
    arr["status"] = gnss.status
    arr["service"] = 1  # GPS
    arr["latitude"], arr["longitude"], arr["altitude"] = gnss.lat_deg, gnss.lon_deg, gnss.height_m
    known = np.isfinite(gnss.cov_enu_m2).all(axis=(1, 2))
    arr["position_covariance"] = np.nan_to_num(gnss.cov_enu_m2.reshape(-1, 9), nan=0.0)
    arr["position_covariance_type"] = np.where(known, 3, 0)
    return arr
