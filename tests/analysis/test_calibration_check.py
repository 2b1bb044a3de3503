"""The verdict on a run against its calibration file (analysis/calibration_check.py): the chi^2 of the shift since
the file against P0 - P1 follows chi^2(dof) when the vehicle has not changed (linear-Gaussian draws), a 1 % scale
change is flagged in words, a direction the dive did not inform is left to the file; end to end on a simulated
dive, in the health."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.calibration_check import check_calibration, tail_probability
from gtsam_dvl.analysis.health import assess_health
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_exp
from gtsam_dvl.core.states import Estimate, joint_slices
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.run import run_estimator
from tests.support.calibration import calibration_at_truth

CONFIG = EstimatorConfig()
NAMES = ["scale", "misalignment", "time_offset"]
R0 = rpy_deg_to_matrix([0.1, -0.2, 0.4])
MU0 = np.array([1.002, 0.0, 0.0, 0.0, -0.05])  # scale, misalignment tangent (at R0), time offset
P0 = np.diag([5e-4, *np.radians([0.05, 0.05, 0.1]), 5e-3]) ** 2
P0[0, 3] = P0[3, 0] = 0.5 * np.sqrt(P0[0, 0] * P0[3, 3])  # scale and yaw correlated
# the dive's information: sigmas 1e-3, 0.1 deg, 0.1 deg, 10 ms on scale, roll, pitch, time offset, none on yaw
INFO = np.diag([1e-3**-2, np.radians(0.1) ** -2, np.radians(0.1) ** -2, 0.0, 0.01**-2])


def _result(delta1: np.ndarray, P1: np.ndarray) -> Any:
    """A run's result (what check_calibration reads): the posterior at MU0 + delta1 (the misalignment R0 Exp(.)),
    its joint covariance P1 inside shared_joint_cov, the file's prior in info."""
    sl = joint_slices(CONFIG)
    joint = np.eye(sum(s.stop - s.start for s in sl.values())) * 1e-10
    idx = np.r_[sl["scale"], sl["misalignment"], sl["time_offset"]]
    joint[np.ix_(idx, idx)] = P1
    values = {
        "scale": MU0[:1] + delta1[:1],
        "misalignment": R0 @ so3_exp(delta1[1:4]),
        "time_offset": MU0[4:] + delta1[4:],
    }
    calibration = {
        "scale": Estimate(values["scale"], P1[:1, :1]),
        "misalignment": Estimate(values["misalignment"], P1[1:4, 1:4]),
        "time_offset": Estimate(values["time_offset"], P1[4:, 4:]),
    }
    prior = {
        "vehicle": "auv-7",
        "date": "2026-11-02T10:15:00Z",
        "states": NAMES,
        "values": {
            "scale": MU0[:1].tolist(),
            "misalignment": R0.tolist(),
            "time_offset": MU0[4:].tolist(),
        },
        "cov": P0.tolist(),
    }
    return SimpleNamespace(
        info={"calibration_prior": prior},
        calibration=calibration,
        shared_joint_cov=joint,
        calib_joint_cov=None,
        estimator_config=CONFIG,
    )


