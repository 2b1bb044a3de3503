"""The whole-log ping screen (ping_screen.screen_pings, bulk) against the sequential PingScreen fed one ping at a
time (the reference, and the online estimator's path): the same code for every ping, on a 5 Hz DVL version of
paper-3d-short with faults injected into its DVL arrays (exact zeros while moving, a frozen output, repeated
messages, gross outliers, a dropout longer than SCREEN_WINDOW_S, an IMU gap, beams switching on and off),
with the screen off, with thresholds tight enough to reject hundreds of pings, and with the bulk's safety band
at zero (its own arithmetic decides) and infinite (every ping goes through PingScreen on the true reference)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from functools import cache
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.types import DvlData, ImuData, LogData
from gtsam_dvl.estimators.inputs import ping_screen
from gtsam_dvl.estimators.inputs.selection import (
    IMPLAUSIBLE_ACCEL,
    REPEATED,
    SCREEN_WINDOW_S,
    USABLE,
    ZERO_WHILE_MOVING,
    PingScreen,
    screen_pings,
    screened_value,
    usable_pings,
)
from tests.support.pings import first_pass_usable
from tests.support.scenarios import simulate_variant

SEED = 7


def sequential_codes(dvl: DvlData, idx: np.ndarray, imu: ImuData, cfg: DvlConfig) -> np.ndarray:
    """The reference: PingScreen.check on each ping in turn (screen_pings before it was vectorised)."""
    screen = PingScreen(cfg, repeats_need_motion=dvl.noise_free)
    code = np.zeros(len(idx), dtype=np.int8)
    b = dvl.beams
    for n, j in enumerate(idx.tolist()):
        beams = None if b is None else (b.d_u[j], b.v[j], b.valid[j])
        code[n] = screen.check(
            float(dvl.t[j]), screened_value(dvl.d_v[j], beams, cfg), imu.t, imu.b_omega, imu.b_f
        )
    return code


@cache
def base_log(white_noise: bool = True) -> LogData:
    """paper-3d-short (120 s static, then the manoeuvres: surge 0 -> 2 m/s over 120-180 s, descent, the square)
    with a 5 Hz DVL (4200 pings, 100 Hz IMU)."""
    return simulate_variant(SEED, white_noise=white_noise, rates={"dvl_hz": 5.0})


def _dvl(log: LogData, **kw: Any) -> LogData:
    return dataclasses.replace(log, dvl=dataclasses.replace(log.dvl, **kw))


def _beams(log: LogData, **kw: Any) -> LogData:
    assert log.dvl.beams is not None
    return _dvl(log, beams=dataclasses.replace(log.dvl.beams, **kw))


def zeros_moving(log: LogData) -> LogData:
    """Exact zeros for 30 s in the square (the 3-D velocity and the beams)."""
    block = (log.dvl.t > 300.0) & (log.dvl.t < 330.0)
    d_v = log.dvl.d_v.copy()
    d_v[block] = 0.0
    assert log.dvl.beams is not None
    v = log.dvl.beams.v.copy()
    v[block] = 0.0
    return _beams(_dvl(log, d_v=d_v), v=v)


def frozen(log: LogData) -> LogData:
    """The output frozen for 10 s while the vehicle speeds up (140-150 s)."""
    t, d_v = log.dvl.t, log.dvl.d_v.copy()
    d_v[(t > 140.0) & (t < 150.0)] = d_v[int(np.searchsorted(t, 140.0))]
    return _dvl(log, d_v=d_v)


def repeated_messages(log: LogData) -> LogData:
    """Every 97th ping sent twice (the same stamp and velocity), and every 89th ping's velocity repeated at
    the next stamp."""
    t, d_v = log.dvl.t.copy(), log.dvl.d_v.copy()
    assert log.dvl.beams is not None
    v, valid = log.dvl.beams.v.copy(), log.dvl.beams.valid.copy()
    again = np.arange(130, len(t), 97)
    t[again], d_v[again], v[again], valid[again] = (
        t[again - 1],
        d_v[again - 1],
        v[again - 1],
        valid[again - 1],
    )
    same = np.arange(150, len(t), 89)
    d_v[same], v[same], valid[same] = d_v[same - 1], v[same - 1], valid[same - 1]
    return _beams(_dvl(log, t=t, d_v=d_v), v=v, valid=valid)


def outliers(log: LogData) -> LogData:
    rng = np.random.default_rng(3)
    d_v = log.dvl.d_v.copy()
    hit = np.flatnonzero((rng.random(len(d_v)) < 0.03) & (log.dvl.t > 130.0))
    direction = rng.normal(size=(len(hit), 3))
    d_v[hit] += 4.0 * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    return _dvl(log, d_v=d_v)


def long_dropout(log: LogData) -> LogData:
    """No bottom lock for 90 s (> SCREEN_WINDOW_S) in the square, then exact zeros for 2 s and an outlier."""
    t, d_v = log.dvl.t, log.dvl.d_v.copy()
    lost, zero = (t > 400.0) & (t < 490.0), (t >= 490.0) & (t < 492.0)
    d_v[zero] = 0.0
    d_v[int(np.searchsorted(t, 495.0))] += [3.0, 0.0, 0.0]
    assert log.dvl.beams is not None
    v, valid = log.dvl.beams.v.copy(), log.dvl.beams.valid & ~lost[:, None]
    v[zero] = 0.0
    return _beams(_dvl(log, d_v=d_v, valid=log.dvl.valid & ~lost), v=v, valid=valid)


def imu_gap(log: LogData) -> LogData:
    """5 s without IMU samples in the square (windows without a sample)."""
    keep = (log.imu.t <= 600.0) | (log.imu.t > 605.0)
    imu = dataclasses.replace(
        log.imu, t=log.imu.t[keep], b_omega=log.imu.b_omega[keep], b_f=log.imu.b_f[keep]
    )
    return dataclasses.replace(log, imu=imu)


def beams_on_off(log: LogData) -> LogData:
    """A fifth of the beams invalid at random (a ping keeps at least one), all beams zero while moving for 10 s,
    the beams frozen for 20 s while the IMU shows motion, and beams 3 m/s off at random."""
    b = log.dvl.beams
    assert b is not None
    rng = np.random.default_rng(5)
    valid = b.valid & (rng.random(b.valid.shape) > 0.2)
    valid[~valid.any(axis=1) & b.valid.any(axis=1), 0] = True
    v = b.v.copy()
    t = log.dvl.t
    v[(t > 300.0) & (t < 310.0)] = 0.0
    still = (t > 140.0) & (t < 160.0)
    v[still], valid[still] = (
        v[int(np.searchsorted(t, 140.0))],
        valid[int(np.searchsorted(t, 140.0))],
    )
    off = (rng.random(v.shape) < 0.01) & (t[:, None] > 130.0)
    v[off] += 3.0
    # meanwhile the IMU's specific force steps by 1 m/s^2 every second, between pings: the beams compare no
    # velocity change (last_rate), so it takes a change of the acceleration for the IMU to show motion
    b_f = log.imu.b_f.copy()
    t_imu = log.imu.t
    b_f[:, 0] += 1.0 * ((t_imu > 140.0) & (t_imu < 160.0) & (np.floor(t_imu - 0.1) % 2 == 1))
    log = dataclasses.replace(log, imu=dataclasses.replace(log.imu, b_f=b_f))
    return _beams(log, v=v, valid=valid)


def everything(log: LogData) -> LogData:
    for fault in (zeros_moving, frozen, repeated_messages, outliers, long_dropout, imu_gap):
        log = fault(log)
    return log


FAULTS: dict[str, Callable[[LogData], LogData]] = {
    "clean": lambda log: log,
    "zeros_moving": zeros_moving,
    "frozen": frozen,
    "repeated_messages": repeated_messages,
    "outliers": outliers,
    "long_dropout": long_dropout,
    "imu_gap": imu_gap,
    "everything": everything,
}
# reasons each fault must produce with the default thresholds (so that a comparison cannot pass vacuously)
MUST_REJECT = {
    "zeros_moving": [ZERO_WHILE_MOVING],
    "frozen": [REPEATED],
    "repeated_messages": [REPEATED],
    "outliers": [IMPLAUSIBLE_ACCEL],
    "long_dropout": [ZERO_WHILE_MOVING, IMPLAUSIBLE_ACCEL],
    "everything": [ZERO_WHILE_MOVING, REPEATED, IMPLAUSIBLE_ACCEL],
}
CONFIGS = {
    "default": DvlConfig(),
    "beams": DvlConfig(use_beams=True),
    "off": DvlConfig(screen=False),
    # tight enough to reject most pings: long runs of rejections, references far back
    "tight": DvlConfig(
        max_accel_m_s2=0.05, accel_imu_factor=1.0, jump_margin_m_s=0.01, motion_dv_m_s=0.005
    ),
}


@cache
def case(fault: str, white_noise: bool = True, beams: bool = False) -> LogData:
    log = FAULTS[fault](base_log(white_noise))
    return beams_on_off(log) if beams else log


@cache
def usable(fault: str, cfg_name: str, white_noise: bool = True, beams: bool = False) -> np.ndarray:
    """The pings classify_pings finds usable (those usable_pings screens)."""
    return first_pass_usable(case(fault, white_noise, beams), CONFIGS[cfg_name], beams=True)


@cache
def reference(
    fault: str, cfg_name: str, white_noise: bool = True, beams: bool = False
) -> np.ndarray:
    log = case(fault, white_noise, beams)
    return sequential_codes(
        log.dvl, usable(fault, cfg_name, white_noise, beams), log.imu, CONFIGS[cfg_name]
    )


def screened(
    fault: str, cfg_name: str, white_noise: bool = True, beams: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(idx, bulk codes, sequential codes) of the usable pings of a case."""
    log, idx = case(fault, white_noise, beams), usable(fault, cfg_name, white_noise, beams)
    bulk = screen_pings(log.dvl, idx, log.imu, CONFIGS[cfg_name])
    return idx, bulk, reference(fault, cfg_name, white_noise, beams)


