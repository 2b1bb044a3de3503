"""Numerical derivatives on manifolds: the one helper every Jacobian test uses.

Central differences of a vector-valued function of any number of arguments, each perturbed in its own tangent
space the way GTSAM retracts it (Pose3 and Rot3 on the right, pose tangent [rotation, translation]; a
ConstantBias as [accelerometer, gyroscope]; numbers and arrays additively). GTSAM's numericalDerivativeNM does
the same, but exists only as a fixed family of functions per argument count and position; this takes any.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gtsam
import numpy as np


def tangent_dim(x: Any) -> int:
    """The dimension of x's tangent space (a float is 1, an array its size)."""
    if hasattr(x, "retract") and hasattr(x, "localCoordinates"):
        return int(np.asarray(x.localCoordinates(x)).size)
    if isinstance(x, gtsam.imuBias.ConstantBias):
        return 6
    return int(np.asarray(x, dtype=float).size)


def perturb(x: Any, d: np.ndarray) -> Any:
    """x moved by the tangent vector d (GTSAM retract for manifold types)."""
    if isinstance(x, gtsam.imuBias.ConstantBias):
        return gtsam.imuBias.ConstantBias(x.accelerometer() + d[:3], x.gyroscope() + d[3:])
    if hasattr(x, "retract"):
        return x.retract(d)
    if isinstance(x, float | int) and not isinstance(x, bool):
        return float(x) + float(d[0])
    arr = np.asarray(x, dtype=float)
    return arr + d.reshape(arr.shape)


def numerical_jacobian(
    f: Callable[..., Any],
    args: Sequence[Any],
    index: int,
    delta: float | Sequence[float] | np.ndarray = 1e-6,
) -> np.ndarray:
    """d f(args) / d args[index] (rows: f's output, columns: the argument's tangent), central differences with
    step delta: one for every tangent component, or one per component (states of different units)."""
    args = list(args)
    x = args[index]
    n = tangent_dim(x)
    steps = np.broadcast_to(np.asarray(delta, dtype=float), (n,))
    columns = []
    for j in range(n):
        d = np.zeros(n)
        d[j] = steps[j]
        plus = args.copy()
        minus = args.copy()
        plus[index] = perturb(x, d)
        minus[index] = perturb(x, -d)
        fp = np.atleast_1d(np.asarray(f(*plus), dtype=float)).reshape(-1)
        fm = np.atleast_1d(np.asarray(f(*minus), dtype=float)).reshape(-1)
        columns.append((fp - fm) / (2.0 * steps[j]))
    return np.stack(columns, axis=1)


def numerical_jacobians(
    f: Callable[..., Any], args: Sequence[Any], delta: float = 1e-6
) -> list[np.ndarray]:
    """[d f / d args[i] for every i]: one block per argument, in order."""
    return [numerical_jacobian(f, args, i, delta) for i in range(len(args))]


def assert_jacobians_match(
    f: Callable[..., Any],
    args: Sequence[Any],
    H: Sequence[np.ndarray | None],
    shapes: Sequence[tuple[int, int]] | None = None,
) -> None:
    """Each H[i], an analytical d f(args) / d args[i], equals the numerical one (numerical_jacobian) to 1e-6 of
    its largest entry (1e-6 absolute where that is below 1); shapes: the (rows, columns) each must have, besides
    the numerical one's."""
    for i in range(len(args)):
        J_num = numerical_jacobian(f, args, i)
        H_i = H[i]
        assert H_i is not None and H_i.shape == J_num.shape
        if shapes is not None:
            assert H_i.shape == shapes[i]
        np.testing.assert_allclose(
            H_i, J_num, rtol=0, atol=1e-6 * max(1.0, np.abs(J_num).max()), err_msg=f"H[{i}]"
        )


def gauss_markov(
    n: int, dt: float, sigma: float, tau: float, rng: np.random.Generator
) -> np.ndarray:
    """n samples at dt of a stationary first-order Gauss-Markov process (sigma, time constant tau), exactly
    discretised."""
    phi = np.exp(-dt / tau)
    g = np.empty(n)
    g[0] = rng.normal(0.0, sigma)
    drive = rng.normal(0.0, sigma * np.sqrt(1.0 - phi**2), n)
    for i in range(1, n):
        g[i] = phi * g[i - 1] + drive[i]
    return g
