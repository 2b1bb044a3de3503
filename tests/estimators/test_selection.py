"""One rule for which pings become epochs and how IMU samples are split (estimators/inputs/selection.py), shared by
the batch smoother, the online estimator and the EKF: the same log with dropouts gives all three the same
epochs and the same counts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.types import DvlData, ImuData, LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.inputs.gaps import with_fillers
from gtsam_dvl.estimators.inputs.ping_screen import frozen_runs
from gtsam_dvl.estimators.inputs.selection import (
    AFTER_IMU,
    BEFORE_IMU,
    IMPLAUSIBLE_ACCEL,
    REPEATED,
    TOO_FAST,
    UNUSABLE,
    USABLE,
    WATER_TRACK,
    ZERO_WHILE_MOVING,
    PingScreen,
    classify_pings,
    imu_pieces,
    sample_starts,
    screen_pings,
    screened_value,
    select_epochs,
)
from gtsam_dvl.estimators.online import OnlineEstimator, smooth_online
from tests.support.pings import first_pass_usable


def _with_dropouts(log: LogData, t_end: float = 800.0) -> tuple[LogData, np.ndarray]:
    """The first t_end seconds of a log with bottom-lock losses: a 30 s block in the motion, every 7th ping
    invalid, one NaN velocity flagged valid and one 15 m/s outlier. Returns the log and the indices of the
    pings that must become epochs."""
    imu_keep = log.imu.t <= t_end
    dvl_keep = log.dvl.t <= t_end
    imu = dataclasses.replace(
        log.imu, t=log.imu.t[imu_keep], b_omega=log.imu.b_omega[imu_keep], b_f=log.imu.b_f[imu_keep]
    )
    d = log.dvl
    t = d.t[dvl_keep]
    d_v, valid = d.d_v[dvl_keep].copy(), d.valid[dvl_keep].copy()
    block = (t > 640.0) & (t < 670.0)
    every7 = (np.arange(len(t)) % 7 == 3) & (t > 100.0)
    valid[block | every7] = False
    d_v[~valid] = np.nan
    nan_ping, fast_ping = (
        int(np.searchsorted(t, t_end - 40.5)),
        int(np.searchsorted(t, t_end - 20.5)),
    )
    valid[nan_ping] = valid[fast_ping] = True
    d_v[nan_ping] = np.nan
    d_v[fast_ping] = [15.0, 0.0, 0.0]
    dvl = DvlData(t, d_v, d.d_cov[dvl_keep], valid, None, noise_free=d.noise_free)
    expected = np.flatnonzero(
        valid
        & np.isfinite(d_v).all(axis=1)
        & (np.linalg.norm(np.nan_to_num(d_v), axis=1) < 10)
        & (t > imu.t[0])
    )
    return dataclasses.replace(log, imu=imu, dvl=dvl, truth=None), expected


@pytest.mark.slow
def test_batch_online_and_ekf_use_the_same_epochs(sim_paper3d_clean: LogData) -> None:
    log, expected = _with_dropouts(sim_paper3d_clean)
    cfg = EstimatorConfig.paper()
    batch = smooth_batch(log, cfg)
    online = smooth_online(log, cfg)
    ekf = run_ekf(log, cfg)
    # the pings, and states without a ping where pings are missing for more than 1.5 s (estimators/inputs/gaps.py)
    t_expected, is_filler = with_fillers(
        log.dvl.t[expected], float(log.imu.t[-1]), cfg.solver.max_state_spacing_s
    )
    assert is_filler.sum() > 30  # the 30 s block and every 7th ping
    assert np.max(np.diff(t_expected)) <= 1.5 * cfg.solver.max_state_spacing_s
    print(
        f"{len(log.dvl)} pings, {len(expected)} epochs; counters batch {batch.info['counters']}, "
        f"online {online.info['counters']}, ekf {ekf.info['counters']}"
    )
    np.testing.assert_array_equal(batch.t, t_expected)
    np.testing.assert_array_equal(online.t, t_expected)
    np.testing.assert_array_equal(ekf.t, t_expected)
    # invalid and the NaN ping flagged valid; apart, the ping at the first IMU stamp (nothing to propagate from)
    n_before = int((log.dvl.t <= log.imu.t[0]).sum())
    n_unusable = int((~log.dvl.valid[n_before:]).sum()) + 1
    assert n_before == 1 and n_unusable + n_before + 1 + len(expected) == len(log.dvl)
    for res in (batch, online, ekf):
        assert res.info["counters"].get("dvl_too_fast", 0) == 1
        assert res.info["counters"].get("dvl_unusable", 0) == n_unusable
        assert res.info["counters"].get("dvl_before_imu", 0) == n_before


def test_keyframe_thinning_is_the_same_online_and_in_batch(sim_paper3d_clean: LogData) -> None:
    log, _ = _with_dropouts(sim_paper3d_clean, t_end=700.0)
    cfg = EstimatorConfig.paper()
    cfg.solver.keyframe_interval_s = 2.5
    cfg.solver.max_state_spacing_s = 2.5  # keyframes 2.5 s apart need states allowed that far apart
    counters: dict[str, int] = {}
    idx = select_epochs(log.dvl, log.imu.t, cfg.dvl, 2.5, counters)
    assert np.all(np.diff(log.dvl.t[idx]) >= 2.5) and counters["dvl_not_keyframe"] > 0
    batch = smooth_batch(log, cfg)
    online = smooth_online(log, cfg)
    t_states, _ = with_fillers(log.dvl.t[idx], float(log.imu.t[-1]), cfg.solver.max_state_spacing_s)
    np.testing.assert_array_equal(batch.t, t_states)
    np.testing.assert_array_equal(online.t, t_states)
    assert batch.info["counters"]["dvl_not_keyframe"] == online.info["counters"]["dvl_not_keyframe"]


def test_classify_pings_reasons() -> None:
    t = np.array([0.5, 1.5, 2.5, 3.5, 4.5, 9.5])
    d_v = np.array(
        [[1.0, 0, 0], [np.nan, 0, 0], [20.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]]
    )
    valid = np.array([True, True, True, False, True, True])
    code = classify_pings(t, d_v, valid, None, None, DvlConfig(), t_imu_first=1.0, t_imu_last=9.0)
    # before the first IMU sample; NaN; too fast; flagged invalid; usable; after the last IMU sample
    assert code.tolist() == [BEFORE_IMU, UNUSABLE, TOO_FAST, UNUSABLE, USABLE, AFTER_IMU]
    beams_ok = np.array(
        [[True, False], [False, False], [True, True], [False, True], [True, True], [True, True]]
    )
    finite = np.array([True, True, True, True, False, True])
    code = classify_pings(t, d_v, valid, beams_ok, finite, DvlConfig(use_beams=True), 1.0, 10.0)
    # with beams: any valid finite beam counts, the 3-D flag and speed do not
    assert code.tolist() == [BEFORE_IMU, UNUSABLE, USABLE, USABLE, UNUSABLE, USABLE]
    # water track, whatever its flag says (the reader marks it invalid), is counted as such
    water = np.array([False, False, True, True, True, False])
    code = classify_pings(t, d_v, valid, None, None, DvlConfig(), 1.0, 9.0, water_track=water)
    assert code.tolist() == [BEFORE_IMU, UNUSABLE, WATER_TRACK, WATER_TRACK, WATER_TRACK, AFTER_IMU]


@pytest.mark.parametrize("a,b", [(0.0, 1.0), (0.013, 0.987), (0.5, 0.5 + 1e-9), (0.9999, 3.0)])
def test_imu_pieces_split_samples_exactly(a: float, b: float) -> None:
    """The pieces of (a, b] cover it exactly once: their durations add up to b - a (inside the IMU's span)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.006, 1000))  # jittered 200 Hz stamps
    starts = sample_starts(t)
    np.testing.assert_array_equal(starts[1:], t[:-1])
    idx, dt = imu_pieces(t, starts, a + t[0], b + t[0])
    assert np.all(dt > 0) and np.all(np.diff(idx) == 1)
    assert abs(dt.sum() - (b - a)) < 1e-12


# ----- bogus pings (PingScreen) -------------------------------------------------------------------------

BOGUS_REASONS = ("dvl_zero_while_moving", "dvl_repeated", "dvl_implausible_accel")


def _with_bogus(log: LogData) -> tuple[LogData, np.ndarray, dict[str, int]]:
    """_with_dropouts, plus what a DVL that lost bottom lock but still flags its velocity valid reports: exact
    zeros for 10 s at 2 m/s (700-710 s), its output frozen while the vehicle speeds up (606-614 s, at the value
    of the last valid ping before), and 4 pings 4 m/s off (720-760 s). Returns the log, the pings that must
    become epochs and the expected counts."""
    log, expected = _with_dropouts(log)
    d = log.dvl
    t, d_v, ok = d.t, d.d_v.copy(), d.valid & np.isfinite(d.d_v).all(axis=1)
    zero = ok & (t >= 700.0) & (t < 710.0)
    d_v[zero] = 0.0
    frozen = ok & (t > 606.0) & (t <= 614.0)
    d_v[frozen] = d_v[np.flatnonzero(ok & (t <= 606.0))[-1]]
    jump = np.flatnonzero(ok & (t > 720.0) & (t < 760.0))[::8][:4]
    d_v[jump] += [4.0, 0.0, 0.0]
    bogus = zero | frozen
    bogus[jump] = True
    counts = {
        "dvl_zero_while_moving": int(zero.sum()),
        "dvl_repeated": int(frozen.sum()),
        "dvl_implausible_accel": len(jump),
    }
    return (
        dataclasses.replace(log, dvl=dataclasses.replace(d, d_v=d_v)),
        expected[~bogus[expected]],
        counts,
    )


def _feed_pings_first(est: OnlineEstimator, log: LogData) -> None:
    """A live order feed_log does not test: each ping arrives before the IMU samples up to its stamp."""
    imu, dvl = log.imu, log.dvl
    ends = np.searchsorted(imu.t, dvl.t, side="right")
    start = 0
    for j in range(len(dvl)):
        est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
        end = int(ends[j])
        if end > start:
            est.push_imu_batch(imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end])
            start = end
    est.push_imu_batch(imu.t[start:], imu.b_omega[start:], imu.b_f[start:])
    est.finish()


