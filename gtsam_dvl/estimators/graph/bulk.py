"""The batch smoother's DVL factors evaluated in bulk: one numpy evaluation per linearisation, not a Python call
per factor.

Why: GTSAM calls a Python CustomFactor once per factor per linearisation and per error evaluation. On a 5 Hz log
with 1 s keyframes that is 18,000 DVL factors per hour of log, ten evaluations per solve, each a Python call:
most of the per-factor graph's solve (docs/results.md, Speed). The batch smoother owns its Gauss-Newton loop
(estimators/graph/solver.py), so here the pings' errors and Jacobians come from factors/dvl_bulk.py, all at once:

- `BulkDvl.error(values)`: the sum of the pings' losses, as GTSAM's factors would return it (Gaussian:
  half the squared whitened error; robust: the kernel's loss of the whitened error's norm);
- `BulkDvl.linearize(values)`: the Jacobian factors. GTSAM's Python constructors of JacobianFactor take at most
  three keys, and a ping's factor has five to seven (pose, velocity, bias, scale, misalignment, time offset, lever
  arm), so
  each state's pings are served to GTSAM by one "carrier" CustomFactor on those keys whose callback returns the
  rows already computed (whitened, and reweighted by the robust kernel as GTSAM's Robust noise model does):
  one cheap Python call per state instead of an evaluation per ping. Stacking a state's pings in one factor
  changes nothing in the least-squares problem (the rows are the same); tests/estimators/test_bulk.py checks
  the linear system against the per-factor graph's to 1e-9.
- `BulkGraph`: the rest of the graph (GTSAM factors) plus the BulkDvl, with the error and linearize of a
  NonlinearFactorGraph, for the solver, the marginals and the filtering timeline.

Every configuration is covered: a row is a ping's 3-D velocity, or with [dvl] use_beams one beam's (its own robust
kernel, as each beam factor has), and the lever arm is a known input or, with [dvl] estimate_lever_arm, the variable
L_LEVER. The per-factor path (LogGraph.build) stays for iSAM2 (the online estimator), which needs real factors, and
for the tests that check this module against it.

Memory: the carriers reference only a small _Served holder (the rows of the last linearisation), never the
BulkDvl or the graph, so no reference cycle runs through C++ (see factors/imu_earth.py, "Memory").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import E, W, key_dim
from gtsam_dvl.core.states import (
    correlated_error,
    dvl_factor_keys,
    enabled,
    read_values,
    water_current,
    water_scale_key,
)
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.graph.bulk_imu import BulkImu, StateArrays, state_arrays
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.selection import ping_covariance, water_covariance
from gtsam_dvl.factors.dvl_bulk import BulkPings, dvl_ping_errors
from gtsam_dvl.factors.dvl_model import DvlJacobians
from gtsam_dvl.factors.ping_motion import PingMotion, keyframe_ping_covariance

CHUNK = 20_000  # rows evaluated at once (about 50 MB of temporaries)


class BulkSource(Protocol):
    """What bulk_dvl reads of a LogGraph (estimators/graph/log_graph.py): its factor maker, configuration, log, epochs
    (each
    with dvl_index, t, b_omega, rate_input and the pings between it and the next state), the states' gravity
    reference positions and the IMU motion to each ping between keyframes."""

    @property
    def maker(self) -> FactorMaker: ...

    @property
    def config(self) -> EstimatorConfig: ...

    @property
    def log(self) -> LogData: ...

    @property
    def epochs(self) -> Sequence[Any]: ...

    @property
    def gravity_positions(self) -> np.ndarray | None: ...

    @property
    def snapshots(self) -> PingMotion | None: ...

    @property
    def water(self) -> np.ndarray: ...


@dataclass
class _Served:
    """The rows of the last linearisation, per state: what the carriers hand to GTSAM."""

    # whitened, reweighted error (N, m)
    e: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    blocks: list[np.ndarray] = field(default_factory=list)  # per key (N, m, d)
    ready: bool = False


class _Carrier:
    """A carrier's callback: state s's rows of _Served (pings lo:hi)."""

    __slots__ = ("served", "lo", "hi")

    def __init__(self, served: _Served, lo: int, hi: int) -> None:
        self.served, self.lo, self.hi = served, lo, hi

    def __call__(self, _factor: Any, _values: gtsam.Values, H: Any) -> np.ndarray:
        s = self.served
        if not s.ready:
            raise RuntimeError("BulkDvl carrier evaluated outside BulkDvl.linearize")
        lo, hi = self.lo, self.hi
        if H is not None:
            for n, J in enumerate(s.blocks):
                H[n] = J[lo:hi].reshape(-1, J.shape[2])
        return s.e[lo:hi].reshape(-1)


@dataclass
class BulkDvl:
    """The DVL factors of a LogGraph as arrays (module doc): N rows (pings, or beams) of m = 3 (or 1) measurements,
    sorted by state."""

    pings: BulkPings
    whiten: np.ndarray  # (N, m, m) W with W^T W = the row's inverse covariance (lower triangular)
    n_states: int
    config: EstimatorConfig  # its enabled shared states are the factors' variables (core/states.py)
    bias_keys: list[int]  # per state
    robust: str  # "huber", "cauchy" or "none"
    robust_k: float
    offset_n_g: np.ndarray | None  # with the time offset model: its gravity in map
    b_l: np.ndarray  # the known lever arm (m, base_link); with lever, L_LEVER's value is used
    # the rows' ping stamps (s), in their order
    t_ping: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # (N,) bool: the water-track rows (velocity relative to the water, on W(state)); None: none used
    water: np.ndarray | None = None
    _served: _Served = field(init=False, default_factory=_Served)
    _bounds: np.ndarray = field(init=False)  # state s's rows are _bounds[s]:_bounds[s + 1]
    _states_with_rows: list[int] = field(init=False)

    def __post_init__(self) -> None:
        # the motion's Earth terms, once (each chunk takes its part of them)
        _ = self.pings.motion.earth
        state = self.pings.state
        if len(state) and np.any(np.diff(state) < 0):
            raise ValueError("BulkDvl: pings must be sorted by state")
        self._bounds = np.searchsorted(state, np.arange(self.n_states + 1), side="left")
        self._bias_random_walk = len(set(self.bias_keys)) > 1
        # (found once: read per evaluation, _correlated_errors)
        self._states_with_rows = np.unique(state).tolist()

    @property
    def offset(self) -> bool:
        return self.offset_n_g is not None

    @property
    def lever(self) -> bool:
        """The lever arm is the variable L_LEVER."""
        return enabled(self.config, "lever_arm")

    def __len__(self) -> int:
        return len(self.pings)

    # ----- evaluation ----------------------------------------------------------------------------
    def states(self, values: gtsam.Values) -> StateArrays:
        """The states' arrays at values (bulk_imu.state_arrays)."""
        return state_arrays(values, self.n_states, self.bias_keys)

    def _ping_states(
        self, values: gtsam.Values, st: StateArrays
    ) -> tuple[
        np.ndarray,
        np.ndarray,
        np.ndarray,
        np.ndarray,
        np.ndarray,
        float,
        np.ndarray,
        float | None,
        np.ndarray,
    ]:
        """Each row's state: n_R_i (N, 3, 3), n_p_i, n_v_i, b_a, b_g (N, 3); k, b_R_d, dt_d, b_l."""
        s = self.pings.state
        bias = st.bias[s] if self._bias_random_walk else np.broadcast_to(st.bias[0], (len(s), 6))
        shared = read_values(values, self.config)
        k = float(shared["scale"][0])
        b_R_d = shared["misalignment"]
        dt_d = float(shared["time_offset"][0]) if "time_offset" in shared else None
        b_l = shared.get("lever_arm", self.b_l)
        return st.n_R[s], st.n_p[s], st.n_v[s], bias[:, :3], bias[:, 3:], k, b_R_d, dt_d, b_l

    def _evaluate(
        self,
        values: gtsam.Values,
        jacobians: bool,
        out: list[np.ndarray] | None = None,
        states: StateArrays | None = None,
    ) -> np.ndarray:
        """Whitened errors (N, m); with jacobians, the whitened Jacobian blocks per key written into out (N, m, d)
        each, unweighted. Evaluated CHUNK rows at a time: the temporaries of a whole day's pings would take GBs."""
        n_R_i, n_p_i, n_v_i, b_a, b_g, k, b_R_d, dt_d, b_l = self._ping_states(
            values, self.states(values) if states is None else states
        )
        # (N, 3) the rows' correlated DVL error E(state), or None
        d_e = self._correlated_errors(values)
        # the water-track rows' own scale (water_scale): h and every Jacobian but the scale's are linear in k, so
        # those rows are evaluated at k and taken times k_w / k; their scale Jacobian goes to K_WATER
        k_water = water_scale_key(self.config)
        ratio = None  # (a log without water-track rows: K_WATER's block all zeros)
        water_rows = self.water if self.water is not None else np.zeros(len(self), dtype=bool)
        if k_water is not None:
            ratio = float(values.atVector(k_water)[0]) / k
        # (N, 3) the water-track rows' current [c_e, c_n, 0] (others 0), or None
        n_c = self._currents(values)
        if n_c is not None:  # the velocity relative to the water (factors/dvl.py current_variable)
            n_v_i = n_v_i - n_c
        d_u = self.pings.d_u
        ew = np.empty((len(self), self.pings.dim))
        for a in range(0, len(self), CHUNK):
            sl = slice(a, a + CHUNK)
            e, J = dvl_ping_errors(
                self.pings.part(sl),
                n_R_i[sl],
                n_p_i[sl],
                n_v_i[sl],
                b_a[sl],
                b_g[sl],
                k,
                b_R_d,
                b_l,
                dt_d,
                self.offset_n_g,
                self.lever,
                jacobians,
            )
            on_water = None
            if ratio is not None:
                on_water = water_rows[sl]
                e = np.where(
                    on_water[:, None], (e + self.pings.y[sl]) * ratio - self.pings.y[sl], e
                )
            if d_e is not None:  # h + E (a beam: d_u . E)
                e = e + (
                    d_e[sl] if d_u is None else np.einsum("ni,ni->n", d_u[sl], d_e[sl])[:, None]
                )
            W = self.whiten[sl]
            ew[sl] = np.einsum("nij,nj->ni", W, e)
            if jacobians:
                assert J is not None and out is not None
                blocks = self._blocks(
                    J, sl, len(e), ratio, on_water, d_e is not None, n_c is not None
                )
                for dst, B in zip(out, blocks, strict=True):
                    np.matmul(W, B, out=dst[sl])
        return ew

    def _blocks(
        self,
        J: DvlJacobians,
        sl: slice,
        n_rows: int,
        ratio: float | None,
        on_water: np.ndarray | None,
        correlated: bool,
        currents: bool,
    ) -> list[np.ndarray]:
        """The Jacobian blocks of a chunk of rows sl (n_rows), per key of the carrier (_evaluate), unwhitened: the
        DVL model's (J, dvl_ping_errors), on water-track rows with their own scale (ratio = k_w / k, on_water)
        times the ratio and the scale's moved to K_WATER (last); then dh/dE (correlated) and dh/dW (currents)."""
        d_u = self.pings.d_u
        blocks = J.variables()
        scale_block = None
        if on_water is not None:
            w3 = on_water[:, None, None]
            i_scale = next(n for n, B in enumerate(blocks) if B is J.scale)
            blocks = [
                B if n == i_scale else np.where(w3, B * ratio, B) for n, B in enumerate(blocks)
            ]
            scale_block = blocks[i_scale]
            blocks[i_scale] = np.where(w3, 0.0, scale_block)
        if correlated:  # dh/dE: I, or a beam's d_u^T
            blocks = [
                *blocks,
                np.broadcast_to(np.eye(3), (n_rows, 3, 3)) if d_u is None else d_u[sl][:, None, :],
            ]
        if currents:  # dh/dW: minus the velocity's east and north columns, on water-track rows
            on = np.zeros(n_rows, dtype=bool) if self.water is None else self.water[sl]
            blocks = [
                *blocks,
                np.where(
                    on[:, None, None], -J.vel[:, :, :2] * (1.0 if ratio is None else ratio), 0.0
                ),
            ]
        if on_water is not None and scale_block is not None:  # dh/dk_w on the water-track rows
            blocks = [*blocks, np.where(on_water[:, None, None], scale_block, 0.0)]
        return blocks

    def _correlated_errors(self, values: gtsam.Values) -> np.ndarray | None:
        """Each row's correlated DVL error E(state) (N, 3) m/s, dvl_link; None when not modelled."""
        if not correlated_error(self.config):
            return None
        per_state = np.zeros((self.n_states, 3))
        for s in self._states_with_rows:
            per_state[s] = values.atVector(E(s))
        return per_state[self.pings.state]

    def _currents(self, values: gtsam.Values) -> np.ndarray | None:
        """Each row's water current [c_east, c_north, 0] (N, 3) m/s, map: W(state) on water-track rows, 0 on the
        others; None when water-track pings are not used."""
        if not water_current(self.config):
            return None
        per_state = np.zeros((self.n_states, 3))
        for s in self._states_with_rows:
            per_state[s, :2] = values.atVector(W(s))
        out = per_state[self.pings.state]
        if self.water is not None:
            out[~self.water] = 0.0
        else:
            out[:] = 0.0
        return out

    def whitened_errors(self, values: gtsam.Values) -> np.ndarray:
        """The rows' whitened errors (N, m) at values, before the robust kernel."""
        return self._evaluate(values, False) if len(self) else np.zeros((0, self.pings.dim))

    def _weights_and_losses(self, ew: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Robust weights and losses of the whitened errors' norms, as GTSAM's mEstimator computes them."""
        x2 = np.einsum("ni,ni->n", ew, ew)
        x = np.sqrt(x2)
        kk = self.robust_k
        if self.robust == "huber":
            inside = x <= kk
            w = np.where(inside, 1.0, kk / np.where(inside, 1.0, x))
            return w, np.where(inside, 0.5 * x2, kk * (x - 0.5 * kk))
        if self.robust == "cauchy":
            k2 = kk * kk
            return k2 / (k2 + x2), 0.5 * k2 * np.log1p(x2 / k2)
        return np.ones_like(x), 0.5 * x2

    def error(self, values: gtsam.Values, states: StateArrays | None = None) -> float:
        """The pings' total loss at values (as graph.error of the per-factor graph counts it); states: its arrays,
        if already extracted."""
        if not len(self):
            return 0.0
        ew = self._evaluate(values, False, states=states)
        return float(self._weights_and_losses(ew)[1].sum())

    def _keys(self, s: int) -> list[int]:
        """The carrier's keys of state s: the DVL factor's, with W(s) (its Jacobian 0 on bottom-track rows) and the
        water-track scale K_WATER last when estimated (the rows' scale Jacobian on K or on K_WATER by their mode)."""
        keys = dvl_factor_keys(self.config, s, motion=True, water=True, swap_scale=False)
        k_water = water_scale_key(self.config)
        return keys if k_water is None else [*keys, k_water]

    def carriers(self) -> gtsam.NonlinearFactorGraph:
        """One carrier CustomFactor per state with pings (module doc), for linearize."""
        graph = gtsam.NonlinearFactorGraph()
        for s in range(self.n_states):
            lo, hi = int(self._bounds[s]), int(self._bounds[s + 1])
            if hi > lo:
                keys = self._keys(s)
                graph.add(
                    gtsam.CustomFactor(
                        gtsam.noiseModel.Unit.Create(self.pings.dim * (hi - lo)),
                        keys,
                        _Carrier(self._served, lo, hi),
                    )
                )
        return graph

    def prepare(self, values: gtsam.Values, states: StateArrays | None = None) -> None:
        """Compute the rows the carriers serve: whitened Jacobians and errors, reweighted by the robust kernel
        (GTSAM's Robust noise model: both scaled by sqrt(weight(|whitened error|)))."""
        n = len(self)
        dims = [key_dim(k) for k in self._keys(0)]
        served = self._served
        # (released after each linearisation)
        if len(served.blocks) != len(dims) or len(served.blocks[0]) != n:
            served.blocks = [np.empty((n, self.pings.dim, d)) for d in dims]
        ew = self._evaluate(values, True, served.blocks, states)
        w, _ = self._weights_and_losses(ew)
        sw = np.sqrt(w)
        if not np.all(sw == 1.0):
            for B in served.blocks:
                B *= sw[:, None, None]
        served.e = ew * sw[:, None]
        served.ready = True

    def rows(self) -> int:
        return self.pings.dim * len(self)

    def release(self) -> None:
        """Let the served rows go (60 doubles a ping) once GTSAM has linearised the
        carriers; the next prepare() makes them again."""
        self._served.blocks, self._served.e, self._served.ready = [], np.zeros((0, 3)), False

    def set_offset_inputs(
        self, b_omega: np.ndarray, b_a: np.ndarray, G: np.ndarray, b_l: np.ndarray
    ) -> None:
        """New time-offset IMU constants of the rows (mean body rate, b_a, G at t_ping, in their order:
        LogGraph.recentre_time_offset) and the known lever arm b_l (m); the rest of the model is unchanged."""
        p = self.pings
        # (the offset model has offset_b_a and G)
        if not self.offset or b_omega.shape != p.b_omega.shape:
            raise ValueError(
                "BulkDvl.set_offset_inputs: not a time-offset model, or not the same pings"
            )
        p.b_omega, p.offset_b_a, p.offset_G = b_omega, b_a, G
        self.b_l = np.asarray(b_l, dtype=float)


class BulkGraph:
    """A NonlinearFactorGraph of GTSAM factors plus the bulk DVL factors (module doc): error and linearize as
    the per-factor graph's, for gauss_newton_qr, the marginals and the filtering timeline."""

    def __init__(
        self, graph: gtsam.NonlinearFactorGraph, bulk: BulkDvl, imu: BulkImu | None = None
    ) -> None:
        self.graph, self.bulk, self.imu = graph, bulk, imu
        self._carriers = bulk.carriers()
        self._imu_carriers = imu.carriers() if imu is not None else None

    def error(self, values: gtsam.Values) -> float:
        states = self.bulk.states(values)  # once for both
        imu = self.imu.error(values, states) if self.imu is not None else 0.0
        return float(self.graph.error(values)) + self.bulk.error(values, states) + imu

    def linearize(self, values: gtsam.Values) -> gtsam.GaussianFactorGraph:
        linear = self.graph.linearize(values)
        states = self.bulk.states(values)  # once for both
        if self.imu is not None and self._imu_carriers is not None and len(self.imu):
            self.imu.prepare(values, states)
            linear.push_back(self._imu_carriers.linearize(values))
            self.imu.release()
        if len(self.bulk):
            self.bulk.prepare(values, states)
            linear.push_back(self._carriers.linearize(values))
            self.bulk.release()  # GTSAM copied the rows into its Jacobian factors
        return linear

    def rows(self) -> int:
        """Measurement rows (for the chi^2's degrees of freedom)."""
        return (
            graph_rows(self.graph)
            + self.bulk.rows()
            + (self.imu.rows() if self.imu is not None else 0)
        )


def graph_rows(graph: gtsam.NonlinearFactorGraph | BulkGraph) -> int:
    """Measurement rows of a graph (a BulkGraph's too)."""
    if isinstance(graph, BulkGraph):
        return graph.rows()
    return sum(graph.at(i).dim() for i in range(graph.size()) if graph.exists(i))


def whitening(cov: np.ndarray) -> np.ndarray:
    """W (N, 3, 3) with W^T W = cov^-1, as GTSAM's noiseModel.Gaussian.Covariance whitens: W = L^-1 for
    cov = L L^T, except that a covariance whose off-diagonal entries are all at most 1e-9 in magnitude is taken
    as diagonal (GTSAM's "smart" construction; a keyframe ping's 1e-12 m^2/s^2 cross terms are dropped)."""
    upper = np.abs(cov[:, [0, 0, 1], [1, 2, 2]]).max(axis=1)
    diagonal = upper <= 1e-9
    W = np.empty_like(cov)
    if (~diagonal).any():
        W[~diagonal] = np.linalg.inv(np.linalg.cholesky(cov[~diagonal]))
    if diagonal.any():
        idx = np.flatnonzero(diagonal)[:, None]
        W[idx[:, 0]] = 0.0
        W[idx, [0, 1, 2], [0, 1, 2]] = 1.0 / np.sqrt(cov[idx, [0, 1, 2], [0, 1, 2]])
    return W


@dataclass
class _PingRows:
    """The pings of a LogGraph in carrier order (bulk_dvl): each one's state, index in log.dvl, snapshot row (-1:
    the state's own ping), stamp (s) and body rate; with the time offset its IMU constants (b_a, G)."""

    state: np.ndarray
    dvl_index: np.ndarray
    snap: np.ndarray
    t: np.ndarray
    b_omega: np.ndarray
    rate: tuple[np.ndarray, np.ndarray] | None


def _ping_rows(builder: BulkSource, offset: bool) -> _PingRows:
    """Each state's own ping, then the pings between it and the next state."""
    state, dvl_idx, b_omega, rate_b_a, rate_G, snap, t_ping = [], [], [], [], [], [], []
    for i, ep in enumerate(builder.epochs):
        of_state: list[tuple[int, Any, int]] = []
        if ep.dvl_index >= 0:
            of_state.append((ep.dvl_index, ep, -1))
        of_state += [(p.dvl_index, p, p.snap) for p in ep.between]
        for j, src, q in of_state:
            state.append(i)
            dvl_idx.append(j)
            snap.append(q)
            t_ping.append(src.t)
            if offset:
                assert src.rate_input is not None
                b_a, b_om_mean, G = src.rate_input
                b_omega.append(b_om_mean)
                rate_b_a.append(b_a)
                rate_G.append(G)
            else:
                b_omega.append(src.b_omega)
    n = len(state)
    rate = (
        (
            np.asarray(rate_b_a, dtype=float).reshape(n, 3),
            np.asarray(rate_G, dtype=float).reshape(n, 3, 3),
        )
        if offset
        else None
    )
    return _PingRows(
        np.asarray(state, dtype=int),
        np.asarray(dvl_idx, dtype=int),
        np.asarray(snap, dtype=int),
        np.asarray(t_ping, dtype=float),
        np.asarray(b_omega, dtype=float).reshape(n, 3),
        rate,
    )


def _ping_motion(
    builder: BulkSource, st: np.ndarray, qs: np.ndarray, d_y: np.ndarray
) -> tuple[PingMotion, np.ndarray]:
    """The IMU motion from each ping's state to it (none for a state's own ping) with gravity at the states, and
    the preintegration's noise in each ping between keyframes (N, 3, 3) (as dvl_keyframe_factors_for)."""
    maker, cfg = builder.maker, builder.config
    n = len(st)
    k0, b_R_d0 = cfg.priors.scale_initial, maker.mounting.b_R_d0
    if builder.gravity_positions is None:
        raise ValueError("bulk_dvl needs the initial guess first (LogGraph.initial_values)")
    g_states, G_states = maker.keyframe_gravity(builder.gravity_positions)
    motion = PingMotion.none(n)
    extra = np.zeros((n, 3, 3))  # the preintegration's noise in each ping between keyframes
    moving = qs >= 0
    if moving.any():
        snaps = builder.snapshots
        if snaps is None:
            raise ValueError(
                "bulk_dvl: the LogGraph's snapshots were let go (build_bulk); make a new LogGraph"
            )
        m = qs[moving]
        for name in ("dt", "dR", "dv", "dp", "dR_dbg", "dv_dba", "dv_dbg"):
            getattr(motion, name)[moving] = getattr(snaps, name)[m]
        # the body velocity at the ping from the ping at the prior calibration (as dvl_keyframe_factors_for)
        d_y_m = d_y[moving]
        finite = np.isfinite(d_y_m).all(axis=1)
        b_v = np.where(finite[:, None], np.where(finite[:, None], d_y_m, 0.0) @ b_R_d0.T / k0, 0.0)
        extra[moving] = keyframe_ping_covariance(snaps.cov[m], motion.dR[moving], b_R_d0.T, b_v, k0)
    motion = motion.motion(
        np.asarray(maker.n_omega_ie(), dtype=float),
        np.asarray(g_states, dtype=float).reshape(-1, 3)[st],
        np.asarray(builder.gravity_positions, dtype=float)[st],
        np.asarray(G_states, dtype=float).reshape(-1, 3, 3)[st],
    )
    return motion, extra


def _measurement_rows(
    cfg: EstimatorConfig,
    dvl: Any,
    jj: np.ndarray,
    d_y: np.ndarray,
    extra: np.ndarray,
    water: np.ndarray,
) -> tuple[np.ndarray | slice, np.ndarray, np.ndarray | None, np.ndarray]:
    """The carrier's rows of the pings jj (rows: which ping each row is), their measurements y, beam directions
    d_u (None: 3-D velocities) and whitening: the 3-D velocity (a water-track ping's with its own noise), or with
    [dvl] use_beams one row per valid beam, in the beams' order (FactorMaker's beam factors)."""
    n = len(jj)
    beams = dvl.beams if cfg.dvl.use_beams else None
    if beams is not None and water.any():
        raise GtsamDvlError(
            "[dvl] use_beams with water-track pings: not supported; set [current] water_track = "
            '"refuse" or use_beams = false'
        )
    if beams is None:
        cov = ping_covariance(cfg.dvl, np.asarray(dvl.d_cov[jj], dtype=float).reshape(n, 3, 3))
        cov[water] = water_covariance(cfg, np.asarray(dvl.d_cov[jj[water]], dtype=float))
        return slice(None), d_y, None, whitening(cov + extra)
    rows, b = np.nonzero(beams.valid[jj])
    d_u = np.asarray(beams.d_u[jj][rows, b], dtype=float)
    y = np.asarray(beams.v[jj][rows, b], dtype=float)[:, None]
    var = cfg.dvl.beam_sigma_m_s() ** 2 + np.einsum("ni,nij,nj->n", d_u, extra[rows], d_u)
    return rows, y, d_u, (1.0 / np.sqrt(var))[:, None, None]


def bulk_dvl(builder: BulkSource) -> BulkDvl:
    """The BulkDvl of a LogGraph's pings: each state's own ping, then the pings between it and the next state
    (their rows: the 3-D velocity, or with [dvl] use_beams each valid beam in its order), with the noise, IMU motion
    and gravity the per-factor path gives them (LogGraph.dvl_factors, between_factors; FactorMaker.dvl_factors_for,
    dvl_keyframe_factors_for)."""
    maker, cfg, dvl = builder.maker, builder.config, builder.log.dvl
    offset = enabled(cfg, "time_offset")
    n_states = len(builder.epochs)
    if builder.gravity_positions is None:
        raise ValueError("bulk_dvl needs the initial guess first (LogGraph.initial_values)")
    p = _ping_rows(builder, offset)
    n, st, jj = len(p.state), p.state, p.dvl_index
    d_y = np.asarray(dvl.d_v[jj], dtype=float).reshape(n, 3)
    motion, extra = _ping_motion(builder, st, p.snap, d_y)
    # (water track: 3-D, own noise)
    water = builder.water[jj] if water_current(cfg) else np.zeros(n, dtype=bool)
    rows, y, d_u, whiten = _measurement_rows(cfg, dvl, jj, d_y, extra, water)
    rate = p.rate
    pings = BulkPings(
        state=st[rows],
        y=y,
        b_omega=p.b_omega[rows],
        motion=motion[rows],
        d_u=d_u,
        offset_b_a=None if rate is None else rate[0][rows],
        offset_G=None if rate is None else rate[1][rows],
    )
    robust = cfg.dvl.robust if cfg.dvl.robust in ("huber", "cauchy") else "none"
    return BulkDvl(
        pings=pings,
        whiten=whiten,
        n_states=n_states,
        config=cfg,
        bias_keys=[maker.bias_key(i) for i in range(n_states)],
        robust=robust,
        robust_k=float(cfg.dvl.robust_threshold()),
        offset_n_g=np.asarray(maker.offset_gravity(), dtype=float) if offset else None,
        b_l=np.asarray(maker.mounting.b_l, dtype=float),
        t_ping=p.t[rows],
        water=water[rows] if water.any() else None,
    )
