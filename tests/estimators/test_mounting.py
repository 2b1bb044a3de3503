"""The IMU's mounting from /tf_static is honoured by every estimator (estimators/inputs/mounting.py): an IMU mounted
rolled 180 deg about x (and yawed 90 deg), with the matching tf, gives the calibration of the unrotated one."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.inputs.mounting import imu_in_base_link, rotate_imu_samples
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log

b_R_IMU = rpy_deg_to_matrix([180.0, 0.0, 90.0])


def _rotated(log: LogData) -> LogData:
    """The same motion measured by an IMU whose axes are b_R_imu from base_link: imu_x = b_R_imu^T b_x."""
    imu = dataclasses.replace(log.imu, b_omega=log.imu.b_omega @ b_R_IMU, b_f=log.imu.b_f @ b_R_IMU)
    mounting = dataclasses.replace(log.mounting, b_R_imu=b_R_IMU.copy())
    return dataclasses.replace(log, imu=imu, mounting=mounting)


def test_rotation_is_undone_exactly(sim_paper2d_clean: LogData) -> None:
    rot = _rotated(sim_paper2d_clean)
    back = imu_in_base_link(rot.imu, rot.mounting)
    np.testing.assert_allclose(back.b_f, sim_paper2d_clean.imu.b_f, rtol=0, atol=1e-12)
    # to rounding: rates up to 0.056 rad/s through two products with a 3x3 matrix (BLAS), whose kernels may round a
    # sum of three products differently by an ulp (7e-18 there); a wrong axis or sign moves them by the rates
    np.testing.assert_allclose(back.b_omega, sim_paper2d_clean.imu.b_omega, rtol=0, atol=1e-15)
    assert (
        imu_in_base_link(sim_paper2d_clean.imu, sim_paper2d_clean.mounting) is sim_paper2d_clean.imu
    )
    w, f = rotate_imu_samples(b_R_IMU, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    # imu z is base_link -z (rolled 180 deg)
    np.testing.assert_allclose(w, [[0.0, 0.0, -1.0]], atol=1e-15)
    # imu x is base_link +y: Rz(90) Rx(180) x = y
    np.testing.assert_allclose(f, [[0.0, 1.0, 0.0]], atol=1e-15)


@pytest.fixture(scope="module")
def batch_reference(sim_paper2d_clean: LogData) -> NavResult:
    """The batch smoother on the unrotated log with the paper configuration (both batch checks compare to it)."""
    return smooth_batch(sim_paper2d_clean, EstimatorConfig.paper())


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["batch", "online", "ekf"])
def test_rotated_imu_with_its_tf_gives_the_same_calibration(
    sim_paper2d_clean: LogData, tmp_path: Path, estimator: str, request: pytest.FixtureRequest
) -> None:
    """Through a written and read log, so the tf is the reader's: same scale and misalignment to 1e-3 sigma."""
    path = tmp_path / "rotated.mcap"
    write_log(path, _rotated(sim_paper2d_clean))
    rotated = read_log(path)
    np.testing.assert_allclose(rotated.mounting.b_R_imu, b_R_IMU, atol=1e-12)
    run = {"batch": smooth_batch, "online": smooth_online, "ekf": run_ekf}[estimator]
    cfg = EstimatorConfig.paper()
    ref = (
        request.getfixturevalue("batch_reference")
        if estimator == "batch"
        else run(sim_paper2d_clean, cfg)
    )
    got = run(rotated, cfg)
    print(
        f"{estimator}: scale {ref.scale:.7f} / {got.scale:.7f}, misalignment {ref.misalignment_deg} / "
        f"{got.misalignment_deg} deg"
    )
    assert abs(got.scale - ref.scale) < 1e-3 * ref.scale_sigma
    assert np.all(
        np.abs(got.misalignment_deg - ref.misalignment_deg) < 1e-3 * ref.misalignment_sigma_deg
    )
    np.testing.assert_allclose(got.n_p[-1], ref.n_p[-1], atol=1e-3)


@pytest.mark.slow
def test_rotated_imu_without_its_tf_is_wrong(
    sim_paper2d_clean: LogData, batch_reference: NavResult
) -> None:
    """The check can fail: ignoring the mounting (identity tf) gives a misalignment wrong by far more than its
    sigma (what happened before the mounting was applied: 168 deg), or a clear error."""
    wrong = dataclasses.replace(_rotated(sim_paper2d_clean), mounting=sim_paper2d_clean.mounting)
    ref = batch_reference
    try:
        res = smooth_batch(wrong, EstimatorConfig.paper())
    except GtsamDvlError as exc:
        print(f"identity tf: {exc}")
        return
    err = np.abs(res.misalignment_deg - ref.misalignment_deg)
    print(f"identity tf: misalignment {res.misalignment_deg} deg vs {ref.misalignment_deg} deg")
    assert np.max(err / ref.misalignment_sigma_deg) > 100
