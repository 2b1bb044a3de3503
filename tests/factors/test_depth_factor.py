"""The depth factor (factors/depth.py), GTSAM style: zero error at the truth, Jacobians against central
differences through retract at random states, near-identity (1e-7 rad) and large rotations, with and without
the curvature term, lever arm and velocity bridge; the factor through GTSAM's linearize."""

from __future__ import annotations

import math
from collections.abc import Callable

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X

from gtsam_dvl.factors import depth_error, make_depth_factor
from tests.support.numerical import assert_jacobians_match

R_EARTH = 6.37e6
Attitude = Callable[[str, np.random.Generator], np.ndarray]  # the attitude fixture (conftest.py)
Check = Callable[..., None]  # the assert_linearization fixture (conftest.py)
CASES = [
    (kind, seed)
    for kind in ("random", "near_identity", "large", "no_lever", "flat")
    for seed in range(4)
]


def _state(
    kind: str, seed: int, attitude: Attitude
) -> tuple[gtsam.Pose3, np.ndarray, np.ndarray, float, float]:
    rng = np.random.default_rng(seed)
    R = attitude(kind, rng)
    n_p = rng.normal(scale=2000.0, size=3)
    lever = np.zeros(3) if kind == "no_lever" else rng.normal(scale=0.8, size=3)
    radius = math.inf if kind == "flat" else R_EARTH
    return (
        gtsam.Pose3(gtsam.Rot3(R), n_p),
        rng.normal(scale=1.0, size=3),
        lever,
        radius,
        float(rng.uniform(-0.5, 0.5)),
    )


def _height(
    pose: gtsam.Pose3, lever: np.ndarray, radius: float, n_v: np.ndarray, dt: float
) -> float:
    """The model, plain numpy: sensor height above the origin's height."""
    p = pose.translation()
    curv = 0.0 if math.isinf(radius) else (p[0] ** 2 + p[1] ** 2) / (2 * radius)
    return float(p[2] + curv + (pose.rotation().matrix() @ lever)[2] + dt * n_v[2])


@pytest.mark.parametrize("kind, seed", CASES)
def test_depth_zero_error_at_truth_and_jacobians(kind: str, seed: int, attitude: Attitude) -> None:
    pose, n_v, lever, radius, dt = _state(kind, seed, attitude)
    z_true = _height(pose, lever, radius, n_v, dt)
    assert abs(depth_error(pose, z_true, lever, radius, n_v, dt)[0]) < 1e-9
    z_meas = z_true - 0.3  # a non-zero residual

    def h(p: gtsam.Pose3, v: np.ndarray) -> np.ndarray:
        return depth_error(p, z_meas, lever, radius, v, dt)

    H: list[np.ndarray | None] = [None, None]
    e = depth_error(pose, z_meas, lever, radius, n_v, dt, H)
    np.testing.assert_allclose(e, [0.3], atol=1e-9)
    assert_jacobians_match(h, [pose, n_v], H)


@pytest.mark.parametrize("kind, seed", CASES[::3])
@pytest.mark.parametrize("with_velocity", [False, True])
def test_depth_factor_linearize_matches_numerical(
    kind: str, seed: int, with_velocity: bool, attitude: Attitude, assert_linearization: Check
) -> None:
    pose, n_v, lever, radius, dt = _state(kind, seed, attitude)
    z_meas = _height(pose, lever, radius, n_v, dt if with_velocity else 0.0) + 0.2
    factor = make_depth_factor(
        gtsam.noiseModel.Unit.Create(1),
        X(0),
        z_meas,
        lever,
        radius,
        V(0) if with_velocity else None,
        dt if with_velocity else 0.0,
    )
    values = gtsam.Values()
    values.insert(X(0), pose)
    values.insert(V(0), n_v)
    assert factor.unwhitenedError(values)[0] == pytest.approx(-0.2, abs=1e-9)
    assert_linearization(factor, pose, n_v, np.array([0.2]), with_velocity)


def test_depth_factor_rejects_bad_input() -> None:
    unit = gtsam.noiseModel.Unit.Create(1)
    with pytest.raises(ValueError, match="z_meas"):
        make_depth_factor(unit, X(0), float("nan"), np.zeros(3))
    with pytest.raises(ValueError, match="b_p_s"):
        make_depth_factor(unit, X(0), 0.0, [0.0, 1.0])
    with pytest.raises(ValueError, match="radius_m"):
        make_depth_factor(unit, X(0), 0.0, np.zeros(3), radius_m=0.0)
    with pytest.raises(ValueError, match="dimension"):
        make_depth_factor(gtsam.noiseModel.Unit.Create(3), X(0), 0.0, np.zeros(3))