@pytest.mark.slow
def test_bogus_pings_dropped_alike_by_batch_online_and_ekf(sim_paper3d_clean: LogData) -> None:
    """The screen's rules are causal (the previous accepted ping and the IMU since it), so batch, online (in either
    message order) and EKF drop the same bogus pings, count them alike and keep the same epochs; the noise-free
    simulation's own exact zeros (at rest) and repeated velocities (constant velocity, steady turns) pass."""
    log, expected, counts = _with_bogus(sim_paper3d_clean)
    cfg = EstimatorConfig.paper()
    batch = smooth_batch(log, cfg)
    online = smooth_online(log, cfg)
    live = OnlineEstimator.for_log(log, cfg)
    _feed_pings_first(live, log)
    ekf = run_ekf(log, cfg)
    t_expected, _ = with_fillers(
        log.dvl.t[expected], float(log.imu.t[-1]), cfg.solver.max_state_spacing_s
    )
    print(
        f"expected drops {counts}; counters batch {batch.info['counters']}, online {online.info['counters']}, "
        f"online pings first {live.counters}, ekf {ekf.info['counters']}"
    )
    for res in (batch, online, live.result(), ekf):
        np.testing.assert_array_equal(res.t, t_expected)
        assert {k: res.info["counters"].get(k, 0) for k in BOGUS_REASONS} == counts
    clean: dict[str, int] = {}
    select_epochs(sim_paper3d_clean.dvl, sim_paper3d_clean.imu, cfg.dvl, 0.0, clean)
    # 601 exact zeros and 1621 bit-identical repeats there
    assert all(clean[k] == 0 for k in BOGUS_REASONS)


