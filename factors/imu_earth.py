"""GTSAM's preintegrated IMU factor with gravity as a function of position (Earth model in `map`).

    e = ImuFactor error (X_i, V_i, X_j, V_j, B) with n_g = g(n_p_mid),  n_p_mid = (n_p_i + n_p_j) / 2

GTSAM's ImuFactor takes gravity as a constant of its parameters. In the Earth-fixed map frame gravity
turns with position (1.6e-7 rad per metre, plus the vertical free-air gradient), and over kilometres a
constant gravity is wrong by more than the accelerometer bias being estimated. Evaluating g at the
current positions without its derivative leaves the solver a slow (or, over long runs, divergent) fixed
point; this factor adds the gradient term to the translation Jacobians so that Gauss-Newton converges as
on the true model:

    de/d(xi_t_i) += de/dg * G * 1/2 * n_R_b_i,   de/dg = [0; n_R_b_j^T M_p; n_R_b_j^T M_v]

(error order [rotation, position, velocity] in the frame of state j; translation tangents in body axes).
M = [M_p; M_v] = d(predicted n_p, n_v) / d n_g is [1/2 dt^2 I; dt I] (dt the pim's deltaTij) in an inertial
frame; with omegaCoriolis set GTSAM 4.3 predicts in the rotating frame and M also carries the Earth-rate
transport of the gravity terms (a relative omega dt, 1.5e-4 over 2 s). The prediction is affine in gravity,
so each factor measures M once, exactly, from its pim. GTSAM's error is the SE_2(3) logarithm of
X_j^-1 * prediction, so de/dg is exact when the rotation error is zero (whatever the position and velocity
errors) and off by a relative O(|rotation error|) otherwise, which only affects the convergence rate,
never the solution (tests/factors/test_imu_earth.py). The gravity model is a callable returning g and its
gradient G at positions; it is evaluated at a reference position and extrapolated linearly; whoever drives
the solver re-references factors whose mid position moved more than REFRESH_M (the quadratic term over
100 m is below 1e-8 m/s^2), in bulk (refresh_gravity of the estimators' graphs).
A factor evaluated before it has a reference takes it at the mid position of that first evaluation.

Gravity reaches GTSAM through the parameters object: the factor writes its n_gravity before every
evaluation (set_gravity), and the pim, which holds a shared pointer to the same object, predicts with it
(the batch graph's initial guess and the online window call set_gravity before pim.predict for that reason).
So each factor needs its own PreintegrationParams, the one its pim was made with; make_earth_imu_factor
(and EarthImuFactor itself) refuse, with ValueError, parameters that are not the pim's or that already
serve another EarthImuFactor: a second factor writing the same object would move the first one's
gravity (a constant-gravity factor, which never writes, would then evaluate with the other's gravity,
and pim.predict would use whichever factor was set last). With one object per factor, each error is a
function of the values and the factor's own reference only, whatever the evaluation order: GTSAM marks
CustomFactor not sendable, so Python factors are linearized one at a time, and write-then-evaluate
cannot interleave.

Memory: the CustomFactor holds its Python callback through C++ (a std::function), where the garbage collector
cannot see it. The callback is therefore a separate model object (_EarthImuModel) with only the data the error
needs, never the EarthImuFactor or the CustomFactor: EarthImuFactor -> CustomFactor -> model, no cycle, so
when a graph (iSAM2's fixed-lag window, marginalising a state) and the caller drop a factor, it is freed at
once, its parameters' claim with it. (An EarthImuFactor that were its own callback would make a cycle through
C++ that keeps every IMU factor of a mission alive and all their parameters claimed;
tests/estimators/test_online_memory.py checks that dropped factors are freed.)
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar, cast

import gtsam
import numpy as np

GravityModel = Callable[
    [np.ndarray], tuple[np.ndarray, np.ndarray]
]  # n_p (3,) -> (g (3,), G (3, 3))
REFRESH_M = 100.0
_DIMS = (6, 3, 6, 3, 6)

# Parameters objects in use by an EarthImuFactor. Weak, so the set never keeps parameters alive itself: a claim
# ends when the factor's last holder (the Python object or a graph holding its CustomFactor) lets it go.
_CLAIMED: weakref.WeakSet[gtsam.PreintegrationParams] = weakref.WeakSet()
_PROBE_DG = 1.0  # m/s^2, the gravity change of _gravity_map's probe
_PROBES = _PROBE_DG * np.eye(3)
_ORIGIN, _NO_BIAS = gtsam.NavState(), gtsam.imuBias.ConstantBias()


def _gravity_map(
    pim: gtsam.PreintegratedImuMeasurements, params: gtsam.PreintegrationParams
) -> np.ndarray:
    """M (6, 3) = d(n_p, n_v of the prediction) / d n_g, by changing params' gravity (restored after).

    GTSAM's prediction is affine in gravity, so the differences are exact (to rounding); they also prove that
    params is the pim's parameters object: otherwise the prediction would not move (ValueError). Once per
    factor."""
    g0 = np.array(params.n_gravity, dtype=float)
    # predicted (n_p, n_v) from the origin at rest, at g0 and at g0 + each probe
    Y = np.empty((4, 6))
    try:
        for k, g in enumerate((g0, *(g0 + _PROBES))):
            params.n_gravity = g
            state = pim.predict(_ORIGIN, _NO_BIAS)
            Y[k, :3], Y[k, 3:] = state.position(), state.velocity()
    finally:
        params.n_gravity = g0
    M = (Y[1:] - Y[0]).T / _PROBE_DG
    dt = pim.deltaTij()
    # (no time integrated: gravity has no effect)
    if dt > 0.0 and not np.abs(M[3:]).max() > 0.5 * dt:
        raise ValueError(
            "params is not the parameters object the pim was made with: the factor's gravity would not reach "
            "the prediction; pass the PreintegrationParams given to PreintegratedImuMeasurements"
        )
    return M


def _check_free(params: gtsam.PreintegrationParams) -> None:
    """ValueError if params already serves an EarthImuFactor (module doc)."""
    if params in _CLAIMED:
        raise ValueError(
            "these PreintegrationParams already serve another EarthImuFactor: each factor writes its gravity "
            "into its parameters, which would change the other factor's prediction; preintegrate each interval "
            "with its own PreintegrationParams"
        )


T = TypeVar("T")


class _ModelData(Generic[T]):
    """A read-only attribute of EarthImuFactor that its model holds (the callback object owns the data)."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __get__(self, obj: EarthImuFactor, owner: type | None = None) -> T:
        return cast(T, getattr(obj.model, self.name))


