"""Fixtures shared by the factor tests: a random IMU motion from a keyframe to a ping with its Earth model, random
attitudes, and the check of a pose factor's linearisation against numerical derivatives."""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import PingMotion
from tests.support.numerical import numerical_jacobian

# map ENU at 30 deg, rad/s
W_IE = 7.292115e-5 * np.array([0.0, np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])
N_G0 = np.array([1e-5, -2e-5, -9.79])  # gravity in map, m/s^2


def _random_motion(seed: int, dt: float = 0.6) -> PingMotion:
    rng = np.random.default_rng(seed)
    return PingMotion(
        dt,
        Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix(),
        rng.normal(size=3),
        rng.normal(size=3),
        dt * np.eye(3) + 0.01 * rng.normal(size=(3, 3)),
        -dt * np.eye(3) + 0.01 * rng.normal(size=(3, 3)),
        0.3 * rng.normal(size=(3, 3)),
        np.eye(9) * 1e-6,
        W_IE,
        N_G0,
        rng.normal(size=3) * 100,
        1.5e-6 * np.diag([-1.0, -1.0, 2.0]) + 1e-7 * rng.normal(size=(3, 3)),
    )


@pytest.fixture
def random_motion() -> Callable[..., PingMotion]:
    """random_motion(seed, dt=0.6): a random IMU motion over dt s with the Earth model (Earth rate W_IE, gravity
    N_G0 and a gradient at a random reference)."""
    return _random_motion


@pytest.fixture
def earth() -> tuple[np.ndarray, np.ndarray]:
    """(W_IE, N_G0): the Earth rate and gravity of random_motion."""
    return W_IE, N_G0


def _attitude(kind: str, rng: np.random.Generator) -> np.ndarray:
    if kind == "near_identity":
        return Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
    if kind == "large":  # near pi, where the log map changes branch
        u = rng.normal(size=3)
        return Rotation.from_rotvec((np.pi - 1e-4) * u / np.linalg.norm(u)).as_matrix()
    return Rotation.random(random_state=rng).as_matrix()


@pytest.fixture
def attitude() -> Callable[[str, np.random.Generator], np.ndarray]:
    """attitude(kind, rng): a random attitude (3x3), near the identity (1e-7 rad) or near pi for those kinds."""
    return _attitude


def _assert_linearization(
    factor: gtsam.CustomFactor,
    pose: gtsam.Pose3,
    n_v: np.ndarray,
    b_expected: np.ndarray,
    with_velocity: bool,
) -> None:
    """factor on [X(0)] or [X(0), V(0)] linearised at (pose, n_v): b as expected, A against numerical derivatives
    of its unwhitened error (unit noise)."""

    def h(p: gtsam.Pose3, v: np.ndarray) -> np.ndarray:
        vals = gtsam.Values()
        vals.insert(X(0), p)
        vals.insert(V(0), v)
        return np.asarray(factor.unwhitenedError(vals))

    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(V(0), n_v)
    A, b = factor.linearize(values).jacobian()
    np.testing.assert_allclose(b, b_expected, atol=1e-9)
    np.testing.assert_allclose(A[:, :6], numerical_jacobian(h, [pose, n_v], 0), atol=1e-6)
    if with_velocity:
        np.testing.assert_allclose(A[:, 6:], numerical_jacobian(h, [pose, n_v], 1), atol=1e-6)
    else:
        assert A.shape == (len(b), 6)


@pytest.fixture
def assert_linearization() -> Callable[..., None]:
    """assert_linearization(factor, pose, n_v, b_expected, with_velocity): a pose (and velocity) factor's
    linearisation against numerical derivatives (tests/support/numerical.py)."""
    return _assert_linearization
