"""A topic decoded piece by piece (TopicStream): the reader's streaming of the high-rate topics (the IMU, the truth
odometry) into arrays of the fields it uses, so that reading holds those arrays and one chunk, not every message
body (io/reader.py module doc; docs/results.md, "Log reader"), and the one pass over a log that feeds them.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io.ros2.decode import decode, first_string
from gtsam_dvl.io.storage.raw import Bodies
from gtsam_dvl.io.storage.sources import Source

IMU_FIELDS = ("sec", "nanosec", "angular_velocity", "linear_acceleration")
IMU_ORIENTATION_FIELDS = ("orientation", "orientation_covariance", "frame_id")
TRUTH_FIELDS = ("sec", "nanosec", "position", "orientation", "linear", "angular")


class TopicStream:
    """One topic decoded piece by piece into preallocated arrays of some of its fields (grown by doubling
    when the storage's message count was missing or short). Decoding errors are kept, not raised, so that
    the caller raises them where a bulk read would (after the storage's own errors). With ``orientation``
    (IMU only): the orientation and its covariance too, but stored only from the first piece in which some
    message has one (orientation_covariance[0] != -1); earlier rows get "no orientation"."""

    def __init__(
        self,
        path: Path,
        topic: str,
        type_name: str,
        fields: tuple[str, ...],
        capacity: int,
        orientation: bool = False,
    ) -> None:
        self.path, self.topic, self.type_name, self.fields = path, topic, type_name, fields
        self.capacity, self.n, self.frame_id = max(capacity, 1), 0, ""
        self.orientation = orientation
        self.out: np.ndarray | None = None
        self.orient: np.ndarray | None = None
        self.error: GtsamDvlError | None = None

    def add(self, bodies: Any) -> None:
        if self.error is not None or not len(bodies):
            return
        try:
            arr = decode(self.path, self.topic, self.type_name, bodies)
        except GtsamDvlError as e:
            self.error = e
            return
        if self.out is None:
            self.frame_id = first_string(arr)
            self.out = np.empty(self.capacity, np.dtype([(f, arr.dtype[f]) for f in self.fields]))
        k = len(arr)
        if self.n + k > len(self.out):
            self.out = self._grow(self.out, self.n + k)
        for f in self.fields:
            self.out[f][self.n : self.n + k] = arr[f]
        if self.orientation:
            self._add_orientation(arr)
        self.n += k

    def _grow(self, a: np.ndarray, need: int) -> np.ndarray:
        b = np.empty(max(need, 2 * len(a)), a.dtype)
        b[: self.n] = a[: self.n]
        return b

    def _add_orientation(self, arr: np.ndarray) -> None:
        k = len(arr)
        if self.orient is None:
            if not (arr["orientation_covariance"][:, 0] != -1.0).any():
                return
            self.orient = np.zeros(
                len(self.out) if self.out is not None else k,
                [("orientation", "<f8", (4,)), ("orientation_covariance", "<f8", (9,))],
            )
            self.orient["orientation_covariance"][: self.n] = -1.0
        if self.n + k > len(self.orient):
            self.orient = self._grow(self.orient, self.n + k)
        self.orient["orientation"][self.n : self.n + k] = arr["orientation"]
        self.orient["orientation_covariance"][self.n : self.n + k] = arr["orientation_covariance"]

    def array(self) -> np.ndarray:
        """The decoded fields of every message (raises a decoding error first)."""
        if self.error is not None:
            raise self.error
        if self.out is None:
            return np.zeros(0, [(f, "<f8") for f in self.fields])
        return self.out[: self.n]

    def attitude_array(self, keep: np.ndarray) -> np.ndarray:
        """What io/attitude.read_attitude needs of the IMU's own orientation, for the messages kept: a
        one-message array with "no orientation" when none had one (read_attitude then returns None)."""
        stamps = self.array()
        dt = [
            ("sec", "<i4"),
            ("nanosec", "<u4"),
            ("orientation", "<f8", (4,)),
            ("orientation_covariance", "<f8", (9,)),
            ("frame_id", "O"),
        ]
        if self.orient is None:
            out = np.zeros(1, dt)
            out["orientation_covariance"] = -1.0
            return out
        out = np.zeros(int(keep.sum()), dt)
        for f in ("sec", "nanosec"):
            out[f] = stamps[f][keep]
        for f in ("orientation", "orientation_covariance"):
            out[f] = self.orient[f][: self.n][keep]
        out["frame_id"] = self.frame_id
        return out


def read_streaming(
    src: Source,
    topics: list[str],
    streams: dict[str, TopicStream],
    keep_bodies: set[str],
    progress: Callable[[float], None] | None,
) -> dict[str, Any]:
    """One pass over the log: streamed topics into their TopicStream, the others' bodies (and those of streamed
    topics in keep_bodies, which another part of the reader decodes itself) collected as src.read would."""
    pieces: dict[str, list[Bodies]] = {
        t: [] for t in topics if t not in streams or t in keep_bodies
    }
    for got in src.iter_read(topics, progress):
        for topic, bodies in got.items():
            if topic in streams:
                streams[topic].add(bodies)
            if topic in pieces:
                pieces[topic].append(bodies)
    return {
        t: p[0] if len(p) == 1 else Bodies.concat(p)
        for t, p in pieces.items()
        if p or t in src.topics
    }
