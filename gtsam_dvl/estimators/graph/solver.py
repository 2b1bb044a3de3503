"""Gauss-Newton with QR, driven from Python, and marginal covariances from the QR Bayes net.

Why not GTSAM's own optimisers: a Python CustomFactor evaluated inside them receives a copy of the
whole Values per call (cost quadratic in the log length), and their Cholesky elimination fails at
navigation-grade noise. `graph.linearize(values)` called from Python does not copy, and QR is stable.

Why the marginals are computed here: `gtsam.Marginals` eliminates with Cholesky (fails at these noise
levels) and has no QR option from Python. With the elimination ordering states-in-time-order and the
shared keys last, the Bayes net is a chain; one backward pass over its conditionals
(x_F = R^-1 (d - S x_P), so Sigma_FA = -R^-1 S Sigma_PA and Sigma_FF = R^-1 R^-T - Sigma_FP S^T R^-T)
gives the marginal of every variable with small dense matrices (an RTS smoother in Bayes-net form).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import gtsam
import numpy as np
from scipy.linalg.lapack import dtrtrs as _trtrs

from gtsam_dvl.core.errors import GtsamDvlError


@dataclass
class SolveReport:
    iterations: int = 0
    initial_error: float = 0.0
    final_error: float = 0.0
    converged: bool = False
    history: list[float] = field(default_factory=list)
    timing_s: dict[str, float] = field(default_factory=dict)
    # QR Bayes net of the last linearisation: after convergence its step changed the error by less than
    # the tolerance, so it serves the marginals without another elimination
    bayes_net: gtsam.GaussianBayesNet | CompactBayesNet | None = None


class Objective(Protocol):
    """What the solver needs of a graph: a NonlinearFactorGraph, or estimators/graph/bulk.py's BulkGraph."""

    def error(self, values: gtsam.Values) -> float: ...

    def linearize(self, values: gtsam.Values) -> gtsam.GaussianFactorGraph: ...


class CompactConditional:
    """One conditional R x_F + S x_P = d of a QR Bayes net (unit sigmas), as numpy arrays."""

    __slots__ = ("_keys", "_R", "_S", "_d")

    def __init__(self, c: gtsam.GaussianConditional) -> None:
        self._keys = c.keys()  # (a new list)
        # copies: the wrapper's arrays are read-only views of the GTSAM conditional, which is let go
        self._R, self._S, self._d = c.R().copy(), c.S().copy(), c.d().copy()

    def keys(self) -> list[int]:
        return self._keys

    def R(self) -> np.ndarray:
        return self._R

    def S(self) -> np.ndarray:
        return self._S

    def d(self) -> np.ndarray:
        return self._d


class CompactBayesNet:
    """A QR Bayes net kept as numpy arrays: GTSAM's conditionals keep the whole matrix of the factor they were
    eliminated from, several times the size of R, S and d (docs/results.md, Speed), so each elimination's
    conditionals are copied out and GTSAM's let go. optimize() is
    GTSAM's back-substitution, x_F = R^-1 (d - S x_P), from the last conditional to the first."""

    def __init__(self) -> None:
        self.conds: list[CompactConditional] = []

    def push_back(self, bn: gtsam.GaussianBayesNet) -> None:
        self.conds += [CompactConditional(bn.at(i)) for i in range(bn.size())]

    def size(self) -> int:
        return len(self.conds)

    def at(self, i: int) -> CompactConditional:
        return self.conds[i]

    def optimize(self, given: dict[int, np.ndarray] | None = None) -> gtsam.VectorValues:
        """The back-substitution; given: the values of parents that no conditional of the net holds (a partial
        elimination's remaining keys), not in the output."""
        x: dict[int, np.ndarray] = dict(given or {})
        out = gtsam.VectorValues()
        for c in reversed(self.conds):
            keys = c._keys
            rhs = c._d
            if len(keys) > 1:
                rhs = rhs - c._S @ np.concatenate([x[k] for k in keys[1:]])
            # R is upper triangular (QR): LAPACK's triangular solve, cheaper than np.linalg.solve (a day of 1 s
            # keyframes has 170,000 conditionals; docs/results.md, Speed)
            sol, info = _trtrs(c._R, rhs)
            if info != 0 or not np.isfinite(sol).all():
                raise GtsamDvlError(
                    "the linear system is indeterminate at variable "
                    f"{gtsam.DefaultKeyFormatter(keys[0])}"
                )
            x[keys[0]] = sol
            out.insert(keys[0], sol)
        return out


