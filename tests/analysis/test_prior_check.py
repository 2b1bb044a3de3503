"""The posterior against the prior (analysis/prior_check.py, in analysis/health.py): a DVL mounting in /tf_static
off by 25 deg in yaw makes every mode "failed" naming the misalignment; the same log with the right mounting stays
"ok"; each state far from its prior names its likely cause; the filters' time-offset window held at the prior's
bound is counted and reported."""

from __future__ import annotations

import copy
import dataclasses
import re
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.health import assess_health
from gtsam_dvl.analysis.prior_check import PRIOR_NSIGMA_FAILED, check_priors
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.states import Estimate
from gtsam_dvl.core.types import DvlData, ImuData, LogData, Mounting
from gtsam_dvl.core.units import DEG_PER_H
from gtsam_dvl.estimators.run import run_estimator
from tests.support.results import resting_result
from tests.support.scenarios import scenario_raw, simulate_variant

MODES = ("batch", "online", "ekf")
WRONG_YAW_DEG = 25.0


def _short_segments() -> list[dict[str, Any]]:
    """paper-3d-short's manoeuvres with a 60 s static start and two sides of its square (540 s)."""
    segments: list[dict[str, Any]] = copy.deepcopy(scenario_raw()["segments"])
    for seg in segments:
        if seg["kind"] == "static":
            seg["duration_s"] = 60.0
        if seg["kind"] == "square":
            seg["sides"] = 2
    return segments


@pytest.fixture(scope="module")
def clean() -> LogData:
    return simulate_variant(3, segments=_short_segments())


@pytest.fixture(scope="module")
def mounted_wrong(clean: LogData) -> LogData:
    """The same data with /tf_static's DVL mounting turned by 25 deg about body z (the data keep the true one)."""
    b_R_d0 = rpy_deg_to_matrix([0.0, 0.0, WRONG_YAW_DEG]) @ clean.mounting.b_R_d0
    return dataclasses.replace(clean, mounting=dataclasses.replace(clean.mounting, b_R_d0=b_R_d0))


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_wrong_mounting_fails_naming_the_misalignment(mode: str, mounted_wrong: LogData) -> None:
    health = assess_health(run_estimator(mounted_wrong, mode, None), mounted_wrong)
    print(mode, health.lines())
    assert health.status == "failed"
    named = [w for w in health.warnings if w.startswith("DVL misalignment about body z (yaw) is ")]
    assert len(named) == 1 and "the DVL mounting in /tf_static" in named[0]
    off = float(re.search(r"is off by ([0-9.]+) deg", named[0]).group(1))  # type: ignore[union-attr]
    # the true misalignment (0.5 deg in yaw) on top of the wrong mounting
    assert abs(off - WRONG_YAW_DEG) < 1.5
    nsigma = health.figures["prior_nsigma"]["misalignment"]["nsigma"]
    assert abs(nsigma[2]) > 20 and max(abs(nsigma[0]), abs(nsigma[1])) < PRIOR_NSIGMA_FAILED


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_clean_log_stays_ok(mode: str, clean: LogData) -> None:
    health = assess_health(run_estimator(clean, mode, None), clean)
    print(mode, health.lines(), health.figures["prior_nsigma"])
    assert health.status == "ok", health.warnings
    for d in health.figures["prior_nsigma"].values():
        assert np.all(np.abs(d["nsigma"]) < PRIOR_NSIGMA_FAILED)


def _tiny(calibration: dict[str, Estimate]) -> tuple[NavResult, LogData]:
    """A two-state result with the given shared states, and a log whose IMU turned at 40 deg/s at most."""
    n = 2
    result = resting_result(np.arange(n, dtype=float), calibration=calibration)
    w = np.zeros((3, 3))
    w[1, 2] = np.radians(40.0)
    log = LogData(
        imu=ImuData(t=np.arange(3.0), b_omega=w, b_f=np.zeros((3, 3))),
        dvl=DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, bool)),
        mounting=Mounting(),
    )
    return result, log


