"""One vehicle calibration from several dives: joint Gauss-Newton over D dives that share the vehicle's states.

The vehicle's states s (core/states.py STATES with vehicle=True that the configuration estimates, but the time
offset: the scale, the misalignment and, when estimated, the lever arm) are shared by every dive; each dive d keeps
its own variables x_d (trajectory, IMU biases, time offset, the DVL's correlated error). The joint problem is

    min over s, x_1..x_D of  sum_d || f_d(x_d, s) ||^2  +  || prior(s) ||^2

with f_d the batch smoother's whitened factors of dive d (estimators/graph/log_graph.py LogGraph,
estimators/batch/smoother.py)
WITHOUT the priors of s, which the joint problem holds once. One Gauss-Newton iteration, exact for the linearised
problem:

1. each dive linearises its graph at (x_d, s) and eliminates its own variables with QR
   (GaussianFactorGraph.eliminatePartialSequential): a Bayes net p(x_d | s), kept for step 3, and what is left on
   s, the dive's reduced square-root information [R_d | d_d] (Reduction: the Schur complement of x_d, in
   square-root form);
2. the caller stacks the D reductions and the priors' rows linearised at s, and solves by QR for the step ds and
   the joint covariance of s (solve_shared);
3. each dive back-substitutes its Bayes net with ds for dx_d, retracts (x_d, s), and the next iteration
   relinearises.

The iterations stop when every component of ds is below a small fraction ([tol], 1e-2 by default) of its sigma.
Each dive's steps touch only that dive's data, so dives run anywhere (app/campaign/calibrate.py runs them as Dask
tasks, each dive's DiveState kept on its worker); this module has no Dask. Before the joint iterations each dive
is smoothed alone with the priors (prepare_dive: the batch smoother's passes, its DVL noise fit), which gives the
per-dive estimates of the fleet table and a starting point close to the joint optimum.

solve_one_graph is the independent check: every dive's linearised factors, their own keys renamed per dive, in ONE
factor graph with the shared keys, eliminated at once (QR) and iterated the same way.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np
from scipy.linalg import solve_triangular

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import key_dim
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.states import (
    BY_NAME,
    Estimate,
    calibration_info,
    enabled_states,
    joint_slices,
    prior_factors,
    read_values,
)
from gtsam_dvl.core.states import calibration_states as states_held
from gtsam_dvl.core.types import LogData, Mounting
from gtsam_dvl.estimators.batch.solve import solve_log
from gtsam_dvl.estimators.graph.bulk import BulkGraph
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.graph.solver import (
    CHUNKED_FROM_STATES,
    ChunkedOrdering,
    CompactBayesNet,
    bayes_net_marginals,
    eliminate_chunks,
)
from gtsam_dvl.estimators.inputs.gaps import screened_in_memory, screened_losses
from gtsam_dvl.estimators.models.current import resolve_water_track
from gtsam_dvl.estimators.models.noise_levels import NoiseReport

# states that stay per dive although core/states.py marks them as the vehicle's: a dive's own clocks
PER_DIVE = ("time_offset",)
TOL = 1e-2  # stop when every |ds_i| < TOL sigma_i
MAX_ITERATIONS = 20


def calibration_states(
    config: EstimatorConfig, calibration: VehicleCalibration | None = None
) -> list[str]:
    """The vehicle's calibration states the dives share, in registry (= key, = covariance) order: the vehicle's
    states the configuration estimates but the time offset, and with a vehicle's calibration as the prior
    (core/states.py calibration_states) every state it holds, the time offset too (one joint prior)."""
    held = {s.name for s in states_held(config, calibration)}
    return [
        s.name
        for s in enabled_states(config)
        if (s.vehicle and s.name not in PER_DIVE) or s.name in held
    ]


def state_keys(names: Sequence[str]) -> list[int]:
    return [BY_NAME[n].key for n in names]


def state_slices(names: Sequence[str]) -> dict[str, slice]:
    out, col = {}, 0
    for n in names:
        out[n] = slice(col, col + BY_NAME[n].dim)
        col += BY_NAME[n].dim
    return out


@dataclass
class Reduction:
    """A dive's information on the shared block after eliminating its own variables: the rows [R | d] of
    || R ds - d ||^2 (square-root information, upper triangular), and the dive's error at the linearisation
    point (half its chi^2, its shared priors not included)."""

    R: np.ndarray
    d: np.ndarray
    error: float


@dataclass
class DiveState:
    """One dive of a calibration: its graph without the shared priors, its estimate, the Bayes net of its last
    reduction (for the back-substitution), and its estimate alone (with the priors) for the fleet table."""

    name: str
    builder: LogGraph
    graph: BulkGraph
    values: gtsam.Values
    states: list[str]
    own: gtsam.Ordering  # the dive's own keys, eliminated in this order
    shared: gtsam.Ordering  # the shared keys, in `states` order
    alone: NavResult  # the dive smoothed alone, with the priors
    # the states' keys in chunks (estimators/graph/log_graph.py elimination_ordering), then the dive's own shared
    # keys
    plan: ChunkedOrdering = field(default_factory=lambda: ChunkedOrdering([], []), repr=False)
    bayes_net: gtsam.GaussianBayesNet | CompactBayesNet | None = field(default=None, repr=False)
    # the prior (prepare_dive)
    calibration: VehicleCalibration | None = field(default=None, repr=False)

    @property
    def config(self) -> EstimatorConfig:
        return self.builder.config

    @property
    def mounting(self) -> Mounting:
        return self.builder.maker.mounting


def prepare_dive(
    log: LogData,
    config: EstimatorConfig | None = None,
    name: str = "",
    calibration: VehicleCalibration | None = None,
) -> DiveState:
    """A dive smoothed alone as the batch smoother does (its passes and DVL noise fit, estimators/batch/smoother.py),
    then its graph without the priors of the shared states, ready for the joint iterations. calibration: a vehicle's
    calibration as the joint prior of the states it holds (batch.smooth_batch's), counted once by the caller."""
    config = (config or EstimatorConfig.for_log(log.metadata)).validate()
    config = resolve_water_track(config, log)  # (the steps of batch.smooth_batch, in its order)
    stated = config
    noise = NoiseReport()
    log = screened_in_memory(log)
    solved = solve_log(log, config, noise, {}, calibration)
    builder, graph, values, ordering = solved.builder, solved.graph, solved.values, solved.ordering
    alone = solved.result()
    alone.info["noise"] = noise.as_dict()
    if (screened := screened_losses(log)) is not None:
        alone.info["screened_losses"] = screened
    alone.config = stated.to_dict()
    if calibration is not None:
        alone.info["calibration_prior"] = calibration_info(builder.config, calibration)
    names = calibration_states(builder.config, calibration)
    keys = state_keys(names)
    # the graph without the shared states' priors (the joint holds them)
    without = gtsam.NonlinearFactorGraph()
    for i in range(graph.graph.size()):
        if graph.graph.exists(i):
            f = graph.graph.at(i)
            if not all(k in keys for k in f.keys()):  # (a factor on shared keys alone: their prior)
                without.add(f)
    own = gtsam.Ordering()
    for k in [k for chunk in ordering.chunks for k in chunk] + [
        k for k in ordering.rest if k not in keys
    ]:
        own.push_back(k)
    shared = gtsam.Ordering()
    for k in keys:
        shared.push_back(k)
    return DiveState(
        name or log.source,
        builder,
        BulkGraph(without, graph.bulk, graph.imu),
        values,
        names,
        own,
        shared,
        alone,
        ChunkedOrdering(ordering.chunks, [k for k in ordering.rest if k not in keys]),
        calibration=calibration,
    )


def own_keys(dive: DiveState) -> list[int]:
    """The dive's own variables' keys, in elimination order."""
    return [dive.own.at(j) for j in range(dive.own.size())]


def shared_values(dive: DiveState) -> dict[str, np.ndarray]:
    """The dive's current values of the shared states (the misalignment as the 3x3 b_R_d)."""
    every = read_values(dive.values, dive.config)
    return {n: np.asarray(every[n], dtype=float) for n in dive.states}


def set_shared(dive: DiveState, values: dict[str, np.ndarray]) -> None:
    """Set the dive's copy of the shared states (every dive holds the caller's values exactly)."""
    for n in dive.states:
        s = BY_NAME[n]
        if s.kind == "rot3":
            dive.values.update(s.key, gtsam.Rot3(np.asarray(values[n], dtype=float)))
        else:
            dive.values.update(s.key, np.asarray(values[n], dtype=float))


def _square_root(A: np.ndarray, b: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """[R | d] (n rows, zero-padded) of the rows A x - b by QR (Householder, numpy/LAPACK)."""
    r = np.asarray(np.linalg.qr(np.column_stack([A, b]), mode="r"))
    out = np.zeros((n, n + 1))
    m = min(n, r.shape[0])
    out[:m] = r[:m]
    return out[:, :n], out[:, n]


def eliminate_own(
    linear: gtsam.GaussianFactorGraph, plan: ChunkedOrdering, own: gtsam.Ordering
) -> tuple[gtsam.GaussianBayesNet | CompactBayesNet, gtsam.GaussianFactorGraph]:
    """QR elimination of a dive's own variables (plan: its states' chunks, then its own shared keys in plan.rest),
    leaving the factor graph on the shared keys: GTSAM's one partial elimination (`own`, the same order), or above
    solver.CHUNKED_FROM_STATES states a chunk at a time, as solver.eliminate_chunked does (GTSAM's one elimination
    costs in proportion to the mission squared there)."""
    if sum(len(ks) for ks in plan.chunks) <= 2 * CHUNKED_FROM_STATES:
        return linear.eliminatePartialSequential(own, gtsam.EliminateQR)
    bn, tail = eliminate_chunks(linear, plan)
    order = gtsam.Ordering()
    for k in plan.rest:
        order.push_back(k)
    part, rest = tail.eliminatePartialSequential(order, gtsam.EliminateQR)
    bn.push_back(part)
    return bn, rest


def back_substitute(
    bn: gtsam.GaussianBayesNet | CompactBayesNet, given: dict[int, np.ndarray]
) -> gtsam.VectorValues:
    """x_F = R^-1 (d - S x_P) from the last conditional to the first, the shared keys' values given."""
    if isinstance(bn, gtsam.GaussianBayesNet):
        vv = gtsam.VectorValues()
        for k, v in given.items():
            vv.insert(k, v)
        return bn.optimize(vv)
    return bn.optimize(given)


def reduce_dive(dive: DiveState) -> Reduction:
    """Linearise the dive at its values and eliminate its own variables (QR): its information on the shared
    states; keeps the Bayes net p(x_d | s) for advance_dive."""
    dive.builder.refresh_gravity(dive.values)
    linear = dive.graph.linearize(dive.values)
    try:
        bn, rest = eliminate_own(linear, dive.plan, dive.own)
    except RuntimeError as exc:
        raise GtsamDvlError(
            f"{dive.name}: its own variables could not be eliminated ({exc})"
        ) from None
    dive.bayes_net = bn
    A, b = rest.jacobian(dive.shared)
    n = sum(BY_NAME[s].dim for s in dive.states)
    R, d = _square_root(A, np.ravel(b), n)
    return Reduction(R, d, float(dive.graph.error(dive.values)))


def advance_dive(dive: DiveState, ds: np.ndarray, new_shared: dict[str, np.ndarray]) -> None:
    """Back-substitute the last reduction's Bayes net with the shared step ds (tangent, `states` order) for the
    dive's own step, retract, and set the shared states to new_shared (the caller's retraction of ds)."""
    if dive.bayes_net is None:
        raise GtsamDvlError(f"{dive.name}: advance_dive before reduce_dive")
    given = {
        BY_NAME[n].key: np.asarray(ds[sl], dtype=float)
        for n, sl in state_slices(dive.states).items()
    }
    dx = back_substitute(dive.bayes_net, given)
    for n, sl in state_slices(dive.states).items():
        if not dx.exists(BY_NAME[n].key):
            dx.insert(BY_NAME[n].key, np.asarray(ds[sl], dtype=float))
    dive.values = dive.values.retract(dx)
    set_shared(dive, new_shared)
    dive.bayes_net = None


# ----- the caller's side: the shared priors, the joint solve, the iterations -----------------------------------


def shared_prior_graph(
    config: EstimatorConfig,
    mounting: Mounting,
    names: Sequence[str],
    calibration: VehicleCalibration | None = None,
) -> gtsam.NonlinearFactorGraph:
    """The priors of the shared states (core/states.py prior_factors: with a vehicle's calibration, its one joint
    prior), once for all dives."""
    keys = set(state_keys(names))
    graph = gtsam.NonlinearFactorGraph()
    for f in prior_factors(config, mounting, calibration):
        if all(k in keys for k in f.keys()):
            graph.add(f)
    return graph


def _values_of(names: Sequence[str], values: dict[str, np.ndarray]) -> gtsam.Values:
    out = gtsam.Values()
    for n in names:
        s = BY_NAME[n]
        if s.kind == "rot3":
            out.insert(s.key, gtsam.Rot3(np.asarray(values[n], dtype=float)))
        else:
            out.insert(s.key, np.asarray(values[n], dtype=float))
    return out


def _dict_of(names: Sequence[str], values: gtsam.Values) -> dict[str, np.ndarray]:
    return {
        n: (
            np.asarray(values.atRot3(BY_NAME[n].key).matrix())
            if BY_NAME[n].kind == "rot3"
            else np.asarray(values.atVector(BY_NAME[n].key), dtype=float)
        )
        for n in names
    }


def retract_shared(
    names: Sequence[str], values: dict[str, np.ndarray], ds: np.ndarray
) -> dict[str, np.ndarray]:
    """The shared states moved by ds (tangent, GTSAM's retraction: b_R_d perturbed on the right)."""
    delta = gtsam.VectorValues()
    for n, sl in state_slices(names).items():
        delta.insert(BY_NAME[n].key, np.asarray(ds[sl], dtype=float))
    return _dict_of(names, _values_of(names, values).retract(delta))


def prior_rows(
    prior: gtsam.NonlinearFactorGraph, names: Sequence[str], values: dict[str, np.ndarray]
) -> Reduction:
    """The shared priors linearised at values, as square-root rows."""
    at = _values_of(names, values)
    order = gtsam.Ordering()
    for k in state_keys(names):
        order.push_back(k)
    A, b = prior.linearize(at).jacobian(order)
    R, d = _square_root(A, np.ravel(b), A.shape[1])
    return Reduction(R, d, float(prior.error(at)))


def solve_shared(parts: Sequence[Reduction]) -> tuple[np.ndarray, np.ndarray]:
    """The Gauss-Newton step of the shared states and their joint covariance from the stacked square-root rows
    (QR: R ds = d, cov = R^-1 R^-T)."""
    A = np.vstack([p.R for p in parts])
    b = np.concatenate([p.d for p in parts])
    R, d = _square_root(A, b, A.shape[1])
    if np.any(np.abs(np.diag(R)) <= 1e-12 * max(1.0, float(np.abs(R).max()))):
        raise GtsamDvlError(
            "the shared calibration states are not determined by the dives and their priors"
        )
    ds = solve_triangular(R, d)
    Rinv = solve_triangular(R, np.eye(len(d)))
    return ds, Rinv @ Rinv.T


@dataclass
class JointSolution:
    """The joint calibration: the shared states' values and joint covariance (SI, `states` order), and how the
    iterations went (per iteration the total error and the largest |ds_i| / sigma_i)."""

    states: list[str]
    values: dict[str, np.ndarray]
    cov: np.ndarray
    iterations: int
    converged: bool
    history: list[dict[str, float]] = field(default_factory=list)
    # the last iteration's rows: each dive's reduction (in the order of the dives kept) and the priors'
    reductions: list[Reduction] = field(default_factory=list, repr=False)
    prior_rows: list[Reduction] = field(default_factory=list, repr=False)

    def estimates(self) -> dict[str, Estimate]:
        sl = state_slices(self.states)
        return {n: Estimate(self.values[n], self.cov[sl[n], sl[n]]) for n in self.states}


# what the caller needs of the dives, wherever they run: reduce every dive still in (one Reduction each) and
# advance them (ds, the new shared values)
ReduceAll = Callable[[], list[Reduction]]
AdvanceAll = Callable[[np.ndarray, dict[str, np.ndarray]], None]


def iterate_joint(
    names: list[str],
    start: dict[str, np.ndarray],
    prior: gtsam.NonlinearFactorGraph,
    reduce_all: ReduceAll,
    advance_all: AdvanceAll,
    tol: float = TOL,
    max_iterations: int = MAX_ITERATIONS,
) -> JointSolution:
    """The joint Gauss-Newton iterations (module doc) over dives that the callbacks reach: reduce_all linearises
    and reduces every dive at the current shared values (which advance_all set), advance_all back-substitutes ds.
    The callbacks leave out a dive that failed (and report it), so that the others finish."""
    values = dict(start)
    history: list[dict[str, float]] = []
    cov = np.zeros((0, 0))
    parts: list[Reduction] = []
    p = Reduction(np.zeros((0, 0)), np.zeros(0), 0.0)
    for it in range(1, max_iterations + 1):
        parts = reduce_all()
        if not parts:
            raise GtsamDvlError("calibrate: every dive failed")
        p = prior_rows(prior, names, values)
        ds, cov = solve_shared(parts + [p])
        step = float(np.max(np.abs(ds) / np.sqrt(np.diag(cov))))
        history.append(
            {
                "error": sum(r.error for r in parts) + p.error,
                "step_sigma": step,
                "dives": len(parts),
            }
        )
        values = retract_shared(names, values, ds)
        advance_all(ds, values)
        if step < tol:
            return JointSolution(names, values, cov, it, True, history, parts, [p])
    return JointSolution(names, values, cov, max_iterations, False, history, parts, [p])


def calibrate_in_process(
    dives: list[DiveState], tol: float = TOL, max_iterations: int = MAX_ITERATIONS
) -> JointSolution:
    """The joint calibration of prepared dives in this process (no Dask): iterate_joint over the list."""
    names, start, prior = joint_setup(dives)
    for d in dives:
        set_shared(d, start)

    def reduce_all() -> list[Reduction]:
        return [reduce_dive(d) for d in dives]

    def advance_all(ds: np.ndarray, new: dict[str, np.ndarray]) -> None:
        for d in dives:
            advance_dive(d, ds, new)

    return iterate_joint(names, start, prior, reduce_all, advance_all, tol, max_iterations)


def joint_setup(
    dives: Sequence[DiveState] | Sequence[DiveSummary],
) -> tuple[list[str], dict[str, np.ndarray], gtsam.NonlinearFactorGraph]:
    """The shared states, the starting values (the dive with the smallest scale sigma alone: the best
    determined) and the shared priors, checked for one vehicle: the same states and the same nominal mounting."""
    summaries = [d if isinstance(d, DiveSummary) else summarise(d) for d in dives]
    first = summaries[0]
    for s in summaries[1:]:
        if s.states != first.states:
            raise GtsamDvlError(
                f"{s.name}: estimates {', '.join(s.states)}, {first.name} "
                f"{', '.join(first.states)}: one configuration for every dive"
            )
        if not (
            np.allclose(s.mounting.b_R_d0, first.mounting.b_R_d0, atol=1e-9)
            and np.allclose(s.mounting.b_l, first.mounting.b_l, atol=1e-9)
        ):
            raise GtsamDvlError(
                f"{s.name}: its nominal DVL mounting (/tf_static) differs from {first.name}'s: "
                "one vehicle's dives share one mounting"
            )
    best = min(
        summaries, key=lambda s: float(s.alone["scale"].sigma[0]) if "scale" in s.alone else 0.0
    )
    start = {n: np.asarray(best.alone[n].value, dtype=float) for n in first.states}
    return (
        list(first.states),
        start,
        shared_prior_graph(first.config, first.mounting, first.states, first.calibration),
    )


@dataclass
class DiveSummary:
    """What the caller needs of a prepared dive (small, picklable): its name, states, configuration, mounting and
    its estimates alone (every shared state, the time offset and biases included)."""

    name: str
    states: list[str]
    config: EstimatorConfig
    mounting: Mounting
    alone: dict[str, Estimate]
    alone_cov: np.ndarray  # the joint covariance of `states` alone (SI, `states` order)
    t0_ns: int
    info: dict[str, Any]
    # the configuration as given (NavResult.config)
    stated_config: dict[str, Any] = field(default_factory=dict)
    # a vehicle's calibration as the prior (prepare_dive)
    calibration: VehicleCalibration | None = None


def summarise(dive: DiveState) -> DiveSummary:
    """The dive's DiveSummary (its estimates alone, from the result of prepare_dive)."""
    result = dive.alone
    sl = joint_slices(dive.config)
    idx = np.concatenate([np.arange(sl[n].start, sl[n].stop) for n in dive.states])
    cov = np.asarray(result.shared_joint_cov)[np.ix_(idx, idx)]
    return DiveSummary(
        dive.name,
        list(dive.states),
        dive.config,
        dive.mounting,
        dict(result.calibration),
        cov,
        int(result.t0_ns),
        {
            "epochs": result.info.get("epochs"),
            "noise": result.info.get("noise"),
            "solver": result.info.get("solver"),
        },
        dict(result.config),
        dive.calibration,
    )


# ----- the independent check: every dive in one graph ---------------------------------------------------------


class Rows:
    """Fixed whitened rows A dx - b as a CustomFactor serves them: a linear factor on any number of keys (GTSAM's
    Python JacobianFactor takes at most three)."""

    __slots__ = ("blocks", "e")

    def __init__(self, blocks: list[np.ndarray], b: np.ndarray) -> None:
        self.blocks, self.e = blocks, -b

    def __call__(self, _factor: Any, _values: gtsam.Values, H: Any) -> np.ndarray:
        if H is not None:
            for n, J in enumerate(self.blocks):
                H[n] = J
        return self.e


def renamed(
    linear: gtsam.GaussianFactorGraph, rename: Callable[[int], int]
) -> tuple[gtsam.GaussianFactorGraph, set[int]]:
    """A linear graph with its keys renamed (GTSAM's Python JacobianFactor takes at most three keys, so each
    factor's whitened rows go through a CustomFactor on the new keys, linearised once); and the new keys."""
    carriers = gtsam.NonlinearFactorGraph()
    keys: set[int] = set()
    for i in range(linear.size()):
        f = linear.at(i)
        if f is None:
            continue
        A, b = gtsam.JacobianFactor(f).jacobian()
        old = list(f.keys())
        cols = np.cumsum([0] + [key_dim(k) for k in old])
        new = [rename(k) for k in old]
        keys.update(new)
        carriers.add(
            gtsam.CustomFactor(
                gtsam.noiseModel.Unit.Create(A.shape[0]),
                new,
                Rows([A[:, cols[j] : cols[j + 1]] for j in range(len(old))], np.ravel(b)),
            )
        )
    at = gtsam.Values()
    for k in keys:
        at.insert(k, np.zeros(key_dim(k)))
    return carriers.linearize(at), keys


def _renaming(shared: set[int], offset: int) -> Callable[[int], int]:
    def rename(k: int) -> int:
        return k if k in shared else k + offset

    return rename


def solve_one_graph(
    dives: Sequence[DiveState], tol: float = TOL, max_iterations: int = MAX_ITERATIONS
) -> JointSolution:
    """The independent check of calibrate: the dives' linearised graphs, each dive's own keys renamed (the symbol
    index moved by (d + 1) * 2^40), with the shared keys and their priors in ONE factor graph, eliminated at once
    (QR, the shared keys last) and iterated by Gauss-Newton as one problem. Works on copies: the dives' values
    are not changed."""
    names, start, prior = joint_setup(dives)
    shift = 1 << 40
    shared = set(state_keys(names))
    values = [gtsam.Values(d.values) for d in dives]
    for v in values:
        for n in names:
            v.update(
                BY_NAME[n].key, gtsam.Rot3(start[n]) if BY_NAME[n].kind == "rot3" else start[n]
            )
    s = dict(start)
    history: list[dict[str, float]] = []
    for it in range(1, max_iterations + 1):
        graph = gtsam.GaussianFactorGraph()
        order = gtsam.Ordering()
        error = 0.0
        for d, (dive, v) in enumerate(zip(dives, values, strict=True)):
            dive.builder.refresh_gravity(v)
            error += float(dive.graph.error(v))
            lin, _ = renamed(dive.graph.linearize(v), _renaming(shared, (d + 1) * shift))
            graph.push_back(lin)
            for j in range(dive.own.size()):
                order.push_back(dive.own.at(j) + (d + 1) * shift)
        at = _values_of(names, s)
        graph.push_back(prior.linearize(at))
        error += float(prior.error(at))
        for k in state_keys(names):
            order.push_back(k)
        bn = graph.eliminateSequential(order, gtsam.EliminateQR)
        delta = bn.optimize()
        ds = np.concatenate([delta.at(k) for k in state_keys(names)])
        marg = bayes_net_marginals(bn, [tuple(state_keys(names))])
        cov = marg.joints[tuple(state_keys(names))]
        step = float(np.max(np.abs(ds) / np.sqrt(np.diag(cov))))
        history.append({"error": error, "step_sigma": step, "dives": len(dives)})
        s = retract_shared(names, s, ds)
        for d, (dive, v) in enumerate(zip(dives, values, strict=True)):
            dx = gtsam.VectorValues()
            for j in range(dive.own.size()):
                k = dive.own.at(j)
                dx.insert(k, delta.at(k + (d + 1) * shift))
            for k in state_keys(names):
                dx.insert(k, delta.at(k))
            values[d] = v.retract(dx)
        if step < tol:
            return JointSolution(names, s, cov, it, True, history)
    return JointSolution(names, s, cov, max_iterations, False, history)
