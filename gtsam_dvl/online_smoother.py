"""The iSAM2 engine of the online estimator: a state per DVL epoch, over a fixed-lag window or the whole history.

Design (the issue's traps, measured on the prototype and here):

- Factorisation QR (Cholesky fails at navigation-grade noise), wildfire threshold 0 (rotations matter at
  1e-4 rad, far below iSAM2's default 1e-3 on every component), relinearisation checked at every update
  with a threshold per variable type and per tangent component (`RelinearizationThresholds`): iSAM2's
  default 0.1 on everything let the scale wander to 0.04 in the static phase.
- Marginal covariances by QR: `ISAM2.marginalCovariance` eliminates with Cholesky and fails; the joint of
  the newest state and the shared keys comes from `jointBayesNet(keys, EliminateQR)`, whose upper-triangular
  square-root information is inverted by a triangular solve (the information matrix itself spans 1e18 and
  cannot be inverted in double precision).
- Fixed lag: the window is managed here, not by GTSAM's fixed-lag smoothers. `ISAM2.marginalizeLeaves`
  (which `IncrementalFixedLagSmoother` calls) freezes the linearisation point of every variable the marginal
  touches, forever: the scale, misalignment and bias would keep the values they had when the first state left
  the window, i.e. during the static phase where the scale is unobservable (0.8). Instead, when a state
  leaves the window its factors are removed from iSAM2 (`removeFactorIndices`; iSAM2 then drops the
  variables that have no factor left) and replaced by their marginal on the separator (the next state, the
  bias, scale and misalignment), obtained here by QR elimination of those factors linearised at the current
  estimate and added back as a `LinearContainerFactor`: linear in the tangent space at that point, with no
  Python call when iSAM2 relinearises it, and no variable frozen. The window then holds a bounded number of
  variables and factors, so neither iSAM2's work nor the copy of the Values that iSAM2 hands to each Python
  CustomFactor it relinearises grows with the mission.
- Full history: the same engine without marginalisation. Every relinearisation of the scale, misalignment or
  bias relinearises every DVL or IMU factor of the mission, each call copying the whole Values: the cost per
  update grows with time (the prototype: 262 s on the 2060 s run, update p99 2.3 s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np
from scipy.linalg import solve_triangular

from gtsam_dvl.errors import GtsamDvlError
from gtsam_dvl.graph import C_MISALIGN, K_SCALE, GraphBuilder, V, X

# tangent dimension of each variable type, by symbol character
_DIMS = {"x": 6, "v": 3, "b": 6, "k": 1, "c": 3}


@dataclass
class RelinearizationThresholds:
    """iSAM2 relinearises a variable when a component of its update since the last linearisation exceeds
    these (tangent components, GTSAM order). Chosen so that the second-order error a stale linearisation
    leaves is far below the noise of one factor: a tilt error dth leaves g dth^2 / 2 in an IMU velocity
    residual (1e-4 m/s per second of accelerometer noise), a heading error almost nothing (gravity does not
    move under it); the scale and misalignment enter the DVL model bilinearly with the velocity."""

    pose: tuple[float, ...] = (3e-4, 3e-4, 3e-3, 0.05, 0.05, 0.05)  # rad (body x, y, z), m (body)
    velocity: tuple[float, ...] = (1e-3, 1e-3, 1e-3)  # m/s, map
    bias: tuple[float, ...] = (1e-4, 1e-4, 1e-4, 5e-6, 5e-6, 5e-6)  # m/s^2, rad/s (the model is linear in it)
    scale: float = 1e-3
    misalignment_rad: float = 1e-3

    def threshold_map(self) -> gtsam.ISAM2ThresholdMap:
        m = gtsam.ISAM2ThresholdMap()
        m.insert(("x", np.asarray(self.pose, dtype=float)))
        m.insert(("v", np.asarray(self.velocity, dtype=float)))
        m.insert(("b", np.asarray(self.bias, dtype=float)))
        m.insert(("k", np.array([self.scale])))
        m.insert(("c", np.full(3, self.misalignment_rad)))
        return m


@dataclass
class StateEstimate:
    """The newest state, bias and calibration with their joint marginal covariance (SI, GTSAM tangents)."""

    index: int
    t: float
    pose: gtsam.Pose3
    n_v: np.ndarray
    bias: gtsam.imuBias.ConstantBias
    scale: float
    b_R_d: np.ndarray
    cov: np.ndarray  # (25, 25): pose (6), n_v (3), bias [accel, gyro] (6), scale (1), b_R_d (3)

    @property
    def pose_cov(self) -> np.ndarray:
        return self.cov[:6, :6]

    @property
    def vel_cov(self) -> np.ndarray:
        return self.cov[6:9, 6:9]

    @property
    def pose_vel_cross(self) -> np.ndarray:
        return self.cov[:6, 6:9]

    @property
    def calib_cov(self) -> np.ndarray:
        """(10, 10) joint of [accel, gyro] bias, scale and b_R_d (the order of NavResult.calib_joint_cov)."""
        return self.cov[9:, 9:]


def _state_of(key: int, rw_bias: bool) -> int | None:
    """The epoch index a key belongs to (X_i, V_i, and B_i for a random-walk bias), None for shared keys."""
    sym = gtsam.Symbol(key)
    c = chr(sym.chr())
    if c in "xv" or (c == "b" and rw_bias):
        return int(sym.index())
    return None


@dataclass
class _Attached:
    """iSAM2 factor slots whose oldest state is this one: removed when it leaves the window."""

    t: float
    slots: list[int] = field(default_factory=list)
    factors: list[gtsam.NonlinearFactor] = field(default_factory=list)


class IncrementalSmoother:
    """iSAM2 over the epochs given to `add_epoch` (factors from the shared GraphBuilder). `window_s` None
    keeps every state (full history); otherwise states older than window_s seconds behind the newest are
    marginalised (at least two states stay)."""

    def __init__(self, builder: GraphBuilder, window_s: float | None, thresholds: RelinearizationThresholds,
                 relinearize_skip: int = 1) -> None:
        self.builder = builder
        self.window_s = window_s
        self.rw_bias = builder.config.imu.bias_model == "random_walk"
        params = gtsam.ISAM2Params()
        params.setFactorization("QR")
        params.setRelinearizeThreshold(thresholds.threshold_map())
        params.relinearizeSkip = relinearize_skip
        params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(0.0))
        params.findUnusedFactorSlots = window_s is not None  # bounded slot table in fixed-lag mode
        self.isam = gtsam.ISAM2(params)
        self.attached: dict[int, _Attached] = {}  # by epoch index, oldest first
        self.n = 0  # epochs added
        self.t_last = -np.inf
        self.relinearized = 0  # variables relinearised, summed over updates
        self.marginalised = 0

    # ----- updates -------------------------------------------------------------------------------
    def add_epoch(self, t: float, dvl_factors: list[gtsam.NonlinearFactor],
                  pim: gtsam.PreintegratedImuMeasurements | None = None,
                  params: gtsam.PreintegrationParams | None = None, first_values: gtsam.Values | None = None) -> None:
        """Add state n at time t with its DVL factors (built by the caller with builder.dvl_factors_for(n, ...))
        and, for n > 0, the preintegration since the previous epoch; for n == 0, first_values (builder.
        first_state_values) seed the state, bias and calibration and the priors."""
        i, b = self.n, self.builder
        factors: list[gtsam.NonlinearFactor] = list(dvl_factors)
        values = gtsam.Values()
        if i == 0:
            if first_values is None:
                raise GtsamDvlError("the first epoch needs its initial values")
            values = first_values
            factors = b.prior_factors(values) + factors
        else:
            if pim is None or params is None:
                raise GtsamDvlError("an epoch after the first needs its preintegration")
            dt = t - self.t_last
            imu = b.new_imu_factor(i - 1, pim, params, dt)
            factors = [imu.factor, *b.bias_link_factors(i - 1, dt), *factors]
            prev = self.isam.calculateEstimate([X(i - 1), V(i - 1), b.bias_key(i - 1)])
            pose, n_v = prev.atPose3(X(i - 1)), prev.atVector(V(i - 1))
            bias = prev.atConstantBias(b.bias_key(i - 1))
            imu.set_gravity(pose.translation() + 0.5 * dt * n_v)
            state = pim.predict(gtsam.NavState(pose, n_v), bias)
            values.insert(X(i), state.pose())
            values.insert(V(i), state.velocity())
            if self.rw_bias:
                values.insert(b.bias_key(i), bias)

        remove: list[int] = []
        if self.window_s is not None:
            old = [s for s, a in self.attached.items() if a.t < t - self.window_s and s < i - 1]
            if old:
                marg_factors, remove = self._marginal(old)
                factors += marg_factors

        graph = gtsam.NonlinearFactorGraph()
        for f in factors:
            graph.add(f)
        try:
            result = self.isam.update(graph, values, remove)
        except RuntimeError as exc:
            raise GtsamDvlError(f"iSAM2 update at t = {t:.3f} s failed ({exc})") from None
        self.relinearized += result.getVariablesRelinearized()
        self.attached[i] = _Attached(t)
        for slot, f in zip(result.getNewFactorsIndices(), factors, strict=True):
            states = [s for s in (_state_of(k, self.rw_bias) for k in f.keys()) if s is not None]
            if states:
                a = self.attached[min(states)]
                a.slots.append(int(slot))
                a.factors.append(f)
        self.n, self.t_last = i + 1, t

    def _marginal(self, old: list[int]) -> tuple[list[gtsam.NonlinearFactor], list[int]]:
        """The marginal, on the oldest kept state and the shared keys, of the factors attached to the epochs
        `old` (oldest first), linearised at the current estimate; and the iSAM2 slots to remove."""
        removed = [self.attached.pop(s) for s in old]
        factors = [f for a in removed for f in a.factors]
        slots = [s for a in removed for s in a.slots]
        keys = sorted({k for f in factors for k in f.keys()})
        values = self.isam.calculateEstimate(keys)
        linear = gtsam.GaussianFactorGraph()
        for f in factors:
            linear.push_back(f.linearize(values))
        ordering = gtsam.Ordering()
        for s in old:
            for k in (X(s), V(s), *((self.builder.bias_key(s),) if self.rw_bias else ())):
                ordering.push_back(k)
        _, rest = linear.eliminatePartialSequential(ordering, gtsam.EliminateQR)
        marg = [gtsam.LinearContainerFactor(rest.at(j), values) for j in range(rest.size()) if rest.at(j) is not None]
        self.marginalised += len(old)
        return marg, slots

    def refine(self, max_updates: int = 10) -> int:
        """Extra iSAM2 updates without new data until no variable is relinearised (the end of a run);
        returns the number of updates made."""
        for k in range(max_updates):
            result = self.isam.update()
            self.relinearized += result.getVariablesRelinearized()
            if result.getVariablesRelinearized() == 0:
                return k + 1
        return max_updates

    # ----- estimates -----------------------------------------------------------------------------
    def shared_keys(self, i: int) -> list[int]:
        return [self.builder.bias_key(i), K_SCALE, C_MISALIGN]

    def estimate(self, with_covariance: bool = True) -> StateEstimate:
        """The newest state, the bias and the calibration, with their joint marginal covariance."""
        i = self.n - 1
        keys = [X(i), V(i), *self.shared_keys(i)]
        values = self.isam.calculateEstimate(keys)
        cov = self.joint_covariance(keys) if with_covariance else np.full((25, 25), np.nan)
        return StateEstimate(
            index=i, t=self.t_last, pose=values.atPose3(X(i)), n_v=values.atVector(V(i)),
            bias=values.atConstantBias(keys[2]), scale=float(values.atVector(K_SCALE)[0]),
            b_R_d=values.atRot3(C_MISALIGN).matrix(), cov=cov)

    def joint_covariance(self, keys: list[int]) -> np.ndarray:
        """Joint marginal covariance of keys (blocks in that order) from iSAM2's Bayes tree, by QR."""
        try:
            bn = self.isam.jointBayesNet(keys, gtsam.EliminateQR)
        except RuntimeError as exc:
            raise GtsamDvlError(f"marginal covariance failed ({exc})") from None
        return bayes_net_covariance(bn, keys)

    def values(self) -> gtsam.Values:
        return self.isam.calculateEstimate()

    def factor_graph(self) -> gtsam.NonlinearFactorGraph:
        """The factors iSAM2 holds now (window factors and marginal priors)."""
        graph = gtsam.NonlinearFactorGraph()
        factors = self.isam.getFactorsUnsafe()
        for j in range(factors.size()):
            f = factors.at(j)
            if f is not None:
                graph.add(f)
        return graph


