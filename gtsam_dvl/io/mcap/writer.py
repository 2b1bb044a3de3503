"""McapLogWriter: typed, bulk writing of ROS 2 topics into one MCAP file, atomically.

Every ``add_*`` takes whole arrays (K messages at once) with times ``t`` in float seconds relative to
the writer's ``t0_ns``; stamps are ``t0_ns + round(t * 1e9)`` and serve as header stamp, log time and
publish time. Messages are kept in memory and written, merged in time order, into zstd chunks on
``close``; the file appears under its final name only then (temporary file + ``os.replace``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from types import TracebackType

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw
from gtsam_dvl.io.mcap.container import McapContainer
from gtsam_dvl.io.ros2 import cdr
from gtsam_dvl.io.ros2.msgdefs import full_definition

_INFINITE = "    sec: 9223372036\n    nsec: 854775807\n"  # rmw's infinite duration, as rosbag2 writes it


def qos_yaml(reliability: str, durability: str, depth: int) -> str:
    """``offered_qos_profiles`` channel metadata in rosbag2's YAML (metadata version 9 spelling)."""
    return (
        f"- history: keep_last\n  depth: {depth}\n  reliability: {reliability}\n  durability: {durability}\n"
        f"  deadline:\n{_INFINITE}  lifespan:\n{_INFINITE}  liveliness: automatic\n"
        f"  liveliness_lease_duration:\n{_INFINITE}  avoid_ros_namespace_conventions: false"
    )


QOS_LATCHED = qos_yaml("reliable", "transient_local", 1)  # /tf_static
QOS_STREAM = qos_yaml("reliable", "volatile", 10)  # sensors and results


def _rows(a: np.ndarray | None, k: int, shape: tuple[int, ...], name: str, fill: float = 0.0) -> np.ndarray:
    if a is None:
        return np.full((k, *shape), fill)
    arr = np.asarray(a, dtype=float)
    if arr.shape != (k, *shape):
        raise ValueError(f"{name}: expected shape {(k, *shape)}, got {arr.shape}")
    return arr