def _synthetic_imu(
    t_end: float,
    accel: float = 0.0,
    t_accel: float = np.inf,
    roll_rate: float = 0.0,
    hz: float = 100.0,
) -> ImuData:
    """Level at rest (specific force up, g = 9.8), optionally accelerating along x by accel m/s^2 from t_accel,
    or rolling at roll_rate rad/s on the spot (gravity turning in the body, no motion)."""
    t = np.arange(1, int(t_end * hz) + 1) / hz
    # the mid-interval attitude: the sample is the interval's mean
    roll = roll_rate * (t - 0.5 / hz)
    f = np.stack(
        [np.where(t > t_accel, accel, 0.0), 9.8 * np.sin(roll), 9.8 * np.cos(roll)], axis=1
    )
    w = np.zeros((len(t), 3))
    w[:, 0] = roll_rate
    return ImuData(t, w, f)


def _codes(
    imu: ImuData,
    t: np.ndarray,
    d_v: np.ndarray,
    cfg: DvlConfig | None = None,
    noise_free: bool = True,
) -> list[int]:
    """The screen's codes; noise_free: the velocities are a noise-free simulation's (repeats need motion)."""
    dvl = DvlData(
        t, d_v, np.zeros((len(t), 3, 3)), np.ones(len(t), dtype=bool), noise_free=noise_free
    )
    got = screen_pings(dvl, np.arange(len(t)), imu, cfg or DvlConfig()).tolist()
    # the reference, ping by ping
    screen = PingScreen(cfg or DvlConfig(), repeats_need_motion=noise_free)
    assert [
        screen.check(float(x), y, imu.t, imu.b_omega, imu.b_f) for x, y in zip(t, d_v, strict=True)
    ] == got
    return got