def key_dim(key: int) -> int:
    return _DIMS[chr(gtsam.Symbol(key).chr())]


def bayes_net_covariance(bn: gtsam.GaussianBayesNet, keys: list[int]) -> np.ndarray:
    """Covariance of a (joint marginal) Gaussian Bayes net, blocks in the order of keys: the net's square-root
    information R (upper triangular in elimination order) is inverted by triangular solves."""
    order: list[int] = []
    conds = [bn.at(j) for j in range(bn.size())]
    frontal_sets = []
    for c in conds:
        ks = list(c.keys())
        n_frontal = _frontal_count(c, ks)
        frontal_sets.append(ks[:n_frontal])
        order.extend(ks[:n_frontal])
    offsets, off = {}, 0
    for k in order:
        offsets[k] = off
        off += key_dim(k)
    R = np.zeros((off, off))
    row = 0
    for c, frontals in zip(conds, frontal_sets, strict=True):
        A, _ = c.jacobian()  # whitened [R S], columns in c.keys() order
        n_rows = A.shape[0]
        col = 0
        for k in c.keys():
            d = key_dim(k)
            R[row:row + n_rows, offsets[k]:offsets[k] + d] = A[:, col:col + d]
            col += d
        row += n_rows
    if row != off:
        raise GtsamDvlError("marginal covariance: the Bayes net is not square (rank-deficient problem)")
    Rinv = solve_triangular(R, np.eye(off))
    cov_elim = Rinv @ Rinv.T
    idx = np.concatenate([np.arange(offsets[k], offsets[k] + key_dim(k)) for k in keys])
    cov = cov_elim[np.ix_(idx, idx)]
    return 0.5 * (cov + cov.T)


def _frontal_count(c: gtsam.GaussianConditional, keys: list[int]) -> int:
    """Number of frontal keys of a conditional: its R block is square with the frontals' total dimension."""
    dim_r = c.R().shape[0]
    total, n = 0, 0
    for k in keys:
        if total >= dim_r:
            break
        total += key_dim(k)
        n += 1
    return n
