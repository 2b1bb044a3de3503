"""GTSAM's preintegrated IMU factor with gravity as a function of position (Earth model in `map`).

    e = ImuFactor error (X_i, V_i, X_j, V_j, B) with n_g = g(n_p_mid),  n_p_mid = (n_p_i + n_p_j) / 2

GTSAM's ImuFactor takes gravity as a constant of its parameters. In the Earth-fixed map frame gravity
turns with position (1.6e-7 rad per metre, plus the vertical free-air gradient), and over kilometres a
constant gravity is wrong by more than the accelerometer bias being estimated. Evaluating g at the
current positions without its derivative leaves the solver a slow (or, over long runs, divergent) fixed
point; this factor adds the gradient term to the translation Jacobians so that Gauss-Newton converges as
on the true model:

    de/d(xi_t_i) += de/dg * G * 1/2 * n_R_b_i,   de/dg = [0; 1/2 dt^2 n_R_b_j^T; dt n_R_b_j^T]

(error order [rotation, position, velocity] in the frame of state j; translation tangents in body axes).
de/dg is exact at zero error and off by the rotation error otherwise, which only affects the convergence
rate, never the solution. The gravity model is a callable returning g and its gradient G at positions;
it is evaluated at a reference position and extrapolated linearly; whoever drives the solver
re-references factors whose mid position moved more than REFRESH_M (the quadratic term over 100 m is
below 1e-8 m/s^2), in bulk (GraphBuilder.refresh_gravity).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gtsam
import numpy as np

GravityModel = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # n_p (3,) -> (g (3,), G (3, 3))
REFRESH_M = 100.0
_DIMS = (6, 3, 6, 3, 6)


class EarthImuFactor:
    """One factor: the wrapped ImuFactor, its own parameters, the local gravity model, and `.factor`, the
    gtsam.CustomFactor to add to a graph."""

    def __init__(self, imu: gtsam.ImuFactor, params: gtsam.PreintegrationParams, dt: float,
                 gravity: GravityModel | None, keys: tuple[int, int, int, int, int]) -> None:
        self.imu, self.params, self.dt, self.gravity, self.keys = imu, params, dt, gravity, keys
        self.ref_p: np.ndarray | None = None
        self.ref_g = np.asarray(params.n_gravity, dtype=float)
        self.ref_G = np.zeros((3, 3))
        noise = gtsam.noiseModel.Gaussian.Covariance(imu.preintegratedMeasurements().preintMeasCov())
        self.factor = gtsam.CustomFactor(noise, list(keys), self)

    def set_reference(self, n_p_ref: np.ndarray, g: np.ndarray, G: np.ndarray) -> None:
        """Give the local gravity model (a caller evaluating many factors at once can do it in bulk)."""
        self.ref_p, self.ref_g, self.ref_G = np.array(n_p_ref, dtype=float), np.asarray(g), np.asarray(G)

    def needs_reference(self, n_p_mid: np.ndarray) -> bool:
        return self.gravity is not None and (self.ref_p is None or np.abs(n_p_mid - self.ref_p).max() > REFRESH_M)

    def set_gravity(self, n_p_mid: np.ndarray) -> np.ndarray:
        if self.gravity is None:
            return self.ref_g
        if self.ref_p is None:
            self.ref_g, self.ref_G = self.gravity(n_p_mid)
            self.ref_p = n_p_mid.copy()
        # Extrapolate from the reference (re-referencing is the owner's job, in bulk, via needs_reference
        # and set_reference: 1 ms per factor one by one). The quadratic term is 1e-8 m/s^2 at 500 m and
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
        Hs = [np.zeros((9, d), order="F") for d in _DIMS]
        error = self.imu.evaluateError(pose_i, v_i, pose_j, v_j, bias, *Hs)
        if self.gravity is not None:
            R_i, R_j = pose_i.rotation().matrix(), pose_j.rotation().matrix()
            dt = self.dt
            E_G = np.zeros((9, 3))
            E_G[3:6] = (0.5 * dt * dt) * (R_j.T @ self.ref_G)
            E_G[6:9] = dt * (R_j.T @ self.ref_G)
            Hs[0][:, 3:6] += 0.5 * (E_G @ R_i)
            Hs[2][:, 3:6] += 0.5 * (E_G @ R_j)
        for k in range(5):
            H[k] = Hs[k]
        return error


def make_earth_imu_factor(
    pim: gtsam.PreintegratedImuMeasurements,
    params: gtsam.PreintegrationParams,
    keys: tuple[int, int, int, int, int],
    dt: float,
    gravity: GravityModel | None,
) -> EarthImuFactor:
    """IMU factor on [X_i, V_i, X_j, V_j, B] whose gravity follows position (gravity=None: constant).

    `params` must be the pim's own parameters object (one per factor): the factor writes its gravity.
    Add `result.factor` to a graph.
    """
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be positive, got {dt}")
    return EarthImuFactor(gtsam.ImuFactor(*keys, pim), params, float(dt), gravity, keys)
