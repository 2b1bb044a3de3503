"""ROS 2 message definitions shipped with the package, concatenated the way rosbag2 stores them.

The .msg files live in ``msg-definitions/`` named ``pkg__msg__Type.msg`` (flat, so pyproject's package-data glob
ships them). We keep our own copies rather than asking a ROS installation because the writer must work
without one; the definitions carry the standard field lists (comments shortened).
"""

from __future__ import annotations

import re
from functools import cache
from importlib import resources
from typing import NamedTuple

SEPARATOR = "=" * 80
PRIMITIVES = frozenset(
    "bool byte char float32 float64 int8 uint8 int16 uint16 int32 uint32 int64 uint64 string wstring".split()
)


def normalize_type(name: str) -> str:
    """'pkg/Type' or 'pkg/msg/Type' -> 'pkg/msg/Type'."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[-1]}" if len(parts) == 2 else name


@cache
def message_text(type_name: str) -> str:
    """The .msg text of one type (no dependencies), e.g. 'sensor_msgs/msg/Imu'."""
    pkg, _, msg = normalize_type(type_name).split("/")
    path = resources.files("gtsam_dvl.io.ros2").joinpath(
        "msg-definitions", f"{pkg}__msg__{msg}.msg"
    )
    try:
        return path.read_text(encoding="utf-8").rstrip("\n")
    except FileNotFoundError:
        raise KeyError(f"no message definition shipped for {type_name}") from None


class MsgField(NamedTuple):
    """One field of a message definition: type a primitive ("float64", "string"; a bounded string<=N is "string")
    or a message type "pkg/msg/Type"; length 1 (one value), N (a fixed array T[N]) or None (a sequence, T[] or
    T[<=N])."""

    type: str
    name: str
    length: int | None


_FIELD_TYPE = re.compile(r"([^\[\]]+)(?:\[(<=)?(\d*)\])?")


@cache
def fields(type_name: str) -> tuple[MsgField, ...]:
    """The fields of a message type in definition order; constants (``uint8 NAME=1``) left out."""
    pkg = normalize_type(type_name).split("/")[0]
    out: list[MsgField] = []
    for line in message_text(type_name).splitlines():
        parts = line.split("#", 1)[0].split()
        if len(parts) < 2 or "=" in "".join(parts[1:]):
            continue  # blank, or a constant
        m = _FIELD_TYPE.fullmatch(parts[0])
        if m is None:
            raise ValueError(f"{type_name}: cannot read the field type {parts[0]!r}")
        base, bounded, size = m.group(1), m.group(2), m.group(3)
        base = base.split("<", 1)[0]  # string<=N, wstring<=N
        length = 1 if size is None else (None if bounded or not size else int(size))
        if base == "Header":
            base = "std_msgs/msg/Header"
        elif base not in PRIMITIVES:
            base = normalize_type(base) if "/" in base else f"{pkg}/msg/{base}"
        out.append(MsgField(base, parts[1], length))
    return tuple(out)


def dependencies(type_name: str) -> list[str]:
    """Field types of a message (fully qualified 'pkg/msg/Type'), in field order, without repeats."""
    out: list[str] = []
    for f in fields(type_name):
        if f.type not in PRIMITIVES and f.type not in out:
            out.append(f.type)
    return out


@cache
def full_definition(type_name: str) -> str:
    """The main definition, then every dependency (depth first) after a separator line and
    ``MSG: pkg/msg/Type``, as rosbag2 writes the ``ros2msg`` schema of a channel."""
    main = normalize_type(type_name)
    order: list[str] = []

    def visit(name: str) -> None:
        for dep in dependencies(name):
            if dep not in order and dep != main:
                order.append(dep)
                visit(dep)

    visit(main)
    parts = [message_text(main)]
    parts += [f"{SEPARATOR}\nMSG: {dep}\n{message_text(dep)}" for dep in order]
    return "\n".join(parts) + "\n"