def _dive(rng: np.random.Generator, true_shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The posterior shift and covariance of a linear-Gaussian dive: the truth at MU0 + true_shift, measured with
    information INFO (its information vector INFO true_shift + INFO^1/2 w)."""
    P1 = np.linalg.inv(np.linalg.inv(P0) + INFO)
    eta = INFO @ true_shift + np.sqrt(INFO) @ rng.normal(size=5)
    return P1 @ eta, P1


def test_chi2_follows_its_distribution_when_the_vehicle_did_not_change() -> None:
    """Truth drawn from the file's prior: chi^2 has mean dof = 4 (yaw uninformed, left out) and the false-alarm
    rate of 3 sigma (0.27 %); the shift tested against P0 alone (the lenient test) would have a mean far below."""
    rng = np.random.default_rng(5)
    chi2, flagged, lenient = [], 0, []
    n = 2000
    L = np.linalg.cholesky(P0)
    for _ in range(n):
        d1, P1 = _dive(rng, L @ rng.normal(size=5))
        check = check_calibration(_result(d1, P1))
        assert check is not None and check.dof == 4
        chi2.append(check.chi2)
        flagged += check.moved
        lenient.append(d1 @ np.linalg.solve(P0, d1))
    assert np.mean(chi2) == pytest.approx(4.0, abs=0.25)  # its standard error 0.06
    assert flagged / n < 3 * tail_probability(3.0)  # 0.27 % expected
    assert np.mean(lenient) < 3.0


def test_a_moved_scale_is_flagged_in_words_and_the_uninformed_yaw_left_to_the_file() -> None:
    rng = np.random.default_rng(1)
    # the scale 1 % off the file
    moved = check_calibration(_result(*_dive(rng, np.array([0.01, 0, 0, 0, 0]))))
    assert moved is not None and moved.moved
    scale = moved.components[0]
    assert scale.name == "scale" and scale.z > 5
    texts = [t for _, t in moved.findings]
    assert any(
        t.startswith(f"DVL scale factor moved {scale.z:.1f} sigma since 2026-11-02")
        and "sound-speed" in t
        for t in texts
    ), texts
    assert [sev for sev, _ in moved.findings] == ["degraded", "warn"]
    same = check_calibration(_result(*_dive(rng, np.zeros(5))))
    assert same is not None and not same.moved and same.findings[0][0] == "note"
    assert "consistent with auv-7's calibration of 2026-11-02" in same.findings[0][1]
    # from the calibration: the dive did not inform it
    assert "about body z (yaw)" in same.findings[0][1]
    yaw = same.components[3]
    assert yaw.informed < 0.1 and same.components[1].informed > 0.15  # yaw only through the scale


def test_without_the_shared_joint_the_calibration_block_keeps_the_correlations() -> None:
    """The online estimator's result has no shared_joint_cov: the calibration block (bias, scale, misalignment) and
    the time offset's marginal give the same chi^2 here (the time offset uncorrelated with the rest)."""
    rng = np.random.default_rng(2)
    d1, P1 = _dive(rng, np.array([0.002, 0, 0, 0, 0.0]))
    full = _result(d1, P1)
    online = _result(d1, P1)
    block = np.eye(10) * 1e-10
    block[6:, 6:] = P1[:4, :4]  # [accel, gyro] bias, scale, misalignment
    online.shared_joint_cov, online.calib_joint_cov = None, block
    a, b = check_calibration(full), check_calibration(online)
    assert a is not None and b is not None and a.dof == b.dof == 4 and a.chi2 > 5
    assert b.chi2 == pytest.approx(a.chi2, rel=1e-9)


def test_one_state_beyond_3_sigma_that_the_joint_test_keeps_is_a_warning() -> None:
    """The scale 3.5 sigma off alone (sigma of what the dive could move it): the joint test over 4 directions keeps
    the file (chi^2 12.3 < 16.3), the scale's line says so, the health is not degraded."""
    P1 = np.linalg.inv(np.linalg.inv(P0) + INFO)
    d1 = np.zeros(5)
    d1[0] = 3.5 * np.sqrt(P0[0, 0] - P1[0, 0])
    check = check_calibration(_result(d1, P1))
    assert check is not None and not check.moved and check.chi2 < check.threshold
    assert [sev for sev, _ in check.findings] == ["warn"]
    assert check.findings[0][1].startswith("DVL scale factor moved 3.5 sigma")
    assert "the joint test does not reject the file" in check.findings[0][1]


def test_a_calibration_of_another_configuration_is_noted() -> None:
    result = _result(*_dive(np.random.default_rng(3), np.zeros(5)))
    result.info["calibration_prior"]["config_hash"] = "0123456789abcdef"
    result.config = CONFIG.to_dict()
    check = check_calibration(result)
    assert check is not None
    assert any(
        s == "note"
        and t.startswith("the calibration was made with another configuration (hash 0123")
        for s, t in check.findings
    )


def test_no_verdict_without_a_calibration_prior() -> None:
    assert check_calibration(SimpleNamespace(info={}, calibration={})) is None


@pytest.mark.slow
def test_end_to_end_a_one_percent_scale_change_is_flagged(sim_paper3d_short: LogData) -> None:
    """paper-3d-short (seed 11) smoothed with a calibration at its truth: consistent; with one whose scale is 1 %
    off the truth (a dive whose true scale moved 1 % since the file): flagged by the health, in words."""
    consistent = run_estimator(
        sim_paper3d_short, "batch", CONFIG, calibration=calibration_at_truth(sim_paper3d_short)
    )
    check = check_calibration(consistent)
    assert check is not None and not check.moved, check.findings
    health = assess_health(consistent, sim_paper3d_short)
    assert health.figures["calibration_check"]["moved"] is False
    assert any(n.startswith("consistent with auv-7's calibration") for n in health.notes), (
        health.notes
    )
    off = run_estimator(
        sim_paper3d_short,
        "batch",
        CONFIG,
        calibration=calibration_at_truth(sim_paper3d_short, scale_off=0.01),
    )
    health = assess_health(off, sim_paper3d_short)
    assert health.figures["calibration_check"]["moved"] is True
    assert any(w.startswith("DVL scale factor moved") for w in health.warnings), health.warnings
    assert health.status == "degraded"


def test_a_straight_transect_takes_its_yaw_from_the_file() -> None:
    """straight-transect (seed 5: one heading, its yaw misalignment not observable) smoothed with a calibration at
    its truth with the sigmas a paper-3d dive gives (paper-3d with this truth, seed 1, batch: scale 890 ppm,
    misalignment 0.27 / 0.045 / 0.052 deg, time offset 27 ms): the yaw within 3 sigma of the truth at the file's
    sigma, the final position within 3 sigma, the verdict consistent with the yaw "from the calibration", and no
    weak-geometry warning for the states the file gave."""
    from gtsam_dvl.analysis.metrics import summary
    from gtsam_dvl.core.calibration import VehicleCalibration
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    log = simulate(load_scenario("straight-transect"), 5)
    truth = log.true_calibration
    assert truth is not None
    sig = np.array([8.9e-4, *np.radians([0.27, 0.045, 0.052]), 0.027])
    cal = VehicleCalibration(
        "auv-7",
        "2023-11-14T00:00:00Z",
        tuple(NAMES),
        {
            "scale": np.array([truth.scale]),
            "misalignment": truth.b_R_d(log.mounting.b_R_d0),
            "time_offset": np.array([truth.time_offset_s]),
        },
        np.diag(sig**2),
    )
    result = run_estimator(
        log, "batch", EstimatorConfig.for_log(log.metadata), calibration=cal, timeline=False
    )
    s = summary(result, log)
    yaw_err, yaw_sigma = s["errors"]["misalignment_deg"][2], result.misalignment_sigma_deg[2]
    assert abs(yaw_err) < 3 * yaw_sigma and yaw_sigma == pytest.approx(0.052, rel=0.05)
    assert s["errors"]["final_horizontal_position_m"] < 3 * s["final_horizontal_position_sigma_m"]
    assert s["calibration_check"]["moved"] is False
    assert "about body z (yaw)" in s["calibration_check"]["verdict"]
    assert not any(
        "misalignment yaw" in w or "scale leans" in w for w in s["health"]["warnings"]
    ), s["health"]
