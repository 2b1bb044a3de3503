"""The epoch scheduler (selection.KeyframeRule, selection.EpochScheduler): the online estimator's ping-by-ping
decisions are the whole-log ones (select_epochs, keyframe_mask) ping for ping, whatever the order in which the IMU
samples and the pings arrive, with the same rejection counters."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.message_order import log_messages
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.selection import (
    BETWEEN,
    KEYFRAME,
    THINNED,
    EpochScheduler,
    KeyframeRule,
    Ping,
    keyframe_mask,
    select_epochs,
)


def _faulty(log: LogData) -> LogData:
    """paper-3d with exact zeros for 30 s at 2 m/s, the output frozen for 20 s in the last manoeuvres, two invalid
    pings: the screen and the classification reject some pings."""
    t, d_v, valid = log.dvl.t, log.dvl.d_v.copy(), log.dvl.valid.copy()
    d_v[(t > 1000.0) & (t < 1030.0)] = 0.0
    d_v[(t > 1970.0) & (t < 1990.0)] = d_v[int(np.searchsorted(t, 1970.0))]
    valid[[20, 400]] = False
    return dataclasses.replace(
        log, dvl=dataclasses.replace(log.dvl, d_v=d_v, valid=valid, beams=None)
    )


def _whole_log(
    log: LogData, cfg: DvlConfig, interval_s: float, spacing_s: float
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """The batch smoother's decisions: the epoch pings and which of them are keyframes."""
    counters: dict[str, int] = {}
    idx = select_epochs(log.dvl, log.imu, cfg, interval_s, counters)
    return idx, keyframe_mask(log.dvl.t[idx], spacing_s), counters


def _ping_by_ping(
    log: LogData, cfg: DvlConfig, interval_s: float, spacing_s: float, imu_last: bool = False
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """EpochScheduler fed in delivery order (or every ping before any IMU sample, imu_last)."""
    counters: dict[str, int] = {}
    sched = EpochScheduler(cfg, interval_s, spacing_s, counters, noise_free=log.dvl.noise_free)
    index = {float(t): j for j, t in enumerate(log.dvl.t.tolist())}
    imu, dvl = log.imu, log.dvl
    t_first = float(imu.t[0])
    kept: list[Ping] = []
    messages = list(log_messages(log))
    if imu_last:
        messages = [m for m in messages if m.kind == "dvl"] + [
            m for m in messages if m.kind == "imu"
        ]
    for m in messages:
        if m.kind == "imu":
            sched.push_imu(
                imu.t[m.start : m.stop], imu.b_omega[m.start : m.stop], imu.b_f[m.start : m.stop]
            )
        elif m.kind == "dvl":
            j = m.start
            sched.push_ping(
                Ping(float(dvl.t[j]), dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]), None), t_first
            )
        kept += sched.ready()
    # the pings after the last IMU sample: outside the IMU's span (classify_pings)
    late = sched.drop_waiting()
    if late:
        counters["dvl_after_imu"] = counters.get("dvl_after_imu", 0) + late
    return np.array([index[p.t] for p in kept]), np.array([p.key for p in kept]), counters


@pytest.mark.parametrize(
    ("interval_s", "spacing_s"), [(0.0, 0.0), (0.0, 3.0), (2.5, 0.0), (2.5, 7.0)]
)
def test_ping_by_ping_is_the_whole_log_rule(
    sim_paper3d_clean: LogData, interval_s: float, spacing_s: float
) -> None:
    log, cfg = _faulty(sim_paper3d_clean), DvlConfig()
    idx, key, counters = _whole_log(log, cfg, interval_s, spacing_s)
    got_idx, got_key, got_counters = _ping_by_ping(log, cfg, interval_s, spacing_s)
    assert np.array_equal(got_idx, idx) and np.array_equal(got_key, key)
    assert {
        k: v for k, v in counters.items() if v
    } == got_counters  # the online counters skip the zeros
    assert counters["dvl_zero_while_moving"] > 0 and counters["dvl_unusable"] >= 2
    if spacing_s > 0:
        assert 0 < key.sum() < len(key)


def test_imu_after_the_pings_gives_the_same_decisions(sim_paper3d_clean: LogData) -> None:
    """Pings that arrive before the IMU reaching them wait for it: the decisions do not depend on the order."""
    log, cfg = _faulty(sim_paper3d_clean), DvlConfig()
    idx, key, _ = _ping_by_ping(log, cfg, 2.5, 7.0)
    late_idx, late_key, _ = _ping_by_ping(log, cfg, 2.5, 7.0, imu_last=True)
    assert np.array_equal(late_idx, idx) and np.array_equal(late_key, key)


def test_keyframe_rule() -> None:
    """Thinning first, then keyframes at least the spacing (less the tolerance) apart; a DVL whose period equals
    the spacing makes a keyframe of every ping, jitter included."""
    rule = KeyframeRule(0.5, 2.0)
    assert [rule.decide(t) for t in (0.0, 0.3, 1.0, 1.2, 2.0, 2.5, 4.0)] == [
        KEYFRAME,
        THINNED,
        BETWEEN,
        THINNED,
        KEYFRAME,
        BETWEEN,
        KEYFRAME,
    ]
    t = np.arange(50) * 1.0 + np.random.default_rng(0).uniform(-0.005, 0.005, 50)
    assert (KeyframeRule(0.0, 1.0).decide_all(t) == KEYFRAME).all()
    assert keyframe_mask(t, 1.0).all() and keyframe_mask(t, 0.0).all()
    assert keyframe_mask(t, 3.0).sum() == 17
