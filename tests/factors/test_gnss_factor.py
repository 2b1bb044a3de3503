"""The GNSS factor (factors/gnss.py): zero error at the truth, Jacobians against numerical derivatives
(tests/support/numerical.py) through retract at random, near-identity (1e-7 rad) and large rotations, with and
without lever arm and velocity bridge, both for the plain error function and the factor through GTSAM's linearize."""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X

from gtsam_dvl.factors import gnss_error, make_gnss_factor
from tests.support.numerical import assert_jacobians_match

Attitude = Callable[[str, np.random.Generator], np.ndarray]  # the attitude fixture (conftest.py)
Check = Callable[..., None]  # the assert_linearization fixture (conftest.py)
CASES = [
    (kind, seed) for kind in ("random", "near_identity", "large", "no_lever") for seed in range(4)
]


def _state(
    kind: str, seed: int, attitude: Attitude
) -> tuple[gtsam.Pose3, np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng(seed)
    R = attitude(kind, rng)
    lever = np.zeros(3) if kind == "no_lever" else rng.normal(scale=0.8, size=3)
    return (
        gtsam.Pose3(gtsam.Rot3(R), rng.normal(scale=2000.0, size=3)),
        rng.normal(scale=1.5, size=3),
        lever,
        float(rng.uniform(-0.5, 0.5)),
    )


def _antenna(pose: gtsam.Pose3, lever: np.ndarray, n_v: np.ndarray, dt: float) -> np.ndarray:
    """The model, plain numpy: the antenna in map."""
    return np.asarray(pose.translation() + pose.rotation().matrix() @ lever + dt * n_v)


@pytest.mark.parametrize("kind, seed", CASES)
def test_gnss_error_zero_at_truth_and_jacobians(kind: str, seed: int, attitude: Attitude) -> None:
    pose, n_v, lever, dt = _state(kind, seed, attitude)
    z_true = _antenna(pose, lever, n_v, dt)
    np.testing.assert_allclose(gnss_error(pose, z_true, lever, n_v, dt), 0.0, atol=1e-9)
    z = z_true - np.array([0.3, -1.2, 2.0])

    def h(p: gtsam.Pose3, v: np.ndarray) -> np.ndarray:
        return gnss_error(p, z, lever, v, dt)

    H: list[np.ndarray | None] = [None, None]
    np.testing.assert_allclose(gnss_error(pose, z, lever, n_v, dt, H), [0.3, -1.2, 2.0], atol=1e-9)
    assert_jacobians_match(h, [pose, n_v], H, shapes=[(3, 6), (3, 3)])


@pytest.mark.parametrize("kind, seed", CASES[::2])
@pytest.mark.parametrize("with_velocity", [False, True])
def test_gnss_factor_linearize_matches_numerical(
    kind: str, seed: int, with_velocity: bool, attitude: Attitude, assert_linearization: Check
) -> None:
    pose, n_v, lever, dt = _state(kind, seed, attitude)
    dt_used = dt if with_velocity else 0.0
    z = _antenna(pose, lever, n_v, dt_used) + np.array([0.2, 0.1, -0.4])
    factor = make_gnss_factor(
        gtsam.noiseModel.Unit.Create(3), X(0), z, lever, V(0) if with_velocity else None, dt_used
    )
    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(V(0), n_v)
    np.testing.assert_allclose(factor.unwhitenedError(values), [-0.2, -0.1, 0.4], atol=1e-9)
    assert_linearization(factor, pose, n_v, np.array([0.2, 0.1, -0.4]), with_velocity)


def test_gnss_factor_whitens_with_the_fix_covariance(attitude: Attitude) -> None:
    pose, n_v, lever, _ = _state("random", 9, attitude)
    cov = np.array([[4.0, 1.0, 0.0], [1.0, 3.0, 0.0], [0.0, 0.0, 16.0]])
    e = np.array([1.0, -2.0, 3.0])
    factor = make_gnss_factor(
        gtsam.noiseModel.Gaussian.Covariance(cov), X(0), _antenna(pose, lever, n_v, 0) - e, lever
    )
    values = gtsam.Values()
    values.insert(X(0), pose)
    assert factor.error(values) == pytest.approx(0.5 * e @ np.linalg.solve(cov, e), rel=1e-9)


def test_gnss_factor_rejects_bad_input() -> None:
    unit = gtsam.noiseModel.Unit.Create(3)
    with pytest.raises(ValueError, match="z"):
        make_gnss_factor(unit, X(0), [0.0, float("nan"), 0.0], np.zeros(3))
    with pytest.raises(ValueError, match="b_p_a"):
        make_gnss_factor(unit, X(0), np.zeros(3), [0.0, 1.0])
    with pytest.raises(ValueError, match="dt"):
        make_gnss_factor(unit, X(0), np.zeros(3), np.zeros(3), V(0), float("inf"))
    with pytest.raises(ValueError, match="dimension"):
        make_gnss_factor(gtsam.noiseModel.Unit.Create(1), X(0), np.zeros(3), np.zeros(3))