@dataclass
class ChunkedOrdering:
    """A sequential elimination order given as consecutive chunks of variables (each a run of states in time
    order) and the rest (the shared keys) last, eliminated one chunk at a time (eliminate_chunked)."""

    chunks: list[list[int]]
    rest: list[int]

    def ordering(self) -> gtsam.Ordering:
        out = gtsam.Ordering()
        for k in [k for ks in self.chunks for k in ks] + self.rest:
            out.push_back(k)
        return out


def eliminate_chunked(linear: gtsam.GaussianFactorGraph, plan: ChunkedOrdering) -> CompactBayesNet:
    """QR elimination in plan's order, the Bayes net of linear.eliminateSequential(plan.ordering()), computed a
    chunk at a time on the factors that involve it (and what the previous chunks left on their separator).

    Why: GTSAM's sequential elimination keeps one variable index over the whole graph, and the shared keys
    (bias, scale, misalignment, time offset) are in nearly every factor; each eliminated variable removes its
    factors from those keys' lists, which costs in proportion to their length: quadratic in the mission
    (docs/results.md, Speed). Chunks keep each index short: linear again."""
    bn, rest = eliminate_chunks(linear, plan)
    order = gtsam.Ordering()
    for k in plan.rest:
        order.push_back(k)
    bn.push_back(rest.eliminateSequential(order, gtsam.EliminateQR))
    return bn


def eliminate_chunks(
    linear: gtsam.GaussianFactorGraph, plan: ChunkedOrdering
) -> tuple[CompactBayesNet, gtsam.GaussianFactorGraph]:
    """plan's chunks eliminated one at a time (eliminate_chunked's method): their Bayes net, and the factor graph
    left on the other keys (plan.rest and any key in no chunk)."""
    chunk_of = {k: c for c, ks in enumerate(plan.chunks) for k in ks}
    groups: list[list[gtsam.GaussianFactor]] = [[] for _ in plan.chunks]
    tail: list[gtsam.GaussianFactor] = []
    for i in range(linear.size()):
        f = linear.at(i)
        if f is None:
            continue
        cs = [chunk_of[k] for k in f.keys() if k in chunk_of]
        (groups[min(cs)] if cs else tail).append(f)
    bn = CompactBayesNet()
    carry = gtsam.GaussianFactorGraph()
    for ks, factors in zip(plan.chunks, groups, strict=True):
        g = gtsam.GaussianFactorGraph()
        for f in factors:
            g.push_back(f)
        # after the chunk's own factors, as sequential elimination appends what it creates
        g.push_back(carry)
        order = gtsam.Ordering()
        for k in ks:
            order.push_back(k)
        part, carry = g.eliminatePartialSequential(order, gtsam.EliminateQR)
        bn.push_back(part)
    g = gtsam.GaussianFactorGraph()
    for f in tail:
        g.push_back(f)
    g.push_back(carry)
    return bn, g


CHUNKED_FROM_STATES = 8000  # below, one GTSAM elimination is faster (docs/results.md, Speed)


def eliminate(
    linear: gtsam.GaussianFactorGraph, ordering: gtsam.Ordering | ChunkedOrdering
) -> gtsam.GaussianBayesNet | CompactBayesNet:
    """QR elimination in the given order: chunk by chunk (a CompactBayesNet) for a ChunkedOrdering of more than
    CHUNKED_FROM_STATES states' chunks, else GTSAM's one sequential elimination (its Bayes net: its quadratic
    cost and its memory only tell beyond a few hours of 1 s states)."""
    if isinstance(ordering, ChunkedOrdering):
        # two or three keys a state
        if sum(len(ks) for ks in ordering.chunks) > 2 * CHUNKED_FROM_STATES:
            return eliminate_chunked(linear, ordering)
        ordering = ordering.ordering()
    return linear.eliminateSequential(ordering, gtsam.EliminateQR)


