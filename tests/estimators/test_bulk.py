"""estimators/graph/bulk.py and bulk_imu.py: the batch smoother's DVL and IMU factors in bulk give the per-factor
graph's
objective and linear systems (error to 1e-12 relative, information matrix and vector to 1e-9), robust kernels
included, beams and the lever arm as a variable included, and the same solution.

Log: paper-3d-short cut to 330 s with a 5 Hz DVL (1 s keyframes: a state per second, four pings between), an
outlier injected so that the robust kernel is active at the solution."""

from __future__ import annotations

import dataclasses
from functools import cache

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, K_WATER, L_LEVER, T_OFFSET, E, W, key_dim
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.graph.bulk import BulkGraph, graph_rows
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.graph.solver import gauss_newton_qr
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict


@cache
def run_log() -> LogData:
    raw = dict(load_scenario("paper-3d-short").raw)
    raw["rates"] = {**raw["rates"], "dvl_hz": 5.0}
    # cut to 330 s (60 s static, the acceleration, descent and one banked turn) to keep the dense checks small
    segments = [dict(seg) for seg in raw["segments"][:6]]
    segments[0]["duration_s"] = 60.0
    segments[5].update(sides=1)
    raw["segments"] = segments
    log = simulate(scenario_from_dict(raw), 7)
    d_v = log.dvl.d_v.copy()
    d_v[len(d_v) // 2] += [
        0.12,
        -0.06,
        0.0,
    ]  # an outlier (7 sigma) mid-log, below the screen's jump margin
    return dataclasses.replace(log, dvl=dataclasses.replace(log.dvl, d_v=d_v))


def configs() -> dict[str, EstimatorConfig]:
    paper, default = EstimatorConfig.paper(), EstimatorConfig()
    return {
        "paper": paper,  # random-constant bias, Huber, no time offset
        "default": default,  # time offset estimated, real-DVL priors
        "random-walk-cauchy": paper.model_copy(
            update={
                "imu": paper.imu.model_copy(update={"bias_model": "random_walk"}),
                "dvl": paper.dvl.model_copy(update={"robust": "cauchy"}),
            }
        ),
        "no-robust-flat": default.model_copy(
            update={
                "dvl": default.dvl.model_copy(update={"robust": "none"}),
                "solver": default.solver.model_copy(update={"earth_model": "flat"}),
            }
        ),
        # one row per valid beam, each with its own Huber kernel; the lever arm a variable
        "beams-lever": paper.model_copy(
            update={
                "dvl": paper.dvl.model_copy(update={"use_beams": True, "estimate_lever_arm": True})
            }
        ),
        "offset-lever": default.model_copy(
            update={"dvl": default.dvl.model_copy(update={"estimate_lever_arm": True})}
        ),
        # the DVL's correlated error E(i) a variable of every DVL factor (estimators/models/correlated.py; with beams:
        # its Jacobian d_u^T, tests/factors/test_dvl.py); with water-track pings (run on water_log): the current
        # W(i) and the water-track scale K_WATER (estimators/models/current.py)
        "correlated-water-scale": default.model_copy(
            update={
                "dvl": default.dvl.model_copy(
                    update={"correlated_sigma_m_s": 0.002, "correlated_tau_s": 60.0}
                ),
                "current": default.current.model_copy(
                    update={"water_track": "use", "water_track_scale": True}
                ),
            }
        ),
    }


@cache
def water_log() -> LogData:
    """run_log with its pings from 150 to 250 s marked water track (the comparison needs no physics)."""
    log = run_log()
    water = (log.dvl.t > 150.0) & (log.dvl.t < 250.0)
    return dataclasses.replace(log, dvl=dataclasses.replace(log.dvl, water_track=water))


