"""Fixtures shared by the factor tests: a random IMU motion from a keyframe to a ping, with its Earth model."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import PingMotion

W_IE = 7.292115e-5 * np.array([0.0, np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])  # map ENU at 30 deg, rad/s
N_G0 = np.array([1e-5, -2e-5, -9.79])  # gravity in map, m/s^2


def _random_motion(seed: int, dt: float = 0.6) -> PingMotion:
    rng = np.random.default_rng(seed)
    return PingMotion(dt, Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix(), rng.normal(size=3),
                      rng.normal(size=3), dt * np.eye(3) + 0.01 * rng.normal(size=(3, 3)),
                      -dt * np.eye(3) + 0.01 * rng.normal(size=(3, 3)), 0.3 * rng.normal(size=(3, 3)),
                      np.eye(9) * 1e-6, W_IE, N_G0, rng.normal(size=3) * 100,
                      1.5e-6 * np.diag([-1.0, -1.0, 2.0]) + 1e-7 * rng.normal(size=(3, 3)))


@pytest.fixture
def random_motion() -> Callable[..., PingMotion]:
    """random_motion(seed, dt=0.6): a random IMU motion over dt s with the Earth model (Earth rate W_IE, gravity
    N_G0 and a gradient at a random reference)."""
    return _random_motion


@pytest.fixture
def earth() -> tuple[np.ndarray, np.ndarray]:
    """(W_IE, N_G0): the Earth rate and gravity of random_motion."""
    return W_IE, N_G0
