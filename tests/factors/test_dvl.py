"""The DVL factor (factors/dvl.py), GTSAM style: the measurement built from the model gives zero error at the
truth, and every Jacobian matches a numerical derivative (central differences through retract, tests/support/
numerical.py) at random states, near-identity (1e-7 rad) and large rotations, a 180 deg roll mounting, non-zero
lever arm and body rate, and a non-zero residual; every combination of the options (time offset, lever arm as a
variable, beam, motion from a keyframe) likewise, the factor's linearisation equal to the error function's.

    y = k * b_R_d^T * ( n_R_b^T * n_v  +  b_omega x b_l )          y_j = d_u_j . y
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, K, L, T, V, X
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import (
    DvlOptions,
    OffsetInput,
    PingMotion,
    dvl_beam_error,
    dvl_error,
    dvl_velocity_error,
    make_dvl_beam_factor,
    make_dvl_factor,
    make_dvl_velocity_factor,
)
from tests.support.numerical import numerical_jacobians

KEYS = (X(0), V(0), K(0), B(0))
KEY_DIMS = (6, 3, 1, 3)
ZERO_TOL = 1e-12  # error at the truth, m/s
JAC_RTOL = 1e-7  # analytic vs numerical Jacobian, relative to the Jacobian's largest entry
CAL_TOL = 1e-9  # end-to-end calibration recovery (scale, and rotation angle in rad)

# Janus configuration: four beams 30 deg off the instrument axis, 90 deg apart (unit vectors in dvl_link).
_S, _C = np.sin(np.radians(30.0)) / np.sqrt(2.0), np.cos(np.radians(30.0))
JANUS = np.array([[_S, _S, _C], [-_S, _S, _C], [-_S, -_S, _C], [_S, -_S, _C]])
ROLL_180 = np.diag([1.0, -1.0, -1.0])  # z-down DVL mounting


def rotvec(v: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(v).as_matrix()


def unit(rng: np.random.Generator) -> np.ndarray:
    u = rng.normal(size=3)
    return u / np.linalg.norm(u)


@dataclass(frozen=True)
class State:
    """A state and the known inputs, as plain numpy (the reference the factors are compared with)."""

    n_R_b: np.ndarray
    n_p: np.ndarray
    n_v: np.ndarray
    k: float
    b_R_d: np.ndarray
    b_omega: np.ndarray
    b_l: np.ndarray
    residual: np.ndarray  # added to the model output to get a non-zero error

    @property
    def pose(self) -> gtsam.Pose3:
        return gtsam.Pose3(gtsam.Rot3(self.n_R_b), self.n_p)

    @property
    def rot(self) -> gtsam.Rot3:
        return gtsam.Rot3(self.b_R_d)

    def y_model(self) -> np.ndarray:
        """The DVL velocity from the formula, plain numpy."""
        return self.k * self.b_R_d.T @ (self.n_R_b.T @ self.n_v + np.cross(self.b_omega, self.b_l))

    def y_measured(self) -> np.ndarray:
        return self.y_model() + self.residual

    def values(self) -> gtsam.Values:
        return make_values(self.pose, self.n_v, self.k, self.rot)


def make_values(
    pose: gtsam.Pose3, n_v: np.ndarray, k: float | np.ndarray, rot: gtsam.Rot3
) -> gtsam.Values:
    values = gtsam.Values()
    values.insert(KEYS[0], pose)
    values.insert(KEYS[1], np.asarray(n_v, dtype=float))
    values.insert(KEYS[2], np.atleast_1d(np.asarray(k, dtype=float)))
    values.insert(KEYS[3], rot)
    return values


def make_state(kind: str, seed: int) -> State:
    rng = np.random.default_rng(seed)
    n_R_b = Rotation.random(random_state=rng).as_matrix()
    b_R_d = Rotation.random(random_state=rng).as_matrix()
    tiny = 1e-7  # rad: exercises the small-angle paths of retract and the Jacobians
    if kind in ("near_identity_n_R_b", "near_identity_both"):
        n_R_b = rotvec(tiny * unit(rng))
    if kind in ("near_identity_b_R_d", "near_identity_both"):
        b_R_d = rotvec(tiny * unit(rng))
    if kind == "large":  # rotation angles close to pi, where the log map changes branch
        n_R_b = rotvec((np.pi - 1e-4) * unit(rng))
        b_R_d = rotvec((np.pi - 1e-3) * unit(rng))
    if kind == "roll_180":  # z-down DVL with a small misalignment correction in body axes
        b_R_d = rotvec(np.radians([-0.1, 0.2, -0.5])) @ ROLL_180
    if kind == "roll_180_exact":
        b_R_d = ROLL_180.copy()
    zero_lever = kind == "zero_lever"
    return State(
        n_R_b=n_R_b,
        n_p=rng.normal(scale=100.0, size=3),
        n_v=rng.normal(scale=1.5, size=3),
        k=float(rng.uniform(0.8, 1.2)),
        b_R_d=b_R_d,
        b_omega=np.zeros(3) if zero_lever else rng.normal(scale=0.3, size=3),
        b_l=np.zeros(3) if zero_lever else rng.normal(scale=0.8, size=3),
        residual=rng.normal(scale=0.05, size=3),
    )


KINDS = {
    "random": 12,
    "near_identity_n_R_b": 3,
    "near_identity_b_R_d": 3,
    "near_identity_both": 3,
    "large": 3,
    "roll_180": 3,
    "roll_180_exact": 2,
    "zero_lever": 2,
}
CASES = [
    pytest.param(kind, 1000 * i + seed, id=f"{kind}-{seed}")
    for i, (kind, n) in enumerate(KINDS.items())
    for seed in range(n)
]


def assert_jacobian_close(actual: np.ndarray, numerical: np.ndarray, what: str) -> None:
    scale = float(np.abs(numerical).max()) or 1.0
    assert actual.shape == numerical.shape, what
    np.testing.assert_allclose(actual, numerical, rtol=0.0, atol=JAC_RTOL * scale, err_msg=what)


def numerical_of(h: Callable[..., np.ndarray], s: State) -> list[np.ndarray]:
    """Central differences of h(pose, n_v, k, b_R_d) on the manifold (Pose3/Rot3 retract, k + dk)."""
    return numerical_jacobians(h, [s.pose, s.n_v, s.k, s.rot])


def split_columns(A: np.ndarray) -> list[np.ndarray]:
    return np.split(A, np.cumsum(KEY_DIMS)[:-1], axis=1)


# ---------------------------------------------------------------------------------------- 3-D factor


@pytest.mark.parametrize("kind, seed", CASES)
def test_velocity_zero_error_at_truth(kind: str, seed: int) -> None:
    s = make_state(kind, seed)
    y = s.y_model()
    e = dvl_velocity_error(s.pose, s.n_v, s.k, s.rot, y, s.b_omega, s.b_l)
    assert e.shape == (3,)
    assert np.abs(e).max() < ZERO_TOL
    factor = make_dvl_velocity_factor(gtsam.noiseModel.Unit.Create(3), *KEYS, y, s.b_omega, s.b_l)
    assert np.abs(factor.unwhitenedError(s.values())).max() < ZERO_TOL


@pytest.mark.parametrize("kind, seed", CASES)
def test_velocity_jacobians_pure_function(kind: str, seed: int) -> None:
    s = make_state(kind, seed)
    y = s.y_measured()

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: float, rot: gtsam.Rot3) -> np.ndarray:
        return dvl_velocity_error(pose, n_v, k, rot, y, s.b_omega, s.b_l)

    H: list[np.ndarray | None] = [None] * 4
    e = dvl_velocity_error(s.pose, s.n_v, s.k, s.rot, y, s.b_omega, s.b_l, H)
    np.testing.assert_allclose(e, s.y_model() - y, atol=ZERO_TOL)
    assert np.abs(e).max() > 1e-3  # the residual really is non-zero
    for i, (J, J_num) in enumerate(zip(H, numerical_of(h, s), strict=True)):
        assert J is not None
        assert_jacobian_close(J, J_num, f"H[{i}]")
    assert [J.shape for J in H if J is not None] == [(3, 6), (3, 3), (3, 1), (3, 3)]


@pytest.mark.parametrize("kind, seed", CASES)
def test_velocity_jacobians_custom_factor(kind: str, seed: int) -> None:
    """Through GTSAM: unwhitenedError with a JacobianVector, and linearize (unit noise: A = J, b = -e)."""
    s = make_state(kind, seed)
    unit_noise = gtsam.noiseModel.Unit.Create(3)
    factor = make_dvl_velocity_factor(unit_noise, *KEYS, s.y_measured(), s.b_omega, s.b_l)

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: float, rot: gtsam.Rot3) -> np.ndarray:
        return factor.unwhitenedError(make_values(pose, n_v, k, rot))

    numerical = numerical_of(h, s)
    jv = gtsam.JacobianVector([np.empty((0, 0))] * 4)
    e = factor.unwhitenedError(s.values(), jv)
    np.testing.assert_allclose(e, -s.residual, atol=ZERO_TOL)
    for i in range(4):
        assert_jacobian_close(jv[i], numerical[i], f"JacobianVector[{i}]")

    linear = factor.linearize(s.values())
    assert list(linear.keys()) == list(KEYS)
    A, b = linear.jacobian()
    np.testing.assert_allclose(b, s.residual, atol=ZERO_TOL)
    for i, J in enumerate(split_columns(A)):
        assert_jacobian_close(J, numerical[i], f"linearize block {i}")


def test_velocity_linearize_whitens_with_full_covariance() -> None:
    """With the DVL's 3x3 covariance the linear system is the analytic one whitened by GTSAM."""
    s = make_state("random", 7)
    cov = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, -0.2], [0.5, -0.2, 6.0]]) * 1e-4
    noise = gtsam.noiseModel.Gaussian.Covariance(cov)
    factor = make_dvl_velocity_factor(noise, *KEYS, s.y_measured(), s.b_omega, s.b_l)
    H: list[np.ndarray] = [np.empty(0)] * 4
    e = dvl_velocity_error(s.pose, s.n_v, s.k, s.rot, s.y_measured(), s.b_omega, s.b_l, H)
    A, b = factor.linearize(s.values()).jacobian()
    np.testing.assert_allclose(A, noise.Whiten(np.hstack(H)), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(b, -noise.whiten(e), rtol=1e-12, atol=1e-9)


# ----------------------------------------------------------------------------------------- beam factor


@pytest.mark.parametrize("kind, seed", CASES)
@pytest.mark.parametrize("beam", range(4))
def test_beam_is_the_projected_3d_factor(kind: str, seed: int, beam: int) -> None:
    s = make_state(kind, seed)
    d_u = JANUS[beam]
    y = s.y_measured()
    y_j = float(d_u @ y)
    H3: list[np.ndarray | None] = [None] * 4
    e3 = dvl_velocity_error(s.pose, s.n_v, s.k, s.rot, y, s.b_omega, s.b_l, H3)
    Hj: list[np.ndarray | None] = [None] * 4
    ej = dvl_beam_error(s.pose, s.n_v, s.k, s.rot, d_u, y_j, s.b_omega, s.b_l, Hj)
    assert ej.shape == (1,)
    np.testing.assert_allclose(ej, [d_u @ e3], rtol=0.0, atol=ZERO_TOL)
    for i, (J3, J) in enumerate(zip(H3, Hj, strict=True)):
        assert J3 is not None and J is not None
        assert J.shape == (1, KEY_DIMS[i])
        np.testing.assert_allclose(J, d_u[None, :] @ J3, rtol=0.0, atol=1e-12 * np.abs(J3).max())

    # Zero error when y_j comes from the model.
    e0 = dvl_beam_error(s.pose, s.n_v, s.k, s.rot, d_u, float(d_u @ s.y_model()), s.b_omega, s.b_l)
    assert abs(e0[0]) < ZERO_TOL


@pytest.mark.parametrize("kind, seed", CASES)
def test_beam_jacobians_numerical(kind: str, seed: int) -> None:
    s = make_state(kind, seed)
    d_u = JANUS[seed % 4]
    y_j = float(d_u @ s.y_measured())

    def h(pose: gtsam.Pose3, n_v: np.ndarray, k: float, rot: gtsam.Rot3) -> np.ndarray:
        return dvl_beam_error(pose, n_v, k, rot, d_u, y_j, s.b_omega, s.b_l)

    numerical = numerical_of(h, s)
    H: list[np.ndarray | None] = [None] * 4
    dvl_beam_error(s.pose, s.n_v, s.k, s.rot, d_u, y_j, s.b_omega, s.b_l, H)
    for i in range(4):
        J = H[i]
        assert J is not None
        assert_jacobian_close(J, numerical[i], f"pure H[{i}]")

    factor = make_dvl_beam_factor(
        gtsam.noiseModel.Unit.Create(1), *KEYS, d_u, y_j, s.b_omega, s.b_l
    )
    jv = gtsam.JacobianVector([np.empty((0, 0))] * 4)
    e = factor.unwhitenedError(s.values(), jv)
    np.testing.assert_allclose(e, [-d_u @ s.residual], atol=ZERO_TOL)
    A, b = factor.linearize(s.values()).jacobian()
    np.testing.assert_allclose(b, [d_u @ s.residual], atol=ZERO_TOL)
    for i, J in enumerate(split_columns(A)):
        assert_jacobian_close(jv[i], numerical[i], f"JacobianVector[{i}]")
        assert_jacobian_close(J, numerical[i], f"linearize block {i}")


# ------------------------------------------------------------------------- error, dimension, validation


def test_factor_error_and_dimension() -> None:
    s = make_state("random", 3)
    cov = np.diag([4e-4, 9e-4, 1.6e-3])
    factor = make_dvl_velocity_factor(
        gtsam.noiseModel.Gaussian.Covariance(cov), *KEYS, s.y_measured(), s.b_omega, s.b_l
    )
    assert factor.dim() == 3
    assert factor.size() == 4
    assert list(factor.keys()) == list(KEYS)
    e = s.y_model() - s.y_measured()
    assert factor.error(s.values()) == pytest.approx(0.5 * e @ np.linalg.solve(cov, e), rel=1e-12)

    sigma = 0.02
    d_u = JANUS[2]
    beam = make_dvl_beam_factor(
        gtsam.noiseModel.Isotropic.Sigma(1, sigma),
        *KEYS,
        d_u,
        d_u @ s.y_measured(),
        s.b_omega,
        s.b_l,
    )
    assert beam.dim() == 1
    assert beam.size() == 4
    assert beam.error(s.values()) == pytest.approx(0.5 * (d_u @ e / sigma) ** 2, rel=1e-12)


def test_robust_noise_and_point3_velocity_accepted() -> None:
    s = make_state("random", 4)
    huber = gtsam.noiseModel.Robust.Create(
        gtsam.noiseModel.mEstimator.Huber.Create(1.345), gtsam.noiseModel.Isotropic.Sigma(3, 0.02)
    )
    factor = make_dvl_velocity_factor(huber, *KEYS, s.y_measured(), s.b_omega, s.b_l)
    values = gtsam.Values()
    values.insert(KEYS[0], s.pose)
    # a fixed-size Vector3 entry, as a C++ factor would store it
    values.insertPoint3(KEYS[1], s.n_v)
    values.insert(KEYS[2], np.array([s.k]))
    values.insert(KEYS[3], s.rot)
    np.testing.assert_allclose(factor.unwhitenedError(values), -s.residual, atol=ZERO_TOL)
    assert np.isfinite(factor.error(values))
    assert factor.linearize(values).jacobian()[0].shape == (3, 13)


def test_pure_function_fills_preallocated_slots_in_place() -> None:
    s = make_state("random", 5)
    J_pose, J_k, J_rot = np.zeros((3, 6)), np.zeros((3, 1)), np.zeros((3, 3))
    pre: list[np.ndarray | None] = [J_pose, None, J_k, J_rot]
    dvl_velocity_error(s.pose, s.n_v, s.k, s.rot, s.y_measured(), s.b_omega, s.b_l, pre)
    assert pre[0] is J_pose and pre[2] is J_k and pre[3] is J_rot
    J_vel = pre[1]
    assert J_vel is not None and J_vel.shape == (3, 3)
    assert np.abs(J_pose[:, :3]).max() > 0 and np.abs(J_k).max() > 0 and np.abs(J_rot).max() > 0
    with pytest.raises(ValueError, match="4 slots"):
        dvl_velocity_error(s.pose, s.n_v, s.k, s.rot, s.y_measured(), s.b_omega, s.b_l, [None] * 3)


GOOD = {"d_y": [1.0, 0.1, -0.2], "b_omega": [0.0, 0.0, 0.1], "b_l": [0.5, 0.0, -0.3]}


@pytest.mark.parametrize(
    "field, bad",
    [
        ("d_y", [1.0, 0.1]),
        ("d_y", [1.0, np.nan, 0.0]),
        ("d_y", [[1.0, 0.1, 0.0]]),
        ("b_omega", [0.0, np.inf, 0.0]),
        ("b_l", [0.5, 0.0]),
        ("b_l", [np.nan, 0.0, 0.0]),
    ],
)
def test_velocity_factor_rejects_bad_input(field: str, bad: list[float]) -> None:
    args = {**GOOD, field: bad}
    noise = gtsam.noiseModel.Unit.Create(3)
    with pytest.raises(ValueError, match=field):
        make_dvl_velocity_factor(noise, *KEYS, args["d_y"], args["b_omega"], args["b_l"])


@pytest.mark.parametrize(
    "field, bad",
    [
        ("d_u", [0.0, 0.0, 1.1]),
        ("d_u", [0.0, 0.5, 0.5]),
        ("d_u", [np.nan, 0.0, 1.0]),
        ("d_u", [0.0, 1.0]),
        ("y_j", np.nan),
        ("y_j", [0.1, 0.2]),
        ("b_omega", [np.nan, 0.0, 0.0]),
        ("b_l", [0.0, 0.0]),
    ],
)
def test_beam_factor_rejects_bad_input(field: str, bad: object) -> None:
    args: dict[str, object] = {
        "d_u": JANUS[0],
        "y_j": 0.3,
        "b_omega": GOOD["b_omega"],
        "b_l": GOOD["b_l"],
    }
    args[field] = bad
    noise = gtsam.noiseModel.Unit.Create(1)
    with pytest.raises(ValueError, match=field):
        make_dvl_beam_factor(noise, *KEYS, args["d_u"], args["y_j"], args["b_omega"], args["b_l"])


def test_factors_reject_noise_of_wrong_dimension() -> None:
    w, l = GOOD["b_omega"], GOOD["b_l"]
    with pytest.raises(ValueError, match="dimension"):
        make_dvl_velocity_factor(gtsam.noiseModel.Unit.Create(1), *KEYS, GOOD["d_y"], w, l)
    with pytest.raises(ValueError, match="dimension"):
        make_dvl_beam_factor(gtsam.noiseModel.Unit.Create(3), *KEYS, JANUS[0], 0.3, w, l)
    with pytest.raises(TypeError):
        make_dvl_velocity_factor(np.eye(3), *KEYS, GOOD["d_y"], w, l)  # type: ignore[arg-type]


def test_factor_copies_its_inputs() -> None:
    """A caller reusing its buffers must not change a factor already in the graph."""
    s = make_state("random", 6)
    y, w, l = s.y_model().copy(), s.b_omega.copy(), s.b_l.copy()
    factor = make_dvl_velocity_factor(gtsam.noiseModel.Unit.Create(3), *KEYS, y, w, l)
    y += 1.0
    w += 1.0
    l += 1.0
    assert np.abs(factor.unwhitenedError(s.values())).max() < ZERO_TOL


# ------------------------------------------------------------------------------------- end to end


@dataclass(frozen=True)
class Calibration:
    k: float
    b_R_d: np.ndarray


def solve_calibration(
    truth: Calibration, b_R_d0: np.ndarray, beams: list[list[int]] | None, n_epochs: int, seed: int
) -> tuple[float, gtsam.Rot3]:
    """Noise-free DVL data from `truth` at n_epochs states (poses and velocities fixed by tight priors,
    velocity directions and attitudes varying); scale and b_R_d free with weak priors at the nominal values,
    started from k = 0.8 and the nominal mounting b_R_d0. beams None: 3-D factors; else beams[i] lists the
    valid beams of epoch i (cycled)."""
    rng = np.random.default_rng(seed)
    graph = gtsam.NonlinearFactorGraph()
    initial = gtsam.Values()
    tight = 1e-6
    b_l = np.array([0.6, -0.1, -0.4])  # DVL forward, right, below the IMU
    for i in range(n_epochs):
        # tilts and headings
        n_R_b = rotvec(np.array([0.1, 0.1, np.pi]) * rng.uniform(-1.0, 1.0, size=3))
        speed = rng.uniform(0.5, 3.0)
        n_v = speed * unit(rng)
        b_omega = rng.normal(scale=0.05, size=3)
        pose = gtsam.Pose3(gtsam.Rot3(n_R_b), rng.normal(scale=50.0, size=3))
        graph.add(gtsam.PriorFactorPose3(X(i), pose, gtsam.noiseModel.Isotropic.Sigma(6, tight)))
        graph.add(gtsam.PriorFactorVector(V(i), n_v, gtsam.noiseModel.Isotropic.Sigma(3, tight)))
        initial.insert(X(i), pose)
        initial.insert(V(i), n_v)
        y = truth.k * truth.b_R_d.T @ (n_R_b.T @ n_v + np.cross(b_omega, b_l))
        keys = (X(i), V(i), K(0), B(0))
        if beams is None:
            noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.02)
            graph.add(make_dvl_velocity_factor(noise, *keys, y, b_omega, b_l))
        else:
            for j in beams[i % len(beams)]:
                graph.add(
                    make_dvl_beam_factor(
                        gtsam.noiseModel.Isotropic.Sigma(1, 0.02),
                        *keys,
                        JANUS[j],
                        JANUS[j] @ y,
                        b_omega,
                        b_l,
                    )
                )
    # Weak priors only make the problem well posed before the data do. Their pull on the optimum is about
    # (prior information / data information) * offset, 1e-6 / (1e3..1e4) * 0.1 rad: ~1e-11 here, 100x
    # inside CAL_TOL (sigma 100 would pull ~1e-9).
    weak = 1000.0
    graph.add(
        gtsam.PriorFactorVector(K(0), np.array([1.0]), gtsam.noiseModel.Isotropic.Sigma(1, weak))
    )
    graph.add(
        gtsam.PriorFactorRot3(B(0), gtsam.Rot3(b_R_d0), gtsam.noiseModel.Isotropic.Sigma(3, weak))
    )
    initial.insert(K(0), np.array([0.8]))
    initial.insert(B(0), gtsam.Rot3(b_R_d0))

    params = gtsam.LevenbergMarquardtParams()
    # the tight priors make normal equations ill-conditioned
    params.setLinearSolverType("MULTIFRONTAL_QR")
    params.setRelativeErrorTol(1e-15)
    params.setAbsoluteErrorTol(1e-20)
    params.setMaxIterations(100)
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()
    return float(result.atVector(K(0))[0]), result.atRot3(B(0))


