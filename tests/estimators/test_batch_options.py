"""Batch smoother options beyond the paper's defaults: random-walk biases, a configured initial attitude
for logs without a static start, per-beam factors with beam dropouts, a 180 deg roll DVL mounting with a
lever arm. Each asserts errors against the truth within 3 sigma."""

from __future__ import annotations

import copy
import dataclasses
import functools

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_rpy_deg, quat_xyzw_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict
from tests.support.logs import cut_log

pytestmark = pytest.mark.slow


@functools.cache
def _paper3d(seed: int = 5) -> LogData:
    return simulate(load_scenario("paper-3d"), seed)


def _assert_within_3_sigma(s: dict) -> None:
    e = s["errors"]
    print(
        {
            k: np.round(e[k], 2).tolist()
            for k in (
                "scale_nsigma",
                "misalignment_nsigma",
                "gyro_bias_nsigma",
                "accel_bias_nsigma",
            )
        }
    )
    assert abs(e["scale_nsigma"]) < 3
    for key in ("misalignment_nsigma", "gyro_bias_nsigma", "accel_bias_nsigma"):
        assert np.all(np.abs(e[key]) < 3), key


def test_random_walk_bias_model() -> None:
    """Bias as a random walk (a state per epoch): the truth is a random constant, so the estimate must
    still land within 3 sigma, with sigmas no smaller than the random-constant model's."""
    log = _paper3d()
    cfg = EstimatorConfig.paper()
    cfg.imu.bias_model = "random_walk"
    rw = summary(smooth_batch(log, cfg), log)
    const = summary(smooth_batch(log, EstimatorConfig.paper()), log)
    _assert_within_3_sigma(rw)
    assert np.all(
        np.array(rw["accel_bias_ug"]["sigma"]) >= 0.99 * np.array(const["accel_bias_ug"]["sigma"])
    )
    assert rw["scale"]["sigma"] < 1500e-6


def _cut(log: LogData, t_start: float) -> LogData:
    """The log from t_start on (no static start), times kept, truth positions from the first kept one."""
    cut = cut_log(log, t_start=t_start)
    assert cut.truth is not None
    return dataclasses.replace(
        cut, truth=dataclasses.replace(cut.truth, n_p=cut.truth.n_p - cut.truth.n_p[0])
    )


def test_log_without_static_start_needs_and_uses_a_configured_attitude() -> None:
    """paper-3d from 595 s (no static start): a clear error with alignment.method = "static"; a configured
    attitude works (method "auto" aligns in motion then: tests/estimators/test_alignment_motion.py)."""
    log = _cut(_paper3d(), 595.0)
    static_only = EstimatorConfig.paper()
    static_only.alignment.method = "static"
    with pytest.raises(GtsamDvlError, match="initial_attitude_deg"):
        smooth_batch(log, static_only)
    assert log.truth is not None
    rpy_true = matrix_to_rpy_deg(quat_xyzw_to_matrix(log.truth.n_q_b[0]))
    cfg = EstimatorConfig.paper()
    # a compass-grade guess
    cfg.alignment.initial_attitude_deg = tuple(rpy_true + np.array([0.02, -0.02, 0.5]))
    s = summary(smooth_batch(log, cfg), log)
    print("initial attitude given, no static start:", np.round(rpy_true, 3))
    _assert_within_3_sigma(s)


def _scenario_with_dvl(**dvl_changes: object) -> dict:
    raw = copy.deepcopy(load_scenario("paper-3d").raw)
    raw["dvl"].update(dvl_changes)
    return raw


def test_beam_factors_with_beam_dropouts() -> None:
    """Per-beam noise and 25% of beams dropped at random (many pings with 2 or 3 beams, so no 3-D velocity):
    the per-beam factors still calibrate the DVL within 3 sigma."""
    raw = _scenario_with_dvl(noise_model="beam", noise_m_s=0.02, dropout_beam_prob=0.25)
    log = simulate(scenario_from_dict(raw, "paper-3d-beams"), 4)
    assert log.dvl.beams is not None
    good = log.dvl.beams.valid.sum(axis=1)
    print("pings with 4/3/2/1/0 valid beams:", [int((good == k).sum()) for k in (4, 3, 2, 1, 0)])
    assert (good < 3).sum() > 50  # many pings without a 3-D velocity
    cfg = EstimatorConfig.paper()
    cfg.dvl.use_beams = True
    cfg.dvl.beam_noise_m_s = 0.02
    s = summary(smooth_batch(log, cfg), log)
    _assert_within_3_sigma(s)
    assert s["info"]["epochs"] > 0.95 * len(log.dvl)  # pings with 1 or 2 beams still make states


def test_dvl_mounted_upside_down_with_lever_arm() -> None:
    """A real DVL often points z down (180 deg roll nominal mounting) and sits away from the IMU."""
    raw = copy.deepcopy(load_scenario("paper-3d").raw)
    raw["mounting"]["dvl_rpy_deg"] = [180.0, 0.0, 0.0]
    raw["mounting"]["dvl_lever_arm_m"] = [1.2, 0.1, -0.4]
    raw["dvl"]["face_axis"] = [0.0, 0.0, 1.0]
    log = simulate(scenario_from_dict(raw, "paper-3d-flipped"), 6)
    print("b_R_d0 diag:", np.round(np.diag(log.mounting.b_R_d0), 3), "lever arm:", log.mounting.b_l)
    s = summary(smooth_batch(log, EstimatorConfig.paper()), log)
    _assert_within_3_sigma(s)
