"""The initial attitude without a static start (estimators/inputs/alignment.py): in-motion alignment with DVL aiding,
and an attitude sensor (the IMU messages' own orientation), on a simulated paper-3d-short run that starts at
2 m/s (no static segment, no acceleration from rest: level surge, descent, surge, the square's turns, ascent).

Measured in-motion alignment errors (seed 7, navigation grade: 0.01 deg/h, 50 micro-g, 2 cm/s DVL, latitude
30 deg; error / 1-sigma of Alignment.sigma_rpy_deg, about east, north, up):
    60 s:  roll/pitch 0.0005 / 0.007 deg (sigma 0.004 / 0.003); heading -2.1 deg (sigma 1.6)
    120 s: roll/pitch 0.003 / 0.006 deg (sigma 0.003);         heading -0.26 deg (sigma 0.32)
    300 s: roll/pitch 0.002 / 0.002 deg (sigma 0.005 / 0.002); heading -0.36 deg (sigma 0.41)
(seeds 8 and 9: heading 0.28 / 0.12 / -0.28 and 1.5 / 0.45 / -0.15 deg). Heading is set by the DVL noise
for short windows (1.6 deg at 60 s) and by the accelerometer bias seen through the turns for long ones
(0.4 deg at 300 s); roll and pitch to a few millidegrees. Both are far inside what the graph needs.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import attitude_errors_deg, truth_at
from gtsam_dvl.core.config import AlignmentConfig, EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, so3_exp
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.inputs.alignment import align, in_motion_alignment, map_frame_of
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

SEED = 7
ATT_SIGMA_DEG = 0.2  # noise of the simulated IMU orientation (per axis, body axes)


def moving_raw() -> dict:
    """paper-3d-short without its static start and its 0 -> 2 m/s acceleration: it starts at 2 m/s."""
    raw = dict(load_scenario("paper-3d-short").raw)
    raw["initial"] = {**raw["initial"], "speed_m_s": 2.0}
    raw["segments"] = [
        s
        for s in raw["segments"]
        if s["kind"] != "static" and not (s["kind"] == "level" and s.get("speed_end_m_s") == 2.0)
    ]
    return raw


@pytest.fixture(scope="module")
def moving_log() -> LogData:
    return simulate(scenario_from_dict(moving_raw()), SEED)


def _config(**alignment: object) -> EstimatorConfig:
    cfg = EstimatorConfig.paper()
    return cfg.model_copy(update={"alignment": cfg.alignment.model_copy(update=alignment)})


def _true_R(log: LogData, t: float) -> np.ndarray:
    assert log.truth is not None
    return np.asarray(truth_at(log.truth, np.array([t]))[1][0])


@pytest.mark.parametrize("window_s", [60.0, 120.0, 300.0])
def test_in_motion_alignment_within_3_sigma(moving_log: LogData, window_s: float) -> None:
    """The in-motion alignment's attitude at the first IMU sample against the truth, within 3 of its sigmas."""
    log = moving_log
    assert log.truth is not None and np.linalg.norm(log.truth.n_v[0]) == pytest.approx(
        2.0, abs=0.01
    )
    frame = map_frame_of(log, EstimatorConfig.paper())
    a = in_motion_alignment(
        log.imu, log.dvl, frame, log.mounting, window_s, EstimatorConfig.paper().imu
    )
    err = attitude_errors_deg(a.n_R_b[None], _true_R(log, float(log.imu.t[0]))[None])[0]
    assert (
        a.method == "in_motion"
        and a.t_ref == log.imu.t[0]
        and a.window_s == pytest.approx(window_s)
    )
    assert a.sigma_rpy_deg is not None
    print(
        f"window {window_s:.0f} s: error {np.round(err, 4)} deg, sigma {np.round(a.sigma_rpy_deg, 4)} deg"
    )
    assert np.all(np.abs(err) < 3.0 * a.sigma_rpy_deg)
    # a few degrees is all the graph needs
    assert np.all(a.sigma_rpy_deg[:2] < 0.05) and a.sigma_rpy_deg[2] < 2.0


def test_alignment_carried_to_the_first_state(moving_log: LogData) -> None:
    """Alignment.at carries the in-motion attitude with the gyros: 100 s later it still matches the truth."""
    log = moving_log
    frame = map_frame_of(log, EstimatorConfig.paper())
    a = in_motion_alignment(log.imu, log.dvl, frame, log.mounting, 120.0)
    R0 = _true_R(log, float(log.imu.t[0]))
    for t in (1.0, 100.0):
        b = a.at(t, log.imu, frame)
        # the truth carried the same way: exact apart from the gyro noise and bias (1e-4 deg over 100 s)
        moved = attitude_errors_deg(b.n_R_b[None], _true_R(log, t)[None])[0]
        start = attitude_errors_deg(a.n_R_b[None], R0[None])[0]
        assert b.t_ref == t and np.all(np.abs(moved - start) < 0.01)
    assert np.allclose(
        a.at(100.0, log.imu, frame).at(0.0, log.imu, frame).n_R_b, a.n_R_b, atol=1e-12
    )


