"""factors/so3.py: skew, exp, log and the right Jacobian against scipy and GTSAM, for one 3-vector and for stacks
with leading axes (the one-vector fast path gives the stacked path's numbers), small angles and angles near pi."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import so3
from tests.support.numerical import numerical_jacobians


def rotation_vectors(rng: np.random.Generator) -> np.ndarray:
    """(2, 6, 3): ordinary, small (1e-10 to 1e-5 rad) and near-pi rotation vectors."""
    u = rng.normal(size=(12, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    angles = np.array(
        [0.3, 1.0, 2.5, 1e-10, 1e-7, 1e-5, 5e-3, 0.05, np.pi - 1e-6, np.pi - 1e-3, 3.0, 0.0]
    )
    return (u * angles[:, None]).reshape(2, 6, 3)


def test_skew_and_cross() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 5, 3))
    np.testing.assert_allclose(np.einsum("nij,nj->ni", so3.skew(a), b), np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(so3.cross(a, b), np.cross(a, b), atol=1e-15)
    for q in range(5):
        np.testing.assert_array_equal(so3.skew(a[q]), so3.skew(a)[q])
        np.testing.assert_allclose(so3.cross(a[q], b[q]), np.cross(a[q], b[q]), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(so3.skew(list(a[0])), so3.skew(a[0]))
    assert so3.skew(a.reshape(5, 1, 3)).shape == (5, 1, 3, 3)
    R = Rotation.random(5, random_state=rng).as_matrix()
    np.testing.assert_allclose(so3.rotate(R, b), np.einsum("nij,nj->ni", R, b), atol=1e-15)
    np.testing.assert_allclose(so3.unrotate(R, b), np.einsum("nji,nj->ni", R, b), atol=1e-15)
    np.testing.assert_allclose(so3.unrotate(R[0], b[0]), R[0].T @ b[0], atol=1e-15)


def test_exp_and_log_are_scipys_and_gtsams() -> None:
    phi = rotation_vectors(np.random.default_rng(1))
    R = so3.exp(phi)
    assert R.shape == (2, 6, 3, 3)
    np.testing.assert_allclose(
        R,
        Rotation.from_rotvec(phi.reshape(-1, 3)).as_matrix().reshape(2, 6, 3, 3),
        rtol=0,
        atol=1e-14,
    )
    # near pi: the axis from the symmetric part
    np.testing.assert_allclose(so3.log(R), phi, rtol=0, atol=1e-8)
    for v in phi.reshape(-1, 3):
        np.testing.assert_allclose(so3.exp(v), gtsam.Rot3.Expmap(v).matrix(), rtol=0, atol=1e-14)
        np.testing.assert_allclose(so3.exp(v), so3.exp(v[None])[0], rtol=0, atol=1e-15)
        np.testing.assert_allclose(
            so3.log(so3.exp(v)), gtsam.Rot3.Logmap(gtsam.Rot3(so3.exp(v))), atol=1e-8
        )


@pytest.mark.parametrize("index", range(12))
def test_right_jacobian_and_its_inverse(index: int) -> None:
    """Exp(phi + d) = Exp(phi) Exp(J_r(phi) d) to first order, by numerical derivatives; J_r^-1 its inverse."""
    phi = rotation_vectors(np.random.default_rng(2)).reshape(-1, 3)[index]
    # J_r is singular at 2 pi; its numerical derivative loses accuracy near pi
    if np.linalg.norm(phi) > 3.0:
        phi = phi / np.linalg.norm(phi) * 2.0
    R0 = gtsam.Rot3(so3.exp(phi))
    Jn = numerical_jacobians(
        lambda d: gtsam.Rot3.Logmap(R0.between(gtsam.Rot3(so3.exp(phi + d)))), [np.zeros(3)]
    )[0]
    Jr = so3.right_jacobian(phi)
    np.testing.assert_allclose(Jr, Jn, rtol=0, atol=1e-8)
    np.testing.assert_allclose(Jr, so3.right_jacobian(phi[None])[0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(so3.inv_right_jacobian(phi) @ Jr, np.eye(3), rtol=0, atol=1e-12)
