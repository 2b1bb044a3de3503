"""estimators/run.py: every registered estimator behind one interface returns one kind of result
(core/result.EstimatorResult) whose calibration covers the truth of a simulated paper-3d-short run (the paper-3d
manoeuvres in 800 s)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult, misalignment_rpy_and_cov
from gtsam_dvl.core.states import Estimate
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.iodvlc import IoDvlcResult
from gtsam_dvl.estimators.run import ESTIMATORS, MODES, get_estimator, run_estimator
from gtsam_dvl.factors.so3 import log as so3_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

CHI2_3_1E4 = 21.108  # chi^2 with 3 degrees of freedom, P(larger) = 1e-4


@functools.cache
def _log() -> LogData:
    return simulate(load_scenario("paper-3d-short"), seed=3)


def test_modes_are_the_registry() -> None:
    assert MODES == ("batch", "online", "online-full", "ekf", "io-dvlc")
    assert all(ESTIMATORS[m].name == m and ESTIMATORS[m].description for m in MODES)
    with pytest.raises(GtsamDvlError, match="unknown mode 'kalman' \\(available: batch, online"):
        get_estimator("kalman")


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_every_estimator_reports_its_calibration_by_state_name(mode: str) -> None:
    log = _log()
    result = run_estimator(log, mode, None)
    assert isinstance(result, NavResult | IoDvlcResult)
    assert isinstance(result.estimator, str) and result.estimator.startswith(mode.split("-")[0])
    assert result.timing_s and all(t >= 0.0 for t in result.timing_s.values())
    scale, mis = result.calibration["scale"], result.calibration["misalignment"]
    assert isinstance(scale, Estimate) and isinstance(mis, Estimate)
    cal = log.true_calibration
    assert cal is not None
    # the scale within 4 sigma of the truth
    assert abs(scale.value[0] - cal.scale) < 4.0 * scale.sigma[0], (
        scale.value,
        scale.sigma,
        cal.scale,
    )
    # the misalignment: the error in GTSAM's right tangent of b_R_d, whitened by its covariance
    b_R_d_true = cal.b_R_d(log.mounting.b_R_d0)
    err = so3_log(b_R_d_true.T @ mis.value)
    chi2 = float(err @ np.linalg.solve(mis.cov, err))
    assert chi2 < CHI2_3_1E4, (mode, np.degrees(err), np.degrees(mis.sigma))
    # the same covariance read in the user's angles is what the result reports in degrees
    _, cov_deg = misalignment_rpy_and_cov(mis.value, log.mounting.b_R_d0, mis.cov)
    reported = (
        result.final_misalignment_sigma_deg
        if isinstance(result, IoDvlcResult)
        else result.misalignment_sigma_deg
    )
    np.testing.assert_allclose(np.sqrt(np.diag(cov_deg)), reported, rtol=1e-9)