def _report(name: str, bulk: np.ndarray, seq: np.ndarray) -> str:
    counts = {
        c: int((seq == c).sum()) for c in (USABLE, ZERO_WHILE_MOVING, REPEATED, IMPLAUSIBLE_ACCEL)
    }
    return f"{name}: {len(seq)} pings, codes {counts}, {int((bulk != seq).sum())} differ"


@pytest.mark.parametrize("fault", list(FAULTS))
def test_bulk_screen_makes_the_sequential_decisions(fault: str) -> None:
    idx, bulk, seq = screened(fault, "default")
    print(_report(fault, bulk, seq))
    np.testing.assert_array_equal(bulk, seq)
    for reason in MUST_REJECT.get(fault, []):
        assert (seq == reason).sum() > 0, reason
    # the ping after the dropout compares a window capped at SCREEN_WINDOW_S
    if fault == "long_dropout":
        assert np.diff(case(fault).dvl.t[idx]).max() > SCREEN_WINDOW_S


def test_noise_free_zeros_and_repeats_pass_alike() -> None:
    """The noise-free simulation reads exact zeros at rest and repeats bit for bit at constant velocity: both
    paths pass them (no motion), and drop the injected faults alike."""
    for fault in ("clean", "everything"):
        _, bulk, seq = screened(fault, "default", white_noise=False)
        print(_report(f"noise-free {fault}", bulk, seq))
        np.testing.assert_array_equal(bulk, seq)
        if fault == "clean":
            assert (seq == USABLE).all()