def perturbed(values: gtsam.Values, rng: np.random.Generator) -> gtsam.Values:
    """values moved off the initial guess (so that no Jacobian is evaluated at a special point)."""
    out = gtsam.Values(values)
    out.update(K_SCALE, np.array([values.atVector(K_SCALE)[0] + 0.004]))
    out.update(C_MISALIGN, values.atRot3(C_MISALIGN).retract(rng.normal(0, 0.01, 3)))
    if values.exists(T_OFFSET):
        out.update(T_OFFSET, np.array([0.12]))
    if values.exists(L_LEVER):
        out.update(L_LEVER, values.atVector(L_LEVER) + rng.normal(0, 0.05, 3))
    i = 0
    while values.exists(E(i)):
        out.update(E(i), rng.normal(0, 0.002, 3))
        i += 1
    i = 0
    while values.exists(W(i)):
        out.update(W(i), rng.normal(0, 0.3, 2))
        i += 1
    if values.exists(K_WATER):
        out.update(K_WATER, np.array([values.atVector(K_WATER)[0] - 0.006]))
    return out


def dvl_graph(builder: LogGraph) -> gtsam.NonlinearFactorGraph:
    """The per-factor DVL factors alone (the other factors are the same objects in both graphs); before
    build_bulk, which lets the pings' snapshots go."""
    dvl = gtsam.NonlinearFactorGraph()
    for i in range(len(builder.epochs)):
        for f in builder.dvl_factors(i) + builder.between_factors(i):
            dvl.add(f)
    return dvl


def imu_graph(builder: LogGraph) -> gtsam.NonlinearFactorGraph:
    """The per-factor IMU factors (EarthImuFactor) alone."""
    out = gtsam.NonlinearFactorGraph()
    for i in range(len(builder.epochs) - 1):
        out.add(builder.imu_factor(i))
    return out


def bulk_imu_linear(graph: BulkGraph, values: gtsam.Values) -> gtsam.GaussianFactorGraph:
    """The IMU carriers' linearisation alone: the bulk IMU factors' Jacobian factors."""
    assert graph.imu is not None and graph._imu_carriers is not None
    graph.imu.prepare(values)
    return graph._imu_carriers.linearize(values)


def bulk_linear(graph: BulkGraph, values: gtsam.Values) -> gtsam.GaussianFactorGraph:
    """The carriers' linearisation alone: the bulk DVL factors' Jacobian factors."""
    graph.bulk.prepare(values)
    return graph._carriers.linearize(values)


