"""Attitude from the log: an IMU's own orientation or an attitude topic, as LogData.attitude (AttitudeData).

Accepted: sensor_msgs/msg/Imu (orientation, orientation_covariance; orientation_covariance[0] == -1 is ROS's
"no orientation", a zero quaternion too, an all-zero covariance "unknown"), nav_msgs/msg/Odometry and
geometry_msgs/msg/PoseWithCovarianceStamped (orientation, rotation block [3:6, 3:6] of the pose covariance).
The orientation is that of the message's own frame: an Imu message's frame is imu_link, turned into base_link
with Mounting.b_R_imu; an Odometry's child frame is normally base_link (imu_link is turned like an Imu
message, other names are taken as base_link with a warning); a PoseWithCovarianceStamped is base_link's pose.

Frame convention (read_log's attitude_frame): REP-103 says the reference is ENU and the body FLU ("enu"), but
many AHRS drivers publish NED orientation of an FRD body ("ned"). For a body orientation the conversion is
    ENU_R_flu = ENU_R_NED @ NED_R_frd @ frd_R_flu,   ENU_R_NED = [[0,1,0],[1,0,0],[0,0,-1]], frd_R_flu = diag(1,-1,-1)
(swap east/north and flip up on the left; flip the body's y and z on the right). The covariance is taken about
the sensor's body axes and turned like a body vector (FRD -> FLU changes no variance, mixes signs of the
covariances).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, quat_xyzw_to_matrix
from gtsam_dvl.core.types import AttitudeData, Mounting
from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.decode import decode, first_string
from gtsam_dvl.io.ros2.msgdefs import normalize_type
from gtsam_dvl.io.stamps import check_stamps
from gtsam_dvl.io.storage.sources import Source

IMU_TYPE = "sensor_msgs/msg/Imu"
ODOM_TYPE = "nav_msgs/msg/Odometry"
POSE_COV_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
ATTITUDE_TYPES = (IMU_TYPE, ODOM_TYPE, POSE_COV_TYPE)
FRAMES = ("enu", "ned")
ENU_R_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FRD_R_FLU = np.diag([1.0, -1.0, -1.0])


def to_enu_flu(ref_R_s: np.ndarray, frame: str) -> np.ndarray:
    """(K, 3, 3) orientation of a sensor's body in the map (ENU, body FLU) from the message's ref_R_s in
    frame "enu" (ENU / FLU: unchanged) or "ned" (NED / FRD: module doc)."""
    if frame == "enu":
        return ref_R_s
    return ENU_R_NED @ ref_R_s @ FRD_R_FLU


def read_attitude(
    src: Source,
    topic: str | None,
    imu_topic: str,
    raw: dict[str, Any],
    imu_arr: np.ndarray,
    t0: int,
    mounting: Mounting,
    repair: bool,
    warnings: list[str],
    dropped: dict[str, dict[str, int]],
    frame: str = "enu",
) -> AttitudeData | None:
    """The attitude of base_link in map (ENU). topic None: the IMU topic's own orientation (imu_arr, decoded
    sensor_msgs/msg/Imu messages) when its covariance says it is valid, else None; "" or "none": None; a topic
    name: that topic (its bodies in raw[topic]). t0: the log's time base (ns). frame: "enu" or "ned", the
    convention of the orientations (module doc)."""
    if frame not in FRAMES:
        raise GtsamDvlError(f"attitude_frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    if topic == "" or topic == "none":
        return None
    if topic is None:
        return _from_arrays(
            imu_arr,
            IMU_TYPE,
            imu_topic,
            t0,
            mounting,
            frame,
            first_string(imu_arr) or "imu_link",
            required=False,
            warnings=warnings,
        )
    type_name = normalize_type(src.topics[topic].type_name)
    if type_name not in ATTITUDE_TYPES:
        raise GtsamDvlError(
            f"{src.path}: {topic} is {type_name}; attitude topics must be one of "
            f"{', '.join(ATTITUDE_TYPES)}"
        )
    arr = decode(src.path, topic, type_name, raw[topic])
    if not len(arr):
        raise GtsamDvlError(f"{src.path}: {topic} has no messages")
    q = arr["orientation"].astype(float)
    keep = check_stamps(
        src.path, topic, stamps_ns(arr), t0, ~np.isfinite(q).all(axis=1), repair, warnings, dropped
    )
    sensor = first_string(arr) or "imu_link"
    if type_name == ODOM_TYPE:
        sensor = first_string(arr, "child_frame_id") or "base_link"
    elif type_name == POSE_COV_TYPE:
        sensor = "base_link"
    return _from_arrays(
        arr[keep],
        type_name,
        topic,
        t0,
        mounting,
        frame,
        sensor,
        required=True,
        warnings=warnings,
        path=str(src.path),
    )


def _from_arrays(
    arr: np.ndarray,
    type_name: str,
    topic: str,
    t0: int,
    mounting: Mounting,
    frame: str,
    sensor_frame: str,
    *,
    required: bool,
    warnings: list[str],
    path: str = "",
) -> AttitudeData | None:
    """AttitudeData from decoded messages of type_name; sensor_frame: the frame whose orientation they give
    (imu_link: turned with mounting.b_R_imu; base_link or another name: taken as base_link)."""
    q = arr["orientation"].astype(float).reshape(-1, 4)
    if type_name == IMU_TYPE:
        cov = arr["orientation_covariance"].astype(float).reshape(-1, 3, 3)
        has = cov[:, 0, 0] != -1.0
    else:
        key = "pose_covariance" if type_name == ODOM_TYPE else "covariance"
        cov = arr[key].astype(float).reshape(-1, 6, 6)[:, 3:, 3:].copy()
        has = np.ones(len(q), bool)
    norm = np.linalg.norm(q, axis=1)
    has &= np.isfinite(q).all(axis=1) & (norm > 0.5)  # a zero quaternion is no orientation
    if not has.any():
        if required:
            raise GtsamDvlError(
                f"{path}: {topic}: no message has an orientation (zero quaternion or "
                "orientation_covariance[0] = -1)"
            )
        return None
    if not has.all():
        warnings.append(
            f"{topic}: {int((~has).sum())} message(s) without orientation ignored for the attitude"
        )
    q, cov, norm = q[has], cov[has], norm[has]
    t = (stamps_ns(arr)[has] - t0) / 1e9
    ref_R_s = quat_xyzw_to_matrix(q / norm[:, None])
    n_R_s = to_enu_flu(ref_R_s, frame)
    cov = cov if frame == "enu" else FRD_R_FLU @ cov @ FRD_R_FLU
    cov[(cov == 0).all(axis=(1, 2))] = np.nan  # all zeros: unknown (ROS)
    if sensor_frame == "imu_link" or type_name == IMU_TYPE:
        b_R_s = mounting.b_R_imu
    else:
        b_R_s = np.eye(3)
        if sensor_frame != "base_link":
            warnings.append(f"{topic}: orientation of {sensor_frame} taken as base_link's")
    n_R_b = n_R_s @ b_R_s.T
    cov_b = b_R_s @ cov @ b_R_s.T
    return AttitudeData(t, matrix_to_quat_xyzw(n_R_b), cov_b, topic)