# FLU roll, pitch, yaw of R_c (small)
PAPER = Calibration(0.9998, rotvec(np.radians([-0.1, 0.2, -0.5])))
LARGE = Calibration(1.05, rotvec(np.radians([2.0, -3.0, 5.0])) @ ROLL_180)


@pytest.mark.parametrize(
    "truth, b_R_d0, beams",
    [
        pytest.param(PAPER, np.eye(3), None, id="3d-paper"),
        pytest.param(LARGE, ROLL_180, None, id="3d-roll180-large"),
        pytest.param(PAPER, np.eye(3), [[0, 1, 2]], id="3-beams-paper"),
        pytest.param(LARGE, ROLL_180, [[1, 2, 3]], id="3-beams-roll180-large"),
        pytest.param(LARGE, ROLL_180, [[0, 2]], id="2-beams-roll180-large"),
        pytest.param(LARGE, ROLL_180, [[0], [1], [2], [3]], id="1-beam-rotating-roll180-large"),
    ],
)
def test_end_to_end_recovers_calibration(
    truth: Calibration, b_R_d0: np.ndarray, beams: list[list[int]] | None
) -> None:
    n_epochs = 8 if beams is None or len(beams[0]) >= 3 else 24
    k, b_R_d = solve_calibration(truth, b_R_d0, beams, n_epochs, seed=11)
    assert abs(k - truth.k) < CAL_TOL
    angle = np.linalg.norm(gtsam.Rot3(truth.b_R_d).localCoordinates(b_R_d))
    assert angle < CAL_TOL


