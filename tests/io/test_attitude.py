"""The attitude reader (io/attitude.py): an IMU's own orientation or a named attitude topic turned into base_link
in map (ENU), against the simulator's truth to 1e-9, for ENU (REP-103) and NED/FRD orientations and a rotated
IMU mounting; what counts as "no orientation"; covariances kept (turned into base_link axes)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import truth_at
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, quat_xyzw_to_matrix, rpy_deg_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.attitude import ENU_R_NED, FRD_R_FLU, to_enu_flu
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

B_R_IMU = rpy_deg_to_matrix([180.0, 0.0, 90.0])  # an IMU mounted upside down and turned 90 deg
COV_IMU = np.diag([1e-4, 2e-4, 9e-4])  # rad^2 about imu_link's axes


@pytest.fixture(scope="module")
def log() -> LogData:
    """40 s at 2 m/s with a turn, the IMU's /tf_static rotation B_R_IMU (the samples are not rotated: only the
    orientation is read here)."""
    raw = dict(load_scenario("paper-3d-short").raw)
    raw["initial"] = {**raw["initial"], "speed_m_s": 2.0}
    raw["segments"] = [
        {"kind": "turn", "duration_s": 40.0, "heading_change_deg": 60.0, "bank_deg": 10.0}
    ]
    out = simulate(scenario_from_dict(raw), 1)
    return dataclasses.replace(out, mounting=dataclasses.replace(out.mounting, b_R_imu=B_R_IMU))


def _truth(log: LogData, t: np.ndarray) -> np.ndarray:
    assert log.truth is not None
    return truth_at(log.truth, t)[1]


def _ned_frd(n_R_s: np.ndarray) -> np.ndarray:
    """NED orientation of the FRD body from ENU/FLU, by components: the FRD axes are x, -y, -z of FLU, and a
    vector's NED components are (north, east, -up) of its ENU ones."""
    ax = np.stack([n_R_s[:, :, 0], -n_R_s[:, :, 1], -n_R_s[:, :, 2]], axis=2)
    return np.stack([ax[:, 1], ax[:, 0], -ax[:, 2]], axis=1)


def test_ned_conversion_formula() -> None:
    """ENU_R_flu = ENU_R_NED NED_R_frd frd_R_flu against the construction by components, and a known case:
    level, heading north in NED (yaw 0) is yaw 90 deg in ENU."""
    R = np.stack(
        [
            rpy_deg_to_matrix(a)
            for a in ([3.0, -20.0, 10.0], [170.0, 45.0, -100.0], [0.0, 89.0, 30.0])
        ]
    )
    np.testing.assert_allclose(to_enu_flu(_ned_frd(R), "ned"), R, atol=1e-12)
    np.testing.assert_allclose(
        to_enu_flu(np.eye(3)[None], "ned")[0], rpy_deg_to_matrix([0.0, 0.0, 90.0]), atol=1e-12
    )
    assert np.allclose(ENU_R_NED @ ENU_R_NED, np.eye(3)) and np.allclose(
        FRD_R_FLU @ FRD_R_FLU, np.eye(3)
    )


@pytest.mark.parametrize("frame", ["enu", "ned"])
def test_imu_orientation_to_base_link(log: LogData, tmp_path: Path, frame: str) -> None:
    n_R_imu = _truth(log, log.imu.t) @ B_R_IMU
    q = matrix_to_quat_xyzw(_ned_frd(n_R_imu) if frame == "ned" else n_R_imu)
    path = tmp_path / "imu_orientation.mcap"
    write_log(path, log, imu_orientation=(q, COV_IMU))
    back = read_log(path, attitude_frame=frame)
    att = back.attitude
    assert att is not None and att.source == "/imu/data_raw" and len(att) == len(log.imu)
    np.testing.assert_allclose(att.t, log.imu.t, atol=1e-9)
    err = np.linalg.norm(quat_xyzw_to_matrix(att.n_q_b) - _truth(log, att.t), axis=(1, 2))
    assert err.max() < 1e-9
    np.testing.assert_allclose(att.cov_rad2[0], B_R_IMU @ COV_IMU @ B_R_IMU.T, atol=1e-15)
    # the same messages read with the wrong convention are far off (the option matters)
    wrong = read_log(path, attitude_frame="enu" if frame == "ned" else "ned").attitude
    assert (
        wrong is not None
        and np.linalg.norm(quat_xyzw_to_matrix(wrong.n_q_b[0]) - _truth(log, att.t[:1])[0]) > 0.5
    )


def test_no_orientation(log: LogData, tmp_path: Path) -> None:
    """orientation_covariance[0] = -1 (the writer's default), or a zero quaternion: no attitude; an all-zero
    covariance: orientation kept, covariance unknown (NaN); "none" reads none."""
    path = tmp_path / "plain.mcap"
    write_log(path, log)
    assert read_log(path).attitude is None
    q = matrix_to_quat_xyzw(_truth(log, log.imu.t) @ B_R_IMU)
    q[:10] = 0.0
    write_log(path, log, imu_orientation=(q, None))
    att = read_log(path).attitude
    assert att is not None and len(att) == len(log.imu) - 10 and np.isnan(att.cov_rad2).all()
    assert any("without orientation" in w for w in read_log(path).metadata["reader_warnings"])
    assert read_log(path, attitude_topic="none").attitude is None
    with pytest.raises(GtsamDvlError, match="attitude_frame must be one of enu, ned"):
        read_log(path, attitude_frame="nwu")


def test_odometry_attitude_topic(log: LogData, tmp_path: Path) -> None:
    """A nav_msgs/msg/Odometry topic (child frame base_link): the ground truth topic read as the attitude."""
    path = tmp_path / "odom.mcap"
    write_log(path, log)
    att = read_log(path, attitude_topic="/ground_truth/odometry").attitude
    assert att is not None and att.source == "/ground_truth/odometry" and log.truth is not None
    assert len(att) == len(log.truth)
    err = np.linalg.norm(quat_xyzw_to_matrix(att.n_q_b) - _truth(log, att.t), axis=(1, 2))
    assert err.max() < 1e-9
    with pytest.raises(GtsamDvlError, match="attitude topics must be one of"):
        read_log(path, attitude_topic="/dvl/twist")