def test_tight_thresholds_and_screen_off() -> None:
    """Thresholds tight enough to reject most pings, and the screen off (every ping kept by both)."""
    _, bulk, seq = screened("everything", "tight")
    print(_report("tight", bulk, seq))
    np.testing.assert_array_equal(bulk, seq)
    assert (seq != USABLE).sum() > 1000
    _, bulk, seq = screened("everything", "off")
    np.testing.assert_array_equal(bulk, seq)
    assert (seq == USABLE).all()


@pytest.mark.parametrize("fault", ["clean", "everything"])
def test_beams_on_and_off(fault: str) -> None:
    """dvl.use_beams: the beam velocities are compared (NaN where a beam is invalid), zero and repeat rules."""
    _, bulk, seq = screened(fault, "beams", beams=True)
    print(_report(f"beams {fault}", bulk, seq))
    np.testing.assert_array_equal(bulk, seq)
    assert (seq == ZERO_WHILE_MOVING).sum() > 0 and (seq == REPEATED).sum() > 0


def test_beam_rules_on_a_log_without_beams() -> None:
    """dvl.use_beams on a log without beam data: PingScreen screens the 3-D velocity by the beam rules (the
    largest component as the speed, no jump rule), and so does the bulk."""
    log = _dvl(case("everything"), beams=None)
    cfg = CONFIGS["beams"]
    idx = first_pass_usable(log, cfg, beams=False)
    bulk, seq = (
        screen_pings(log.dvl, idx, log.imu, cfg),
        sequential_codes(log.dvl, idx, log.imu, cfg),
    )
    print(_report("beam rules, no beams", bulk, seq))
    np.testing.assert_array_equal(bulk, seq)
    assert (seq == ZERO_WHILE_MOVING).sum() > 0 and (seq == IMPLAUSIBLE_ACCEL).sum() == 0