@dataclass(eq=False)  # (eq=False: compared and hashed by identity, as the callback object it is)
class _EarthImuModel:
    """What the CustomFactor's callback needs and nothing else: the wrapped ImuFactor, its parameters, the
    gravity model and reference, M. It holds no reference to its CustomFactor or to the EarthImuFactor, so
    that no reference cycle runs through C++ (module doc, "Memory")."""

    imu: gtsam.ImuFactor
    params: gtsam.PreintegrationParams
    dt: float
    gravity: GravityModel | None
    keys: tuple[int, int, int, int, int]
    M: np.ndarray  # d(prediction's n_p, n_v) / d n_g

    def __post_init__(self) -> None:
        self.MG: np.ndarray = np.zeros((6, 3))  # M @ ref_G, computed once per reference
        self.MG_of: np.ndarray | None = None  # the ref_G it is of
        self.ref_p: np.ndarray | None = None
        # a copy: the property is a view of the C++ vector
        self.ref_g = np.array(self.params.n_gravity, dtype=float)
        self.ref_G = np.zeros((3, 3))
        self._MG2: np.ndarray = np.zeros((2, 3, 3))
        self._Hs = [np.zeros((9, d), order="F") for d in _DIMS]

    def set_gravity(self, n_p_mid: np.ndarray) -> np.ndarray:
        if self.gravity is None:
            return self.ref_g
        if self.ref_p is None:
            self.ref_g, self.ref_G = self.gravity(n_p_mid)
            self.ref_p = n_p_mid.copy()
        # Extrapolate from the reference (re-referencing is the owner's job, in bulk, via needs_reference
        # and set_reference, not one factor at a time). The quadratic term is 1e-8 m/s^2 at 500 m and
        # 1e-6 m/s^2 at 5 km, so extrapolation stays right between re-referencings.
        g = self.ref_g + self.ref_G @ (n_p_mid - self.ref_p)
        self.params.n_gravity = g
        return g

    def __call__(self, _factor: Any, values: gtsam.Values, H: Any) -> np.ndarray:
        xi, vi, xj, vj, b = self.keys
        pose_i, pose_j = values.atPose3(xi), values.atPose3(xj)
        v_i, v_j, bias = values.atVector(vi), values.atVector(vj), values.atConstantBias(b)
        self.set_gravity(0.5 * (pose_i.translation() + pose_j.translation()))
        if H is None:
            return self.imu.evaluateError(pose_i, v_i, pose_j, v_j, bias)
        # one set of output buffers per model: GTSAM copies each Jacobian when it is assigned to H
        Hs = self._Hs
        error = self.imu.evaluateError(pose_i, v_i, pose_j, v_j, bias, *Hs)
        if self.gravity is not None:
            if self.MG_of is not self.ref_G:
                self.MG, self.MG_of = self.M @ self.ref_G, self.ref_G
                self._MG2 = 0.5 * self.MG.reshape(2, 3, 3)  # [M_p G; M_v G] / 2
            R_i, R_j = pose_i.rotation().matrix(), pose_j.rotation().matrix()
            T = R_j.T @ self._MG2  # (2, 3, 3): de/dg G / 2 for the position and velocity rows
            Hs[0][3:9, 3:6] += (T @ R_i).reshape(6, 3)
            Hs[2][3:9, 3:6] += (T @ R_j).reshape(6, 3)
        H[0], H[1], H[2], H[3], H[4] = Hs
        return error


