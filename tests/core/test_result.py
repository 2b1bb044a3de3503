"""The misalignment conversion (closed form) against an independent numerical derivative; the result's
calibration as a mapping of the shared states, read by the attributes of old."""

import dataclasses
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult, misalignment_rpy_and_cov
from gtsam_dvl.core.states import Estimate
from tests.support.numerical import numerical_jacobian
from tests.support.results import resting_result


def _rpy(R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_euler("ZYX")[::-1]


@pytest.mark.parametrize("seed", range(8))
def test_closed_form_matches_numerical_derivative(seed: int) -> None:
    rng = np.random.default_rng(seed)
    b_R_d0 = Rotation.from_euler("x", 180.0 * (seed % 2), degrees=True).as_matrix()
    R_c = Rotation.from_rotvec(rng.normal(size=3) * (1e-7 if seed < 2 else 0.3)).as_matrix()
    b_R_d = R_c @ b_R_d0
    A = rng.normal(size=(3, 3)) * 1e-3
    cov = A @ A.T
    rpy, cov_rpy = misalignment_rpy_and_cov(b_R_d, b_R_d0, cov)
    np.testing.assert_allclose(rpy, np.degrees(_rpy(R_c)), atol=1e-9)
    # independent: d(rpy)/d(right tangent of b_R_d) by central differences through scipy
    J = numerical_jacobian(
        lambda e: _rpy(b_R_d @ Rotation.from_rotvec(e).as_matrix() @ b_R_d0.T), [np.zeros(3)], 0
    )
    np.testing.assert_allclose(
        cov_rpy, np.degrees(np.degrees(J @ cov @ J.T)), rtol=1e-5, atol=1e-14
    )


def _result(**calibration: Any) -> NavResult:
    return resting_result(np.zeros(2), **calibration)


def test_calibration_is_a_mapping_of_the_states_and_the_old_attributes_read_it() -> None:
    """A result made from the attributes of old holds them as the states' estimates, and the other way round."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    bias_cov = A @ A.T
    b_R_d = Rotation.from_rotvec([0.01, -0.02, 0.03]).as_matrix()
    old = _result(
        accel_bias=np.array([1e-4, 2e-4, 3e-4]),
        gyro_bias=np.array([1e-6, 2e-6, 3e-6]),
        bias_cov=bias_cov,
        scale=1.002,
        scale_sigma=1e-3,
        b_R_d=b_R_d,
        b_R_d_cov=np.eye(3) * 1e-6,
        time_offset_s=0.12,
        time_offset_sigma_s=0.01,
    )
    assert list(old.calibration) == [
        "accel_bias",
        "gyro_bias",
        "scale",
        "misalignment",
        "time_offset",
    ]
    np.testing.assert_array_equal(old.calibration["gyro_bias"].cov, bias_cov[3:, 3:])
    assert (old.scale, old.scale_sigma, old.time_offset_s, old.time_offset_sigma_s) == (
        1.002,
        1e-3,
        0.12,
        0.01,
    )
    assert old.lever_arm_m is None and old.lever_arm_cov is None and old.lever_arm_sigma_m is None
    new = _result(calibration=dict(old.calibration))
    for name in (
        "accel_bias",
        "gyro_bias",
        "scale",
        "scale_sigma",
        "b_R_d",
        "b_R_d_cov",
        "time_offset_s",
        "time_offset_sigma_s",
        "misalignment_deg",
        "gyro_bias_sigma_deg_per_h",
        "accel_bias_ug",
    ):
        np.testing.assert_array_equal(getattr(new, name), getattr(old, name), err_msg=name)
    # without the calibration block's joint, the bias covariance is its two blocks; with it, the block's
    np.testing.assert_array_equal(new.bias_cov[:3, :3], bias_cov[:3, :3])
    assert not new.bias_cov[:3, 3:].any()
    joint = np.eye(10)
    joint[:6, :6] = bias_cov
    np.testing.assert_array_equal(
        dataclasses.replace(new, calib_joint_cov=joint).bias_cov, bias_cov
    )
    # not estimated: no time offset (0 s, nan sigma), no lever arm
    plain = _result(calibration={k: v for k, v in old.calibration.items() if k != "time_offset"})
    assert plain.time_offset_s == 0.0 and np.isnan(plain.time_offset_sigma_s)
    lever = dataclasses.replace(
        plain,
        info={"a": 1},
        calibration={
            **plain.calibration,
            "lever_arm": Estimate(np.array([0.1, 0.2, 0.3]), np.eye(3) * 4e-4),
        },
    )
    np.testing.assert_array_equal(lever.lever_arm_sigma_m, [0.02] * 3)
    assert lever.info == {"a": 1} and lever.scale == 1.002


def test_a_result_needs_every_required_state() -> None:
    with pytest.raises(ValueError, match="no estimate of scale"):
        _result(
            accel_bias=np.zeros(3),
            gyro_bias=np.zeros(3),
            bias_cov=np.eye(6),
            b_R_d=np.eye(3),
            b_R_d_cov=np.eye(3),
        )
    with pytest.raises(ValueError, match="scale needs both"):
        _result(scale=1.0)


def test_the_configuration_a_result_carries() -> None:
    cfg = EstimatorConfig.paper()
    res = _result(
        calibration=_result(
            scale=1.0,
            scale_sigma=0.1,
            accel_bias=np.zeros(3),
            gyro_bias=np.zeros(3),
            bias_cov=np.eye(6),
            b_R_d=np.eye(3),
            b_R_d_cov=np.eye(3),
        ).calibration
    )
    assert res.estimator_config == EstimatorConfig()  # none recorded: the defaults
    res = dataclasses.replace(res, config=cfg.to_dict())
    assert res.estimator_config == cfg
    assert dataclasses.replace(res, config={"no_such_section": {}}).estimator_config is None
