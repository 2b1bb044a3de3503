"""The misalignment conversion (closed form) against an independent numerical derivative."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.result import misalignment_rpy_and_cov
from tests.support.numerical import numerical_jacobian


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
    J = numerical_jacobian(lambda e: _rpy(b_R_d @ Rotation.from_rotvec(e).as_matrix() @ b_R_d0.T), [np.zeros(3)], 0)
    np.testing.assert_allclose(cov_rpy, np.degrees(np.degrees(J @ cov @ J.T)), rtol=1e-5, atol=1e-14)
