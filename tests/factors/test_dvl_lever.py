"""The DVL factors with the lever arm b_l (m, base_link) a variable (factors/dvl_velocity.py *_lever,
factors/dvl_beam_lever.py), GTSAM style: at a given b_l each variant equals its known-lever-arm factor, and
every Jacobian (pose, velocity, scale, misalignment, time offset, lever arm) matches central differences on
the manifold at random states, including near-identity rotations and a 180 deg roll mounting; the
linearised CustomFactor gives the same blocks.

    y = k b_R_d^T (n_R_b^T n_v + b_omega x b_l),   de/d(b_l) = k b_R_d^T [b_omega]_x
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, K, L, T, V, X
from gtsam.utils import numerical_derivative as nd
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import (
    dvl_beam_error,
    dvl_beam_lever_error,
    dvl_velocity_error,
    dvl_velocity_lever_error,
    dvl_velocity_offset_error,
    dvl_velocity_offset_lever_error,
    make_dvl_beam_lever_factor,
    make_dvl_velocity_lever_factor,
    make_dvl_velocity_offset_lever_factor,
)

N_G = np.array([0.0, 0.0, -9.79])
CASES = [(kind, seed) for kind in ("random", "near_identity", "roll_180") for seed in range(3)]


def _state(kind: str, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng(100 + seed)
    n_R_b = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    b_R_d = Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix()
    if kind == "near_identity":
        n_R_b = Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
        b_R_d = Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
    if kind == "roll_180":
        b_R_d = b_R_d @ np.diag([1.0, -1.0, -1.0])
    d_u = rng.normal(size=3)
    return {"pose": gtsam.Pose3(gtsam.Rot3(n_R_b), rng.normal(size=3) * 10), "n_v": rng.normal(size=3) * 2,
            "k": np.array([1.0 + 0.01 * rng.normal()]), "rot": gtsam.Rot3(b_R_d),
            "dt": np.array([rng.uniform(-1.5, 1.5)]), "b_l": rng.normal(size=3),
            "b_omega": 0.1 * rng.normal(size=3), "b_a": 0.2 * rng.normal(size=3) + n_R_b.T @ -N_G,
            "G": Rotation.from_rotvec(0.02 * rng.normal(size=3)).as_matrix(), "d_u": d_u / np.linalg.norm(d_u)}


def _numerical(h: Callable[..., np.ndarray], point: tuple[Any, ...]) -> list[np.ndarray]:
    """Central differences of h on the manifold (GTSAM's numericalDerivativeNM), one block per argument."""
    n = len(point)
    return [getattr(nd, f"numericalDerivative{n}{i + 1}")(h, *point) for i in range(n)]


def _check(H: list[Any], numerical: list[np.ndarray]) -> None:
    for i, (J, Jn) in enumerate(zip(H, numerical, strict=True)):
        assert J.shape == Jn.shape, f"block {i}"
        scale = max(1.0, float(np.max(np.abs(Jn))))
        np.testing.assert_allclose(J, Jn, rtol=0.0, atol=1e-7 * scale, err_msg=f"block {i}")


def _check_linearize(factor: gtsam.CustomFactor, point: tuple[Any, ...], e: np.ndarray, H: list[Any]) -> None:
    values = gtsam.Values()
    for key, x in zip(factor.keys(), point, strict=True):
        values.insert(key, x)
    A, b = factor.linearize(values).jacobian()
    np.testing.assert_allclose(b, -e, atol=1e-12)
    dims = np.cumsum([J.shape[1] for J in H])[:-1]
    for i, J in enumerate(np.split(A, dims, axis=1)):
        np.testing.assert_allclose(J, H[i], atol=1e-12, err_msg=f"linearize block {i}")


@pytest.mark.parametrize("kind, seed", CASES)
def test_velocity_lever_factor(kind: str, seed: int) -> None:
    s = _state(kind, seed)
    d_y = np.array([0.3, -0.2, 0.1])  # a non-zero residual
    e_known = dvl_velocity_error(s["pose"], s["n_v"], s["k"], s["rot"], d_y, s["b_omega"], s["b_l"])

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: np.ndarray, rot: gtsam.Rot3, b_l: np.ndarray) -> np.ndarray:
        return dvl_velocity_lever_error(pose, n_v, k, rot, b_l, d_y, s["b_omega"])

    point = (s["pose"], s["n_v"], s["k"], s["rot"], s["b_l"])
    H: list[Any] = [None] * 5
    e = dvl_velocity_lever_error(*point, d_y, s["b_omega"], H=H)
    np.testing.assert_allclose(e, e_known, atol=1e-14)  # the same model as the known-lever-arm factor
    _check(H, _numerical(h, point))
    # the stated closed form of the lever arm's block
    k_d_R_b = s["k"][0] * s["rot"].matrix().T
    np.testing.assert_allclose(H[4], k_d_R_b @ np.cross(s["b_omega"], np.eye(3), axisb=0, axisc=0), atol=1e-14)
    factor = make_dvl_velocity_lever_factor(gtsam.noiseModel.Unit.Create(3), X(0), V(0), K(0), B(0), L(0), d_y,
                                            s["b_omega"])
    _check_linearize(factor, point, e, H)


