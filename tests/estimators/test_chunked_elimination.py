"""solver.eliminate_chunked: QR elimination a chunk of states at a time gives the Bayes net of one sequential
elimination in the same order (the same solution to 1e-12 relative, the same marginal covariances to 1e-9), for
chunks of one state, a few states, more states than the log has, with the random-walk bias (a bias key per
state in the chunks) and with the time offset among the shared keys."""

from __future__ import annotations

from functools import cache

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.graph.solver import bayes_net_marginals, eliminate_chunked
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict


@cache
def short_log() -> LogData:
    raw = dict(load_scenario("paper-3d-short").raw)
    segments = [dict(seg) for seg in raw["segments"][:6]]
    segments[0]["duration_s"] = 60.0
    segments[5].update(sides=1)
    raw["segments"] = segments
    return simulate(scenario_from_dict(raw), 2)


def configs() -> dict[str, EstimatorConfig]:
    paper = EstimatorConfig.paper()
    return {
        "default": EstimatorConfig(),
        "random-walk": paper.model_copy(
            update={"imu": paper.imu.model_copy(update={"bias_model": "random_walk"})}
        ),
    }


@pytest.mark.parametrize("name", list(configs()))
@pytest.mark.parametrize("chunk_states", [1, 37, 100_000])
def test_same_bayes_net_as_one_sequential_elimination(name: str, chunk_states: int) -> None:
    builder = LogGraph(short_log(), configs()[name])
    graph, values = builder.build_bulk()
    linear = graph.linearize(values)
    plan = builder.elimination_ordering(chunk_states)
    assert len(plan.chunks) == -(-len(builder.epochs) // chunk_states)
    # GTSAM's, solved by GTSAM
    full = linear.eliminateSequential(plan.ordering(), gtsam.EliminateQR)
    # CompactBayesNet, solved by its own back-substitution
    chunked = eliminate_chunked(linear, plan)
    assert chunked.size() == full.size()
    d_full, d_chunked = full.optimize(), chunked.optimize()
    for key in [k for ks in plan.chunks[:2] for k in ks] + plan.rest:
        a, b = d_full.at(key), d_chunked.at(key)
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12 * (1 + np.abs(a).max()))
    m_full, m_chunked = bayes_net_marginals(full), bayes_net_marginals(chunked)
    for key, cov in m_full.covariances.items():
        assert np.abs(m_chunked.covariances[key] - cov).max() <= 1e-9 * np.abs(cov).max()


def test_smooth_batch_through_the_chunked_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """smooth_batch with the chunked elimination forced (as on logs of more than 8000 states) gives the plain
    elimination's estimates and marginal covariances (to 1e-9 of a sigma, covariances to 1e-9 in correlation
    units)."""
    from gtsam_dvl.estimators.batch.smoother import smooth_batch
    from gtsam_dvl.estimators.graph import solver

    plain = smooth_batch(short_log(), EstimatorConfig())
    monkeypatch.setattr(solver, "CHUNKED_FROM_STATES", 10)
    chunked = smooth_batch(short_log(), EstimatorConfig())
    assert abs(chunked.scale - plain.scale) <= 1e-9 * plain.scale_sigma
    assert abs(chunked.scale_sigma - plain.scale_sigma) <= 1e-9 * plain.scale_sigma
    assert abs(chunked.time_offset_s - plain.time_offset_s) <= 1e-9 * plain.time_offset_sigma_s
    assert np.allclose(chunked.n_p, plain.n_p, rtol=0, atol=1e-9)
    # covariances compared in correlation units: each entry over the product of its two sigmas
    sig = np.sqrt(np.einsum("nii->ni", plain.pose_cov))
    assert (
        np.abs((chunked.pose_cov - plain.pose_cov) / (sig[:, :, None] * sig[:, None, :])).max()
        < 1e-9
    )
