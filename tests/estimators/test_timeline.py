"""The filtering timeline from a linearised graph: exact against the smoother at the last epoch, and it
tells the paper's observability story (Figures 6-9 and 12)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.estimators.batch.solve import extract_result
from gtsam_dvl.estimators.batch.timeline import filtering_timeline
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.graph.solver import gauss_newton_qr
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

pytestmark = pytest.mark.slow


@functools.cache
def _run(name: str) -> tuple[Timeline, NavResult]:
    log = simulate(load_scenario(name), 8)
    builder = LogGraph(log, EstimatorConfig.paper())
    graph, values = builder.build()
    ordering = builder.elimination_ordering()
    values, _ = gauss_newton_qr(graph, values, ordering, before_iteration=builder.refresh_gravity)
    return filtering_timeline(builder, graph, values), extract_result(
        builder, graph, values, ordering
    )


def _at(tl: Timeline, t: float) -> int:
    return int(np.searchsorted(tl.t, t))


@pytest.mark.parametrize("name", ["paper-3d", "paper-2d"])
def test_last_epoch_equals_the_smoother_marginals(name: str) -> None:
    tl, res = _run(name)
    np.testing.assert_allclose(tl.scale_sigma[-1], res.scale_sigma, rtol=1e-8)
    np.testing.assert_allclose(tl.misalignment_sigma_deg[-1], res.misalignment_sigma_deg, rtol=1e-8)
    np.testing.assert_allclose(
        tl.gyro_bias_sigma_deg_per_h[-1], res.gyro_bias_sigma_deg_per_h, rtol=1e-8
    )
    np.testing.assert_allclose(tl.accel_bias_sigma_ug[-1], res.accel_bias_sigma_ug, rtol=1e-8)
    np.testing.assert_allclose(tl.attitude_sigma_deg[-1], res.attitude_sigma_deg[-1], rtol=1e-6)


def test_paper_3d_story() -> None:
    tl, _ = _run("paper-3d")
    prior_mis = 1.0
    i599, i660, i719, i749, i1100 = (_at(tl, t) for t in (599, 659, 719, 749, 1100))
    mis = tl.misalignment_sigma_deg
    print(
        f"scale sigma 599 s {tl.scale_sigma[i599]:.4f} -> 660 s {tl.scale_sigma[i660]:.6f}; misalignment sigma "
        f"660 s {np.round(mis[i660], 3)}, 720 s {np.round(mis[i719], 3)}; "
        f"accel bias sigma 749 s {np.round(tl.accel_bias_sigma_ug[i749], 1)}, 1100 s "
        f"{np.round(tl.accel_bias_sigma_ug[i1100], 1)} micro-g"
    )
    # the scale converges as soon as motion starts
    assert tl.scale_sigma[i660] < tl.scale_sigma[i599] / 10
    # pitch and yaw misalignment converge from 600 s (the sigmas of the paper's Figure 7)
    assert np.all(tl.misalignment_sigma_deg[i660, 1:] < prior_mis / 5)
    # roll stays at its prior until the descent at 660 s, then falls at least 2x by 720 s
    assert np.all(tl.misalignment_sigma_deg[:i660, 0] > 0.9 * prior_mis)
    assert tl.misalignment_sigma_deg[i719, 0] < prior_mis / 2
    # horizontal accelerometer biases stay near their prior until the turns start at 750 s
    assert np.all(tl.accel_bias_sigma_ug[i749, :2] > 0.9 * 50.0)
    assert np.all(tl.accel_bias_sigma_ug[i1100, :2] < 0.3 * 50.0)


def test_paper_2d_roll_never_determined() -> None:
    tl, _ = _run("paper-2d")
    print(f"2-D roll sigma: min {tl.misalignment_sigma_deg[:, 0].min():.4f} deg (prior 1)")
    assert np.all(tl.misalignment_sigma_deg[:, 0] > 0.9)
    assert tl.scale_sigma[-1] < 1500e-6 and np.all(tl.misalignment_sigma_deg[-1, 1:] < 0.1)