# ------------------------------------------------------------------ options: time offset, lever arm, motion, beam

N_G = np.array([0.0, 0.0, -9.79])
OPTION_SETS = [
    pytest.param(
        offset,
        lever,
        beam,
        motion,
        id=f"offset{offset:d}-lever{lever:d}-beam{beam:d}-motion{motion:d}",
    )
    for offset in (False, True)
    for lever in (False, True)
    for beam in (False, True)
    for motion in (False, True)
]
OPTION_CASES = [
    (kind, seed) for kind in ("random", "near_identity", "roll_180") for seed in range(2)
]


def option_state(kind: str, seed: int, random_motion: Callable[..., PingMotion]) -> dict[str, Any]:
    """A state, the known inputs and a random IMU motion (large biases, so that the bias correction's curvature is
    exercised)."""
    rng = np.random.default_rng(100 + seed)
    n_R_b = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    b_R_d = Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix()
    if kind == "near_identity":
        n_R_b = Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
        b_R_d = Rotation.from_rotvec(1e-7 * rng.normal(size=3)).as_matrix()
    if kind == "roll_180":
        b_R_d = b_R_d @ ROLL_180
    d_u = rng.normal(size=3)
    return {
        "pose": gtsam.Pose3(gtsam.Rot3(n_R_b), rng.normal(size=3) * 200),
        "n_v": rng.normal(size=3) * 2,
        "bias": gtsam.imuBias.ConstantBias(0.05 * rng.normal(size=3), 0.02 * rng.normal(size=3)),
        "k": np.array([1.0 + 0.01 * rng.normal()]),
        "rot": gtsam.Rot3(b_R_d),
        "dt": np.array([rng.uniform(-1.0, 1.0)]),
        "b_l": rng.normal(size=3),
        "b_omega": 0.1 * rng.normal(size=3),
        "b_a": 0.2 * rng.normal(size=3) + n_R_b.T @ -N_G,
        "G": Rotation.from_rotvec(0.02 * rng.normal(size=3)).as_matrix()
        + 1e-4 * rng.normal(size=(3, 3)),
        "d_u": d_u / np.linalg.norm(d_u),
        "motion": random_motion(seed),
    }


