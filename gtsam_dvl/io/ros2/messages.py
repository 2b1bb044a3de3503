"""One CDR encoder per ROS 2 message type that gtsam_dvl writes: the MCAP writers and the live view call these.

The fixed-layout types come back as structured arrays of K messages (cdr.new_messages: one row per message,
``.tobytes()`` of one row is its CDR body); the types with sequences (nav_msgs/msg/Path, tf2_msgs/msg/TFMessage)
are one message, returned as bytes. Stamps are integer ROS times (ns), the header stamp of each message. Array
arguments hold one row per message; a covariance given as None is written as zeros (ROS: unknown), and a
wrongly shaped array raises ValueError naming the argument.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gtsam_dvl.io.ros2 import cdr

IMU = "sensor_msgs/msg/Imu"
TWIST_COV = "geometry_msgs/msg/TwistWithCovarianceStamped"
ACCEL_COV = "geometry_msgs/msg/AccelWithCovarianceStamped"
POSE_COV = "geometry_msgs/msg/PoseWithCovarianceStamped"
VECTOR3 = "geometry_msgs/msg/Vector3Stamped"
TEMPERATURE = "sensor_msgs/msg/Temperature"
ODOMETRY = "nav_msgs/msg/Odometry"
PATH = "nav_msgs/msg/Path"
TF = "tf2_msgs/msg/TFMessage"

# (stamp ns, parent frame, child frame, parent_p_child (3,) m, parent_q_child (4,) [x, y, z, w])
Transform = tuple[int, str, str, np.ndarray, np.ndarray]


def rows(
    a: np.ndarray | None, k: int, shape: tuple[int, ...], name: str, fill: float = 0.0
) -> np.ndarray:
    """a as float (k, *shape), or filled with fill when None; ValueError naming the argument for another shape."""
    if a is None:
        return np.full((k, *shape), fill)
    arr = np.asarray(a, dtype=float)
    if arr.shape != (k, *shape):
        raise ValueError(f"{name}: expected shape {(k, *shape)}, got {arr.shape}")
    return arr


def _new(type_name: str, stamps_ns: np.ndarray, strings: dict[str, str]) -> np.ndarray:
    stamps = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
    arr = cdr.new_messages(cdr.SPECS[type_name], strings, len(stamps))
    cdr.set_stamps(arr, stamps)
    return arr


def imu(
    stamps_ns: np.ndarray,
    b_omega: np.ndarray,
    b_f: np.ndarray,
    frame_id: str = "imu_link",
    gyro_var: np.ndarray | None = None,
    accel_var: np.ndarray | None = None,
    orientation: np.ndarray | None = None,
    orientation_cov: np.ndarray | None = None,
) -> np.ndarray:
    """sensor_msgs/msg/Imu: rate b_omega (K, 3) rad/s and specific force b_f (K, 3) m/s^2 in frame_id, their
    covariances diag(gyro_var), diag(accel_var) (None: zeros = unknown). Without orientation (K, 4) [x, y, z, w]
    orientation_covariance[0] = -1 (ROS: no orientation); with it, orientation_cov (3, 3) or (K, 3, 3) rad^2."""
    arr = _new(IMU, stamps_ns, {"frame_id": frame_id})
    k = len(arr)
    if orientation is None:
        arr["orientation_covariance"][:, 0] = -1.0
    else:
        arr["orientation"] = rows(orientation, k, (4,), "orientation")
        if orientation_cov is not None:
            cov = np.asarray(orientation_cov, dtype=float)
            cov = np.broadcast_to(cov, (k, 3, 3)) if cov.shape == (3, 3) else cov
            arr["orientation_covariance"] = rows(cov, k, (3, 3), "orientation_cov").reshape(k, 9)
    arr["angular_velocity"] = rows(b_omega, k, (3,), "b_omega")
    arr["linear_acceleration"] = rows(b_f, k, (3,), "b_f")
    if gyro_var is not None:
        arr["angular_velocity_covariance"][:, [0, 4, 8]] = np.asarray(gyro_var, dtype=float)
    if accel_var is not None:
        arr["linear_acceleration_covariance"][:, [0, 4, 8]] = np.asarray(accel_var, dtype=float)
    return arr


def six_dof_with_covariance(
    type_name: str,
    stamps_ns: np.ndarray,
    linear: np.ndarray,
    angular: np.ndarray | None,
    cov: np.ndarray | None,
    frame_id: str,
) -> np.ndarray:
    """TwistWithCovarianceStamped or AccelWithCovarianceStamped (type_name, one layout): linear (K, 3), angular
    (K, 3) (None: zeros), covariance (K, 6, 6) over (linear, angular)."""
    arr = _new(type_name, stamps_ns, {"frame_id": frame_id})
    k = len(arr)
    arr["linear"] = rows(linear, k, (3,), "linear")
    arr["angular"] = rows(angular, k, (3,), "angular")
    arr["covariance"] = rows(cov, k, (6, 6), "cov").reshape(k, 36)
    return arr


def pose_with_covariance(
    stamps_ns: np.ndarray, n_p: np.ndarray, n_q: np.ndarray, cov: np.ndarray | None, frame_id: str
) -> np.ndarray:
    """geometry_msgs/msg/PoseWithCovarianceStamped: position (K, 3) m and orientation (K, 4) [x, y, z, w] in
    frame_id, covariance (K, 6, 6) over (position, rotation vector)."""
    arr = _new(POSE_COV, stamps_ns, {"frame_id": frame_id})
    k = len(arr)
    arr["position"], arr["orientation"] = rows(n_p, k, (3,), "n_p"), rows(n_q, k, (4,), "n_q")
    arr["covariance"] = rows(cov, k, (6, 6), "cov").reshape(k, 36)
    return arr


def vector3_stamped(stamps_ns: np.ndarray, vec: np.ndarray, frame_id: str) -> np.ndarray:
    """geometry_msgs/msg/Vector3Stamped: vec (K, 3)."""
    arr = _new(VECTOR3, stamps_ns, {"frame_id": frame_id})
    arr["vector"] = rows(vec, len(arr), (3,), "vec")
    return arr


def scalar_with_variance(
    stamps_ns: np.ndarray, value: np.ndarray, variance: np.ndarray | None, frame_id: str = ""
) -> np.ndarray:
    """A stamped scalar (K,) and its variance (K,) as sensor_msgs/msg/Temperature (fields ``temperature``,
    ``variance``): the one standard ROS 2 message that is exactly (header, float64 value, float64 variance), so
    ros2 bag, Foxglove and rosbags plot it without custom definitions. The topic name says what the value is."""
    arr = _new(TEMPERATURE, stamps_ns, {"frame_id": frame_id})
    arr["temperature"] = rows(value, len(arr), (), "value")
    arr["variance"] = rows(variance, len(arr), (), "variance")
    return arr


def odometry(
    stamps_ns: np.ndarray,
    n_p: np.ndarray,
    n_q_b: np.ndarray,
    b_v: np.ndarray,
    b_omega: np.ndarray,
    pose_cov: np.ndarray | None = None,
    twist_cov: np.ndarray | None = None,
    frame_id: str = "map",
    child_frame_id: str = "base_link",
) -> np.ndarray:
    """nav_msgs/msg/Odometry: pose of child_frame_id in frame_id (n_p (K, 3) m, n_q_b (K, 4) [x, y, z, w]), twist
    (b_v (K, 3) m/s, b_omega (K, 3) rad/s) in child_frame_id; covariances (K, 6, 6) in ROS order
    (io/ros2/covariance.py)."""
    arr = _new(ODOMETRY, stamps_ns, {"frame_id": frame_id, "child_frame_id": child_frame_id})
    k = len(arr)
    arr["position"], arr["orientation"] = rows(n_p, k, (3,), "n_p"), rows(n_q_b, k, (4,), "n_q_b")
    arr["linear"], arr["angular"] = rows(b_v, k, (3,), "b_v"), rows(b_omega, k, (3,), "b_omega")
    arr["pose_covariance"] = rows(pose_cov, k, (6, 6), "pose_cov").reshape(k, 36)
    arr["twist_covariance"] = rows(twist_cov, k, (6, 6), "twist_cov").reshape(k, 36)
    return arr


def path(
    stamp_ns: int, stamps_ns: np.ndarray, n_p: np.ndarray, n_q_b: np.ndarray, frame_id: str = "map"
) -> bytes:
    """One nav_msgs/msg/Path stamped stamp_ns holding K poses: PoseStamped at stamps_ns[k] (ns), position n_p[k]
    (m) and orientation n_q_b[k] [x, y, z, w] in frame_id."""
    k = len(stamps_ns)
    pos, quat = rows(n_p, k, (3,), "n_p"), rows(n_q_b, k, (4,), "n_q_b")
    w = cdr.CdrWriter()
    w.stamp(stamp_ns)
    w.string(frame_id)
    w.u32(k)
    for i in range(k):  # one message; a Python loop over its poses is fine
        w.stamp(int(stamps_ns[i]))
        w.string(frame_id)
        w.f64(np.concatenate([pos[i], quat[i]]))
    return bytes(w.buf)


def tf_message(transforms: Sequence[Transform]) -> bytes:
    """One tf2_msgs/msg/TFMessage of the transforms (Transform: stamp, parent, child, translation, rotation)."""
    w = cdr.CdrWriter()
    w.u32(len(transforms))
    for ns, parent, child, p, q in transforms:
        w.stamp(ns)
        w.string(parent)
        w.string(child)
        w.f64(
            np.concatenate(
                [np.asarray(p, dtype=float).reshape(3), np.asarray(q, dtype=float).reshape(4)]
            )
        )
    return bytes(w.buf)
