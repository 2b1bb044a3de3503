"""Tests of EarthImuFactor (factors/imu_earth.py), GTSAM style: the state predicted by the preintegration
gives zero error, and every Jacobian matches central differences through retract (Pose3 tangent [rotation,
translation] on the right, Vector3, ConstantBias [acc, gyro]) at random states, near-identity rotations
(1e-7 rad), states 20 km from the map origin, with gravity following position (the estimators' WGS-84
model, and an analytic model with a large gradient) and constant (gravity=None). Then: the graph error does
not depend on the order the factors are evaluated in, and a parameters object serves one factor only.

The factor's error, once referenced, is e(x) = ImuFactor error with n_g = ref_g + ref_G (n_p_mid(x) - ref_p):
the numerical derivatives are of that function (reference set first, then perturbed).
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, V, X
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame, normal_gravity
from gtsam_dvl.core.types import Mounting
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.alignment import Alignment
from gtsam_dvl.factors import EarthImuFactor, GravityModel, imu_earth, make_earth_imu_factor
from tests.support.numerical import numerical_jacobians

FRAME = LocalFrame(30.0, 120.0, -50.0)
KEYS = (X(0), V(0), X(1), V(1), B(0))
DIMS = (6, 3, 6, 3, 6)
FAR = np.array([20000.0, -3000.0, -150.0])  # m from the map origin: gravity has turned by 3 mrad
TINY = 1e-7  # rad: the small-angle paths of retract, Logmap and the Jacobians
# error at the predicted state (rad, m, m/s); positions of 2e4 m have an ulp of 4e-12 m
ZERO_TOL = 1e-9
# Analytic vs numerical Jacobian: each group of 3 columns (rotation, translation, velocity, accelerometer,
# gyroscope; their scales differ by 1e3) to JAC_RTOL of its largest entry. Central differences of step STEP
# (1e-4, not GTSAM's default 1e-5): rounding is the floor at 20 km, where positions carry 4e-12 m, i.e.
# 2e-8 over a 2e-4 difference (2e-7 with 1e-5, too close to the tolerance) for translation entries of
# order 1; the truncation error, step^2 times the curvature, is below 1e-7 relative in the rotation
# columns (measured worst over all cases: 1e-7 relative). 1e-6 is 10x above both and far below the
# gravity-gradient term under test (1e-2 relative with the analytic model, 7e-5 with WGS-84 over 10 s;
# test_gradient_term_is_visible checks it would be caught).
JAC_RTOL = 1e-6
STEP = 1e-4
DT = {"earth": 10.0, "analytic": 2.0, "none": 1.0}  # s of preintegration per gravity kind


def earth_gravity() -> GravityModel:
    """The estimators' model (WGS-84 normal gravity plus the centrifugal fix, and its gradient)."""
    maker = FactorMaker(
        EstimatorConfig.paper(), FRAME, Alignment(np.eye(3), 0.0, "configured"), Mounting()
    )
    return maker.gravity_model