def gauss_newton_qr(
    graph: Objective,
    values: gtsam.Values,
    ordering: gtsam.Ordering | ChunkedOrdering,
    *,
    max_iterations: int = 30,
    relative_tol: float = 1e-9,
    absolute_tol: float = 1e-9,
    before_iteration: Callable[[gtsam.Values], bool] | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[gtsam.Values, SolveReport]:
    """Minimise the graph's error from `values`: linearise, eliminate with QR, retract; halve the step
    when the error grows. `before_iteration(values)` may update factor parameters (gravity) and returns
    whether it did; the loop converges only on an iteration where it did not."""
    report = SolveReport()
    t_lin = t_elim = 0.0
    error = np.inf
    for it in range(max_iterations):
        # the hook may change the objective (gravity follows the positions): re-evaluate the error after it
        changed = before_iteration(values) if before_iteration is not None else False
        if changed or not np.isfinite(error):
            error = graph.error(values)
        if it == 0:
            report.initial_error = error
            report.history.append(error)
        t0 = time.perf_counter()
        report.bayes_net = bn = None  # the previous iteration's: not alive beside this one's
        linear = graph.linearize(values)
        t1 = time.perf_counter()
        try:
            bn = eliminate(linear, ordering)
            delta = bn.optimize()
        except RuntimeError as exc:
            raise GtsamDvlError(
                f"the linear system could not be solved ({exc}); check priors and data"
            ) from None
        t_lin += t1 - t0
        t_elim += time.perf_counter() - t1
        step, new_error, new_values = 1.0, np.inf, values
        for _ in range(8):
            candidate = values.retract(delta if step == 1.0 else delta.scale(step))
            new_error = graph.error(candidate)
            if np.isfinite(new_error) and new_error <= error * (1 + 1e-12):
                new_values = candidate
                break
            step *= 0.5
        report.iterations = it + 1
        report.bayes_net = bn
        del linear  # before the next linearisation: two of a day's linear systems at once cost a GB
        # no step decreased the error: at the minimum to numerical precision
        if new_values is values:
            report.converged = not changed
            if not changed:
                break
            continue
        decrease = error - new_error
        values, error = new_values, new_error
        report.history.append(error)
        if progress is not None:
            progress(min(0.95, (it + 1) / max_iterations * 4))
        if not changed and (decrease <= absolute_tol or decrease <= relative_tol * error):
            report.converged = True
            break
    report.final_error = graph.error(values)
    report.timing_s = {"linearize": t_lin, "eliminate": t_elim}
    return values, report


def tail_covariance(
    bn: gtsam.GaussianBayesNet | CompactBayesNet, keys: Iterable[int]
) -> np.ndarray:
    """The joint marginal covariance of keys that a QR Bayes net eliminated last (the shared states: every
    ordering of the estimators puts them there), from the last conditionals alone: the tail from the first of
    keys to the end conditions only on itself, so its R gives the block's covariance without a pass over the
    states (cheap enough to ask after every solve)."""
    keys = list(keys)
    wanted = set(keys)
    n = bn.size()
    tail: list[Any] = []
    for i in range(n - 1, -1, -1):
        c = bn.at(i)
        tail.append(c)
        wanted.discard(c.keys()[0])
        if not wanted:
            break
    if wanted:
        raise GtsamDvlError("tail_covariance: a key is not a frontal variable of the Bayes net")
    tail.reverse()
    starts: dict[int, int] = {}
    col = 0
    for c in tail:
        starts[c.keys()[0]] = col
        col += c.R().shape[0]
    R = np.zeros((col, col))
    for c in tail:
        a = starts[c.keys()[0]]
        d = c.R().shape[0]
        R[a : a + d, a : a + d] = c.R()
        S, j = c.S(), 0
        for k in c.keys()[1:]:
            if k not in starts:
                raise GtsamDvlError("tail_covariance: the keys were not eliminated last")
            dk = S.shape[1] if len(c.keys()) == 2 else _parent_dim(tail, k)
            R[a : a + d, starts[k] : starts[k] + dk] = S[:, j : j + dk]
            j += dk
    R_inv = np.linalg.inv(R)
    cov = R_inv @ R_inv.T
    idx = np.concatenate([np.arange(starts[k], starts[k] + _parent_dim(tail, k)) for k in keys])
    return np.asarray(cov[np.ix_(idx, idx)])


def _parent_dim(conds: list[Any], key: int) -> int:
    """The dimension of key, a frontal variable of one of conds."""
    for c in conds:
        if c.keys()[0] == key:
            return int(c.R().shape[0])
    raise GtsamDvlError("tail_covariance: a key is not a frontal variable of the Bayes net")


@dataclass
class MarginalResult:
    """Marginal covariances (in each variable's tangent space, GTSAM order) and chosen joints."""

    covariances: dict[int, np.ndarray]
    joints: dict[tuple[int, ...], np.ndarray]


def bayes_net_marginals(
    bn: gtsam.GaussianBayesNet | CompactBayesNet,
    joint_groups: Iterable[tuple[int, ...]] = (),
) -> MarginalResult:
    """Marginal covariance of every variable of a sequentially eliminated (QR) Bayes net, plus the joint
    covariance of each group in joint_groups (e.g. (X_i, V_i) or the calibration block)."""
    n = bn.size()
    conds = [bn.at(i) for i in range(n)]
    keys = [list(c.keys()) for c in conds]
    keep_until, groups_at = _sweep_plan(keys, joint_groups)
    active: list[int] = []
    dims: dict[int, int] = {}
    sigma = np.zeros((0, 0))
    covs: dict[int, np.ndarray] = {}
    joints: dict[tuple[int, ...], np.ndarray] = {}
    Rinvs = _inverse_rs(conds)
    starts: dict[int, int] = {}  # column of each active key in sigma, kept in step with active

    def restart() -> None:
        starts.clear()
        col = 0
        for k in active:
            starts[k] = col
            col += dims[k]

    def index_of(ks: list[int] | tuple[int, ...]) -> np.ndarray:
        return np.array(
            [c for k in ks for c in range(starts[k], starts[k] + dims[k])], dtype=np.intp
        )

    for i in range(n - 1, -1, -1):
        frontal, parents = keys[i][0], keys[i][1:]
        Rinv = Rinvs[i]
        dim_f = Rinv.shape[0]
        s_ff, cross = _frontal_blocks(conds[i], Rinv, sigma, index_of(parents) if parents else None)
        m = sigma.shape[0]
        grown = np.empty((dim_f + m, dim_f + m))
        grown[:dim_f, :dim_f] = s_ff
        grown[:dim_f, dim_f:] = cross
        grown[dim_f:, :dim_f] = cross.T
        grown[dim_f:, dim_f:] = sigma
        sigma = grown
        active.insert(0, frontal)
        dims[frontal] = dim_f
        restart()
        covs[frontal] = s_ff
        for g in groups_at.get(i, []):
            idx = index_of(g)
            joints[g] = sigma[np.ix_(idx, idx)].copy()
        keep = [k for k in active if keep_until.get(k, np.inf) < i]
        if len(keep) != len(active):
            idx = index_of(keep) if keep else np.zeros(0, dtype=int)
            sigma = sigma[np.ix_(idx, idx)]
            active = keep
            restart()
    return MarginalResult(covs, joints)


def _sweep_plan(
    keys: list[list[int]], joint_groups: Iterable[tuple[int, ...]]
) -> tuple[dict[int, float], dict[int, list[tuple[int, ...]]]]:
    """For the sweep from the last conditional to the first: keep_until[k], the smallest conditional index that
    still needs k (as a parent, or to read a joint), so that after processing conditional i every key with
    keep_until >= i can be dropped; and the joint groups to read at each conditional index (where the group's
    first key is eliminated)."""
    eliminated_at = {ks[0]: i for i, ks in enumerate(keys)}
    keep_until: dict[int, float] = {}
    for i, ks in enumerate(keys):
        for k in ks[1:]:
            keep_until[k] = min(keep_until.get(k, np.inf), i)
    groups_at: dict[int, list[tuple[int, ...]]] = {}
    for group in joint_groups:
        g = tuple(group)
        first = min(eliminated_at[k] for k in g)
        groups_at.setdefault(first, []).append(g)
        for k in g:
            keep_until[k] = min(keep_until.get(k, np.inf), first)
    return keep_until, groups_at


def _inverse_rs(conds: list[Any]) -> list[np.ndarray]:
    """The inverses of the conditionals' R (tiny, <= 6x6), by stacks of equal size: one numpy call per size, not
    one per conditional (scipy's solve_triangular and np.linalg.inv cost more per call than these blocks'
    arithmetic)."""
    Rs = [c.R() for c in conds]
    Rinvs: list[np.ndarray] = [np.empty((0, 0))] * len(conds)
    for d in {R.shape[0] for R in Rs}:
        at = [i for i, R in enumerate(Rs) if R.shape[0] == d]
        for i, inv in zip(at, np.linalg.inv(np.array([Rs[i] for i in at])), strict=True):
            Rinvs[i] = inv
    return Rinvs


def _frontal_blocks(
    c: Any, Rinv: np.ndarray, sigma: np.ndarray, idx_p: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """A conditional's frontal variable F given the joint covariance sigma of the active keys (its parents at
    the rows idx_p; None: no parent): Sigma_FF (symmetrised) and Sigma_{F, active}."""
    dim_f = Rinv.shape[0]
    if idx_p is not None:
        G = Rinv @ c.S()  # x_F = R^-1 d - G x_P
        cross = -G @ sigma[idx_p, :]  # Sigma_{F, active}
        s_ff = Rinv @ Rinv.T - cross[:, idx_p] @ G.T
    else:
        cross = np.zeros((dim_f, sigma.shape[0]))
        s_ff = Rinv @ Rinv.T
    return 0.5 * (s_ff + s_ff.T), cross
