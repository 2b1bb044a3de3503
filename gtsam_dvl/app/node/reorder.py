"""Messages from several topics put back in stamp order within a bounded window, with what each stream did.

Why: the online estimator takes each stream in stamp order (a message older than its stream's previous one is
dropped: estimators/online/messages.py), while DDS delivers each topic in its own order and a driver may stamp a
message after a later one. ReorderBuffer holds every message until the IMU's newest stamp (the estimator's clock)
is `window` past it, then releases the held ones in stamp order, an IMU sample before a ping stamped the same (the
order of core/message_order.py, which `smooth --mode online` replays). A message arriving later than that, behind
what its stream already released, is counted and dropped ("late"); one with the stamp its stream just released,
a "duplicate". The window costs latency only in sensor time: a ping's epoch is made when the IMU samples a window
past it arrive, and at their arrival it is released at once (bench/bench_node.py measures it).

Stamps are integers (ns) until release: no rounding decides an order. StreamStats keeps each stream's counts,
newest stamp, arrival wall time and stamp jumps for the diagnostics: a stream's stamps stepping more than `jump_ns`
further than its clock moved between two arrivals (the IMU's clock is the wall; the others' the IMU's stamps, so that
a replay faster than real time shows no jumps in the other streams), or back by more than `jump_ns`.
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

# release order at equal stamps: IMU first (core/message_order.py), then depth and fixes, then the ping
RANK = {"imu": 0, "pressure": 1, "gnss": 1, "dvl": 2}


@dataclass
class StreamStats:
    """One input stream: messages received, released, dropped late or as duplicates, its newest stamp (ns), the
    wall time of its last arrival (s, the node's steady clock), and its stamp jumps (count, the largest in s,
    negative back, and the stamp at the last one, ns)."""

    received: int = 0
    released: int = 0
    late: int = 0
    duplicates: int = 0
    newest_ns: int | None = None
    released_ns: int | None = None
    last_wall: float = -math.inf
    # its clock at its last arrival: wall time for the IMU, the IMU's stamps for others
    ref_ns: int | None = None
    jumps: int = 0
    largest_jump_s: float = 0.0
    last_jump_ns: int | None = None
    frame_id: str = ""

    # what the diagnostics report of a stream, by field name
    REPORTED: ClassVar[tuple[str, ...]] = (
        "received",
        "released",
        "late",
        "duplicates",
        "jumps",
        "largest_jump_s",
    )

    def as_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in self.REPORTED}


@dataclass(order=True)
class Held:
    """A message waiting for release: its stamp (ns), rank (RANK), arrival order, stream and decoded payload."""

    stamp_ns: int
    rank: int
    seq: int
    kind: str = field(compare=False)
    payload: Any = field(compare=False)


class ReorderBuffer:
    """Stamp-ordered release of the messages of several streams (module doc). window_ns: how far behind the newest
    stamp a message is held; jump_ns: a stamp stepping forward more than this from its stream's newest is a jump."""

    def __init__(self, window_ns: int, jump_ns: int) -> None:
        self.window_ns, self.jump_ns = int(window_ns), int(jump_ns)
        self.streams: dict[str, StreamStats] = {k: StreamStats() for k in RANK}
        self.newest_ns: int | None = None
        self._heap: list[Held] = []
        self._seq = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, kind: str, stamp_ns: int, payload: Any, wall: float) -> bool:
        """Hold a message; False when it is dropped at once (behind what its stream already released)."""
        s = self.streams[kind]
        s.received += 1
        imu = self.streams["imu"].newest_ns
        ref = round(wall * 1e9) if kind == "imu" or imu is None else imu
        if s.newest_ns is not None and s.ref_ns is not None:
            # the stamps stepped further than their clock moved since the previous message: a jump (a silent
            # stream that comes back has a step as long as the silence, and is no jump)
            step = (stamp_ns - s.newest_ns) - max(ref - s.ref_ns, 0)
            if step > self.jump_ns or stamp_ns - s.newest_ns < -self.jump_ns:
                s.jumps += 1
                jump_s = (stamp_ns - s.newest_ns) * 1e-9 if step <= self.jump_ns else step * 1e-9
                s.largest_jump_s = (
                    jump_s if abs(jump_s) > abs(s.largest_jump_s) else s.largest_jump_s
                )
                s.last_jump_ns = max(stamp_ns, s.newest_ns)
        s.last_wall, s.ref_ns = wall, ref
        if s.released_ns is not None and stamp_ns <= s.released_ns:
            if stamp_ns == s.released_ns:
                s.duplicates += 1
            else:
                s.late += 1
            return False
        s.newest_ns = stamp_ns if s.newest_ns is None else max(s.newest_ns, stamp_ns)
        # the IMU is the clock: a ping stamped ahead of it (another clock) releases nothing
        if kind == "imu":
            self.newest_ns = stamp_ns if self.newest_ns is None else max(self.newest_ns, stamp_ns)
        heapq.heappush(self._heap, Held(stamp_ns, RANK[kind], next(self._seq), kind, payload))
        return True

    def ready(self) -> list[Held]:
        """The held messages now a window behind the IMU's newest stamp, in release order."""
        if self.newest_ns is None:
            return []
        return self._pop(self.newest_ns - self.window_ns)

    def flush(self) -> list[Held]:
        """Every held message, in release order (no new message for a while, or the end)."""
        return self._pop(None)

    def _pop(self, until_ns: int | None) -> list[Held]:
        out: list[Held] = []
        heap = self._heap
        while heap and (until_ns is None or heap[0].stamp_ns <= until_ns):
            m = heapq.heappop(heap)
            s = self.streams[m.kind]
            if s.released_ns is not None and m.stamp_ns <= s.released_ns:  # two held with one stamp
                s.duplicates += 1
                continue
            s.released_ns = m.stamp_ns
            s.released += 1
            out.append(m)
        return out
