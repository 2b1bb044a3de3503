"""Memory of the online estimator: the IMU factors the fixed-lag window drops are freed.

EarthImuFactor's CustomFactor holds its Python callback through C++, out of the garbage collector's sight; the
callback is a separate model object that holds neither the factor nor its wrapper (factors/imu_earth.py,
"Memory"), so nothing keeps a dropped factor alive. Measured with weak references (no timing): every factor
made by the estimator's FactorMaker is tracked, and after a run only those of the states still in the window
may be alive. The RSS over a 6-hour run is bench/bench_online_long.py's.
"""

from __future__ import annotations

import gc
import weakref
from dataclasses import replace

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.online import OnlineEstimator, feed_log
from gtsam_dvl.factors import EarthImuFactor, imu_earth, make_earth_imu_factor
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario
from tests.support.logs import cut_log
from tests.support.memory import track_returns
from tests.support.window_memory import run_window

T_END_S = 400.0  # paper-3d-short: 120 s static, then the Type-I manoeuvres and the first legs


@pytest.fixture(scope="module")
def log() -> LogData:
    return replace(
        cut_log(simulate(load_scenario("paper-3d-short"), 5), T_END_S, beams=False), truth=None
    )


@pytest.mark.slow
@pytest.mark.parametrize("preset", ["default", "paper"])
def test_dropped_imu_factors_are_freed(
    log: LogData, monkeypatch: pytest.MonkeyPatch, preset: str
) -> None:
    """Every IMU factor the estimator made is tracked (the EarthImuFactor and its gtsam.CustomFactor)."""
    config = EstimatorConfig() if preset == "default" else EstimatorConfig.paper()
    tracked = {
        "IMU factors": track_returns(monkeypatch, FactorMaker, "new_imu_factor"),
        "CustomFactors": track_returns(
            monkeypatch, FactorMaker, "new_imu_factor", lambda f: f.factor
        ),
    }
    run = run_window(log, config, tracked, lambda smoother: len(smoother.imus))
    assert run.made["IMU factors"] > 5 * run.in_window  # the window dropped most of them
    # alive: those of the window (the estimator's dict) and the newest (its gravity reference), nothing else
    assert run.alive["IMU factors"] <= run.in_window + 1
    assert run.alive["CustomFactors"] <= run.in_window + 1
    assert run.alive_after == {"IMU factors": 0, "CustomFactors": 0}


@pytest.mark.slow
def test_parameters_claims_are_released(log: LogData) -> None:
    """Each factor claims its PreintegrationParams (imu_earth._CLAIMED); the claims of dropped factors end with
    them, so the set stays bounded by the window."""
    gc.collect()
    before = len(imu_earth._CLAIMED)
    est = OnlineEstimator.for_log(log, EstimatorConfig.paper())
    feed_log(est, log)
    gc.collect()
    assert est.smoother is not None
    during = len(imu_earth._CLAIMED) - before
    print(
        f"claims held after {est.epochs} epochs: {during} (window: {len(est.smoother.imus)} IMU factors)"
    )
    assert during <= len(est.smoother.imus) + 1
    del est
    gc.collect()
    assert len(imu_earth._CLAIMED) == before


def _one_factor() -> tuple[EarthImuFactor, gtsam.Values]:
    params = gtsam.PreintegrationParams.MakeSharedU(9.81)
    params.setAccelerometerCovariance(1e-6 * np.eye(3))
    params.setGyroscopeCovariance(1e-8 * np.eye(3))
    params.setIntegrationCovariance(1e-8 * np.eye(3))
    pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
    for _ in range(100):
        pim.integrateMeasurement(np.array([0.1, 0.0, 9.81]), np.array([0.0, 0.0, 0.01]), 0.01)
    keys = (
        gtsam.symbol("x", 0),
        gtsam.symbol("v", 0),
        gtsam.symbol("x", 1),
        gtsam.symbol("v", 1),
        gtsam.symbol("b", 0),
    )

    def gravity(n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # a made-up gradient, 1e-6 s^-2
        G = 1e-6 * np.diag([-1.0, -1.0, 2.0])
        return np.array([0.0, 0.0, -9.81]) + G @ n_p, G

    f = make_earth_imu_factor(pim, params, keys, 1.0, gravity)
    values = gtsam.Values()
    values.insert(keys[0], gtsam.Pose3(gtsam.Rot3(), np.array([1.0, 2.0, 3.0])))
    values.insert(keys[1], np.array([0.5, 0.0, 0.0]))
    values.insert(keys[2], gtsam.Pose3(gtsam.Rot3.Yaw(0.01), np.array([1.6, 2.1, 3.0])))
    values.insert(keys[3], np.array([0.6, 0.0, 0.01]))
    values.insert(keys[4], gtsam.imuBias.ConstantBias())
    return f, values


def test_factor_outlives_its_python_object_in_a_graph() -> None:
    """A graph that holds only the CustomFactor keeps a working factor (the same error and linearisation as
    while the EarthImuFactor existed); once the graph lets it go too, everything is freed."""
    f, values = _one_factor()
    graph = gtsam.NonlinearFactorGraph()
    graph.add(f.factor)
    e_before = graph.error(values)
    A_before, b_before = graph.linearize(values).jacobian()
    ref_f, ref_custom = weakref.ref(f), weakref.ref(f.factor)
    del f
    gc.collect()
    assert ref_f() is None  # nothing but the caller held the Python object
    assert graph.error(values) == e_before > 0.0
    A_after, b_after = graph.linearize(values).jacobian()
    np.testing.assert_array_equal(A_after, A_before)
    np.testing.assert_array_equal(b_after, b_before)
    del graph
    gc.collect()
    assert ref_custom() is None