def test_ping_screen_rules() -> None:
    """Each rule on synthetic data: exact zeros pass at rest and when the body only turns on the spot (gravity
    turning in the body is no motion), are dropped when the IMU shows acceleration or the previous ping was
    moving; repeats pass at constant velocity and are dropped while the vehicle speeds up; a jump the IMU cannot
    explain is dropped and the next sound ping is compared with the last accepted one; dvl.screen = false keeps
    everything."""
    t = np.arange(1.0, 21.0)
    zeros = np.zeros((20, 3))
    assert _codes(_synthetic_imu(21.0), t, zeros) == [USABLE] * 20
    # 1 rad rolled: 9.8 m/s^2 turned
    assert _codes(_synthetic_imu(21.0, roll_rate=0.05), t, zeros) == [USABLE] * 20
    moving = _codes(_synthetic_imu(21.0, accel=0.3, t_accel=10.5), t, zeros)
    # 0.3 m/s^2 from 10.5 s: 0.15 m/s by 11 s
    assert moving == [USABLE] * 10 + [ZERO_WHILE_MOVING] * 10
    cruise = np.tile([2.0, 0.0, 0.0], (20, 1))
    cruise[12:] = 0.0
    # the DVL said 2 m/s
    assert _codes(_synthetic_imu(21.0), t, cruise) == [USABLE] * 12 + [ZERO_WHILE_MOVING] * 8
    # constant velocity
    assert _codes(_synthetic_imu(21.0), t, np.tile([2.0, 0.0, 0.0], (20, 1))) == [USABLE] * 20
    speeding = np.stack([np.clip(0.3 * (t - 10.5), 0.0, None), np.zeros(20), np.zeros(20)], axis=1)
    speeding[14:] = speeding[13]  # frozen at 14 s while the vehicle keeps accelerating
    assert (
        _codes(_synthetic_imu(21.0, accel=0.3, t_accel=10.5), t, speeding)
        == [USABLE] * 14 + [REPEATED] * 6
    )
    jumps = np.tile([2.0, 0.0, 0.0], (20, 1))
    jumps[5] = [5.0, 0.0, 0.0]  # 3 m/s in 1 s at constant IMU: more than 2 m/s^2 + 0.3 m/s
    jumps[6] = [2.0, 0.0, 5.0]  # 5 m/s off the last accepted ping, 2 s before: allowed 4.3 m/s
    # back to 2 m/s: compared with the last accepted ping (5 m/s off the previous one), and repeated from there
    # on, at constant IMU and no change between the last two accepted pings: no motion
    codes = _codes(_synthetic_imu(21.0), t, jumps)
    assert (
        codes[5:8] == [IMPLAUSIBLE_ACCEL, IMPLAUSIBLE_ACCEL, USABLE] and codes.count(USABLE) == 18
    )
    assert _codes(_synthetic_imu(21.0), t, jumps, DvlConfig(screen=False)) == [USABLE] * 20


