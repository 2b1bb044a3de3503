"""The DVL's constant error as a consider term of the calibration's covariance (estimators/models/constant_error.py):
its response against the model's own first-order algebra and scipy's rotations, the covariance it adds, none along
held directions; over seeds of realistic-turns the calibration's error/sigma with it (a slow test)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.estimators.models.constant_error import consider_constant_error, response
from tests.support.results import nominal_estimates

WIDE = np.diag([1.0, 1.0, 1.0, 1.0])  # a prior that takes nothing: the data's response alone


def test_straight_ahead_response_is_the_ratio_to_the_speed() -> None:
    """Forward at v along the DVL's x: dk = b_x / v, pitch b_z / v, yaw -b_y / v, roll nothing (worked by hand
    from k d_R_b u + b = (k + dk) d_R_b u + k [w]_x dtheta)."""
    v = 1.9
    b_v = np.tile([v, 0.0, 0.0], (50, 1))
    S = response(b_v, 1.0, np.eye(3), 0.02, WIDE)
    b = np.array([0.002, -0.001, 0.003])
    np.testing.assert_allclose(S @ b, [b[0] / v, 0.0, b[2] / v, -b[1] / v], atol=1e-7)


def test_response_moves_the_model_by_the_constant_error() -> None:
    """Over a log of varied velocities at a misaligned mounting, the calibration moved by S b reproduces k d_R_b u
    + b in the least-squares sense: S b is numpy's lstsq of b on the model's columns, and the residual of the
    moved model (scipy's rotations) against the pings with b is that fit's, well below the calibration left's."""
    rng = np.random.default_rng(3)
    b_v = np.c_[rng.uniform(0.5, 2.0, 200), rng.normal(0, 0.3, 200), rng.normal(0, 0.2, 200)]
    b_R_d = Rotation.from_euler("xyz", [180.0, 1.0, 45.0], degrees=True).as_matrix()
    k = 1.004
    b = np.array([0.003, -0.002, 0.004])
    S = response(b_v, k, b_R_d, 0.02, WIDE)
    dx = S @ b
    # (b_R_d exp(dtheta))^T u
    moved = (k + dx[0]) * b_v @ (b_R_d @ Rotation.from_rotvec(dx[1:]).as_matrix())
    pings = k * b_v @ b_R_d + b
    left = k * b_v @ b_R_d
    r_moved, r_left = np.linalg.norm(pings - moved), np.linalg.norm(pings - left)
    # the linear least-squares residual of b on the model's columns, computed apart with lstsq
    w = b_v @ b_R_d
    A = np.concatenate(
        [w[:, :, None], np.stack([k * np.cross(w, e) for e in np.eye(3)], axis=2)], axis=2
    )
    x, *_ = np.linalg.lstsq(A.reshape(-1, 4), np.tile(b, len(w)), rcond=None)
    np.testing.assert_allclose(dx, x, rtol=1e-3, atol=1e-9)
    r_linear = np.linalg.norm(np.tile(b, len(w)) - A.reshape(-1, 4) @ x)
    assert r_moved == pytest.approx(r_linear, rel=0.01) and r_moved < 0.5 * r_left


def _result(held: object = None) -> NavResult:
    n = 20
    t = np.arange(n, dtype=float)
    n_R_b = np.repeat(np.eye(3)[None], n, axis=0)
    n_v = np.tile([1.5, 0.0, 0.0], (n, 1))
    cov = np.zeros((n, 6, 6)) + np.eye(6) * 1e-4
    joint = np.eye(10) * 1e-8
    r = NavResult(
        "batch",
        t,
        np.zeros((n, 3)),
        n_R_b,
        n_v,
        cov,
        np.repeat(np.eye(3)[None] * 1e-4, n, axis=0),
        b_R_d0=np.eye(3),
        **nominal_estimates(bias_var=1e-8),
        calib_joint_cov=joint.copy(),
        shared_joint_cov=joint.copy(),
    )
    if held is not None:
        r.info["calibration_hold"] = held
    return r


def test_added_covariance_and_held_directions() -> None:
    config = EstimatorConfig()
    sigma_b, v = config.dvl.constant_error_sigma_m_s, 1.5
    r = _result()
    consider_constant_error(r, config)
    # one direction at a time (forward motion decouples them): the regression's gain N v / s_w^2 over its
    # information N v^2 / s_w^2 + 1 / s_0^2, worked by hand for the 20 states at 1.5 m/s
    n, s_w = 20, config.dvl.default_noise_m_s

    def added(s_0: float) -> float:
        return sigma_b * (n * v / s_w**2) / (n * v**2 / s_w**2 + 1.0 / s_0**2)

    want = np.sqrt(1e-8 + added(config.priors.scale_sigma) ** 2)
    want_yaw = np.sqrt(1e-8 + added(np.radians(config.priors.misalignment_sigma_deg[2])) ** 2)
    assert r.scale_sigma == pytest.approx(want, rel=1e-3)
    # roll: not excited
    assert r.misalignment_sigma_deg[0] == pytest.approx(np.degrees(1e-4), rel=1e-3)
    assert np.sqrt(r.b_R_d_cov[2, 2]) == pytest.approx(want_yaw, rel=1e-3)
    assert r.calib_joint_cov[6, 6] == pytest.approx(want**2, rel=1e-3)
    assert r.shared_joint_cov[8, 8] == pytest.approx(r.b_R_d_cov[1, 1])
    assert r.info["dvl_constant_error"]["sigma_m_s"] == sigma_b
    # held at the nominal: nothing added
    nominal = _result({"nominal": {"pays": False}, "held": []})
    consider_constant_error(nominal, config)
    assert nominal.scale_sigma == pytest.approx(1e-4)
    # the yaw held (a weak direction): the scale takes its share, the yaw none
    yaw = _result(
        {
            "held": [
                {
                    "direction": {
                        "scale": 0.0,
                        "misalignment roll": 0.0,
                        "misalignment pitch": 0.0,
                        "misalignment yaw": 1.0,
                    }
                }
            ]
        }
    )
    consider_constant_error(yaw, config)
    assert yaw.scale_sigma == pytest.approx(want, rel=1e-3)
    assert np.sqrt(yaw.b_R_d_cov[2, 2]) == pytest.approx(1e-4, rel=1e-6)
    off = EstimatorConfig.paper()
    assert off.dvl.constant_error_sigma_m_s == 0.0
    r0 = _result()
    consider_constant_error(r0, off)
    assert r0.scale_sigma == pytest.approx(1e-4) and "dvl_constant_error" not in r0.info