class EarthImuFactor:
    """One factor: the wrapped ImuFactor, its own parameters, the local gravity model, and `.factor`, the
    gtsam.CustomFactor to add to a graph. dt is the interval as given; the Jacobian uses the time the pim
    integrated (through M, module doc), which differs where the IMU data have a gap. The CustomFactor's
    callback is a separate model object, `.model` (module doc, "Memory"): the factor stays valid in a graph after
    this object is gone, and both are freed as soon as neither is held."""

    def __init__(
        self,
        imu: gtsam.ImuFactor,
        params: gtsam.PreintegrationParams,
        dt: float,
        gravity: GravityModel | None,
        keys: tuple[int, int, int, int, int],
        extra_cov: np.ndarray | None = None,
    ) -> None:
        _check_free(params)  # before the probe, which writes (and restores) the parameters' gravity
        # a copy, sharing the parameters object with the ImuFactor's
        pim = imu.preintegratedMeasurements()
        self.model = _EarthImuModel(imu, params, dt, gravity, keys, _gravity_map(pim, params))
        cov = pim.preintMeasCov() if extra_cov is None else pim.preintMeasCov() + extra_cov
        noise = gtsam.noiseModel.Gaussian.Covariance(cov)
        self.factor = gtsam.CustomFactor(noise, list(keys), self.model)
        _CLAIMED.add(params)  # last: a factor that failed to build claims nothing

    # the model's data, read-only here (set_reference changes the reference)
    imu = _ModelData[gtsam.ImuFactor]("imu")
    params = _ModelData[gtsam.PreintegrationParams]("params")
    dt = _ModelData[float]("dt")
    gravity = _ModelData["GravityModel | None"]("gravity")
    keys = _ModelData[tuple[int, int, int, int, int]]("keys")
    # M (6, 3) = d(predicted n_p, n_v) / d n_g (module doc)
    gravity_map = _ModelData[np.ndarray]("M")
    ref_p = _ModelData["np.ndarray | None"]("ref_p")
    ref_g = _ModelData[np.ndarray]("ref_g")
    ref_G = _ModelData[np.ndarray]("ref_G")

    def set_reference(self, n_p_ref: np.ndarray, g: np.ndarray, G: np.ndarray) -> None:
        """Give the local gravity model (a caller evaluating many factors at once can do it in bulk)."""
        m = self.model
        m.ref_p, m.ref_g, m.ref_G = np.array(n_p_ref, dtype=float), np.asarray(g), np.asarray(G)

    def needs_reference(self, n_p_mid: np.ndarray) -> bool:
        m = self.model
        return m.gravity is not None and (
            m.ref_p is None or np.abs(n_p_mid - m.ref_p).max() > REFRESH_M
        )

    def set_gravity(self, n_p_mid: np.ndarray) -> np.ndarray:
        """Gravity at n_p_mid from the reference, written into this factor's parameters (and so its pim's)."""
        return self.model.set_gravity(n_p_mid)

    def __call__(self, _factor: Any, values: gtsam.Values, H: Any) -> np.ndarray:
        """The error (and with H the Jacobians) as the CustomFactor computes it."""
        return self.model(_factor, values, H)


def make_earth_imu_factor(
    pim: gtsam.PreintegratedImuMeasurements,
    params: gtsam.PreintegrationParams,
    keys: tuple[int, int, int, int, int],
    dt: float,
    gravity: GravityModel | None,
    extra_cov: np.ndarray | None = None,
) -> EarthImuFactor:
    """IMU factor on [X_i, V_i, X_j, V_j, B] whose gravity follows position (gravity=None: constant).

    `params` must be the pim's own parameters object, used by no other EarthImuFactor (the factor writes
    its gravity there; ValueError otherwise, see the module doc). extra_cov (9, 9): covariance added to the
    preintegration's, in its error order [rotation, position, velocity] (e.g. the motion model across an IMU
    gap). Add `result.factor` to a graph.
    """
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be positive, got {dt}")
    if extra_cov is not None and np.shape(extra_cov) != (9, 9):
        raise ValueError(f"extra_cov must be 9x9, got shape {np.shape(extra_cov)}")
    return EarthImuFactor(gtsam.ImuFactor(*keys, pim), params, float(dt), gravity, keys, extra_cov)