def test_frozen_dvl_dropped_whatever_the_imu_shows() -> None:
    """A real DVL (not a noise-free simulation) never repeats a velocity bit for bit: a frozen output is dropped
    at constant velocity, in a steady turn (the IMU shows no change of the velocity) and while speeding up; the
    first ping of the stretch is the real reading and stays; noisy pings pass; exact zeros at rest are left to
    the zero rule (they pass at rest)."""
    t = np.arange(1.0, 21.0)
    rng = np.random.default_rng(5)
    noisy = np.tile([2.0, 0.0, 0.0], (20, 1)) + rng.normal(0.0, 0.02, (20, 3))
    assert _codes(_synthetic_imu(21.0), t, noisy, noise_free=False) == [USABLE] * 20
    frozen = noisy.copy()
    frozen[8:14] = frozen[7]
    want = [USABLE] * 8 + [REPEATED] * 6 + [USABLE] * 6
    assert _codes(_synthetic_imu(21.0), t, frozen, noise_free=False) == want
    assert _codes(_synthetic_imu(21.0, roll_rate=0.05), t, frozen, noise_free=False) == want
    # no motion: the model's
    assert _codes(_synthetic_imu(21.0), t, frozen, noise_free=True) == [USABLE] * 20
    assert _codes(_synthetic_imu(21.0), t, np.zeros((20, 3)), noise_free=False) == [USABLE] * 20
    dvl = DvlData(t, frozen, np.zeros((20, 3, 3)), np.ones(20, dtype=bool))
    assert frozen_runs(dvl) == [(9.0, 14.0, 6)]
    assert frozen_runs(dataclasses.replace(dvl, noise_free=True)) == []


@pytest.mark.parametrize(("chunk", "noise_free"), [(1, True), (37, True), (250, True), (37, False)])
def test_ping_screen_online_matches_the_whole_log(
    chunk: int, noise_free: bool, sim_paper3d_clean: LogData
) -> None:
    """The online estimator's use (IMU pushed in chunks, each ping checked once the IMU reaches it) gives the
    whole-log decisions exactly, whatever the chunking; also when the noise-free simulation is taken for a real
    DVL (its repeats at constant velocity are then frozen output)."""
    log, _, counts = _with_bogus(sim_paper3d_clean)
    log = dataclasses.replace(log, dvl=dataclasses.replace(log.dvl, noise_free=noise_free))
    cfg = DvlConfig()
    idx = first_pass_usable(log, cfg, beams=False)
    whole = screen_pings(log.dvl, idx, log.imu, cfg)
    screen = PingScreen(cfg, repeats_need_motion=noise_free)
    imu, online = log.imu, []
    pos = 0
    for j in idx.tolist():
        while not screen.reaches(float(log.dvl.t[j])):
            screen.push_imu(
                imu.t[pos : pos + chunk], imu.b_omega[pos : pos + chunk], imu.b_f[pos : pos + chunk]
            )
            pos += chunk
        online.append(
            screen.check_buffered(float(log.dvl.t[j]), screened_value(log.dvl.d_v[j], None, cfg))
        )
    assert online == whole.tolist()
    got = [int((whole == c).sum()) for c in (ZERO_WHILE_MOVING, REPEATED, IMPLAUSIBLE_ACCEL)]
    if noise_free:
        assert got == list(counts.values())
    else:  # the simulation's own repeats at constant velocity too
        assert got[1] > counts["dvl_repeated"]


def test_ping_covariance_rule() -> None:
    """The one rule for a ping's noise: configured sigma, else the message's covariance when positive definite,
    else the default sigma."""
    from gtsam_dvl.estimators.inputs.selection import ping_covariance

    good = np.diag([1e-4, 2e-4, 3e-4])
    bad = np.diag([1e-4, -1.0, 1e-4])  # not positive definite
    unknown = np.full((3, 3), np.nan)  # TwistStamped: no covariance
    got = ping_covariance(DvlConfig(), np.stack([good, bad, unknown]))
    np.testing.assert_array_equal(got[0], good)
    np.testing.assert_array_equal(got[1], np.eye(3) * DvlConfig().default_noise_m_s ** 2)
    np.testing.assert_array_equal(got[2], np.eye(3) * DvlConfig().default_noise_m_s ** 2)
    fixed = ping_covariance(DvlConfig(noise_m_s=0.05), good)
    np.testing.assert_allclose(fixed, np.eye(3) * 0.0025, rtol=1e-15)
