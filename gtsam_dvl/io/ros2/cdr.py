"""Hand-written ROS 2 CDR for the message types we log, as numpy structured dtypes.

Why by hand: a generic (de)serializer builds one Python object per message and tops out near
10^4-10^5 messages/s. A message whose strings are the same in every instance (a fixed frame_id per
topic) has one byte layout, so a whole topic is one numpy structured array: encoding is filling
columns, decoding is ``np.frombuffer``. The layout is computed once per topic from the CDR rules:
4-byte encapsulation header (00 01 00 00 = little endian), then every primitive aligned to its own size
counted from the end of that header; a string is a uint32 length (including the NUL) and the bytes;
fixed arrays have no count. Sequences (TFMessage, Path) are rare and go through the small
``CdrWriter``/``CdrReader`` instead. The fields of each type are read from its shipped .msg definition
(msgdefs.fields) and flattened (flat_spec), so the layouts and the schemas written into logs are one source.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.io.ros2.msgdefs import fields

ENCAP_LE = b"\x00\x01\x00\x00"


@dataclass(frozen=True)
class Field:
    """One flattened field. code: numpy scalar code ('i4', 'u4', 'f8', 'f4', 'u1', '?') or 'str'."""

    name: str
    code: str
    count: int = 1


Spec = tuple[Field, ...]

# numpy scalar code of each ROS primitive ('str': a CDR string)
CODES = {
    "bool": "?",
    "byte": "u1",
    "char": "u1",
    "int8": "i1",
    "uint8": "u1",
    "int16": "i2",
    "uint16": "u2",
    "int32": "i4",
    "uint32": "u4",
    "int64": "i8",
    "uint64": "u8",
    "float32": "f4",
    "float64": "f8",
    "string": "str",
}


def _leaves(type_name: str) -> list[tuple[tuple[str, ...], str, int]]:
    """(field path, code, count) of a message's primitive fields; a nested message whose fields are all one numeric
    scalar type (Vector3, Point, Quaternion) is one leaf of that type (a fixed array of them: count times)."""
    out: list[tuple[tuple[str, ...], str, int]] = []
    for f in fields(type_name):
        if f.length is None:
            raise ValueError(
                f"{type_name}.{f.name}: a sequence has no fixed layout (CdrWriter/CdrReader)"
            )
        if f.type in CODES:
            out.append(((f.name,), CODES[f.type], f.length))
            continue
        inner = _leaves(f.type)
        codes = {code for _, code, _ in inner}
        if len(codes) == 1 and "str" not in codes and all(n == 1 for _, _, n in inner):
            out.append(((f.name,), codes.pop(), len(inner) * f.length))
        elif f.length == 1:
            out += [((f.name, *path), code, n) for path, code, n in inner]
        else:
            raise ValueError(f"{type_name}.{f.name}: an array of {f.type} has no flat layout here")
    return out


def flat_spec(type_name: str) -> Spec:
    """The flattened fields of a message type from its shipped definition (msgdefs): every primitive field named by
    its own name, prefixed with its top-level field where two share a name (Odometry: pose_covariance,
    twist_covariance); Vector3, Point and Quaternion fields are float64 arrays (module doc for the byte layout)."""
    leaves = _leaves(type_name)
    names = [path[-1] for path, _, _ in leaves]
    return tuple(
        Field(path[-1] if names.count(path[-1]) == 1 else f"{path[0]}_{path[-1]}", code, n)
        for path, code, n in leaves
    )


# the fixed-layout types gtsam_dvl reads and writes in bulk (TwistWithCovarianceStamped and
# AccelWithCovarianceStamped share one layout)
SPECS: dict[str, Spec] = {
    name: flat_spec(name)
    for name in (
        "sensor_msgs/msg/Imu",
        "geometry_msgs/msg/TwistStamped",
        "geometry_msgs/msg/TwistWithCovarianceStamped",
        "geometry_msgs/msg/AccelWithCovarianceStamped",
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "geometry_msgs/msg/Vector3Stamped",
        "sensor_msgs/msg/Temperature",
        "sensor_msgs/msg/FluidPressure",
        "nav_msgs/msg/Odometry",
        "sensor_msgs/msg/NavSatFix",
        "marine_acoustic_msgs/msg/Dvl",
    )
}
IMU = SPECS["sensor_msgs/msg/Imu"]
FLUID_PRESSURE = SPECS["sensor_msgs/msg/FluidPressure"]
NAVSATFIX = SPECS["sensor_msgs/msg/NavSatFix"]
ODOMETRY = SPECS["nav_msgs/msg/Odometry"]
DVL = SPECS["marine_acoustic_msgs/msg/Dvl"]


def layout(
    spec: Spec,
    strings: dict[str, str] | None = None,
    body: bytes | np.ndarray | None = None,
    itemsize: int | None = None,
) -> np.dtype:
    """The structured dtype of one message: string values from ``strings`` (encoding) or read from
    a sample ``body`` (decoding; its byte order is honoured). Field ``encap`` is the 4-byte header;
    a string field ``s`` becomes ``s_len`` (uint32) and ``s`` (bytes with the NUL)."""
    sample = bytes(body[:4096]) if body is not None else None
    big = sample is not None and sample[1] == 0
    bo = ">" if big else "<"
    names: list[str] = ["encap"]
    formats: list[object] = [("u1", (4,))]
    offsets: list[int] = [0]
    pos = 0  # position counted from the end of the encapsulation header
    for f in spec:
        if f.code == "str":
            pos += -pos % 4
            if sample is not None:
                (n,) = struct.unpack_from(bo + "I", sample, pos + 4)
            else:
                n = len((strings or {})[f.name].encode()) + 1
            names += [f.name + "_len", f.name]
            formats += [bo + "u4", f"S{n}"]
            offsets += [pos + 4, pos + 8]
            pos += 4 + n
            continue
        size = np.dtype(f.code).itemsize
        pos += -pos % size
        names.append(f.name)
        formats.append((bo + f.code, (f.count,)) if f.count > 1 else bo + f.code)
        offsets.append(pos + 4)
        pos += size * f.count
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": itemsize or pos + 4}
    )


def new_messages(spec: Spec, strings: dict[str, str], n: int) -> np.ndarray:
    """n zeroed little-endian messages with the encapsulation header and strings filled in."""
    arr = np.zeros(n, dtype=layout(spec, strings))
    arr["encap"] = np.frombuffer(ENCAP_LE, np.uint8)
    for name, value in strings.items():
        arr[name + "_len"] = len(value.encode()) + 1
        arr[name] = value.encode()
    return arr


def set_stamps(arr: np.ndarray, stamp_ns: np.ndarray) -> None:
    """header.stamp from integer nanoseconds (sec = floor division, so nanosec is in [0, 1e9))."""
    sec, nsec = np.divmod(np.asarray(stamp_ns, dtype=np.int64), 1_000_000_000)
    arr["sec"] = sec
    arr["nanosec"] = nsec


def stamps_ns(arr: np.ndarray) -> np.ndarray:
    """Integer nanoseconds of header.stamp."""
    return arr["sec"].astype(np.int64) * 1_000_000_000 + arr["nanosec"].astype(np.int64)


def string_ranges(dtype: np.dtype, spec: Spec) -> list[tuple[int, int]]:
    """Byte ranges [start, end) of every string (length word included): the part of a body that
    must be equal across messages for one layout to fit them all."""
    fields: dict[str, Any] = dict(dtype.fields or {})
    out: list[tuple[int, int]] = []
    for f in spec:
        if f.code == "str":
            start = int(fields[f.name + "_len"][1])
            out.append((start, int(fields[f.name][1]) + fields[f.name][0].itemsize))
    return out


class CdrWriter:
    """Little-endian CDR for the few messages with sequences (TFMessage, Path)."""

    def __init__(self) -> None:
        self.buf = bytearray(ENCAP_LE)

    def _align(self, n: int) -> None:
        self.buf += b"\0" * (-(len(self.buf) - 4) % n)

    def u32(self, v: int) -> None:
        self._align(4)
        self.buf += struct.pack("<I", v)

    def stamp(self, ns: int) -> None:
        self._align(4)
        self.buf += struct.pack("<iI", *divmod(int(ns), 1_000_000_000))

    def string(self, s: str) -> None:
        data = s.encode() + b"\0"
        self.u32(len(data))
        self.buf += data

    def f64(self, values: np.ndarray | list[float]) -> None:
        self._align(8)
        self.buf += np.asarray(values, dtype="<f8").tobytes()


class CdrReader:
    """Minimal CDR reader for the sequence types we read (TFMessage); either byte order."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.bo = "<" if data[1] == 1 else ">"
        self.pos = 4

    def _take(self, fmt: str, size: int) -> tuple:
        self.pos += -(self.pos - 4) % size
        out = struct.unpack_from(self.bo + fmt, self.data, self.pos)
        self.pos += struct.calcsize(fmt)
        return out

    def u32(self) -> int:
        return int(self._take("I", 4)[0])

    def stamp_ns(self) -> int:
        sec, nsec = self._take("iI", 4)
        return int(sec) * 1_000_000_000 + int(nsec)

    def string(self) -> str:
        n = self.u32()
        s = self.data[self.pos : self.pos + n - 1].decode()
        self.pos += n
        return s

    def f64(self, n: int) -> np.ndarray:
        return np.array(self._take(f"{n}d", 8), dtype=float)
