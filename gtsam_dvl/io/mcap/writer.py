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

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw
from gtsam_dvl.io.atomic import AtomicWriter
from gtsam_dvl.io.mcap.container import McapContainer, MessageRows
from gtsam_dvl.io.ros2 import cdr, messages
from gtsam_dvl.io.ros2.msgdefs import full_definition

# rmw's infinite duration, as rosbag2 writes it
_INFINITE = "    sec: 9223372036\n    nsec: 854775807\n"


def qos_yaml(reliability: str, durability: str, depth: int) -> str:
    """``offered_qos_profiles`` channel metadata in rosbag2's YAML (metadata version 9 spelling)."""
    return (
        f"- history: keep_last\n  depth: {depth}\n  reliability: {reliability}\n  durability: {durability}\n"
        f"  deadline:\n{_INFINITE}  lifespan:\n{_INFINITE}  liveliness: automatic\n"
        f"  liveliness_lease_duration:\n{_INFINITE}  avoid_ros_namespace_conventions: false"
    )


QOS_LATCHED = qos_yaml("reliable", "transient_local", 1)  # /tf_static
QOS_STREAM = qos_yaml("reliable", "volatile", 10)  # sensors and results


class McapLogWriter(AtomicWriter):
    """Context manager writing a ROS 2 MCAP (profile ros2, CDR, ros2msg schemas, zstd chunks)."""

    def __init__(
        self, path: str | os.PathLike[str], *, t0_ns: int = 0, chunk_size: int = 1 << 20
    ) -> None:
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
        self._batches: list[
            tuple[int, np.ndarray, np.ndarray, np.ndarray]
        ] = []  # channel, stamps, pool, len
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
            self._schemas[type_name] = self._mcap.add_schema(
                type_name, "ros2msg", full_definition(type_name)
            )
        cid = self._mcap.add_channel(
            topic, self._schemas[type_name], "cdr", {"offered_qos_profiles": qos}
        )
        self._channels[topic] = (type_name, cid)
        self._seq[cid] = 0
        return cid

    def add_encoded(
        self,
        topic: str,
        type_name: str,
        stamps_ns: np.ndarray,
        bodies: np.ndarray | list[bytes],
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

    def add_structured(
        self, topic: str, type_name: str, arr: np.ndarray, qos: str = QOS_STREAM
    ) -> None:
        """Messages filled by ``cdr.new_messages``; stamps are read back from their headers."""
        self.add_encoded(topic, type_name, cdr.stamps_ns(arr), arr, qos)

    # -- typed topics (encoders: io/ros2/messages.py; t (K,) s relative to t0_ns) -----------------------------
    # the others: add_structured of an encoder's messages (messages.imu, six_dof_with_covariance, odometry)
    def add_pose_with_covariance(
        self,
        topic: str,
        t: np.ndarray,
        n_p: np.ndarray,
        n_q: np.ndarray,
        cov: np.ndarray | None,
        frame_id: str,
    ) -> None:
        """geometry_msgs/msg/PoseWithCovarianceStamped; n_q [x, y, z, w]; cov (K,6,6) over
        (position, rotation vector)."""
        arr = messages.pose_with_covariance(
            self.stamps_ns(np.atleast_1d(t)), n_p, n_q, cov, frame_id
        )
        self.add_structured(topic, messages.POSE_COV, arr)

    def add_vector3_stamped(
        self, topic: str, t: np.ndarray, vec: np.ndarray, frame_id: str
    ) -> None:
        """geometry_msgs/msg/Vector3Stamped."""
        self.add_structured(
            topic,
            messages.VECTOR3,
            messages.vector3_stamped(self.stamps_ns(np.atleast_1d(t)), vec, frame_id),
        )

    def add_scalar_with_variance(
        self,
        topic: str,
        t: np.ndarray,
        value: np.ndarray,
        variance: np.ndarray | None,
        frame_id: str = "",
    ) -> None:
        """A stamped scalar and its variance as sensor_msgs/msg/Temperature (messages.scalar_with_variance); the
        topic name says what it is (e.g. /gtsam_dvl/scale)."""
        arr = messages.scalar_with_variance(
            self.stamps_ns(np.atleast_1d(t)), value, variance, frame_id
        )
        self.add_structured(topic, messages.TEMPERATURE, arr)

    def add_path(
        self, topic: str, t: np.ndarray, n_p: np.ndarray, n_q_b: np.ndarray, frame_id: str = "map"
    ) -> None:
        """nav_msgs/msg/Path: one message, stamped at t[-1] (t0 without poses), holding every pose (PoseStamped
        at t[k])."""
        stamps = self.stamps_ns(t)
        stamp = stamps[-1:] if len(stamps) else np.array([self.t0_ns])
        self.add_encoded(
            topic,
            messages.PATH,
            stamp,
            [messages.path(int(stamp[0]), stamps, n_p, n_q_b, frame_id)],
        )

    def add_tf_static(
        self, topic: str, t: float, transforms: list[tuple[str, str, np.ndarray, np.ndarray]]
    ) -> None:
        """tf2_msgs/msg/TFMessage, latched QoS: (parent, child, parent_R_child, parent_p_child) each."""
        ns = int(self.stamps_ns([t])[0])
        body = messages.tf_message(
            [
                (ns, parent, child, p, matrix_to_quat_xyzw(np.asarray(R, dtype=float)))
                for parent, child, R, p in transforms
            ]
        )
        self.add_encoded(topic, messages.TF, np.array([ns]), [body], QOS_LATCHED)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        """An MCAP Metadata record (string -> string)."""
        self._mcap.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def add_attachment(
        self, name: str, data: bytes, media_type: str = "application/octet-stream"
    ) -> None:
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
            rows = self._take_batches()
            # ties keep the order topics were added
            order = np.argsort(rows.log_time, kind="stable")
            self._mcap.write_messages(rows.take(order))

    def _take_batches(self) -> MessageRows:
        """The messages added since the last call, concatenated in the order added, with their sequence numbers;
        the list of batches is emptied."""
        batches, self._batches = self._batches, []
        chan = np.concatenate([np.full(len(s), c, np.uint16) for c, s, _, _ in batches])
        seq = np.concatenate([self._next_seq(c, len(s)) for c, s, _, _ in batches])
        stamps = np.concatenate([s for _, s, _, _ in batches])
        lens = np.concatenate([n for _, _, _, n in batches])
        pool = np.concatenate([p for _, _, p, _ in batches])
        start = np.concatenate([[0], np.cumsum(lens)[:-1]])
        return MessageRows(chan, seq, stamps, pool, start, lens)

    def _next_seq(self, cid: int, n: int) -> np.ndarray:
        first = self._seq[cid]
        self._seq[cid] += n
        return np.arange(first, first + n, dtype=np.uint32)

    def abort(self) -> None:
        """Drop the temporary file; nothing appears under the final name."""
        if not self._file.closed:
            self._file.close()
        self._tmp.unlink(missing_ok=True)


class McapStreamWriter(McapLogWriter):
    """McapLogWriter for logs too long to hold: ``flush(before_ns)`` writes the messages added so far whose
    stamps are before ``before_ns`` (the caller promises that no later message is stamped earlier), so memory
    holds one part of the log at a time. The file is the one McapLogWriter writes from the same messages
    when every topic is added in the same order on first use: one log-time order (ties by channel, then
    sequence: McapLogWriter's order when each topic was one batch) and the same chunks, which are cut on
    the running byte count of the message records from the first message."""

    def __init__(
        self, path: str | os.PathLike[str], *, t0_ns: int = 0, chunk_size: int = 1 << 20
    ) -> None:
        super().__init__(path, t0_ns=t0_ns, chunk_size=chunk_size)
        empty = np.zeros(0, np.int64)
        # messages added and not yet in a chunk: channel, seq, stamp, body length, bodies back to back
        self._pending: tuple[np.ndarray, ...] = (
            np.zeros(0, np.uint16),
            np.zeros(0, np.uint32),
            empty,
            empty,
            np.zeros(0, np.uint8),
        )
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
            chan, seq, stamps = (
                np.concatenate([chan, c2]),
                np.concatenate([seq, s2]),
                np.concatenate([stamps, t2]),
            )
            lens, pool = np.concatenate([lens, n2]), np.concatenate([pool, p2])
        if not len(stamps):
            return
        start = np.concatenate([[0], np.cumsum(lens)[:-1]])
        order = np.lexsort((seq, chan, stamps))
        rows = MessageRows(chan, seq, stamps, pool, start, lens).take(order)
        ready = (
            len(order)
            if before_ns is None
            else int(np.searchsorted(rows.log_time, before_ns, side="left"))
        )
        rec_end = self._bytes_written + np.cumsum(31 + rows.length[:ready])
        # as McapContainer.write_messages, from the first message
        chunk_no = (rec_end - 1) // self._mcap.chunk_size
        bounds = np.concatenate([[0], np.flatnonzero(np.diff(chunk_no)) + 1, [ready]])
        done = len(bounds) - 1 if final else len(bounds) - 2  # the last chunk may still grow
        for a, b in zip(bounds[:done], bounds[1 : done + 1], strict=True):
            if b > a:
                self._mcap.write_chunk(rows.take(slice(a, b)))
        cut = int(bounds[done]) if done > 0 else 0
        if cut:
            self._bytes_written = int(rec_end[cut - 1])
        keep = rows.take(slice(cut, None))
        self._pending = (
            keep.channel,
            keep.seq,
            keep.log_time,
            keep.length,
            _gather(keep.pool, keep.start, keep.length),
        )


def _gather(pool: np.ndarray, start: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """The bodies pool[start[k] : start[k] + lens[k]] back to back."""
    if not len(lens):
        return np.zeros(0, np.uint8)
    new_start = np.cumsum(lens) - lens
    idx = np.arange(int(lens.sum()), dtype=np.int64) + np.repeat(start - new_start, lens)
    return pool[idx]
