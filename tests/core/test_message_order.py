"""core/message_order.log_messages: every message exactly once, in stamp order, IMU before a ping stamped alike."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.message_order import log_messages
from gtsam_dvl.core.types import LogData


def _stamps(log: LogData) -> list[tuple[float, str, int]]:
    out: list[tuple[float, str, int]] = []
    for m in log_messages(log):
        t = {
            "imu": log.imu.t,
            "dvl": log.dvl.t,
            "depth": log.depth.t if log.depth is not None else None,
        }[m.kind]
        assert t is not None
        assert m.stop > m.start
        out.extend((float(t[i]), m.kind, i) for i in range(m.start, m.stop))
    return out


def test_every_message_once_in_time_order(sim_paper3d_clean: LogData) -> None:
    log = sim_paper3d_clean
    seen = _stamps(log)
    n_depth = 0 if log.depth is None else len(log.depth)
    assert len(seen) == len(log.imu) + len(log.dvl) + n_depth
    for kind, n in (("imu", len(log.imu)), ("dvl", len(log.dvl)), ("depth", n_depth)):
        assert sorted(i for _, k, i in seen if k == kind) == list(range(n))
    t = np.array([s[0] for s in seen])
    assert np.all(np.diff(t) >= 0.0), "messages out of stamp order"


def test_sample_stamped_like_a_ping_comes_first(sim_paper3d_clean: LogData) -> None:
    log = sim_paper3d_clean
    seen = _stamps(log)
    t_ping = float(log.dvl.t[3])
    at_ping = [k for t, k, _ in seen if t == t_ping]
    if "imu" in at_ping:
        assert at_ping.index("imu") < at_ping.index("dvl")
    # every IMU sample stamped at or before the ping is delivered before it
    pos_ping = next(n for n, s in enumerate(seen) if s[1] == "dvl" and s[2] == 3)
    assert all(s[0] > t_ping for s in seen[pos_ping + 1 :] if s[1] == "imu")