@pytest.mark.parametrize("band", [0.0, np.inf])
def test_band_zero_and_infinite(band: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """With no safety band the bulk's own arithmetic decides every ping it can and still agrees (its sums differ
    from PingScreen's by rounding only); with an infinite band every ping after the first goes through
    PingScreen on the reference the walk tracks (last accepted ping, last_rate)."""
    monkeypatch.setattr(ping_screen, "_BAND", band)
    for cfg_name, beams in (("default", False), ("tight", False), ("beams", True)):
        _, bulk, seq = screened("everything", cfg_name, beams=beams)
        np.testing.assert_array_equal(bulk, seq)


def test_the_bulk_decides_all_but_the_pings_after_a_rejection(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PingScreen runs only where the bulk's assumption fails: the pings after a rejection up to two after the
    next accepted one (reference, then last_rate) and windows capped at SCREEN_WINDOW_S."""
    calls = []
    classify = PingScreen._classify

    def counted(self: PingScreen, *a: object) -> int:
        calls.append(1)
        return classify(self, *a)  # type: ignore[arg-type]

    monkeypatch.setattr(PingScreen, "_classify", counted)
    log, idx = case("everything"), usable("everything", "default")
    code = screen_pings(log.dvl, idx, log.imu, CONFIGS["default"])
    rejected = int((code != USABLE).sum())
    capped = int((np.diff(log.dvl.t[idx]) > SCREEN_WINDOW_S).sum())
    print(
        f"{len(idx)} pings, {rejected} rejected, {capped} capped windows: PingScreen ran {len(calls)} times"
    )
    assert rejected > 250
    assert len(calls) <= 2 * rejected + 2 * capped


def test_usable_pings_on_imu_stamps_only() -> None:
    """usable_pings given the IMU's stamps alone screens without IMU evidence, as PingScreen does on no samples."""
    log, cfg = case("everything"), CONFIGS["default"]
    counters: dict[str, int] = {}
    got = usable_pings(log.dvl, log.imu.t, cfg, counters)
    idx = first_pass_usable(log, cfg, beams=False)
    none = ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
    seq = sequential_codes(log.dvl, idx, none, cfg)
    np.testing.assert_array_equal(got, idx[seq == USABLE])
    assert counters["dvl_implausible_accel"] == int((seq == IMPLAUSIBLE_ACCEL).sum()) > 0