def hessians(*linear: gtsam.GaussianFactorGraph) -> list[tuple[np.ndarray, np.ndarray]]:
    """Information matrix and vector of each linear graph over the union of their keys (a carrier has bias
    columns of zeros where the per-factor graph has no bias key)."""
    keys = sorted({k for lin in linear for i in range(lin.size()) for k in lin.at(i).keys()})
    ordering = gtsam.Ordering()
    for k in keys:
        ordering.push_back(k)
    out = []
    for lin in linear:
        missing = set(keys) - {k for i in range(lin.size()) for k in lin.at(i).keys()}
        for k in missing:  # an all-zero row block, so that hessian() knows the key
            lin.add(
                gtsam.JacobianFactor(
                    k, np.zeros((1, key_dim(k))), np.zeros(1), gtsam.noiseModel.Unit.Create(1)
                )
            )
        out.append(lin.hessian(ordering))
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", list(configs()))
def test_same_objective_and_linear_system(name: str) -> None:
    builder = LogGraph(water_log() if "water" in name else run_log(), configs()[name])
    per_factor, values = builder.build()
    dvl = dvl_graph(builder)
    bulk, _ = builder.build_bulk(values)
    assert isinstance(bulk, BulkGraph)
    assert graph_rows(bulk) == graph_rows(per_factor)
    pings = builder.counters["keyframes"] + builder.counters["pings_between_keyframes"]
    assert len(bulk.bulk) == pings if not builder.config.dvl.use_beams else len(bulk.bulk) > pings
    for vals in (values, perturbed(values, np.random.default_rng(1))):
        e1, e2 = per_factor.error(vals), bulk.error(vals)
        assert abs(e1 - e2) <= 1e-12 * e1
        (H1, g1), (H2, g2) = hessians(dvl.linearize(vals), bulk_linear(bulk, vals))
        assert H1.shape == H2.shape
        assert np.abs(H1 - H2).max() <= 1e-9 * np.abs(H1).max()
        assert np.abs(g1 - g2).max() <= 1e-9 * np.abs(g1).max()
        # the IMU factors alone (GTSAM's ImuFactor through the EarthImuFactor against factors/imu_bulk.py), then
        # the whole graphs
        (H1, g1), (H2, g2) = hessians(
            imu_graph(builder).linearize(vals), bulk_imu_linear(bulk, vals)
        )
        assert np.abs(H1 - H2).max() <= 1e-9 * np.abs(H1).max()
        assert np.abs(g1 - g2).max() <= 1e-9 * np.abs(g1).max()
        # (the whole systems by their Gauss-Newton steps: a random-walk graph has a constrained factor, which
        # GTSAM cannot turn into a Hessian). Measured: 1e-12 to 3.5e-12 of the largest step component, 3.4e-9 in
        # the flat configuration, whose step is ill-conditioned: there the per-factor IMU factors with the bulk DVL
        # factors differ from the per-factor graph by 3.1e-9 already.
        ordering = builder.elimination_ordering().ordering()
        d1 = per_factor.linearize(vals).eliminateSequential(ordering, gtsam.EliminateQR).optimize()
        d2 = bulk.linearize(vals).eliminateSequential(ordering, gtsam.EliminateQR).optimize()
        a = np.concatenate([d1.at(ordering.at(i)) for i in range(ordering.size())])
        b = np.concatenate([d2.at(ordering.at(i)) for i in range(ordering.size())])
        assert np.abs(a - b).max() <= 1e-8 * np.abs(a).max()