def analytic_gravity(rng: np.random.Generator, centre: np.ndarray) -> GravityModel:
    """g = g0 + A (p - c) + quadratic: a gradient 1e4 x the Earth's, so its Jacobian term is large; the
    quadratic term is not followed by the factor's linear extrapolation (reference set first)."""
    g0 = np.array([0.0, 0.0, -9.8])
    A = rng.normal(scale=1e-2, size=(3, 3))
    q = rng.normal(scale=1e-5, size=3)

    def model(n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = np.asarray(n_p, dtype=float) - centre
        g = g0 + d @ A.T + (d * d).sum(axis=-1, keepdims=True) * q
        G = A + 2.0 * q[:, None] * d[..., None, :]
        return g, G

    return model


def unit(rng: np.random.Generator) -> np.ndarray:
    u = rng.normal(size=3)
    return u / np.linalg.norm(u)


def rot(v: np.ndarray) -> gtsam.Rot3:
    return gtsam.Rot3(Rotation.from_rotvec(v).as_matrix())


def make_params() -> gtsam.PreintegrationParams:
    params = gtsam.PreintegrationParams(
        np.array([0.0, 0.0, -normal_gravity(FRAME.lat0, FRAME.height_m)])
    )
    params.setAccelerometerCovariance(np.eye(3) * 1e-6)
    params.setGyroscopeCovariance(np.eye(3) * 1e-8)
    params.setIntegrationCovariance(np.eye(3) * 1e-10)
    params.setOmegaCoriolis(FRAME.n_omega_ie)
    return params


def preintegrate(
    rng: np.random.Generator,
    params: gtsam.PreintegrationParams,
    dt: float,
    n_R_b: gtsam.Rot3,
    near_identity: bool,
    bias_hat: gtsam.imuBias.ConstantBias,
) -> gtsam.PreintegratedImuMeasurements:
    """n samples over dt: a manoeuvring vehicle, or (near_identity) one that keeps its attitude (the gyro
    sees Earth rate, and a 1e-7 rad turn)."""
    pim = gtsam.PreintegratedImuMeasurements(params, bias_hat)
    n = 50
    b_g = -n_R_b.matrix().T @ params.n_gravity
    for _ in range(n):
        b_f = b_g + rng.normal(scale=0.3, size=3)
        if near_identity:
            b_omega = n_R_b.matrix().T @ FRAME.n_omega_ie + TINY / dt * unit(rng)
        else:
            b_omega = rng.normal(scale=0.1, size=3)
        pim.integrateMeasurement(b_f, b_omega, dt / n)
    return pim


@dataclass
class Case:
    factor: EarthImuFactor
    pim: gtsam.PreintegratedImuMeasurements
    pose_i: gtsam.Pose3
    v_i: np.ndarray
    pose_j: gtsam.Pose3
    v_j: np.ndarray
    bias: gtsam.imuBias.ConstantBias

    def values(self) -> gtsam.Values:
        return make_values(self.pose_i, self.v_i, self.pose_j, self.v_j, self.bias)

    def args(
        self,
    ) -> tuple[gtsam.Pose3, np.ndarray, gtsam.Pose3, np.ndarray, gtsam.imuBias.ConstantBias]:
        return self.pose_i, self.v_i, self.pose_j, self.v_j, self.bias


def make_values(
    pose_i: gtsam.Pose3,
    v_i: np.ndarray,
    pose_j: gtsam.Pose3,
    v_j: np.ndarray,
    bias: gtsam.imuBias.ConstantBias,
    keys: tuple[int, ...] = KEYS,
) -> gtsam.Values:
    values = gtsam.Values()
    values.insert(keys[0], pose_i)
    values.insert(keys[1], np.asarray(v_i, dtype=float))
    values.insert(keys[2], pose_j)
    values.insert(keys[3], np.asarray(v_j, dtype=float))
    values.insert(keys[4], bias)
    return values


def make_case(
    gravity_kind: str,
    kind: str,
    seed: int,
    residual: str = "none",
    keys: tuple[int, int, int, int, int] = KEYS,
) -> Case:
    """State i at random (or near-identity attitude, or FAR away), a preintegration from it, the reference
    at 30 m from the mid position, and state j predicted with the factor's own gravity (fixed point in the
    mid position), so the error is zero; residual "pv" then moves positions, velocities and the accelerometer
    bias (the rotation error stays zero), "rot" also the attitudes and the gyro bias."""
    rng = np.random.default_rng(seed)
    near_identity = kind in ("near_identity", "far_near_identity")
    n_p_i = rng.normal(scale=100.0, size=3) + (FAR if kind.startswith("far") else 0.0)
    n_R_b = (
        rot(TINY * unit(rng))
        if near_identity
        else gtsam.Rot3(Rotation.random(random_state=rng).as_matrix())
    )
    pose_i, v_i = gtsam.Pose3(n_R_b, n_p_i), rng.normal(scale=1.5, size=3)
    gyro = 0.0 if near_identity else 1.0
    bias_hat = gtsam.imuBias.ConstantBias(
        rng.normal(scale=1e-3, size=3), gyro * rng.normal(scale=1e-4, size=3)
    )
    bias = gtsam.imuBias.ConstantBias(
        bias_hat.accelerometer() + rng.normal(scale=1e-3, size=3),
        bias_hat.gyroscope() + gyro * rng.normal(scale=1e-4, size=3),
    )
    dt = DT[gravity_kind]
    params = make_params()
    pim = preintegrate(rng, params, dt, n_R_b, near_identity, bias_hat)
    model = {
        "earth": earth_gravity,
        "analytic": lambda: analytic_gravity(rng, n_p_i),
        "none": lambda: None,
    }[gravity_kind]()
    factor = make_earth_imu_factor(pim, params, keys, dt, model)
    state = pim.predict(gtsam.NavState(pose_i, v_i), bias)
    if model is not None:
        ref = 0.5 * (n_p_i + state.position()) + rng.normal(scale=30.0 / np.sqrt(3.0), size=3)
        factor.set_reference(ref, *model(ref))
        for _ in range(50):  # contraction 1/4 dt^2 |G| < 0.1
            factor.set_gravity(0.5 * (n_p_i + state.position()))
            new = pim.predict(gtsam.NavState(pose_i, v_i), bias)
            moved = np.abs(new.position() - state.position()).max()
            state = new
            if moved < 1e-12 * (1.0 + np.abs(state.position()).max()):
                break
    pose_j, v_j = state.pose(), state.velocity()
    if residual in ("pv", "rot"):
        pose_i = gtsam.Pose3(
            pose_i.rotation(), pose_i.translation() + rng.normal(scale=0.5, size=3)
        )
        pose_j = gtsam.Pose3(
            pose_j.rotation(), pose_j.translation() + rng.normal(scale=0.5, size=3)
        )
        v_i, v_j = v_i + rng.normal(scale=0.1, size=3), v_j + rng.normal(scale=0.1, size=3)
        bias = gtsam.imuBias.ConstantBias(
            bias.accelerometer() + rng.normal(scale=1e-2, size=3), bias.gyroscope()
        )
    if residual == "rot":
        pose_i = gtsam.Pose3(
            pose_i.rotation().retract(rng.normal(scale=1e-2, size=3)), pose_i.translation()
        )
        pose_j = gtsam.Pose3(
            pose_j.rotation().retract(rng.normal(scale=1e-2, size=3)), pose_j.translation()
        )
        bias = gtsam.imuBias.ConstantBias(
            bias.accelerometer(), bias.gyroscope() + rng.normal(scale=1e-3, size=3)
        )
    return Case(factor, pim, pose_i, v_i, pose_j, v_j, bias)


def analytic(case: Case) -> tuple[np.ndarray, list[np.ndarray]]:
    H: list[np.ndarray | None] = [None] * 5
    e = case.factor(None, case.values(), H)
    assert all(J is not None for J in H)
    return e, [J for J in H if J is not None]


def numerical(case: Case) -> list[np.ndarray]:
    def h(
        pose_i: gtsam.Pose3,
        v_i: np.ndarray,
        pose_j: gtsam.Pose3,
        v_j: np.ndarray,
        bias: gtsam.imuBias.ConstantBias,
    ) -> np.ndarray:
        return case.factor(None, make_values(pose_i, v_i, pose_j, v_j, bias), None)

    return numerical_jacobians(h, case.args(), delta=STEP)


def column_groups(J: np.ndarray) -> list[slice]:
    """Columns by 3 (rotation, translation, velocity, accelerometer, gyroscope): their scales differ by 1e3."""
    return [slice(c, c + 3) for c in range(0, J.shape[1], 3)]


def discrepancy(J: np.ndarray, J_num: np.ndarray) -> tuple[float, float]:
    """Worst (absolute, relative to its column group's largest entry)."""
    worst = (0.0, 0.0)
    for c in column_groups(J_num):
        err = float(np.abs(J[:, c] - J_num[:, c]).max())
        worst = max(worst[0], err), max(worst[1], err / (float(np.abs(J_num[:, c]).max()) or 1.0))
    return worst


def assert_jacobian_close(J: np.ndarray, J_num: np.ndarray, what: str, extra: float = 0.0) -> None:
    """Each column group to JAC_RTOL of its largest entry (plus extra, absolute)."""
    assert J.shape == J_num.shape, what
    for c in column_groups(J_num):
        scale = float(np.abs(J_num[:, c]).max()) or 1.0
        np.testing.assert_allclose(
            J[:, c],
            J_num[:, c],
            rtol=0.0,
            atol=JAC_RTOL * scale + extra,
            err_msg=f"{what}, columns {c.start}:{c.stop}",
        )


GRAVITY_KINDS = ("earth", "analytic", "none")
STATE_KINDS = {"random": 3, "near_identity": 2, "far": 3, "far_near_identity": 2}
CASES = [
    pytest.param(g, kind, 100 * i + s, id=f"{g}-{kind}-{s}")
    for g in GRAVITY_KINDS
    for i, (kind, n) in enumerate(STATE_KINDS.items())
    for s in range(n)
]


# ---------------------------------------------------------------------------------------- one factor


@pytest.mark.parametrize("gravity, kind, seed", CASES)
def test_zero_error_at_predicted_state(gravity: str, kind: str, seed: int) -> None:
    case = make_case(gravity, kind, seed)
    e = case.factor(None, case.values(), None)
    assert e.shape == (9,)
    assert np.abs(e).max() < ZERO_TOL
    assert case.factor.factor.error(case.values()) < 1e-6  # whitened: information up to 1e10


@pytest.mark.parametrize("residual", ["none", "pv"])
@pytest.mark.parametrize("gravity, kind, seed", CASES)
def test_jacobians_match_numerical(gravity: str, kind: str, seed: int, residual: str) -> None:
    """Exact (to JAC_RTOL) at zero error and with position, velocity and accelerometer-bias residuals."""
    case = make_case(gravity, kind, seed, residual)
    e, H = analytic(case)
    if residual == "pv":
        # a real residual, no rotation
        assert np.abs(e[3:]).max() > 0.1 and np.abs(e[:3]).max() < ZERO_TOL
    for k, (J, J_num) in enumerate(zip(H, numerical(case), strict=True)):
        assert J.shape == (9, DIMS[k])
        assert_jacobian_close(J, J_num, f"H[{k}]")


@pytest.mark.parametrize(
    "gravity, kind, seed", [c for c in CASES if "near_identity" not in c.values[1]]
)
def test_jacobians_with_rotation_residual(gravity: str, kind: str, seed: int) -> None:
    """With a rotation error phi the gravity-gradient term (translation columns of X_i and X_j) is off by a
    relative O(|phi|) (module doc); every other column is exact, and without a gravity model all are."""
    case = make_case(gravity, kind, seed, "rot")
    e, H = analytic(case)
    phi = float(np.linalg.norm(e[:3]))
    assert phi > 1e-3
    raw = [np.zeros((9, d), order="F") for d in DIMS]
    case.factor.model.imu.evaluateError(*case.args(), *raw)
    for k, (J, J_num) in enumerate(zip(H, numerical(case), strict=True)):
        if k in (0, 2):
            assert_jacobian_close(J[:, :3], J_num[:, :3], f"H[{k}] rotation")
            term = float(np.abs(J - raw[k]).max())  # the gradient term (zero if gravity is None)
            assert_jacobian_close(J[:, 3:], J_num[:, 3:], f"H[{k}] translation", extra=phi * term)
        else:
            assert_jacobian_close(J, J_num, f"H[{k}]")


@pytest.mark.parametrize("gravity, margin", [("earth", 20.0), ("analytic", 1000.0)])
def test_gradient_term_is_visible(gravity: str, margin: float) -> None:
    """The gradient term is well above the tolerance (WGS-84 over 10 s: 1/4 dt^2 |G| = 7e-5, the analytic
    model: 1e-2), so the comparisons above do test it: without it (GTSAM's ImuFactor Jacobians at fixed
    gravity) the translation columns would fail."""
    case = make_case(gravity, "far", 7, "pv")
    _, H = analytic(case)
    raw = [np.zeros((9, d), order="F") for d in DIMS]
    case.factor.model.imu.evaluateError(*case.args(), *raw)
    num = numerical(case)
    for k in (0, 2):
        t = slice(3, 6)
        assert (
            np.abs(raw[k][:, t] - num[k][:, t]).max()
            > margin * JAC_RTOL * np.abs(num[k][:, t]).max()
        )
        assert_jacobian_close(H[k], num[k], f"H[{k}]")


@pytest.mark.parametrize("gravity, kind, seed", [CASES[0], CASES[7], CASES[10], CASES[-1]])
def test_linearize_is_the_whitened_jacobian(gravity: str, kind: str, seed: int) -> None:
    """Through GTSAM: linearize gives A = R J and b = -R e with R the preintegration covariance's
    square-root information; compared with the whitened numerical derivative."""
    case = make_case(gravity, kind, seed, "pv")
    noise = gtsam.noiseModel.Gaussian.Covariance(case.pim.preintMeasCov())
    e = case.factor(None, case.values(), None)
    linear = case.factor.factor.linearize(case.values())
    assert list(linear.keys()) == list(KEYS)
    A, b = linear.jacobian()
    np.testing.assert_allclose(b, -noise.whiten(e), rtol=1e-9, atol=1e-9 * np.abs(b).max())
    for k, J in enumerate(np.split(A, np.cumsum(DIMS)[:-1], axis=1)):
        assert_jacobian_close(J, noise.Whiten(numerical(case)[k]), f"linearize block {k}")


def test_jacobian_uses_the_preintegrated_time() -> None:
    """Gravity enters GTSAM's prediction times the pim's deltaTij: a dt argument that differs (an interval
    with an IMU gap) must not change the Jacobian."""
    case = make_case("analytic", "far", 11, "pv")
    pim, f = case.pim, case.factor
    params = make_params()
    pim2 = gtsam.PreintegratedImuMeasurements(params, pim.biasHat())
    rng = np.random.default_rng(11)
    for _ in range(20):
        pim2.integrateMeasurement(
            rng.normal(size=3) + [0.0, 0.0, 9.8], rng.normal(scale=0.1, size=3), 0.1
        )
    short = make_earth_imu_factor(pim2, params, KEYS, 2.5, f.model.gravity)  # 2 s integrated
    short.set_reference(f.model.ref_p, f.model.ref_g, f.model.ref_G)
    # for a zero rotation error
    state = pim2.predict(gtsam.NavState(case.pose_i, case.v_i), case.bias)
    pose_j = gtsam.Pose3(state.attitude(), state.position() + rng.normal(scale=0.5, size=3))
    gapped = Case(
        short,
        pim2,
        case.pose_i,
        case.v_i,
        pose_j,
        state.velocity() + rng.normal(scale=0.1, size=3),
        case.bias,
    )
    _, H = analytic(gapped)
    for k, (J, J_num) in enumerate(zip(H, numerical(gapped), strict=True)):
        assert_jacobian_close(J, J_num, f"H[{k}]")


def test_first_evaluation_takes_the_reference() -> None:
    """Without a reference the first evaluation takes it at its own mid position (then extrapolates)."""
    case = make_case("earth", "far", 3, "pv")
    model = case.factor.model.gravity
    assert model is not None
    params = make_params()
    pim = preintegrate(
        np.random.default_rng(3), params, 10.0, case.pose_i.rotation(), False, case.pim.biasHat()
    )
    lazy = make_earth_imu_factor(pim, params, KEYS, 10.0, model)
    assert lazy.model.ref_p is None and lazy.needs_reference(np.zeros(3))
    e_lazy = lazy(None, case.values(), None)
    mid = 0.5 * (case.pose_i.translation() + case.pose_j.translation())
    np.testing.assert_array_equal(lazy.model.ref_p, mid)
    g, G = model(mid)
    np.testing.assert_array_equal(lazy.model.ref_g, g)
    np.testing.assert_array_equal(params.n_gravity, g)
    assert not lazy.needs_reference(mid + 99.0) and lazy.needs_reference(mid + [0.0, 101.0, 0.0])
    lazy.set_reference(mid, g, G)
    np.testing.assert_array_equal(lazy(None, case.values(), None), e_lazy)


# ---------------------------------------------------------------------------- several factors, order


def chain(n: int, seed: int) -> tuple[list[EarthImuFactor], gtsam.Values, gtsam.Values]:
    """n factors X_k -> X_k+1 (each its own params: WGS-84 far away, the analytic model, constant gravity),
    referenced as the builder does; values with residuals, and other values for the interleaving."""
    kinds = ["earth", "analytic", "none"]
    factors, values, other = [], gtsam.Values(), gtsam.Values()
    rng = np.random.default_rng(seed)
    for k in range(n):
        keys = (X(k), V(k), X(k + 1), V(k + 1), B(k))
        case = make_case(kinds[k % 3], "far", seed + k, "rot", keys)
        factors.append(case.factor)
        for key, value in zip(keys, case.args(), strict=True):
            # consecutive factors share a state: keep the first's (a residual)
            if values.exists(key):
                continue
            values.insert(key, value)
            moved: object
            if isinstance(value, gtsam.Pose3):
                moved = gtsam.Pose3(
                    value.rotation().retract(rng.normal(scale=1e-2, size=3)),
                    value.translation() + rng.normal(scale=500.0, size=3),
                )
            elif isinstance(value, gtsam.imuBias.ConstantBias):
                moved = value.retract(rng.normal(scale=1e-3, size=6))
            else:
                moved = value + rng.normal(size=3)
            other.insert(key, moved)
    return factors, values, other


def test_graph_error_does_not_depend_on_evaluation_order() -> None:
    factors, values, other = chain(6, 40)
    graph = gtsam.NonlinearFactorGraph()
    for f in factors:
        graph.add(f.factor)
    forward = [f.factor.error(values) for f in factors]
    assert min(forward) > 1.0  # real residuals
    reverse = [f.factor.error(values) for f in reversed(factors)][::-1]
    assert forward == reverse
    total = graph.error(values)
    assert total == pytest.approx(sum(forward), rel=1e-13)
    lin_forward = [f.factor.linearize(values).jacobian() for f in factors]
    graph.error(other)
    graph.linearize(other)
    lin_reverse = [f.factor.linearize(values).jacobian() for f in reversed(factors)][::-1]
    for (A1, b1), (A2, b2) in zip(lin_forward, lin_reverse, strict=True):
        np.testing.assert_array_equal(A1, A2)
        np.testing.assert_array_equal(b1, b2)
    assert graph.error(values) == total
    for a in factors:  # one factor evaluated elsewhere in between leaves the others unchanged
        a.factor.error(other)
        a.factor.linearize(other)
        assert [f.factor.error(values) for f in factors] == forward


# ------------------------------------------------------------------------------ shared parameters


def test_shared_params_would_give_wrong_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    """What sharing would do, with the protection switched off: three factors on one parameters object,
    a and c with WGS-84 gravity (a 20 km away, c at the origin), b with constant gravity."""
    monkeypatch.setattr(imu_earth, "_check_free", lambda params: None)
    rng = np.random.default_rng(5)
    params = make_params()
    pims = [
        preintegrate(rng, params, 1.0, gtsam.Rot3(), False, gtsam.imuBias.ConstantBias())
        for _ in range(3)
    ]
    model = earth_gravity()
    keys = [(X(2 * k), V(2 * k), X(2 * k + 1), V(2 * k + 1), B(k)) for k in range(3)]
    b = make_earth_imu_factor(pims[1], params, keys[1], 1.0, None)  # constant: the origin's gravity
    a = make_earth_imu_factor(pims[0], params, keys[0], 1.0, model)
    c = make_earth_imu_factor(pims[2], params, keys[2], 1.0, model)
    state, zero_bias = gtsam.NavState(), gtsam.imuBias.ConstantBias()

    def at(n_p: np.ndarray, key: tuple[int, int, int, int, int]) -> gtsam.Values:
        pose = gtsam.Pose3(gtsam.Rot3(), n_p)
        return make_values(pose, np.zeros(3), pose, np.zeros(3), zero_bias, key)

    values_b = at(np.zeros(3), keys[1])
    e_b = b(None, values_b, None)
    a(None, at(FAR, keys[0]), None)  # writes a's gravity, 20 km away, into the shared object
    e_b_after = b(None, values_b, None)
    print(
        f"constant-gravity factor's error moved by {np.abs(e_b_after - e_b).max():.2e} (rad, m, m/s)"
    )
    # b's error depends on whether a was evaluated before it
    assert np.abs(e_b_after - e_b).max() > 1e-2
    # The pims predict with whichever factor was set last: the builder sets all, then predicts each
    a.set_gravity(FAR)
    own = pims[0].predict(state, zero_bias).velocity()
    c.set_gravity(np.zeros(3))
    shared = pims[0].predict(state, zero_bias).velocity()
    assert np.abs(own - shared).max() > 1e-2
    # (each factor writes before it evaluates, so a and c's own errors are still right; b's is not)


def test_shared_params_are_rejected() -> None:
    case = make_case("earth", "far", 5, "pv")
    a = case.factor
    before = np.array(a.model.params.n_gravity)
    rng = np.random.default_rng(5)
    pim_b = preintegrate(
        rng, a.model.params, 1.0, gtsam.Rot3(), False, gtsam.imuBias.ConstantBias()
    )
    keys_b = (X(5), V(5), X(6), V(6), B(5))
    for gravity in (None, a.model.gravity):
        with pytest.raises(ValueError, match="already serve another EarthImuFactor"):
            make_earth_imu_factor(pim_b, a.model.params, keys_b, 1.0, gravity)
        with pytest.raises(ValueError, match="already serve another EarthImuFactor"):
            # the same pim twice
            make_earth_imu_factor(case.pim, a.model.params, keys_b, 1.0, gravity)
    np.testing.assert_array_equal(a.model.params.n_gravity, before)


def test_params_not_the_pims_are_rejected() -> None:
    rng = np.random.default_rng(6)
    params, stranger = make_params(), make_params()
    pim = preintegrate(rng, params, 1.0, gtsam.Rot3(), False, gtsam.imuBias.ConstantBias())
    model = earth_gravity()
    with pytest.raises(ValueError, match="not the parameters object the pim was made with"):
        make_earth_imu_factor(pim, stranger, KEYS, 1.0, model)
    np.testing.assert_array_equal(stranger.n_gravity, params.n_gravity)  # the probe restored it
    pose = gtsam.Pose3(gtsam.Rot3(), FAR)
    values = make_values(pose, np.zeros(3), pose, np.zeros(3), gtsam.imuBias.ConstantBias())
    imu = gtsam.ImuFactor(*KEYS, pim)
    constant = imu.evaluateError(pose, np.zeros(3), pose, np.zeros(3), gtsam.imuBias.ConstantBias())
    stranger.n_gravity = model(FAR)[
        0
    ]  # why: what the factor would write never reaches the prediction
    np.testing.assert_array_equal(
        imu.evaluateError(pose, np.zeros(3), pose, np.zeros(3), gtsam.imuBias.ConstantBias()),
        constant,
    )
    f = make_earth_imu_factor(pim, params, KEYS, 1.0, model)  # the rejection did not claim params
    assert np.abs(f(None, values, None) - constant).max() > 1e-2  # its own params do reach it


def test_one_params_per_factor_is_accepted_and_untouched() -> None:
    """The builder's use (one params per interval): accepted, and the check leaves the parameters as they
    were (bit for bit)."""
    rng = np.random.default_rng(8)
    model = earth_gravity()
    for i in range(20):
        params = make_params()
        g = np.array(params.n_gravity)
        pim = preintegrate(rng, params, 0.5, gtsam.Rot3(), False, gtsam.imuBias.ConstantBias())
        f = make_earth_imu_factor(
            pim, params, (X(i), V(i), X(i + 1), V(i + 1), B(0)), 0.5, model if i % 2 else None
        )
        np.testing.assert_array_equal(params.n_gravity, g)
        np.testing.assert_array_equal(f.model.ref_g, g)