def _check_run(r: NavResult, log: LogData) -> None:
    tc, tb = log.true_calibration, log.true_imu_bias
    assert tc is not None and tb is not None and log.truth is not None
    mis = (r.misalignment_deg - np.array(tc.misalignment_deg)) / r.misalignment_sigma_deg
    scale = (r.scale - tc.scale) / r.scale_sigma
    j = int(np.argmin(np.abs(log.truth.t - r.t[-1])))
    pos = (r.n_p[-1] - log.truth.n_p[j]) / np.sqrt(np.diag(r.pose_cov[-1][3:, 3:]))
    print(
        f"{r.alignment_method}: scale {scale:+.2f} sigma, misalignment {np.round(mis, 2)} sigma, "
        f"final position {np.round(r.n_p[-1] - log.truth.n_p[j], 3)} m ({np.round(pos, 2)} sigma)"
    )
    assert abs(scale) < 3.0 and np.all(np.abs(mis) < 3.0) and np.all(np.abs(pos) < 3.0)


@pytest.fixture(scope="module")
def in_motion_result(moving_log: LogData) -> NavResult:
    return smooth_batch(moving_log, _config(in_motion_window_s=120.0))


def test_batch_with_in_motion_alignment(moving_log: LogData, in_motion_result: NavResult) -> None:
    """No static start and no attitude given: "auto" aligns in motion, the prior takes the alignment's sigmas,
    and the calibration and the final position come out within 3 sigma of the truth."""
    r = in_motion_result
    assert r.alignment_method == "in_motion" and r.info["alignment"]["method"] == "in_motion"
    sig = r.info["alignment"]["sigma_rpy_deg"]
    assert sig is not None and sig[2] < 1.0
    _check_run(r, moving_log)


def _with_imu_orientation(log: LogData, path: Path, ned: bool) -> None:
    """Write the log with the truth attitude of imu_link (plus ATT_SIGMA_DEG noise) in the IMU messages."""
    rng = np.random.default_rng(3)
    assert log.truth is not None
    n_R_b = truth_at(log.truth, log.imu.t)[1]
    noise = so3_exp(np.radians(ATT_SIGMA_DEG) * rng.standard_normal((len(log.imu.t), 3)))
    n_R_imu = n_R_b @ noise @ log.mounting.b_R_imu
    if ned:  # NED orientation of the FRD body, built from the axes' components (not the reader's formula)
        # FRD axes in ENU
        ax = np.stack([n_R_imu[:, :, 0], -n_R_imu[:, :, 1], -n_R_imu[:, :, 2]], axis=2)
        n_R_imu = np.stack([ax[:, 1], ax[:, 0], -ax[:, 2]], axis=1)  # rows: north, east, down
    cov = np.eye(3) * np.radians(ATT_SIGMA_DEG) ** 2
    write_log(path, log, imu_orientation=(matrix_to_quat_xyzw(n_R_imu), cov))


@pytest.mark.parametrize("ned", [False, True])
def test_batch_with_imu_orientation(moving_log: LogData, tmp_path: Path, ned: bool) -> None:
    """The IMU messages carry an orientation (ENU, or NED of an FRD body): the log is read with it and the batch
    smoother starts from its first sample, with its covariance as the prior."""
    path = tmp_path / "ahrs.mcap"
    _with_imu_orientation(moving_log, path, ned)
    log = read_log(path, attitude_frame="ned" if ned else "enu")
    assert log.attitude is not None and len(log.attitude) == len(log.imu)
    a = align(
        log.imu,
        log.dvl,
        map_frame_of(log, EstimatorConfig.paper()),
        AlignmentConfig(),
        attitude=log.attitude,
    )
    assert a.method == "attitude_topic" and a.sigma_rpy_deg is not None
    np.testing.assert_allclose(a.sigma_rpy_deg, ATT_SIGMA_DEG, rtol=1e-9)
    err = attitude_errors_deg(a.n_R_b[None], _true_R(moving_log, float(a.t_ref or 0.0))[None])[0]
    assert np.all(np.abs(err) < 3.0 * ATT_SIGMA_DEG)
    if not ned:
        r = smooth_batch(log, _config())
        assert r.alignment_method == "attitude_topic"
        _check_run(r, log)


def test_forced_static_needs_an_attitude_source(moving_log: LogData) -> None:
    """Forced methods that cannot be done are errors naming what to give (the online estimator's start in motion:
    tests/estimators/test_online_alignment.py)."""
    frame = map_frame_of(moving_log, EstimatorConfig.paper())
    with pytest.raises(
        GtsamDvlError, match=r"no static segment.*attitude topic.*initial_attitude_deg"
    ):
        align(moving_log.imu, moving_log.dvl, frame, AlignmentConfig(method="static"))
    with pytest.raises(GtsamDvlError, match=r"has no attitude.*--attitude-topic"):
        align(moving_log.imu, moving_log.dvl, frame, AlignmentConfig(method="attitude_topic"))
    # a gyro bias of 200 deg/h: no gyrocompassing
    short = dataclasses.replace(
        moving_log, imu=dataclasses.replace(moving_log.imu, b_omega=moving_log.imu.b_omega + 1e-3)
    )
    with pytest.raises(GtsamDvlError, match=r"heading only to .* deg.*attitude topic"):
        align(short.imu, short.dvl, frame, AlignmentConfig(), mounting=short.mounting)


def test_static_start_keeps_the_prior_sigmas() -> None:
    """A static start aligns from the static phase: no sigmas of its own, so the graph's prior keeps [priors]."""
    log = simulate(load_scenario("paper-3d-short"), SEED)
    a = align(log.imu, log.dvl, map_frame_of(log, EstimatorConfig.paper()), AlignmentConfig())
    assert a.method == "static" and a.sigma_rpy_deg is None and a.t_ref is None
    assert a.at(50.0, log.imu, map_frame_of(log, EstimatorConfig.paper())) is a
