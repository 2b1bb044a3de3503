"""FactorMaker.velocity_rate_inputs (the time-offset model's IMU constants of many pings at once) against the
one-ping-at-a-time computation it replaced (kept here as the reference), on a simulated log's IMU samples, for
offsets of either sign, windows cut by the log's ends, chunks smaller than one window, and an empty window."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.rotations import so3_exp
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario


@cache
def maker_and_imu() -> tuple[FactorMaker, np.ndarray, np.ndarray, np.ndarray]:
    log = simulate(load_scenario("paper-3d-short"), 3)
    builder = LogGraph(log, EstimatorConfig())
    imu = builder.log.imu
    return builder.maker, imu.t, imu.b_f, imu.b_omega


def reference(
    maker: FactorMaker, t: float, imu_t: np.ndarray, b_f: np.ndarray, b_omega: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """velocity_rate_input written per ping, one window at a time: the reference for the vectorised one."""
    w = maker.config.dvl.time_offset_window_s
    # [t, t + dt], widened to 2 w about its middle
    start, end = (t, t + dt) if dt >= 0 else (t + dt, t)
    if end - start < 2 * w:
        mid = 0.5 * (start + end)
        start, end = mid - w, mid + w
    lo = int(np.searchsorted(imu_t, start, side="left"))
    hi = int(np.searchsorted(imu_t, end, side="right"))
    sel = np.arange(lo, hi)
    if sel.size == 0:
        sel = np.array([int(np.clip(np.searchsorted(imu_t, t), 0, len(imu_t) - 1))])
    b_a = b_f[sel].mean(axis=0)
    w_rel = b_omega[sel] - maker.alignment.n_R_b.T @ maker.n_omega_ie()
    step = np.diff(imu_t[sel], prepend=imu_t[sel[0]])
    phi = np.cumsum(w_rel * step[:, None], axis=0)
    phi -= phi[int(np.argmin(np.abs(imu_t[sel] - t)))]
    G = so3_exp(-phi).reshape(-1, 3, 3).mean(axis=0)
    return b_a, w_rel.mean(axis=0), G


@pytest.mark.parametrize("dt", [0.0, 0.35, -1.2])
def test_equal_to_one_at_a_time(dt: float) -> None:
    maker, imu_t, b_f, b_omega = maker_and_imu()
    rng = np.random.default_rng(1)
    t = np.sort(
        np.concatenate(
            [rng.uniform(imu_t[0], imu_t[-1], 40), [imu_t[0], imu_t[-1], imu_t[-1] + 5.0]]
        )
    )
    for chunk in (2_000_000, 50):  # one block, and blocks of a single ping
        b_a, w_mean, G = maker.velocity_rate_inputs(t, imu_t, b_f, b_omega, dt, chunk_samples=chunk)
        for q, tq in enumerate(t):
            ra, rw, rG = reference(maker, float(tq), imu_t, b_f, b_omega, dt)
            assert np.allclose(b_a[q], ra, rtol=0, atol=1e-12)
            assert np.allclose(w_mean[q], rw, rtol=0, atol=1e-15)
            assert np.allclose(G[q], rG, rtol=0, atol=1e-13)
    one = maker.velocity_rate_input(float(t[3]), imu_t, b_f, b_omega, dt)
    assert all(np.array_equal(a, b) for a, b in zip(one, (b_a[3], w_mean[3], G[3]), strict=True))
