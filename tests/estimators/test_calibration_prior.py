"""Every estimator takes a vehicle's calibration as the prior (estimators/run.py run_estimator(..., calibration)):
the batch smoother's posterior tighter with it and at its mean where the log says nothing (a static log), the EKF
and the online estimator starting from its values and joint covariance, the run recording it."""

from __future__ import annotations

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.run import run_estimator
from tests.support.calibration import MOVING, STATIC, calibration_at_truth
from tests.support.scenarios import simulate_variant

# the default: scale 1 +- 1 %, misalignment +- 1 deg, the time offset estimated
CONFIG = EstimatorConfig()


@pytest.fixture(scope="module")
def static_log() -> LogData:
    return simulate_variant(3, segments=STATIC)


@pytest.fixture(scope="module")
def moving_log() -> LogData:
    return simulate_variant(3, segments=MOVING)


def test_batch_posterior_is_tighter_with_the_file_and_within_it(moving_log: LogData) -> None:
    cal = calibration_at_truth(moving_log)
    alone = run_estimator(moving_log, "batch", CONFIG)
    with_file = run_estimator(moving_log, "batch", CONFIG, calibration=cal)
    for name in ("scale", "misalignment", "time_offset"):
        s_alone, s_file = alone.calibration[name].sigma, with_file.calibration[name].sigma
        assert np.all(s_file < s_alone), name
        assert np.all(s_file <= cal.sigma(name) * (1 + 1e-9)), name  # data only add information
    truth = moving_log.true_calibration
    assert truth is not None
    scale = with_file.calibration["scale"]
    assert abs(scale.value[0] - truth.scale) < 3 * scale.sigma[0]
    prior = with_file.info["calibration_prior"]
    assert (
        prior["states"] == ["scale", "misalignment", "time_offset"] and prior["vehicle"] == "auv-7"
    )
    np.testing.assert_allclose(prior["cov"], cal.cov)


def test_batch_on_a_static_log_keeps_the_file(static_log: LogData) -> None:
    """Nothing calibrates a vehicle at rest: the posterior is the file's mean and covariance, to 1 % of a sigma."""
    cal = calibration_at_truth(static_log, scale_off=0.003)
    result = run_estimator(static_log, "batch", CONFIG, calibration=cal)
    scale = result.calibration["scale"]
    assert abs(scale.value[0] - cal.values["scale"][0]) < 0.01 * cal.sigma("scale")[0]
    np.testing.assert_allclose(scale.sigma, cal.sigma("scale"), rtol=0.01)
    mis = result.calibration["misalignment"]
    np.testing.assert_allclose(
        mis.value, cal.values["misalignment"], atol=0.01 * cal.sigma("misalignment").min()
    )
    np.testing.assert_allclose(mis.sigma, cal.sigma("misalignment"), rtol=0.01)


@pytest.mark.parametrize("mode", ["ekf", "online"])
def test_filters_start_at_the_inflated_file(mode: str, static_log: LogData) -> None:
    """The EKF's initial mean and covariance, the online estimator's prior: the file's values and its inflated
    sigmas at the first state (a static log adds nothing there)."""
    # variances x2
    cal = calibration_at_truth(static_log, scale_off=0.003).inflated(days=50.0, per_day=0.02)
    result = run_estimator(static_log, mode, CONFIG, calibration=cal)
    tl = result.timeline
    assert tl is not None
    np.testing.assert_allclose(tl.scale_sigma[0], cal.sigma("scale")[0], rtol=0.01)
    np.testing.assert_allclose(
        tl.misalignment_sigma_deg[0], np.degrees(cal.sigma("misalignment")), rtol=0.01
    )
    offset = result.calibration[
        "time_offset"
    ]  # (not in the filters' timelines) at rest: the file's to the end
    np.testing.assert_allclose(offset.sigma, cal.sigma("time_offset"), rtol=0.01)
    np.testing.assert_allclose(
        offset.value, cal.values["time_offset"], atol=0.05 * cal.sigma("time_offset")[0]
    )
    np.testing.assert_allclose(
        tl.scale[0], cal.values["scale"][0], atol=0.01 * cal.sigma("scale")[0]
    )
    assert result.info["calibration_prior"]["states"] == ["scale", "misalignment", "time_offset"]


def test_io_dvlc_takes_no_calibration(static_log: LogData) -> None:
    with pytest.raises(
        GtsamDvlError, match="calibration as the prior is batch, online and ekf only"
    ):
        run_estimator(static_log, "io-dvlc", CONFIG, calibration=calibration_at_truth(static_log))
