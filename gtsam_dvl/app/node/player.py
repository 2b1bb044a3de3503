"""A recorded log published on its own topics, at real time or faster: `gtsam-dvl play LOG --rate 10`.

For the tests and the benchmark of the node (a real rclpy publisher in another process), and for a vehicle's
computer without a ROS install (no `ros2 bag play`). Each message goes out as the bytes recorded (rclpy's raw
publish): the node receives exactly what `smooth` reads from the log, header stamps included, so that the two can
be compared to the last bit. Messages are published in log-time order; message k at wall0 + (log_time_k -
log_time_0) / rate. Topics whose message package is not importable (tf2_msgs, marine_acoustic_msgs have no wheel)
are skipped and named.

Every message reaches a reliable subscriber, and soon, also one on a loaded machine. DDS repairs a message a
subscriber missed (its reception starved of CPU) from the publisher's history once the publisher's heartbeat
announces it: so each topic's history holds all its messages (they are in memory already; a history of 1000, half
a second of a 100 Hz IMU at 20x, dropped messages never delivered), and the publishers heartbeat often
(ros.py fast_repairs). At the end the player waits for every subscriber's acknowledgement (at most ACK_WAIT_S)
before its publishers go, taking undelivered messages with them.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gtsam_dvl.app.node.ros import (
    fast_repairs,
    import_ros,
    message_class,
    qos,
    wait_for_acknowledgements,
)
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io.ros2.msgdefs import normalize_type
from gtsam_dvl.io.storage.sources import Source, open_source

# at the end, how long to wait for the subscribers' acknowledgements: a subscriber behind a fast replay (a node on a
# loaded machine) is still taking the messages then, and those it has not taken when the publishers go are lost (10 s
# lost the last 60 s of the log to a node slowed to 0.7 ms a message at 20x)
ACK_WAIT_S = 60.0


@dataclass
class PlayOutcome:
    """What play_log did: messages published per topic, topics skipped (no Python package), the wall time (s) and
    per message the log time (ns), topic and wall time (steady clock, s) of its publication (record=True)."""

    published: dict[str, int] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)
    wall_s: float = 0.0
    log_ns: list[int] = field(default_factory=list)
    topics: list[str] = field(default_factory=list)
    wall: list[float] = field(default_factory=list)

    def describe(self) -> str:
        n = sum(self.published.values())
        skipped = (
            f"; skipped {', '.join(self.skipped)} (no Python message package)"
            if self.skipped
            else ""
        )
        return f"published {n} messages on {len(self.published)} topics in {self.wall_s:.1f} s{skipped}"


def play_log(
    path: Path | str,
    *,
    rate: float = 1.0,
    topics: Sequence[str] | None = None,
    remap: dict[str, str] | None = None,
    wait_for_subscribers_s: float = 0.0,
    reliable_depth: int | None = None,
    domain_id: int | None = None,
    record: bool = False,
    start: Callable[[], None] | None = None,
    skip: Callable[[str, int], bool] | None = None,
) -> PlayOutcome:
    """Publish a log's messages (module doc) at rate times real time (math.inf: as fast as possible). topics: those
    to play (None: every topic but the truth's and our results'); remap: topic -> published name;
    wait_for_subscribers_s: wait up to this long for each topic to have a subscriber before starting (a late
    subscriber misses the start); reliable_depth: each publisher's history (None: the topic's message count, module
    doc); record: keep each publication's time (PlayOutcome); skip(topic, log_ns): leave a message out (a sensor
    stopping, in a test)."""
    if not rate > 0:
        raise GtsamDvlError(f"--rate must be > 0 (times real time), got {rate}")
    rclpy = import_ros()
    src = open_source(path)
    chosen = (
        list(topics)
        if topics
        else [t for t in src.topics if not t.startswith(("/gtsam_dvl", "/ground_truth"))]
    )
    missing = [t for t in chosen if t not in src.topics]
    if missing:
        raise GtsamDvlError(
            f"{src.path}: no topic {', '.join(missing)}; topics in the log: {src.describe_topics()}"
        )
    out = PlayOutcome()
    classes, rows = _messages(src, chosen, out.skipped)
    counts = Counter(t for _, t, _ in rows)
    remap = remap or {}
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        from rclpy.node import Node

        with fast_repairs():  # DDS starts with the context's first node
            node = Node("gtsam_dvl_player", context=context)
        pubs = {
            t: node.create_publisher(
                cls,
                remap.get(t, t),
                qos(
                    "reliable",
                    100 if t == "/tf_static" else reliable_depth or max(counts[t], 1),
                    latched=t == "/tf_static",
                ),
            )
            for t, cls in classes.items()
        }
        if wait_for_subscribers_s > 0:
            deadline = time.monotonic() + wait_for_subscribers_s
            while time.monotonic() < deadline and not all(
                p.get_subscription_count() for p in pubs.values()
            ):
                time.sleep(0.02)
        if start is not None:
            start()
        _publish(rows, pubs, out, rate, skip, record)
        wait_for_acknowledgements(pubs.values(), ACK_WAIT_S)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    return out


def _messages(
    src: Source, chosen: list[str], skipped: list[str]
) -> tuple[dict[str, Any], list[tuple[int, str, bytes]]]:
    """The chosen topics' message classes (a topic whose message package is not importable appended to skipped)
    and their messages as recorded, (log time ns, topic, bytes) in log-time order."""
    classes: dict[str, Any] = {}
    for t in chosen:
        cls = message_class(normalize_type(src.topics[t].type_name))
        if cls is None:
            skipped.append(t)
        else:
            classes[t] = cls
    raw = src.read(list(classes))
    rows: list[tuple[int, str, bytes]] = []
    for t, bodies in raw.items():
        rows += [(int(ns), t, b) for ns, b in zip(bodies.log_time, bodies.items(), strict=True)]
    rows.sort(key=lambda r: r[0])
    return classes, rows


def _publish(
    rows: list[tuple[int, str, bytes]],
    pubs: dict[str, Any],
    out: PlayOutcome,
    rate: float,
    skip: Callable[[str, int], bool] | None,
    record: bool,
) -> None:
    """Each message published at wall0 + (log_time - log_time_0) / rate, counted (and with record, timed) in
    out; out.wall_s the time it took."""
    wall0 = time.monotonic()
    ns0 = rows[0][0] if rows else 0
    for ns, t, body in rows:
        if skip is not None and skip(t, ns):
            continue
        if math.isfinite(rate):
            wait = wall0 + (ns - ns0) * 1e-9 / rate - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        pubs[t].publish(body)
        out.published[t] = out.published.get(t, 0) + 1
        if record:
            out.log_ns.append(ns)
            out.topics.append(t)
            out.wall.append(time.monotonic())
    out.wall_s = time.monotonic() - wall0