def options_of(
    s: dict[str, Any], offset: bool, lever: bool, beam: bool, motion: bool, considered: bool = False
) -> tuple[DvlOptions, list[Any]]:
    """The options and the variables in their keys' order."""
    o = DvlOptions(
        s["b_omega"],
        s["b_l"],
        s["d_u"] if beam else None,
        OffsetInput(s["b_a"], N_G, s["G"]) if offset else None,
        s["motion"] if motion else None,
        lever,
        considered,
    )
    x = (
        [s["pose"], s["n_v"]]
        + [s["bias"]] * motion
        + [s["k"], s["rot"]]
        + [s["dt"]] * offset
        + [s["b_l"]] * lever
    )
    return o, x


def linearized(
    factor: gtsam.CustomFactor, x: list[Any], dims: list[int]
) -> tuple[np.ndarray, list[np.ndarray]]:
    """b and the Jacobian blocks (of dims columns) of factor linearised at the variables x (in its keys' order)."""
    values = gtsam.Values()
    for key, value in zip(factor.keys(), x, strict=True):
        values.insert(key, value)
    A, b = factor.linearize(values).jacobian()
    return b, np.split(A, np.cumsum(dims)[:-1], axis=1)


@pytest.mark.parametrize("offset, lever, beam, motion", OPTION_SETS)
@pytest.mark.parametrize("kind, seed", OPTION_CASES)
def test_every_option_against_numerical_derivatives(
    kind: str,
    seed: int,
    offset: bool,
    lever: bool,
    beam: bool,
    motion: bool,
    random_motion: Callable[..., PingMotion],
) -> None:
    """dvl_error's Jacobians against numerical derivatives on the manifold for every combination of options; the
    factor's linearisation equals them (unit noise); a lever arm as a variable gives the known-lever-arm error."""
    s = option_state(kind, seed, random_motion)
    o, x = options_of(s, offset, lever, beam, motion)
    y: np.ndarray | float = 0.3 if beam else np.array([0.3, -0.2, 0.1])  # a non-zero residual
    H: list[Any] = [None] * len(x)
    e = dvl_error(x, y, o, H)
    assert e.shape == ((1,) if beam else (3,))
    for i, (J, Jn) in enumerate(
        zip(H, numerical_jacobians(lambda *v: dvl_error(list(v), y, o), x), strict=True)
    ):
        assert J.shape == Jn.shape, f"block {i}"
        np.testing.assert_allclose(
            J, Jn, rtol=0.0, atol=1e-7 * max(1.0, float(np.abs(Jn).max())), err_msg=f"block {i}"
        )
    if lever:
        o_known, x_known = options_of(s, offset, False, beam, motion)
        np.testing.assert_allclose(dvl_error(x_known, y, o_known), e, atol=1e-14)
    keys = [X(0), V(0)] + [B(1)] * motion + [K(0), B(0)] + [T(0)] * offset + [L(0)] * lever
    factor = make_dvl_factor(gtsam.noiseModel.Unit.Create(len(e)), keys, y, o)
    b, blocks = linearized(factor, x, [J.shape[1] for J in H])
    np.testing.assert_allclose(b, -e, atol=1e-12)
    for i, J in enumerate(blocks):
        np.testing.assert_allclose(J, H[i], atol=1e-12, err_msg=f"linearize block {i}")