@pytest.mark.slow
def test_bulk_imu_arrays_are_the_earth_imu_factors() -> None:
    """The bulk IMU factors' gravity maps (analytic) and whitening equal the EarthImuFactors' (probed from the pim;
    GTSAM's noise model), and the gravity references are shared: a factor made after the references were set
    holds them."""
    builder = LogGraph(run_log(), configs()["default"])
    per_factor, values = builder.build()
    bulk, _ = builder.build_bulk(values)
    assert bulk.imu is not None
    fs = builder.imu_factors
    M = np.array([f.model.M for f in fs])
    assert np.abs(bulk.imu.arrays.M - M).max() <= 1e-12 * np.abs(M).max()
    W = np.array([f.factor.noiseModel().R() for f in fs])
    assert np.array_equal(bulk.imu.whiten, W)
    refs = builder.gravity_refs
    assert not np.isnan(refs.n_p).any()
    for i in (0, len(fs) // 2, len(fs) - 1):
        assert np.array_equal(fs[i].model.ref_p, refs.n_p[i]) and np.array_equal(
            fs[i].model.ref_G, refs.G[i]
        )


@pytest.mark.slow
def test_bulk_imu_factors_across_an_imu_gap() -> None:
    """An IMU gap of 1.3 s in the banked turn (held, its motion-model covariance added to the intervals it crosses,
    between keyframes too): the bulk IMU factors' objective and linear system are still the EarthImuFactors'."""
    log = run_log()
    keep = (log.imu.t <= 300.0) | (log.imu.t > 301.3)
    log = dataclasses.replace(
        log,
        imu=dataclasses.replace(
            log.imu, t=log.imu.t[keep], b_omega=log.imu.b_omega[keep], b_f=log.imu.b_f[keep]
        ),
    )
    builder = LogGraph(log, configs()["default"])
    assert builder.counters["imu_gaps"] == 1 and sum(bool(h) for h in builder.imu_held) >= 2
    per_factor, values = builder.build()
    bulk, _ = builder.build_bulk(values)
    vals = perturbed(values, np.random.default_rng(2))
    e1, e2 = per_factor.error(vals), bulk.error(vals)
    assert abs(e1 - e2) <= 1e-12 * e1
    (H1, g1), (H2, g2) = hessians(imu_graph(builder).linearize(vals), bulk_imu_linear(bulk, vals))
    assert np.abs(H1 - H2).max() <= 1e-9 * np.abs(H1).max()
    assert np.abs(g1 - g2).max() <= 1e-9 * np.abs(g1).max()


@pytest.mark.slow
def test_same_solution_with_the_robust_kernel_active() -> None:
    cfg = configs()["default"]
    builder = LogGraph(run_log(), cfg)
    per_factor, values = builder.build()
    bulk, _ = builder.build_bulk(values)
    ordering = builder.elimination_ordering()
    s = cfg.solver
    kw = dict(
        max_iterations=s.max_iterations,
        relative_tol=s.relative_error_tol,
        absolute_tol=s.absolute_error_tol,
        before_iteration=builder.refresh_gravity,
    )
    v1, r1 = gauss_newton_qr(per_factor, values, ordering, **kw)
    v2, r2 = gauss_newton_qr(bulk, values, ordering, **kw)
    assert r1.iterations == r2.iterations and r1.converged and r2.converged
    assert abs(r1.final_error - r2.final_error) <= 1e-9 * r1.final_error
    # the outlier is down-weighted at the solution: its whitened error is beyond the Huber threshold
    ew = bulk.bulk._evaluate(v2, False)
    w, _ = bulk.bulk._weights_and_losses(ew)
    assert (w < 0.7).sum() >= 1
    # the same estimates (the scale's sigma is 4e-4, the offset's 0.02 s)
    for key in (K_SCALE, T_OFFSET):
        a, b = v1.atVector(key)[0], v2.atVector(key)[0]
        assert abs(a - b) < 1e-9 + 1e-6 * abs(a)
    assert np.allclose(v1.atRot3(C_MISALIGN).matrix(), v2.atRot3(C_MISALIGN).matrix(), atol=1e-9)


def test_smooth_batch_reports_progress_through_the_preintegration() -> None:
    """The progress callback moves during the preintegration (a day's takes about a minute), never goes back, and
    ends at 1."""
    seen: list[float] = []
    smooth_batch(run_log(), configs()["paper"], progress=seen.append)
    assert all(b >= a for a, b in zip(seen, seen[1:], strict=False)) and seen[-1] == 1.0
    assert len([f for f in seen if 0.0 < f < 0.15]) >= 15


@pytest.mark.slow
def test_smooth_batch_unchanged_by_bulk() -> None:
    """smooth_batch (bulk) against the per-factor graph solved the same way: estimates within 1e-6 sigma."""
    cfg = configs()["paper"]
    r = smooth_batch(run_log(), cfg)
    builder = LogGraph(run_log(), cfg)
    graph, values = builder.build()
    ordering = builder.elimination_ordering()
    s = cfg.solver
    ref, _ = gauss_newton_qr(
        graph,
        values,
        ordering,
        max_iterations=s.max_iterations,
        relative_tol=s.relative_error_tol,
        absolute_tol=s.absolute_error_tol,
        before_iteration=builder.refresh_gravity,
    )
    assert abs(r.scale - ref.atVector(K_SCALE)[0]) < 1e-6 * r.scale_sigma
    assert r.info["solver"]["dof"] == graph_rows(graph) - values.dim()


def test_build_bulk_lets_the_snapshots_go() -> None:
    """After build_bulk the per-ping snapshots are gone (their numbers are in the bulk arrays): asking for the
    per-factor keyframe factors, or a second bulk graph, is a clear error, not a wrong graph."""
    builder = LogGraph(run_log(), EstimatorConfig.paper())
    builder.build_bulk()
    i = next(i for i, ep in enumerate(builder.epochs) if ep.between)
    with pytest.raises(GtsamDvlError, match="snapshots go"):
        builder.between_factors(i)
    with pytest.raises(GtsamDvlError, match="let go by an earlier build_bulk"):
        builder.build_bulk()
