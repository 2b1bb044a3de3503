"""IMU gaps and DVL dropouts (estimators/inputs/gaps.py): never bridged by a held sample without saying so, crossed
the same way by the batch smoother, the online estimator and the EKF, with sigmas that cover the errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig, ImuConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.inputs.gaps import (
    filler_due,
    find_gaps,
    hold_covariance,
    pieces_with_holds,
    sample_starts_with_gaps,
    with_fillers,
)
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

RUNS = {"batch": smooth_batch, "online": smooth_online, "ekf": run_ekf}


def test_gap_pieces_cover_every_interval_once() -> None:
    # 100 Hz, a 0.2 s hole
    t = np.concatenate([np.arange(1, 501) * 0.01, 5.0 + np.arange(1, 301) * 0.01])
    t[500:] += 0.2
    gaps = find_gaps(t, 3.0)
    assert len(gaps) == 1 and gaps.period_s == pytest.approx(0.01)
    assert gaps.start[0] == pytest.approx(5.0) and gaps.end[0] == pytest.approx(5.2)
    starts = sample_starts_with_gaps(t, gaps)
    # the first sample after the gap covers its own period only
    assert starts[500] == pytest.approx(5.2)
    for a, b in [(4.0, 6.0), (5.05, 5.15), (5.1, 5.25), (4.995, 5.005), (1.0, 4.0)]:
        idx, dt, held = pieces_with_holds(t, starts, gaps, a, b)
        assert abs(dt.sum() - (b - a)) < 1e-12  # every instant once: samples or the held one
        assert held.total_s == pytest.approx(max(0.0, min(b, 5.2) - max(a, 5.0)))
        assert np.all(np.diff(idx) >= 0)  # in time order: the held sample 499 before sample 500
        if held:
            assert 499 in idx.tolist()
    no_gap = find_gaps(
        np.arange(1000) * 0.005 + np.random.default_rng(1).uniform(0, 0.001, 1000), 3.0
    )
    assert len(no_gap) == 0  # jitter is not a gap


def test_hold_covariance_grows_with_the_gap() -> None:
    cfg = ImuConfig()
    from gtsam_dvl.estimators.inputs.gaps import Holds

    s1, s5 = (np.sqrt(np.diag(hold_covariance(cfg, Holds(((0.0, T),)), T))) for T in (1.0, 5.0))
    assert np.all(s5 > s1) and s5[0] == pytest.approx(5 * np.radians(cfg.gap_rate_sigma_deg_s))
    assert np.all(hold_covariance(cfg, Holds(), 1.0) == 0)


def test_fillers_keep_the_spacing_and_are_causal() -> None:
    pings = np.array([1.0, 2.0, 3.0, 10.0, 11.0])
    times, filler = with_fillers(pings, 20.0, 1.0)
    assert times.tolist() == [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17]
    assert filler.tolist() == [False] * 3 + [True] * 6 + [False] * 2 + [True] * 6
    assert filler_due(3.0, None, 6.0, 1.0) is None  # the IMU has not yet reached 4.5 + the margin
    assert filler_due(3.0, None, 6.5, 1.0) == 4.0
    assert filler_due(3.0, 4.4, 100.0, 1.0) is None  # the next ping comes in time


@pytest.fixture(scope="module")
def paper3d() -> LogData:
    return simulate(load_scenario("paper-3d"), seed=5)


def _without_imu(log: LogData, t0: float, t1: float) -> LogData:
    keep = (log.imu.t <= t0) | (log.imu.t > t1)
    return dataclasses.replace(
        log,
        imu=dataclasses.replace(
            log.imu, t=log.imu.t[keep], b_omega=log.imu.b_omega[keep], b_f=log.imu.b_f[keep]
        ),
    )


def _worst_nsigma(result: object, log: LogData) -> tuple[float, float]:
    e = summary(result, log)["errors"]  # type: ignore[arg-type]
    cal = max(abs(e["scale_nsigma"]), *np.abs(e["misalignment_nsigma"]))
    final_sigma = summary(result, log)["final_horizontal_position_sigma_m"]  # type: ignore[arg-type]
    return float(cal), float(e["final_horizontal_position_m"] / final_sigma)


@pytest.mark.slow
@pytest.mark.parametrize("gap_s", [5.0, 9.0])
@pytest.mark.parametrize("mode", ["batch", "online", "ekf"])
def test_imu_gap_in_a_turn_is_crossed_inside_its_sigmas(
    paper3d: LogData, gap_s: float, mode: str
) -> None:
    """An IMU outage in the first turn of the square (780 s: 3.3 deg/s peak, body rolled 15 deg): counted, and
    the calibration and final position inside 3 sigma (before: scale 0.31 +- 0.0003, 1.2 km off)."""
    log = _without_imu(paper3d, 780.0, 780.0 + gap_s)
    res = RUNS[mode](log, EstimatorConfig.paper())
    cal, pos = _worst_nsigma(res, log)
    print(
        f"{mode}, {gap_s:.0f} s IMU gap: calibration {cal:.2f} sigma, final position {pos:.2f} sigma, "
        f"gaps {res.info['imu_gaps']}"
    )
    assert res.info["imu_gaps"]["count"] == 1
    assert res.info["imu_gaps"]["total_s"] == pytest.approx(gap_s, abs=0.02)
    assert cal < 3.0 and pos < 3.0


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["batch", "online", "ekf"])
def test_long_dvl_dropout_keeps_honest_sigmas(paper3d: LogData, mode: str) -> None:
    """600 s without a ping in the square (before: batch and online final position 6.6 sigma off)."""
    d = paper3d.dvl
    lost = (d.t > 900.0) & (d.t < 1500.0)
    log = dataclasses.replace(paper3d, dvl=dataclasses.replace(d, valid=d.valid & ~lost))
    res = RUNS[mode](log, EstimatorConfig.paper())
    cal, pos = _worst_nsigma(res, log)
    print(
        f"{mode}, 600 s DVL dropout: calibration {cal:.2f} sigma, final position {pos:.2f} sigma, "
        f"{res.info['counters'].get('states_without_ping')} states without a ping"
    )
    assert res.info["counters"]["states_without_ping"] >= 590
    assert np.max(np.diff(res.t)) <= 1.5
    assert cal < 3.0 and pos < 3.0


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["online", "ekf"])
def test_imu_gap_longer_than_the_limit_is_a_clear_error(paper3d: LogData, mode: str) -> None:
    """30 s without IMU in a turn: held that long the motion model's error is systematic (measured: batch scale
    3400 sigma off with the white-noise hold covariance), so the filters stop with an error that names the gap
    (the batch smoother cuts the log there: tests/estimators/test_pieces.py)."""
    log = _without_imu(paper3d, 780.0, 810.0)
    with pytest.raises(
        GtsamDvlError, match=r"IMU gap of 30.0 s at 780.00-810.00 s .*imu.max_gap_s = 10 s"
    ):
        RUNS[mode](log, EstimatorConfig.paper())


@pytest.mark.slow
def test_imu_gap_longer_than_the_limit_batch_smooths_the_pieces(paper3d: LogData) -> None:
    """The same 30 s gap in paper-3d's first turn: the batch smoother cuts the log there and smooths two pieces
    with one DVL calibration (estimators/batch/pieces.py), within 3 sigma of the truth."""
    log = _without_imu(paper3d, 780.0, 810.0)
    res = RUNS["batch"](log, EstimatorConfig.paper())
    cal, pos = _worst_nsigma(res, log)
    print(
        f"batch, 30 s IMU gap in a turn: {len(res.info['pieces'])} pieces, calibration {cal:.2f} sigma, final "
        f"position {pos:.2f} sigma"
    )
    assert len(res.info["pieces"]) == 2 and res.info["breaks"][0]["gap_start_s"] == pytest.approx(
        780.0
    )
    assert cal < 3.0 and pos < 3.0


@pytest.mark.slow
def test_online_drops_a_ping_that_comes_after_its_missing_ping_state(paper3d: LogData) -> None:
    """A ping pushed 5 s after the IMU samples of its time, in a dropout: a state without a ping was made in its
    place (the IMU reached 2 s past it), so the ping is dropped and counted, not inserted out of order."""
    from gtsam_dvl.estimators.online import OnlineConfig, OnlineEstimator

    d = paper3d.dvl
    est = OnlineEstimator.for_log(paper3d, EstimatorConfig.paper(), OnlineConfig(window_s=10.0))
    imu = paper3d.imu
    stop = int(np.searchsorted(imu.t, 700.0, side="right"))
    late = int(np.searchsorted(d.t, 690.0))
    start = 0
    for j in range(int(np.searchsorted(d.t, 685.0))):  # pings up to 685 s, in step with the IMU
        end = int(np.searchsorted(imu.t, d.t[j], side="right"))
        est.push_imu_batch(imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end])
        start = end
        est.push_dvl(d.t[j], d.d_v[j], d.d_cov[j], bool(d.valid[j]))
    est.push_imu_batch(imu.t[start:stop], imu.b_omega[start:stop], imu.b_f[start:stop])
    est.push_dvl(d.t[late], d.d_v[late], d.d_cov[late], True)  # 10 s behind the IMU
    est.push_imu_batch(
        imu.t[stop : stop + 100], imu.b_omega[stop : stop + 100], imu.b_f[stop : stop + 100]
    )
    assert est.counters.get("dvl_late") == 1
    assert est.counters.get("states_without_ping", 0) >= 8


def test_a_hold_turns_the_attitude_as_samples_would() -> None:
    """Review finding: a held piece of several seconds integrated as one GTSAM step used the attitude at its
    start throughout. Split into nominal periods, a 2 s hold of a pitching IMU (0.05 rad/s, specific force g
    along z) gives the delta-v of the same samples repeated, within 1e-3 m/s (one piece: 1 m/s off)."""
    import gtsam

    # a 2 s gap after 1.00 s
    t = np.concatenate([np.arange(1, 101) * 0.01, 3.0 + np.arange(1, 101) * 0.01])
    gaps = find_gaps(t, 3.0)
    starts = sample_starts_with_gaps(t, gaps)
    idx, dt, holds = pieces_with_holds(t, starts, gaps, 0.5, 3.5)
    assert holds.total_s == pytest.approx(2.0, abs=1e-9) and np.all(dt <= 0.01 + 1e-12)
    w, f = np.array([0.0, 0.05, 0.0]), np.array([0.0, 0.0, 9.8])

    def delta_v(pieces: list[float]) -> np.ndarray:
        params = gtsam.PreintegrationParams(np.zeros(3))
        params.setAccelerometerCovariance(np.eye(3) * 1e-8)
        params.setGyroscopeCovariance(np.eye(3) * 1e-10)
        params.setIntegrationCovariance(np.eye(3) * 1e-10)
        pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
        for d in pieces:
            pim.integrateMeasurement(f, w, d)
        return np.asarray(pim.deltaVij())

    exact = delta_v([0.01] * 300)  # the same constant sample at the nominal rate over the same 3 s
    split = delta_v(dt.tolist())
    assert np.max(np.abs(split - exact)) < 1e-3


def test_hold_covariance_of_a_gap_across_intervals_adds_up_to_the_whole_hold() -> None:
    """Review finding: a 9 s gap cut into 1 s intervals must not grow its attitude sigma like sqrt(N): the
    increments of the intervals add up to the covariance of one 9 s hold."""
    from gtsam_dvl.estimators.inputs.gaps import Holds

    cfg = ImuConfig()
    whole = hold_covariance(cfg, Holds(((0.0, 9.0),)), 9.0)
    pieces = sum(hold_covariance(cfg, Holds(((k, k + 1.0),)), 1.0) for k in range(9))
    np.testing.assert_allclose(np.diag(pieces)[:3], np.diag(whole)[:3], rtol=1e-12)  # rotation
    np.testing.assert_allclose(np.diag(pieces)[6:], np.diag(whole)[6:], rtol=1e-12)  # velocity