def test_options_reduce_to_the_base_case(
    random_motion: Callable[..., PingMotion], earth: tuple[np.ndarray, np.ndarray]
) -> None:
    """dt_d = 0 is the model without offset; no motion (PingMotion.none with the Earth model) is the ping at its
    state (zero bias columns); a considered factor keeps the error and zeroes the scale's and misalignment's
    Jacobians."""
    s = option_state("random", 0, random_motion)
    d_y = np.array([0.3, -0.2, 0.1])
    o, x = options_of(s, False, False, False, False)
    e = dvl_error(x, d_y, o)
    o_off, x_off = options_of(s, True, False, False, False)
    x_off[4] = np.array([0.0])
    np.testing.assert_allclose(dvl_error(x_off, d_y, o_off), e, atol=1e-14)
    still = dict(s, motion=PingMotion.none().motion(earth[0], N_G, np.zeros(3), np.zeros((3, 3))))
    o_m, x_m = options_of(still, False, False, False, True)
    H: list[Any] = [None] * 5
    np.testing.assert_allclose(dvl_error(x_m, d_y, o_m, H), e, atol=1e-14)
    assert np.array_equal(H[2], np.zeros((3, 6)))
    o_c, x_c = options_of(s, True, False, False, True, considered=True)
    Hc: list[Any] = [None] * 6
    np.testing.assert_allclose(
        dvl_error(x_c, d_y, o_c, Hc),
        dvl_error(x_c, d_y, options_of(s, True, False, False, True)[0]),
        atol=0,
    )
    assert not Hc[3].any() and not Hc[4].any() and Hc[5].any()


