"""Containers shared by the storage readers: topic descriptions, serialized bodies, salvage losses."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class TopicInfo:
    topic: str
    type_name: str
    schema: str | None  # ros2msg text, None when the storage has none
    message_encoding: str = "cdr"
    metadata: dict[str, str] = field(default_factory=dict)


@dataclass
class Bodies:
    """Serialized messages of one topic in file order: (N, L) uint8 when all have one length."""

    log_time: np.ndarray
    fixed: np.ndarray | None = None
    var: list[bytes] | None = None

    def __len__(self) -> int:
        return int(self.log_time.shape[0])

    def items(self) -> list[bytes]:
        if self.var is not None:
            return list(self.var)
        return [] if self.fixed is None else [r.tobytes() for r in self.fixed]

    @staticmethod
    def concat(parts: list[Bodies]) -> Bodies:
        t = np.concatenate([p.log_time for p in parts]) if parts else np.zeros(0, np.int64)
        fixed = [p.fixed for p in parts if p.fixed is not None]
        if len(fixed) == len(parts) and len({f.shape[1] for f in fixed}) <= 1:
            return Bodies(t, fixed=np.concatenate(fixed) if fixed else np.zeros((0, 0), np.uint8))
        return Bodies(t, var=[b for p in parts for b in p.items()])


@dataclass
class Loss:
    """A chunk (or file tail) salvage had to drop: log-time span (None if unknown), message count (exact from
    the chunk's MessageIndex records, else at least what could be decompressed), and the count per topic."""

    offset: int
    start_ns: int | None
    end_ns: int | None
    messages: int
    exact: bool
    per_topic: dict[str, int] = field(default_factory=dict)