def test_each_state_far_from_its_prior_names_its_cause() -> None:
    """Per state: within 4 prior sigmas nothing; beyond, "failed" with the distance and the cause."""
    # scale 1 +- 1 %, misalignment 1 deg, gyro bias 0.01 deg/h, offset 0 +- 0.5 s
    config = EstimatorConfig()
    small = 1e-12 * np.eye(3)

    def states(
        scale: float = 1.0, gyro_z_deg_h: float = 0.0, offset_s: float = 0.0, yaw_deg: float = 0.0
    ) -> dict[str, Estimate]:
        return {
            "accel_bias": Estimate(np.zeros(3), small),
            "gyro_bias": Estimate(np.array([0.0, 0.0, gyro_z_deg_h * DEG_PER_H]), small),
            "scale": Estimate(np.array([scale]), small[:1, :1]),
            "misalignment": Estimate(rpy_deg_to_matrix([0.0, 0.0, yaw_deg]), small),
            "time_offset": Estimate(np.array([offset_s]), small[:1, :1]),
        }

    near = check_priors(*_tiny(states(1.035, 0.035, -1.7, 3.5)), config)
    assert near.findings == []
    assert near.distances["scale"].z[0] == pytest.approx(3.5)
    assert near.distances["misalignment"].z == pytest.approx([0.0, 0.0, 3.5])
    assert near.distances["time_offset"].z[0] == pytest.approx(-3.4)
    far = check_priors(*_tiny(states(1.05, -0.06, 2.5, -30.0)), config)
    text = {t.split(" is ")[0]: t for _, t in far.findings}
    assert all(severity == "failed" for severity, _ in far.findings) and len(far.findings) == 4
    assert (
        "5.0 prior sigmas" in text["DVL scale factor"] and "sound-speed" in text["DVL scale factor"]
    )
    assert "IMU saturation?" in text["DVL scale factor"]
    gyro = text["gyro bias about body z (up, vertical)"]
    assert "6.0 prior sigmas" in gyro and "IMU saturation?" in gyro
    assert "peak body rate in this log is 40.0 deg/s" in gyro
    assert (
        "time offset is beyond its prior (the DVL stamps early by 2.500 s)"
        in text["DVL-IMU time offset"]
    )
    yaw = text["DVL misalignment about body z (yaw)"]
    assert (
        "30.0 prior sigmas" in yaw
        and "/tf_static (base_link -> dvl_link) is off by 30.0 deg" in yaw
    )


@pytest.mark.slow
@pytest.mark.parametrize("mode", MODES)
def test_time_offset_beyond_its_prior_is_reported(mode: str) -> None:
    """DVL stamps 0.3 s off with a 0.05 s prior sigma (6 sigma): every mode fails naming the time offset; the
    filters, which centre their offset model's IMU windows on the estimate within the prior +- 3 sigma, say how
    many pings they held at that bound."""
    log = simulate_variant(3, segments=_short_segments(), rates={"dvl_time_offset_s": 0.3})
    config = EstimatorConfig.named("paper")
    config.dvl.estimate_time_offset = True
    config.dvl.time_offset_sigma_s = 0.05
    result = run_estimator(log, mode, config)
    health = assess_health(result, log)
    print(mode, result.time_offset_s, result.info["counters"], health.lines())
    assert health.status == "failed"
    assert any(
        w.startswith("DVL-IMU time offset is ") and "beyond its prior" in w for w in health.warnings
    )
    clipped = result.info["counters"].get("time_offset_window_clipped", 0)
    assert health.figures["counters"]["time_offset_window_clipped"] == clipped
    if mode == "batch":  # its windows are centred on its first estimate, unbounded
        assert clipped == 0
    # the EKF holds the offset state itself at the bound: its windows never pass it
    elif mode == "ekf":
        bounded = result.info["counters"]["time_offset_bounded"]
        assert bounded > 0 and clipped == 0
        assert any(
            w.startswith("DVL-IMU time offset is held at its bound")
            and f"after {bounded} ping(s)" in w
            for w in health.warnings
        )
    else:
        assert clipped > 0
        assert any(
            f"held at that bound for {clipped} ping(s), to the end" in w for w in health.warnings
        )


def test_forward_accel_bias_on_a_straight_run_names_the_pitch_coupling() -> None:
    """A forward accelerometer bias 5 prior sigmas off: on a straight run (one heading) a "degraded" warning that
    names the pitch coupling and the pitch it is worth (1 micro-g = 1e-6 rad); the lateral axis and a run that
    turns 90 deg stay "failed"."""
    from gtsam_dvl.core.units import UG

    config = EstimatorConfig()
    sigma_ug = config.imu.accel_bias_sigma_ug
    small = 1e-12 * np.eye(3)

    def result(axis: int, heading_deg: float) -> tuple[NavResult, LogData]:
        b = np.zeros(3)
        b[axis] = 5.0 * sigma_ug * UG
        r, log = _tiny(
            {
                "accel_bias": Estimate(b, small),
                "gyro_bias": Estimate(np.zeros(3), small),
                "scale": Estimate(np.ones(1), small[:1, :1]),
                "misalignment": Estimate(np.eye(3), small),
                "time_offset": Estimate(np.zeros(1), small[:1, :1]),
            }
        )
        a = np.radians(heading_deg)
        r.n_R_b[1] = np.array(
            [[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]]
        )
        return r, log

    straight = check_priors(*result(0, 0.0), config).findings
    assert len(straight) == 1 and straight[0][0] == "degraded"
    assert "trades against the pitch" in straight[0][1] and "5.0 prior sigmas" in straight[0][1]
    assert f"{np.degrees(5.0 * sigma_ug * 1e-6):+.3f} deg" in straight[0][1]
    lateral = check_priors(*result(1, 0.0), config).findings
    assert len(lateral) == 1 and lateral[0][0] == "failed"
    turning = check_priors(*result(0, 90.0), config).findings
    assert len(turning) == 1 and turning[0][0] == "failed"
