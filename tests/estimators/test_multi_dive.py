"""One calibration from several dives (estimators/batch/multi_dive.py): each dive's own variables eliminated by QR, the
shared block solved jointly, back-substituted and iterated. Checked against the one-graph solve (every dive's
factors in ONE graph), against the dives alone (the reduction is exact: with the priors it gives back a dive's
marginal) and against the truth. The same on 4 dives of paper-3d: bench/calibrate_workers.py."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_log
from gtsam_dvl.estimators.batch import multi_dive as md
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.campaign import SCENARIO


def _tiny() -> Any:
    import tomllib

    return scenario_from_dict(tomllib.loads(SCENARIO))


def _errors_in_sigma(sol: md.JointSolution, other_scale: float, other_R: np.ndarray) -> np.ndarray:
    """sol - other over [scale, misalignment] in sol's sigmas (misalignment in sol's right tangent)."""
    sig = np.sqrt(np.diag(sol.cov))
    r = np.concatenate(
        [sol.values["scale"] - other_scale, so3_log(other_R.T @ sol.values["misalignment"])]
    )
    return r / sig[:4]


@pytest.fixture(scope="module")
def two_dives() -> dict[str, Any]:
    scen = _tiny()
    logs = [simulate(scen, seed=s) for s in (1, 2)]
    dives = [md.prepare_dive(log, name=f"seed{s}") for s, log in zip((1, 2), logs, strict=True)]
    names = dives[0].states
    prior = md.shared_prior_graph(dives[0].config, dives[0].mounting, names)
    # each dive's reduction at its own solution alone, with the priors: its marginal alone
    alone_back = []
    for d in dives:
        values = md.shared_values(d)
        _, cov = md.solve_shared([md.reduce_dive(d), md.prior_rows(prior, names, values)])
        alone_back.append(cov)
    one = md.solve_one_graph(dives)
    joint = md.calibrate_in_process(dives)
    return {"logs": logs, "dives": dives, "alone_back": alone_back, "one": one, "joint": joint}


def test_a_dive_reduced_with_the_priors_gives_back_its_marginal_alone(
    two_dives: dict[str, Any],
) -> None:
    for d, cov in zip(two_dives["dives"], two_dives["alone_back"], strict=True):
        alone = md.summarise(d).alone_cov
        assert cov.shape == (4, 4)
        np.testing.assert_allclose(np.sqrt(np.diag(cov)), np.sqrt(np.diag(alone)), rtol=1e-5)
        corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
        corr_alone = alone / np.sqrt(np.outer(np.diag(alone), np.diag(alone)))
        np.testing.assert_allclose(corr, corr_alone, atol=1e-5)


def test_joint_calibration_matches_the_one_graph_solve(two_dives: dict[str, Any]) -> None:
    joint, one = two_dives["joint"], two_dives["one"]
    assert joint.converged and one.converged and joint.states == ["scale", "misalignment"]
    diff = _errors_in_sigma(joint, float(one.values["scale"][0]), one.values["misalignment"])
    assert np.max(np.abs(diff)) < 0.1  # the done-when bound; measured 1e-12
    np.testing.assert_allclose(np.sqrt(np.diag(joint.cov)), np.sqrt(np.diag(one.cov)), rtol=1e-6)
    # the iterations lowered the joint objective (the dives' solutions alone are not the joint optimum)
    assert joint.history[-1]["error"] < joint.history[0]["error"]


def test_joint_sigmas_shrink_by_sqrt_of_the_dives_and_hold_the_truth(
    two_dives: dict[str, Any],
) -> None:
    joint, dives = two_dives["joint"], two_dives["dives"]
    sig = np.sqrt(np.diag(joint.cov))
    alone = np.mean([np.sqrt(np.diag(md.summarise(d).alone_cov)) for d in dives], axis=0)
    ratio = sig / alone * np.sqrt(2)
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
    truth = two_dives["logs"][0].true_calibration
    b_R_d = rpy_deg_to_matrix(truth.misalignment_deg) @ two_dives["logs"][0].mounting.b_R_d0
    assert np.all(np.abs(_errors_in_sigma(joint, truth.scale, b_R_d)) < 3)


def test_dives_of_different_vehicles_are_refused(two_dives: dict[str, Any]) -> None:
    from dataclasses import replace

    from gtsam_dvl.core.errors import GtsamDvlError
    from gtsam_dvl.core.types import Mounting

    a, b = (md.summarise(d) for d in two_dives["dives"])
    other = replace(b, mounting=Mounting(b_R_d0=rpy_deg_to_matrix([180.0, 0.0, 0.0])))
    with pytest.raises(GtsamDvlError, match="one vehicle's dives share one mounting"):
        md.joint_setup([a, other])


def test_a_long_dive_eliminated_chunk_by_chunk_reduces_the_same(
    two_dives: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Above solver.CHUNKED_FROM_STATES states a dive's own variables are eliminated a chunk at a time: the same
    information on the shared block and the same back-substitution as GTSAM's one elimination."""
    import dataclasses

    from gtsam_dvl.estimators.graph.solver import ChunkedOrdering

    d = two_dives["dives"][0]
    one = md.reduce_dive(d)
    assert d.bayes_net is not None
    given = {
        k: np.full(md.BY_NAME[n].dim, 1e-4)
        for n, k in zip(d.states, md.state_keys(d.states), strict=True)
    }
    dx_one = md.back_substitute(d.bayes_net, given)
    plan = d.builder.elimination_ordering(chunk_states=40)
    shared = set(md.state_keys(d.states))
    chunked = dataclasses.replace(
        d,
        plan=ChunkedOrdering(plan.chunks, [k for k in plan.rest if k not in shared]),
        bayes_net=None,
    )
    monkeypatch.setattr(md, "CHUNKED_FROM_STATES", 10)
    many = md.reduce_dive(chunked)
    assert isinstance(chunked.bayes_net, md.CompactBayesNet) and len(plan.chunks) > 3
    np.testing.assert_allclose(
        many.R.T @ many.R, one.R.T @ one.R, rtol=1e-7, atol=1e-9 * np.abs(one.R).max() ** 2
    )
    np.testing.assert_allclose(
        many.R.T @ many.d, one.R.T @ one.d, rtol=1e-7, atol=1e-9 * np.abs(one.R.T @ one.d).max()
    )
    dx_many = md.back_substitute(chunked.bayes_net, given)
    for k in md.own_keys(d):
        np.testing.assert_allclose(dx_many.at(k), dx_one.at(k), rtol=1e-6, atol=1e-12)