def test_lever_arm_along_the_rotation_axis_is_invisible(
    random_motion: Callable[..., PingMotion],
) -> None:
    """h depends on b_l only through b_omega x b_l: the Jacobian's null space is the rotation axis; its closed form
    is k b_R_d^T [b_omega]_x."""
    s = option_state("random", 0, random_motion)
    o, x = options_of(s, False, True, False, False)
    H: list[Any] = [None] * 5
    dvl_error(x, np.zeros(3), o, H)
    axis = s["b_omega"] / np.linalg.norm(s["b_omega"])
    assert np.linalg.norm(H[4] @ axis) < 1e-14
    assert np.linalg.matrix_rank(H[4], tol=1e-10) == 2
    k_d_R_b = s["k"][0] * s["rot"].matrix().T
    np.testing.assert_allclose(
        H[4], k_d_R_b @ np.cross(s["b_omega"], np.eye(3), axisb=0, axisc=0), atol=1e-14
    )


def test_option_factors_reject_bad_input(random_motion: Callable[..., PingMotion]) -> None:
    s = option_state("random", 1, random_motion)
    unit3 = gtsam.noiseModel.Unit.Create(3)
    o, _ = options_of(s, True, True, False, True)
    keys = [X(0), V(0), B(1), K(0), B(0), T(0), L(0)]
    with pytest.raises(ValueError, match="b_a"):
        make_dvl_factor(
            unit3,
            keys,
            np.zeros(3),
            replace(o, offset=OffsetInput(np.array([np.inf, 0, 0]), N_G, s["G"])),
        )
    with pytest.raises(ValueError, match="G must be"):
        make_dvl_factor(
            unit3, keys, np.zeros(3), replace(o, offset=OffsetInput(s["b_a"], N_G, np.eye(2)))
        )
    with pytest.raises(ValueError, match="7 keys"):
        make_dvl_factor(unit3, keys[:-1], np.zeros(3), o)
    with pytest.raises(ValueError, match="Earth model"):
        make_dvl_factor(unit3, keys, np.zeros(3), replace(o, motion=replace(s["motion"], n_G=None)))
    with pytest.raises(ValueError, match="unit vector"):
        make_dvl_factor(
            gtsam.noiseModel.Unit.Create(1), keys, 0.1, replace(o, d_u=np.array([1.0, 1.0, 0.0]))
        )


