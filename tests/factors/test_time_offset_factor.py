"""The DVL velocity factor with a DVL-IMU time offset dt (factors/dvl_velocity.py, make_dvl_velocity_offset_factor),
GTSAM style: zero error at a measurement built from the model, the dt = 0 factor equal to the plain 3-D factor,
and every Jacobian (pose, velocity, scale, misalignment, dt) against central differences on the manifold at
random states, including near-identity rotations and a 180 deg roll mounting.

    y = k b_R_d^T (b_v + dt (b_a + n_R_b^T n_g - b_omega x b_v) + b_omega x b_l),   b_v = n_R_b^T n_v
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, K, T, V, X
from gtsam.utils.numerical_derivative import (
    numericalDerivative51,
    numericalDerivative52,
    numericalDerivative53,
    numericalDerivative54,
    numericalDerivative55,
)
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import dvl_velocity_error, dvl_velocity_offset_error, make_dvl_velocity_offset_factor

KEYS = (X(0), V(0), K(0), B(0), T(0))
DIMS = (6, 3, 1, 3, 1)
N_G = np.array([0.0, 0.0, -9.79])
NUMERICAL = (numericalDerivative51, numericalDerivative52, numericalDerivative53, numericalDerivative54,
             numericalDerivative55)


def _state(kind: str, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    n_R_b = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    b_R_d = Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix()
    if kind == "near_identity":
        n_R_b = Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
        b_R_d = Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
    if kind == "roll_180":
        b_R_d = b_R_d @ np.diag([1.0, -1.0, -1.0])
    return {"pose": gtsam.Pose3(gtsam.Rot3(n_R_b), rng.normal(size=3) * 10), "n_v": rng.normal(size=3) * 2,
            "k": np.array([1.0 + 0.01 * rng.normal()]), "rot": gtsam.Rot3(b_R_d),
            "dt": np.array([rng.uniform(-1.5, 1.5)]), "b_omega": 0.1 * rng.normal(size=3),
            "b_l": rng.normal(size=3), "b_a": 0.2 * rng.normal(size=3) + n_R_b.T @ -N_G,
            "G": Rotation.from_rotvec(0.02 * rng.normal(size=3)).as_matrix() + 1e-4 * rng.normal(size=(3, 3))}


CASES = [(kind, seed) for kind in ("random", "near_identity", "roll_180") for seed in range(3)]


@pytest.mark.parametrize("kind, seed", CASES)
def test_zero_error_at_model_and_dt_zero_is_the_plain_factor(kind: str, seed: int) -> None:
    s = _state(kind, seed)
    args = (s["b_omega"], s["b_l"], s["b_a"], N_G, s["G"])
    y = dvl_velocity_offset_error(s["pose"], s["n_v"], s["k"], s["rot"], s["dt"], np.zeros(3), *args)
    e = dvl_velocity_offset_error(s["pose"], s["n_v"], s["k"], s["rot"], s["dt"], y, *args)
    assert np.max(np.abs(e)) < 1e-12
    y0 = dvl_velocity_error(s["pose"], s["n_v"], s["k"], s["rot"], np.zeros(3), s["b_omega"], s["b_l"])
    e0 = dvl_velocity_offset_error(s["pose"], s["n_v"], s["k"], s["rot"], np.array([0.0]), y0, *args)
    assert np.max(np.abs(e0)) < 1e-12


@pytest.mark.parametrize("kind, seed", CASES)
def test_jacobians_match_numerical_derivatives(kind: str, seed: int) -> None:
    s = _state(kind, seed)
    d_y = np.array([0.3, -0.2, 0.1])  # a non-zero residual
    args = (d_y, s["b_omega"], s["b_l"], s["b_a"], N_G, s["G"])

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: np.ndarray, rot: gtsam.Rot3, dt: np.ndarray) -> np.ndarray:
        return dvl_velocity_offset_error(pose, n_v, k, rot, dt, *args)

    point = (s["pose"], s["n_v"], s["k"], s["rot"], s["dt"])
    numerical = [nd(h, *point) for nd in NUMERICAL]
    H: list = [None] * 5
    dvl_velocity_offset_error(*point, *args, H=H)
    for i, (J, Jn) in enumerate(zip(H, numerical, strict=True)):
        scale = max(1.0, float(np.max(np.abs(Jn))))
        np.testing.assert_allclose(J, Jn, rtol=0.0, atol=1e-7 * scale, err_msg=f"block {i}")

    factor = make_dvl_velocity_offset_factor(gtsam.noiseModel.Unit.Create(3), *KEYS, *args)
    values = gtsam.Values()
    values.insert(KEYS[0], s["pose"])
    values.insert(KEYS[1], s["n_v"])
    values.insert(KEYS[2], s["k"])
    values.insert(KEYS[3], s["rot"])
    values.insert(KEYS[4], s["dt"])
    A, b = factor.linearize(values).jacobian()
    np.testing.assert_allclose(b, -h(*point), atol=1e-12)
    for i, J in enumerate(np.split(A, np.cumsum(DIMS)[:-1], axis=1)):
        np.testing.assert_allclose(J, H[i], atol=1e-12, err_msg=f"linearize block {i}")


def test_factor_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="b_a"):
        make_dvl_velocity_offset_factor(gtsam.noiseModel.Unit.Create(3), *KEYS, np.zeros(3), np.zeros(3),
                                        np.zeros(3), [np.nan, 0.0, 0.0], N_G)
