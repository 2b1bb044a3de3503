"""The batch smoother's IMU factors evaluated in bulk: GTSAM's ImuFactor with the Earth model, for every interval at
once (factors/imu_bulk.py), served to GTSAM by carrier factors (estimators/graph/bulk.py explains carriers).

Why: each EarthImuFactor (factors/imu_earth.py) is a Python CustomFactor; GTSAM calls it once per factor per
linearisation and per error evaluation, and a day of 1 s keyframes has 86,400 of them. Here one
numpy evaluation covers them all; GTSAM still sees one Jacobian factor per interval, with the same rows (the
same whitening: the square root information matrix of the EarthImuFactor's own noise model), so the linear
system is the per-factor graph's to rounding (tests/estimators/test_bulk.py).

The preintegrations come from LogGraph's pims (x, dt, and the bias Jacobian from one ImuFactor evaluation each:
factors/imu_bulk.bias_jacobians), with the gravity map M in closed form (the EarthImuFactor probes its pim for
the same, tests/estimators/test_bulk.py). Gravity follows position as in the EarthImuFactor: a reference per
factor (n_p_ref, n_g_ref, G_ref) set by LogGraph.set_gravity_from_positions in the arrays it shares with this
object, extrapolated linearly to the interval's mid position, and its gradient term added to the translation
Jacobians.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.factors.imu_bulk import ImuArrays, imu_errors

CHUNK = 10_000  # factors evaluated at once (about 100 MB of temporaries)
_DIMS = (6, 3, 6, 3, 6)  # X_i, V_i, X_j, V_j, B


@dataclass
class GravityRefs:
    """The IMU factors' gravity references (module doc), shared by LogGraph and BulkImu: n_p (N, 3) m (NaN: none
    yet), n_g (N, 3) m/s^2, G (N, 3, 3) 1/s^2; model None: constant gravity n_g (the flat Earth model)."""

    n_p: np.ndarray
    n_g: np.ndarray
    G: np.ndarray
    model: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None

    def gravity_at(self, mid: np.ndarray) -> np.ndarray:
        """Gravity at the mid positions (N, 3), referencing first the factors without a reference there (as an
        EarthImuFactor's first evaluation does)."""
        if self.model is None:
            return self.n_g
        missing = np.isnan(self.n_p[:, 0])
        if missing.any():
            g, G = self.model(mid[missing])
            self.n_p[missing], self.n_g[missing], self.G[missing] = mid[missing], g, G
        return self.n_g + np.einsum("nij,nj->ni", self.G, mid - self.n_p)


@dataclass
class StateArrays:
    """Every state's variables at a linearisation point, in state order: n_R (S, 3, 3) base_link -> map, n_p (S, 3)
    m and n_v (S, 3) m/s in map, bias (S, 6) [b_a m/s^2, b_g rad/s] of each state's bias key. Extracted once per
    evaluation and shared by the bulk IMU and DVL factors (estimators/graph/bulk.py)."""

    n_R: np.ndarray
    n_p: np.ndarray
    n_v: np.ndarray
    bias: np.ndarray


def state_arrays(values: gtsam.Values, n_states: int, bias_keys: list[int]) -> StateArrays:
    """StateArrays of values, whose poses X(0..S-1) and velocities V(0..S-1) are all the Pose3 and V-keyed vectors
    it holds; bias_keys: each state's bias key (one key for all: a random-constant bias)."""
    poses = gtsam.utilities.extractPose3(values)  # every Pose3 in key order: the states X(0..n-1)
    vels = gtsam.utilities.extractVectors(values, "v")  # every V(i), in order
    if poses.shape[0] != n_states or vels.shape[0] != n_states:
        raise ValueError(
            f"values hold {poses.shape[0]} poses and {vels.shape[0]} velocities, the graph {n_states} "
            "states"
        )
    if len(set(bias_keys)) > 1:
        bias = np.array([values.atConstantBias(k).vector() for k in bias_keys])
    else:
        bias = np.broadcast_to(values.atConstantBias(bias_keys[0]).vector(), (n_states, 6))
    return StateArrays(poses[:, :9].reshape(-1, 3, 3), poses[:, 9:], vels, bias)


@dataclass
class _ImuServed:
    e: np.ndarray = field(default_factory=lambda: np.zeros((0, 9)))
    blocks: list[np.ndarray] = field(default_factory=list)
    ready: bool = False


class _ImuCarrier:
    """A carrier's callback: factor n's whitened rows of _ImuServed."""

    __slots__ = ("served", "n")

    def __init__(self, served: _ImuServed, n: int) -> None:
        self.served, self.n = served, n

    def __call__(self, _factor: Any, _values: gtsam.Values, H: Any) -> np.ndarray:
        s, n = self.served, self.n
        if not s.ready:
            raise RuntimeError("BulkImu carrier evaluated outside BulkImu.prepare")
        if H is not None:
            for k, J in enumerate(s.blocks):
                H[k] = J[n]
        return s.e[n]


@dataclass
class BulkImu:
    """The IMU factors of a LogGraph as arrays: factor n joins states n and n + 1 with state n's bias key."""

    arrays: ImuArrays
    whiten: np.ndarray  # (N, 9, 9) the noise models' square root information matrices
    keys: list[tuple[int, int, int, int, int]]  # (X_i, V_i, X_j, V_j, B) per factor
    gravity: GravityRefs
    state_bias_keys: list[int]  # each of the N + 1 states' bias key
    _served: _ImuServed = field(init=False, default_factory=_ImuServed)

    def __len__(self) -> int:
        return len(self.arrays)

    def states(self, values: gtsam.Values) -> StateArrays:
        """The states' arrays at values (state_arrays)."""
        return state_arrays(values, len(self) + 1, self.state_bias_keys)

    def _evaluate(
        self, values: gtsam.Values, out: list[np.ndarray] | None, states: StateArrays | None = None
    ) -> np.ndarray:
        """Whitened errors (N, 9); with out, the whitened Jacobian blocks written into it."""
        st = self.states(values) if states is None else states
        n_R, n_p, n_v, b = st.n_R, st.n_p, st.n_v, st.bias[:-1]  # (bias: state i's, of factor i)
        n_g = self.gravity.gravity_at(0.5 * (n_p[:-1] + n_p[1:]))
        a, gr = self.arrays, self.gravity
        ew = np.empty((len(self), 9))
        for lo in range(0, len(self), CHUNK):
            hi = min(lo + CHUNK, len(self))
            sl, sl_j = (
                slice(lo, hi),
                slice(lo + 1, hi + 1),
            )  # states i and j = i + 1 of factors lo:hi
            part = a.part(sl)
            MG2 = None
            if out is not None and gr.model is not None:
                MG2 = 0.5 * (part.M @ gr.G[sl]).reshape(-1, 2, 3, 3)
            e, J = imu_errors(
                part,
                n_R[sl],
                n_p[sl],
                n_v[sl],
                n_R[sl_j],
                n_p[sl_j],
                n_v[sl_j],
                b[sl],
                n_g[sl],
                MG2,
                out is not None,
            )
            W = self.whiten[sl]
            ew[sl] = np.einsum("nij,nj->ni", W, e)
            if out is not None:
                assert J is not None
                for dst, B in zip(out, (J.pose_i, J.vel_i, J.pose_j, J.vel_j, J.bias), strict=True):
                    np.matmul(W, B, out=dst[sl])
        return ew

    def error(self, values: gtsam.Values, states: StateArrays | None = None) -> float:
        """The IMU factors' total error at values (half the squared whitened errors, as GTSAM's); states: its
        arrays, if already extracted."""
        if not len(self):
            return 0.0
        ew = self._evaluate(values, None, states)
        return 0.5 * float(np.einsum("ni,ni->", ew, ew))

    def carriers(self) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        unit = gtsam.noiseModel.Unit.Create(9)
        for n, keys in enumerate(self.keys):
            graph.add(gtsam.CustomFactor(unit, list(keys), _ImuCarrier(self._served, n)))
        return graph

    def prepare(self, values: gtsam.Values, states: StateArrays | None = None) -> None:
        """Compute the whitened rows the carriers serve."""
        s = self._served
        if len(s.blocks) != len(_DIMS) or len(s.blocks[0]) != len(self):
            s.blocks = [np.empty((len(self), 9, d)) for d in _DIMS]
        s.e = self._evaluate(values, s.blocks, states)
        s.ready = True

    def release(self) -> None:
        """Let the served rows go (216 doubles a factor) once GTSAM has copied them."""
        self._served.blocks, self._served.e, self._served.ready = [], np.zeros((0, 9)), False

    def rows(self) -> int:
        return 9 * len(self)