class McapLogWriter:
    """Context manager writing a ROS 2 MCAP (profile ros2, CDR, ros2msg schemas, zstd chunks)."""

    def __init__(self, path: str | os.PathLike[str], *, t0_ns: int = 0, chunk_size: int = 1 << 20) -> None:
        self.path = Path(path)
        self.t0_ns = int(t0_ns)
        folder = self.path.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{self.path.name}.", suffix=".part")
        except OSError as e:
            raise GtsamDvlError(f"{self.path}: cannot write ({e.strerror})") from None
        self._tmp = Path(tmp)
        self._file = os.fdopen(fd, "wb")
        self._mcap = McapContainer(self._file, chunk_size=chunk_size)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[str, int]] = {}
        self._seq: dict[int, int] = {}
        self._batches: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []  # channel, stamps, pool, len
        self.add_metadata("gtsam_dvl_time", {"t0_ns": str(self.t0_ns)})

    # -- plumbing -------------------------------------------------------------------------------
    def stamps_ns(self, t: np.ndarray | list[float]) -> np.ndarray:
        """Integer ROS time (ns) of relative times t (s)."""
        ns = self.t0_ns + np.rint(np.asarray(t, dtype=float) * 1e9).astype(np.int64)
        if ns.size and ns.min() < 0:
            raise GtsamDvlError(f"{self.path}: stamps before ROS time 0 (t0_ns = {self.t0_ns})")
        return ns

    def channel(self, topic: str, type_name: str, qos: str = QOS_STREAM) -> int:
        """The channel id of a topic, registering its schema and channel on first use."""
        if topic in self._channels:
            known, cid = self._channels[topic]
            if known != type_name:
                raise ValueError(f"{topic}: already written as {known}, not {type_name}")
            return cid
        if type_name not in self._schemas:
            self._schemas[type_name] = self._mcap.add_schema(type_name, "ros2msg", full_definition(type_name))
        cid = self._mcap.add_channel(topic, self._schemas[type_name], "cdr", {"offered_qos_profiles": qos})
        self._channels[topic] = (type_name, cid)
        self._seq[cid] = 0
        return cid

    def add_encoded(
        self, topic: str, type_name: str, stamps_ns: np.ndarray, bodies: np.ndarray | list[bytes],
        qos: str = QOS_STREAM,
    ) -> None:
        """Low level: serialized CDR bodies, either a structured/uint8 array of equal-size messages
        or a list of bytes, with their stamps (ns) as log and publish times."""
        cid = self.channel(topic, type_name, qos)
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        if isinstance(bodies, list):
            lens = np.array([len(b) for b in bodies], dtype=np.int64)
            pool = np.frombuffer(b"".join(bodies), np.uint8)
        else:
            pool = np.ascontiguousarray(bodies).view(np.uint8).reshape(-1)
            lens = np.full(len(stamps), pool.size // max(len(stamps), 1), dtype=np.int64)
        if len(lens) != len(stamps):
            raise ValueError(f"{topic}: {len(lens)} bodies for {len(stamps)} stamps")
        self._batches.append((cid, stamps, pool, lens))

    def add_structured(self, topic: str, type_name: str, arr: np.ndarray, qos: str = QOS_STREAM) -> None:
        """Messages filled by ``cdr.new_messages``; stamps are read back from their headers."""
        self.add_encoded(topic, type_name, cdr.stamps_ns(arr), arr, qos)

    def _new(self, type_name: str, t: np.ndarray, strings: dict[str, str]) -> np.ndarray:
        arr = cdr.new_messages(cdr.SPECS[type_name], strings, len(np.atleast_1d(t)))
        cdr.set_stamps(arr, self.stamps_ns(np.atleast_1d(t)))
        return arr

    # -- typed topics ---------------------------------------------------------------------------
    def add_imu(
        self, topic: str, t: np.ndarray, b_omega: np.ndarray, b_f: np.ndarray, frame_id: str = "imu_link",
        gyro_var: np.ndarray | None = None, accel_var: np.ndarray | None = None,
        orientation: np.ndarray | None = None, orientation_cov: np.ndarray | None = None,
    ) -> None:
        """sensor_msgs/msg/Imu, without orientation (orientation_covariance[0] = -1) unless orientation (K, 4)
        [x, y, z, w] is given, with orientation_cov (3, 3) or (K, 3, 3) rad^2 (None: zeros = unknown); the rate
        and specific-force covariances are diag(gyro_var), diag(accel_var) (zeros = unknown)."""
        arr = self._new("sensor_msgs/msg/Imu", t, {"frame_id": frame_id})
        k = len(arr)
        if orientation is None:
            arr["orientation_covariance"][:, 0] = -1.0
        else:
            arr["orientation"] = _rows(orientation, k, (4,), "orientation")
            if orientation_cov is not None:
                cov = np.asarray(orientation_cov, dtype=float)
                cov = np.broadcast_to(cov, (k, 3, 3)) if cov.shape == (3, 3) else cov
                arr["orientation_covariance"] = _rows(cov, k, (3, 3), "orientation_cov").reshape(k, 9)
        arr["angular_velocity"] = _rows(b_omega, k, (3,), "b_omega")
        arr["linear_acceleration"] = _rows(b_f, k, (3,), "b_f")
        if gyro_var is not None:
            arr["angular_velocity_covariance"][:, [0, 4, 8]] = np.asarray(gyro_var, dtype=float)
        if accel_var is not None:
            arr["linear_acceleration_covariance"][:, [0, 4, 8]] = np.asarray(accel_var, dtype=float)
        self.add_structured(topic, "sensor_msgs/msg/Imu", arr)

    def _six_dof(
        self, type_name: str, topic: str, t: np.ndarray, linear: np.ndarray, angular: np.ndarray | None,
        cov: np.ndarray | None, frame_id: str,
    ) -> None:
        arr = self._new(type_name, t, {"frame_id": frame_id})
        k = len(arr)
        arr["linear"] = _rows(linear, k, (3,), "linear")
        arr["angular"] = _rows(angular, k, (3,), "angular")
        arr["covariance"] = _rows(cov, k, (6, 6), "cov").reshape(k, 36)
        self.add_structured(topic, type_name, arr)

    def add_twist_with_covariance(
        self, topic: str, t: np.ndarray, linear: np.ndarray, angular: np.ndarray | None,
        cov: np.ndarray | None, frame_id: str,
    ) -> None:
        """geometry_msgs/msg/TwistWithCovarianceStamped; cov (K,6,6), None = zeros (ROS: unknown)."""
        self._six_dof("geometry_msgs/msg/TwistWithCovarianceStamped", topic, t, linear, angular, cov, frame_id)

    def add_accel_with_covariance(
        self, topic: str, t: np.ndarray, linear: np.ndarray, angular: np.ndarray, cov: np.ndarray | None,
        frame_id: str,
    ) -> None:
        """geometry_msgs/msg/AccelWithCovarianceStamped. For IMU biases: linear = accelerometer bias
        (m/s^2), angular = gyro bias (rad/s), cov (K,6,6) in that order."""
        self._six_dof("geometry_msgs/msg/AccelWithCovarianceStamped", topic, t, linear, angular, cov, frame_id)

    def add_pose_with_covariance(
        self, topic: str, t: np.ndarray, n_p: np.ndarray, n_q: np.ndarray, cov: np.ndarray | None, frame_id: str
    ) -> None:
        """geometry_msgs/msg/PoseWithCovarianceStamped; n_q [x, y, z, w]; cov (K,6,6) over
        (position, rotation vector)."""
        arr = self._new("geometry_msgs/msg/PoseWithCovarianceStamped", t, {"frame_id": frame_id})
        k = len(arr)
        arr["position"], arr["orientation"] = _rows(n_p, k, (3,), "n_p"), _rows(n_q, k, (4,), "n_q")
        arr["covariance"] = _rows(cov, k, (6, 6), "cov").reshape(k, 36)
        self.add_structured(topic, "geometry_msgs/msg/PoseWithCovarianceStamped", arr)

    def add_vector3_stamped(self, topic: str, t: np.ndarray, vec: np.ndarray, frame_id: str) -> None:
        """geometry_msgs/msg/Vector3Stamped."""
        arr = self._new("geometry_msgs/msg/Vector3Stamped", t, {"frame_id": frame_id})
        arr["vector"] = _rows(vec, len(arr), (3,), "vec")
        self.add_structured(topic, "geometry_msgs/msg/Vector3Stamped", arr)

    def add_scalar_with_variance(
        self, topic: str, t: np.ndarray, value: np.ndarray, variance: np.ndarray | None, frame_id: str = ""
    ) -> None:
        """A stamped scalar and its variance as sensor_msgs/msg/Temperature (fields ``temperature``,
        ``variance``): the one standard ROS 2 message that is exactly (header, float64 value, float64
        variance), so ros2 bag, Foxglove and rosbags plot it without custom definitions. The name
        of the value field is historical; the topic name says what it is (e.g. /gtsam_dvl/scale)."""
        arr = self._new("sensor_msgs/msg/Temperature", t, {"frame_id": frame_id})
        arr["temperature"] = _rows(value, len(arr), (), "value")
        arr["variance"] = _rows(variance, len(arr), (), "variance")
        self.add_structured(topic, "sensor_msgs/msg/Temperature", arr)

    def add_odometry(
        self, topic: str, t: np.ndarray, n_p: np.ndarray, n_q_b: np.ndarray, b_v: np.ndarray,
        b_omega: np.ndarray, pose_cov: np.ndarray | None = None, twist_cov: np.ndarray | None = None,
        frame_id: str = "map", child_frame_id: str = "base_link",
    ) -> None:
        """nav_msgs/msg/Odometry: pose of child in frame_id, twist (b_v, b_omega) in the child frame;
        covariances (K,6,6) or None (zeros)."""
        arr = self._new("nav_msgs/msg/Odometry", t, {"frame_id": frame_id, "child_frame_id": child_frame_id})
        k = len(arr)
        arr["position"], arr["orientation"] = _rows(n_p, k, (3,), "n_p"), _rows(n_q_b, k, (4,), "n_q_b")
        arr["linear"], arr["angular"] = _rows(b_v, k, (3,), "b_v"), _rows(b_omega, k, (3,), "b_omega")
        arr["pose_covariance"] = _rows(pose_cov, k, (6, 6), "pose_cov").reshape(k, 36)
        arr["twist_covariance"] = _rows(twist_cov, k, (6, 6), "twist_cov").reshape(k, 36)
        self.add_structured(topic, "nav_msgs/msg/Odometry", arr)

    def add_path(self, topic: str, t: np.ndarray, n_p: np.ndarray, n_q_b: np.ndarray, frame_id: str = "map") -> None:
        """nav_msgs/msg/Path: one message, stamped at t[-1], holding every pose (PoseStamped at t[k])."""
        stamps = self.stamps_ns(t)
        k = len(stamps)
        pos, quat = _rows(n_p, k, (3,), "n_p"), _rows(n_q_b, k, (4,), "n_q_b")
        w = cdr.CdrWriter()
        w.stamp(int(stamps[-1]) if k else self.t0_ns)
        w.string(frame_id)
        w.u32(k)
        for i in range(k):  # one message; a Python loop over its poses is fine
            w.stamp(int(stamps[i]))
            w.string(frame_id)
            w.f64(np.concatenate([pos[i], quat[i]]))
        self.add_encoded(topic, "nav_msgs/msg/Path", stamps[-1:] if k else np.array([self.t0_ns]), [bytes(w.buf)])

    def add_tf_static(
        self, topic: str, t: float, transforms: list[tuple[str, str, np.ndarray, np.ndarray]]
    ) -> None:
        """tf2_msgs/msg/TFMessage, latched QoS: (parent, child, parent_R_child, parent_p_child) each."""
        ns = int(self.stamps_ns([t])[0])
        w = cdr.CdrWriter()
        w.u32(len(transforms))
        for parent, child, R, p in transforms:
            w.stamp(ns)
            w.string(parent)
            w.string(child)
            w.f64(np.asarray(p, dtype=float).reshape(3))
            w.f64(matrix_to_quat_xyzw(np.asarray(R, dtype=float)))
        self.add_encoded(topic, "tf2_msgs/msg/TFMessage", np.array([ns]), [bytes(w.buf)], QOS_LATCHED)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """An MCAP Metadata record (string -> string)."""
        self._mcap.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def add_attachment(self, name: str, data: bytes, media_type: str = "application/octet-stream") -> None:
        """An MCAP Attachment record, stamped at t0."""
        self._mcap.add_attachment(name, media_type, data, self.t0_ns, self.t0_ns)

    # -- closing --------------------------------------------------------------------------------
    def close(self) -> None:
        """Write every message in log-time order, the summary and footer; then move into place."""
        if self._file.closed:
            return
        try:
            self._write_batches()
            self._mcap.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            mask = os.umask(0)
            os.umask(mask)
            os.chmod(self._tmp, 0o666 & ~mask)
            os.replace(self._tmp, self.path)
        except BaseException:
            self.abort()
            raise

    def _write_batches(self) -> None:
        """Every message added, merged in log-time order, into chunks."""
        if self._batches:
            chan, seq, stamps, pool, start, lens = self._take_batches()
            order = np.argsort(stamps, kind="stable")  # ties keep the order topics were added
            self._mcap.write_messages(chan[order], seq[order], stamps[order], pool, start[order], lens[order])

    def _take_batches(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The messages added since the last call, concatenated in the order added, with their sequence numbers
        (channel, seq, stamps, pool, start, length); the list of batches is emptied."""
        batches, self._batches = self._batches, []
        chan = np.concatenate([np.full(len(s), c, np.uint16) for c, s, _, _ in batches])
        seq = np.concatenate([self._next_seq(c, len(s)) for c, s, _, _ in batches])
        stamps = np.concatenate([s for _, s, _, _ in batches])
        lens = np.concatenate([n for _, _, _, n in batches])
        pool = np.concatenate([p for _, _, p, _ in batches])
        start = np.concatenate([[0], np.cumsum(lens)[:-1]])
        return chan, seq, stamps, pool, start, lens

    def _next_seq(self, cid: int, n: int) -> np.ndarray:
        first = self._seq[cid]
        self._seq[cid] += n
        return np.arange(first, first + n, dtype=np.uint32)

    def abort(self) -> None:
        """Drop the temporary file; nothing appears under the final name."""
        if not self._file.closed:
            self._file.close()
        self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> McapLogWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class McapStreamWriter(McapLogWriter):
    """McapLogWriter for logs too long to hold: ``flush(before_ns)`` writes the messages added so far whose
    stamps are before ``before_ns`` (the caller promises that no later message is stamped earlier), so memory
    holds one part of the log at a time. The file is the one McapLogWriter writes from the same messages
    when every topic is added in the same order on first use: one log-time order (ties by channel, then
    sequence: McapLogWriter's order when each topic was one batch) and the same chunks, which are cut on
    the running byte count of the message records from the first message."""

    def __init__(self, path: str | os.PathLike[str], *, t0_ns: int = 0, chunk_size: int = 1 << 20) -> None:
        super().__init__(path, t0_ns=t0_ns, chunk_size=chunk_size)
        empty = np.zeros(0, np.int64)
        # messages added and not yet in a chunk: channel, seq, stamp, body length, bodies back to back
        self._pending: tuple[np.ndarray, ...] = (np.zeros(0, np.uint16), np.zeros(0, np.uint32), empty, empty,
                                                 np.zeros(0, np.uint8))
        self._bytes_written = 0  # message record bytes in the chunks written so far

    def flush(self, before_ns: int | None = None) -> None:
        """Write the complete chunks of the messages stamped before ``before_ns`` (None: all of them); the
        last, unfilled chunk and later messages wait for the next flush or close."""
        self._write_ready(before_ns, final=False)

    def _write_batches(self) -> None:
        self._write_ready(None, final=True)

    def _write_ready(self, before_ns: int | None, final: bool) -> None:
        chan, seq, stamps, lens, pool = self._pending
        if self._batches:
            c2, s2, t2, p2, _, n2 = self._take_batches()
            chan, seq, stamps = np.concatenate([chan, c2]), np.concatenate([seq, s2]), np.concatenate([stamps, t2])
            lens, pool = np.concatenate([lens, n2]), np.concatenate([pool, p2])
        if not len(stamps):
            return
        start = np.concatenate([[0], np.cumsum(lens)[:-1]])
        order = np.lexsort((seq, chan, stamps))
        chan, seq, stamps, lens, start = chan[order], seq[order], stamps[order], lens[order], start[order]
        ready = len(stamps) if before_ns is None else int(np.searchsorted(stamps, before_ns, side="left"))
        rec_end = self._bytes_written + np.cumsum(31 + lens[:ready])
        chunk_no = (rec_end - 1) // self._mcap.chunk_size  # as McapContainer.write_messages, from the first message
        bounds = np.concatenate([[0], np.flatnonzero(np.diff(chunk_no)) + 1, [ready]])
        done = len(bounds) - 1 if final else len(bounds) - 2  # the last chunk may still grow
        for a, b in zip(bounds[:done], bounds[1 : done + 1], strict=True):
            if b > a:
                self._mcap.write_chunk(chan[a:b], seq[a:b], stamps[a:b], pool, start[a:b], lens[a:b])
        cut = int(bounds[done]) if done > 0 else 0
        if cut:
            self._bytes_written = int(rec_end[cut - 1])
        keep = slice(cut, None)
        self._pending = (chan[keep], seq[keep], stamps[keep], lens[keep], _gather(pool, start[keep], lens[keep]))


def _gather(pool: np.ndarray, start: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """The bodies pool[start[k] : start[k] + lens[k]] back to back."""
    if not len(lens):
        return np.zeros(0, np.uint8)
    new_start = np.cumsum(lens) - lens
    idx = np.arange(int(lens.sum()), dtype=np.int64) + np.repeat(start - new_start, lens)
    return pool[idx]