@pytest.mark.parametrize("kind, seed", CASES)
def test_velocity_offset_lever_factor(kind: str, seed: int) -> None:
    s = _state(kind, seed)
    d_y = np.array([0.3, -0.2, 0.1])
    consts = (s["b_omega"], s["b_a"], N_G, s["G"])
    e_known = dvl_velocity_offset_error(s["pose"], s["n_v"], s["k"], s["rot"], s["dt"], d_y, s["b_omega"], s["b_l"],
                                        s["b_a"], N_G, s["G"])

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: np.ndarray, rot: gtsam.Rot3, dt: np.ndarray,
          b_l: np.ndarray) -> np.ndarray:
        return dvl_velocity_offset_lever_error(pose, n_v, k, rot, dt, b_l, d_y, *consts)

    point = (s["pose"], s["n_v"], s["k"], s["rot"], s["dt"], s["b_l"])
    H: list[Any] = [None] * 6
    e = dvl_velocity_offset_lever_error(*point, d_y, *consts, H=H)
    np.testing.assert_allclose(e, e_known, atol=1e-14)
    _check(H, _numerical(h, point))
    factor = make_dvl_velocity_offset_lever_factor(gtsam.noiseModel.Unit.Create(3), X(0), V(0), K(0), B(0), T(0),
                                                   L(0), d_y, *consts)
    _check_linearize(factor, point, e, H)


@pytest.mark.parametrize("kind, seed", CASES)
def test_beam_lever_factor(kind: str, seed: int) -> None:
    s = _state(kind, seed)
    y_j = 0.37
    e_known = dvl_beam_error(s["pose"], s["n_v"], s["k"], s["rot"], s["d_u"], y_j, s["b_omega"], s["b_l"])

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: np.ndarray, rot: gtsam.Rot3, b_l: np.ndarray) -> np.ndarray:
        return dvl_beam_lever_error(pose, n_v, k, rot, b_l, s["d_u"], y_j, s["b_omega"])

    point = (s["pose"], s["n_v"], s["k"], s["rot"], s["b_l"])
    H: list[Any] = [None] * 5
    e = dvl_beam_lever_error(*point, s["d_u"], y_j, s["b_omega"], H=H)
    assert e.shape == (1,)
    np.testing.assert_allclose(e, e_known, atol=1e-14)
    _check(H, _numerical(h, point))
    factor = make_dvl_beam_lever_factor(gtsam.noiseModel.Unit.Create(1), X(0), V(0), K(0), B(0), L(0), s["d_u"],
                                        y_j, s["b_omega"])
    _check_linearize(factor, point, e, H)


def test_lever_arm_along_the_rotation_axis_is_invisible() -> None:
    """h depends on b_l only through b_omega x b_l: the Jacobian's null space is the rotation axis."""
    s = _state("random", 0)
    H: list[Any] = [None] * 5
    dvl_velocity_lever_error(s["pose"], s["n_v"], s["k"], s["rot"], s["b_l"], np.zeros(3), s["b_omega"], H=H)
    axis = s["b_omega"] / np.linalg.norm(s["b_omega"])
    assert np.linalg.norm(H[4] @ axis) < 1e-14
    assert np.linalg.matrix_rank(H[4], tol=1e-10) == 2


def test_lever_factors_reject_bad_input() -> None:
    unit3 = gtsam.noiseModel.Unit.Create(3)
    with pytest.raises(ValueError, match="b_omega"):
        make_dvl_velocity_lever_factor(unit3, X(0), V(0), K(0), B(0), L(0), np.zeros(3), [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="dimension"):
        make_dvl_velocity_lever_factor(gtsam.noiseModel.Unit.Create(1), X(0), V(0), K(0), B(0), L(0), np.zeros(3),
                                       np.zeros(3))
    with pytest.raises(ValueError, match="b_a"):
        make_dvl_velocity_offset_lever_factor(unit3, X(0), V(0), K(0), B(0), T(0), L(0), np.zeros(3), np.zeros(3),
                                              [np.inf, 0.0, 0.0], N_G)
    with pytest.raises(ValueError, match="unit vector"):
        make_dvl_beam_lever_factor(gtsam.noiseModel.Unit.Create(1), X(0), V(0), K(0), B(0), L(0), [1.0, 1.0, 0.0],
                                   0.1, np.zeros(3))


def test_cross3_is_the_cross_product() -> None:
    from gtsam_dvl.factors._common import cross3

    rng = np.random.default_rng(1)
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_allclose(cross3(a, b), np.cross(a, b), rtol=0, atol=1e-15)