@pytest.mark.parametrize("beam", [False, True])
@pytest.mark.parametrize("offset, motion", [(False, False), (True, True)])
def test_correlated_error_variable(
    beam: bool, offset: bool, motion: bool, random_motion: Callable[..., PingMotion]
) -> None:
    """The DVL's correlated error E (error_variable, last key): h + E (a beam: d_u . E), its Jacobian and every
    other's against numerical derivatives, the factor's linearisation equal to them; E = 0 is the model without it."""
    s = option_state("random", 1, random_motion)
    o0, x0 = options_of(s, offset, False, beam, motion)
    o = replace(o0, error_variable=True)
    d_e = np.array([0.004, -0.003, 0.002])  # m/s, dvl_link
    x = [*x0, d_e]
    y: np.ndarray | float = 0.3 if beam else np.array([0.3, -0.2, 0.1])
    H: list[Any] = [None] * len(x)
    e = dvl_error(x, y, o, H)
    expected = dvl_error(x0, y, o0) + (s["d_u"] @ d_e if beam else d_e)  # an independent sum
    np.testing.assert_allclose(e, expected, atol=1e-15)
    np.testing.assert_allclose(dvl_error([*x0, np.zeros(3)], y, o), dvl_error(x0, y, o0), atol=0)
    for i, (J, Jn) in enumerate(
        zip(H, numerical_jacobians(lambda *v: dvl_error(list(v), y, o), x), strict=True)
    ):
        np.testing.assert_allclose(
            J, Jn, rtol=0.0, atol=1e-7 * max(1.0, float(np.abs(Jn).max())), err_msg=f"block {i}"
        )
    keys = [X(0), V(0)] + [B(1)] * motion + [K(0), B(0)] + [T(0)] * offset + [L(0)]
    factor = make_dvl_factor(gtsam.noiseModel.Unit.Create(len(e)), keys, y, o)
    b, blocks = linearized(factor, x, [J.shape[1] for J in H])
    np.testing.assert_allclose(b, -e, atol=1e-12)
    for i, J in enumerate(blocks):
        np.testing.assert_allclose(J, H[i], atol=1e-12, err_msg=f"linearize block {i}")


