"""Bulk decoding of a topic's CDR bodies into a numpy structured array (layouts from ``cdr``).

Fast path: all bodies have one length and identical strings (a fixed frame_id), so one layout fits and
the (N, L) byte matrix is viewed as N records with no copy. Otherwise (frame_id changing length, say)
each body is decoded on its own with its own layout; slower, but such topics are rare.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.io.ros2.cdr import SPECS, CdrReader, Spec, layout, string_ranges
from gtsam_dvl.io.storage.raw import Bodies


def _plain_dtype(spec: Spec) -> np.dtype:
    return np.dtype(
        [
            (f.name, "O")
            if f.code == "str"
            else (f.name, f.code, (f.count,))
            if f.count > 1
            else (f.name, f.code)
            for f in spec
        ]
    )


def _bad(path: Path, topic: str, type_name: str) -> GtsamDvlError:
    return GtsamDvlError(f"{path}: messages on {topic} do not decode as {type_name}")


def _check_encapsulation(path: Path, topic: str, heads: np.ndarray) -> None:
    if (heads[:, 0] != 0).any() or (heads[:, 1] > 1).any():
        b = heads[np.flatnonzero((heads[:, 0] != 0) | (heads[:, 1] > 1))[0]]
        raise GtsamDvlError(
            f"{path}: {topic}: CDR encapsulation 0x{b[0]:02x}{b[1]:02x} not supported (plain CDR only)"
        )


def decode(path: Path, topic: str, type_name: str, bodies: Bodies) -> np.ndarray:
    """Structured array of the messages on ``topic`` with the fields of ``cdr.SPECS[type_name]``
    (string fields hold the bytes or str of the frame ids)."""
    spec = SPECS[type_name]
    if not len(bodies):
        return np.zeros(0, _plain_dtype(spec))
    if bodies.fixed is not None and bodies.fixed.shape[1] >= 4:
        rows = bodies.fixed
        _check_encapsulation(path, topic, rows[:, :4])
        try:
            dt = layout(spec, body=rows[0], itemsize=rows.shape[1])
        except (ValueError, struct.error):
            raise _bad(path, topic, type_name) from None
        ranges = [(0, 4), *string_ranges(dt, spec)]
        if all((rows[:, a:b] == rows[0, a:b]).all() for a, b in ranges):
            return np.ascontiguousarray(rows).view(dt)[:, 0]
    items = bodies.items()
    out = np.zeros(len(items), _plain_dtype(spec))
    for i, body in enumerate(items):
        if len(body) < 4:
            raise _bad(path, topic, type_name)
        _check_encapsulation(path, topic, np.frombuffer(body[:4], np.uint8)[None, :])
        try:
            rec = np.frombuffer(body, layout(spec, body=body, itemsize=len(body)), count=1)[0]
        except (ValueError, struct.error):
            raise _bad(path, topic, type_name) from None
        for f in spec:
            out[f.name][i] = rec[f.name].decode() if f.code == "str" else rec[f.name]
    return out


class MessageDecoder:
    """One topic's messages decoded one at a time (a live subscription: the ROS 2 node), as decode() decodes them:
    the layout of the last body is kept and reused while the length, encapsulation and strings (the frame_id) stay
    the same, which is every message of a topic from one driver; anything else goes through decode()."""

    def __init__(self, topic: str, type_name: str) -> None:
        self.topic, self.type_name, self.spec = topic, type_name, SPECS[type_name]
        self._dtype: np.dtype | None = None
        self._size = -1
        self._fixed: list[
            tuple[int, int, bytes]
        ] = []  # (start, stop, bytes) that must match to reuse the layout

    def __call__(self, body: bytes) -> np.ndarray:
        """A one-row structured array of the message (decode()'s fields)."""
        dt = self._dtype
        if (
            dt is not None
            and len(body) == self._size
            and all(body[a:b] == v for a, b, v in self._fixed)
        ):
            return np.frombuffer(body, dt, count=1)
        arr = decode(
            Path(self.topic),
            self.topic,
            self.type_name,
            Bodies(np.zeros(1, np.int64), fixed=np.frombuffer(body, np.uint8)[None, :]),
        )
        # decode()'s fast path: its layout fits
        if arr.dtype.names is not None and "encap" in arr.dtype.names:
            self._dtype, self._size = arr.dtype, len(body)
            self._fixed = [
                (a, b, body[a:b]) for a, b in [(0, 4), *string_ranges(arr.dtype, self.spec)]
            ]
        return arr


def first_string(arr: np.ndarray, name: str = "frame_id") -> str:
    """The string field of the first message ('' if none)."""
    if not len(arr):
        return ""
    v = arr[name][0]
    return v.decode() if isinstance(v, bytes) else str(v)


def decode_tf(
    path: Path, topic: str, bodies: Bodies
) -> dict[str, tuple[str, np.ndarray, np.ndarray]]:
    """tf2_msgs/msg/TFMessage: child frame -> (parent, parent_R_child, parent_p_child); later wins."""
    out: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    for body in bodies.items():
        try:
            r = CdrReader(body)
            for _ in range(r.u32()):
                r.stamp_ns()
                parent = r.string()
                child = r.string()
                p = r.f64(3)
                q = r.f64(4)
                out[child] = (parent, quat_xyzw_to_matrix(q), p)
        except (struct.error, UnicodeDecodeError, ValueError):
            raise _bad(path, topic, "tf2_msgs/msg/TFMessage") from None
    return out


def to_base(
    tfs: dict[str, tuple[str, np.ndarray, np.ndarray]], frame: str, base: str = "base_link"
) -> tuple[np.ndarray, np.ndarray] | None:
    """base_R_frame, base_p_frame by chaining transforms up to ``base``; None if not connected."""
    R, p, f = np.eye(3), np.zeros(3), frame
    for _ in range(64):
        if f == base:
            return R, p
        if f not in tfs:
            return None
        parent, R_pf, p_pf = tfs[f]
        R, p, f = R_pf @ R, R_pf @ p + p_pf, parent
    return None
