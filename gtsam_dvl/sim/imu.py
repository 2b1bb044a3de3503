"""IMU outputs: true increments by Gauss-Legendre quadrature, then biases and white noise.

A real IMU outputs increments over each sample interval, delta_theta = int omega_ib^b dt and
delta_v = int f^b dt in the body frame; the sample stamped t covers (t - dt, t] and is delivered as rate
and specific force averaged over the interval (increment / dt). Both integrands are smooth analytic
functions of time, so 4 Gauss-Legendre nodes per 10 ms interval integrate them to rounding error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from gtsam_dvl.core.units import DEG_PER_H, MICRO_G, PER_SQRT_H
from gtsam_dvl.sim.local_level import imu_truth
from gtsam_dvl.sim.motion import MotionProfile
from gtsam_dvl.sim.position import GL_W, PositionTrack, node_times

if TYPE_CHECKING:
    from gtsam_dvl.sim.scenario import ImuSpec

CHUNK = 1 << 15  # samples per vectorised block: bounds memory on long runs


def true_imu(
    motion: MotionProfile,
    track: PositionTrack,
    n_samples: int,
    progress: Callable[[float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Error-free averaged gyro (rad/s) and specific force (m/s^2), (n_samples, 3) each."""
    b_omega = np.empty((n_samples, 3))
    b_f = np.empty((n_samples, 3))
    for a in range(0, n_samples, CHUNK):
        b = min(a + CHUNK, n_samples)
        b_omega[a:b], b_f[a:b] = _true_imu_block(motion, track, a, b)
        if progress is not None:
            progress(0.1 + 0.8 * b / n_samples)
    return b_omega, b_f


def true_imu_range(
    motion: MotionProfile, track: PositionTrack, a: int, b: int
) -> tuple[np.ndarray, np.ndarray]:
    """true_imu's outputs of samples a..b-1 only (track: any PositionTrack holding their grid points), in the
    same blocks of CHUNK samples as true_imu, so the values are true_imu's bit for bit (sim/stream.py)."""
    b_omega = np.empty((b - a, 3))
    b_f = np.empty((b - a, 3))
    lo = a
    while lo < b:
        hi = min((lo // CHUNK + 1) * CHUNK, b)
        b_omega[lo - a : hi - a], b_f[lo - a : hi - a] = _true_imu_block(motion, track, lo, hi)
        lo = hi
    return b_omega, b_f


def _true_imu_block(
    motion: MotionProfile, track: PositionTrack, a: int, b: int
) -> tuple[np.ndarray, np.ndarray]:
    """Averaged rate and specific force of samples a..b-1."""
    avg_w = 0.5 * GL_W  # interval average = (1/dt) int = sum_i (w_i / 2) f(node_i)
    k = np.arange(a, b)
    t = node_times(k, track.rate).ravel()
    lat, h = (x.ravel() for x in track.at_nodes(a, b))
    w_ib, f, _, _ = imu_truth(motion.evaluate(t), lat, h)
    return (
        np.einsum("kni,n->ki", w_ib.reshape(len(k), -1, 3), avg_w),
        np.einsum("kni,n->ki", f.reshape(len(k), -1, 3), avg_w),
    )


@dataclass
class ImuErrors:
    """Bias of each sample (n, 3) and the initial values, SI units."""

    gyro_bias: np.ndarray  # rad/s
    accel_bias: np.ndarray  # m/s^2
    gyro_bias0: np.ndarray
    accel_bias0: np.ndarray


def draw_biases(spec: ImuSpec, n_samples: int, rate: float, rng: np.random.Generator) -> ImuErrors:
    """Random-constant biases drawn N(0, sigma) per axis (or the spec's values), plus optional random walk.

    The draws always happen in the same order, so a seed gives the same biases with and without white noise.
    """
    g0, a0 = initial_biases(spec, rng)
    g_walk, a_walk = walk_step_sigmas(spec, rate)

    def walk(b0: np.ndarray, step_sigma: float) -> np.ndarray:
        if step_sigma == 0.0:
            return np.broadcast_to(b0, (n_samples, 3))
        steps = rng.normal(0.0, step_sigma, (n_samples, 3))
        steps[0] = 0.0  # the first sample has the initial bias
        return b0 + np.cumsum(steps, axis=0)

    return ImuErrors(walk(g0, g_walk), walk(a0, a_walk), g0, a0)


def initial_biases(spec: ImuSpec, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(gyro rad/s, accelerometer m/s^2) biases at t = 0: the first six draws of the bias stream."""
    g0 = rng.normal(0.0, spec.gyro_bias_deg_per_h, 3) * DEG_PER_H
    a0 = rng.normal(0.0, spec.accel_bias_micro_g, 3) * MICRO_G
    if spec.gyro_bias_values_deg_per_h is not None:
        g0 = np.asarray(spec.gyro_bias_values_deg_per_h, dtype=float) * DEG_PER_H
    if spec.accel_bias_values_micro_g is not None:
        a0 = np.asarray(spec.accel_bias_values_micro_g, dtype=float) * MICRO_G
    return g0, a0


def walk_step_sigmas(spec: ImuSpec, rate: float) -> tuple[float, float]:
    """1-sigma per-sample steps of the gyro (rad/s) and accelerometer (m/s^2) bias random walks (0: none)."""
    sqrt_dt = np.sqrt(1.0 / rate)
    g_walk = spec.gyro_bias_walk_deg_per_h_per_sqrt_h * DEG_PER_H * PER_SQRT_H * sqrt_dt
    a_walk = spec.accel_bias_walk_micro_g_per_sqrt_h * MICRO_G * PER_SQRT_H * sqrt_dt
    return g_walk, a_walk


def white_noise_sigmas(spec: ImuSpec, rate: float) -> tuple[float, float]:
    """1-sigma white noise of the averaged gyro (rad/s) and accelerometer (m/s^2) outputs: density * sqrt(rate)."""
    sg = spec.gyro_noise_deg_per_h_per_sqrt_hz * DEG_PER_H * np.sqrt(rate)
    sa = spec.accel_noise_micro_g_per_sqrt_hz * MICRO_G * np.sqrt(rate)
    return sg, sa


def white_noise(
    spec: ImuSpec, n_samples: int, rate: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Gyro and accelerometer white noise of the averaged outputs: sigma = density * sqrt(rate). All the gyro
    draws come first, then the accelerometer's (sim/stream.py relies on this order)."""
    sg, sa = white_noise_sigmas(spec, rate)
    return rng.normal(0.0, sg, (n_samples, 3)), rng.normal(0.0, sa, (n_samples, 3))


def quantise(x: np.ndarray, step: float | tuple[float, float, float]) -> np.ndarray:
    """x (n, 3) rounded to multiples of step per axis, round(x / q) q (a step of 0 leaves that axis alone): the
    logged output of an IMU whose driver or export keeps a fixed resolution."""
    q = np.broadcast_to(np.asarray(step, dtype=float), (3,))
    if not np.any(q > 0):
        return x
    safe = np.where(q > 0, q, 1.0)
    return np.where(q > 0, np.round(x / safe) * safe, x)


def saturate(x: np.ndarray, limit: float) -> np.ndarray:
    """x (n, 3) clipped to +-limit on every axis (limit 0: untouched): the output of a sensor driven past its
    range, which reports the range's limit while the true value exceeds it."""
    return x if limit <= 0 else np.clip(x, -limit, limit)