@pytest.mark.parametrize("beam", [False, True])
@pytest.mark.parametrize("offset, motion, error", [(False, False, False), (True, True, True)])
def test_water_current_variable(
    beam: bool, offset: bool, motion: bool, error: bool, random_motion: Callable[..., PingMotion]
) -> None:
    """A water-track ping (current_variable, last key W = [c_east, c_north]): the model of the velocity relative to
    the water, i.e. the bottom-track factor at n_v - [W, 0] (an independent evaluation), its Jacobian and every
    other's against numerical derivatives, the factor's linearisation equal to them; W = 0 is bottom track."""
    s = option_state("random", 1, random_motion)
    o0, x0 = options_of(s, offset, False, beam, motion)
    o0 = replace(o0, error_variable=error)
    x0 = [*x0, np.array([0.004, -0.003, 0.002])] if error else x0
    o = replace(o0, current_variable=True)
    n_c = np.array([0.35, -0.22])  # m/s, east and north
    x = [*x0, n_c]
    y: np.ndarray | float = 0.3 if beam else np.array([0.3, -0.2, 0.1])
    H: list[Any] = [None] * len(x)
    e = dvl_error(x, y, o, H)
    x_water = list(x0)
    # the velocity relative to the water
    x_water[1] = np.asarray(x0[1]) - np.array([n_c[0], n_c[1], 0.0])
    np.testing.assert_allclose(e, dvl_error(x_water, y, o0), atol=1e-15)
    np.testing.assert_allclose(dvl_error([*x0, np.zeros(2)], y, o), dvl_error(x0, y, o0), atol=0)
    assert np.abs(e - dvl_error(x0, y, o0)).max() > 0.1  # the current matters
    for i, (J, Jn) in enumerate(
        zip(H, numerical_jacobians(lambda *v: dvl_error(list(v), y, o), x), strict=True)
    ):
        np.testing.assert_allclose(
            J, Jn, rtol=0.0, atol=1e-7 * max(1.0, float(np.abs(Jn).max())), err_msg=f"block {i}"
        )
    keys = (
        [X(0), V(0)]
        + [B(1)] * motion
        + [K(0), B(0)]
        + [T(0)] * offset
        + [L(0)] * error
        + [gtsam.symbol("w", 0)]
    )
    factor = make_dvl_factor(gtsam.noiseModel.Unit.Create(len(e)), keys, y, o)
    b, blocks = linearized(factor, x, [J.shape[1] for J in H])
    np.testing.assert_allclose(b, -e, atol=1e-12)
    for i, J in enumerate(blocks):
        np.testing.assert_allclose(J, H[i], atol=1e-12, err_msg=f"linearize block {i}")
