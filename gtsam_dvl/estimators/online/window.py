"""The iSAM2 engine of the online estimator: a state per keyframe (or per DVL epoch without keyframes), over a
fixed-lag window or the whole history.

Settings (where iSAM2's defaults fail on this problem):
- Factorisation QR: Cholesky fails at navigation-grade noise. Wildfire threshold 0: rotations matter at
  1e-4 rad, below iSAM2's default 1e-3 on every component. Relinearisation checked at every update against a
  threshold per variable type and tangent component (RelinearizationThresholds), not iSAM2's 0.1 on all.
- Marginal covariances by QR: ISAM2.marginalCovariance eliminates with Cholesky and fails. The joint of the
  newest state, bias, scale and misalignment comes from jointBayesNet(keys, EliminateQR) (those keys sit in
  the root clique, so this is cheap), its square-root information inverted as a triangular matrix (the
  information matrix itself spans 1e18 and cannot be inverted in double precision).

Fixed lag, and why it is built this way (the alternatives compared on paper-3d with bench/bench_online.py; the
figures of this design: docs/results.md, "Online estimator"):
- The window is a chain of states sharing the bias, scale and misalignment. A new epoch touches its top, a
  state leaving the window its bottom. Removing the old state's factors from iSAM2 and adding back their
  marginal (removeFactorIndices plus a LinearContainerFactor) touches the bottom: iSAM2 re-eliminates from
  there to the root, i.e. everything, which past 65 % of the variables is its batch step, relinearising every
  factor through its Python callback: several times the latency of the design below.
- ISAM2.marginalizeLeaves cuts the bottom clique off and keeps its cached marginal, without re-eliminating
  (IncrementalFixedLagSmoother is built on it). Its catch: every variable of the marginal it keeps is frozen at
  its linearisation point, forever, the scale, misalignment and bias included; the first marginalisation
  happens in the static phase, where the scale is its prior 0.8. Hence the rebase: when a frozen variable's
  update exceeds its relinearisation threshold, a new iSAM2 is built from the same factors at the current
  estimate (the marginals pinned to the old linearisation point as LinearContainerFactors, since
  marginalizeLeaves keeps them relative to it). That costs what one relinearisation of the scale costs iSAM2
  anyway, every factor of the window once, and happens while the estimate converges: mostly in the first 100 s
  (gyrocompassing from the 5 deg heading prior) and the first Type-I manoeuvres (result.info["isam2"]
  ["rebases"] counts them).
- marginalizeLeaves needs the oldest state alone in a leaf clique (splitting a clique whose keys are not in
  elimination order corrupts iSAM2, GTSAM issue #1101). Updates therefore give elimination groups (oldest
  first, shared keys last) to the few newest states iSAM2 may relinearise, and mark older ones not to be
  relinearised (an old state relinearised would re-eliminate the whole chain in an order of iSAM2's choosing);
  they drift little and are relinearised by a rebase when they pass their threshold.
- Bounded: the window holds a bounded number of variables and factors (and iSAM2 reuses the slots of removed
  factors), so neither iSAM2's work per update nor the copy of the Values it hands to each Python CustomFactor
  grows with the mission: the last hour of a 6-hour survey has no higher p99 than the first (docs/results.md).
  The factors it drops are freed (the IMU factor's callback holds no reference back to it: factors/imu_earth.py,
  "Memory"), so memory is flat too; at 200 Hz IMU / 5 Hz DVL over 6 h see bench/bench_online_long.py.
- The alternative of a sliding-window Gauss-Newton written in Python (solver.py on the window, a QR marginal
  prior on the oldest state) relinearises the whole window at every iteration: a higher median latency than
  this design, everything included.

Shared keys: those of the shared states the configuration estimates (core/states.py: the bias, the scale, the
misalignment and, with [dvl] estimate_time_offset, the DVL time offset, relinearised past the registry's
thresholds), part of the joint marginal of `estimate` (the time offset reported in StateEstimate.time_offset_s /
time_offset_sigma_s). Factors on states already held (a depth sample after the
newest state) go in through `add_factors`.

Full history: iSAM2 with every state and its default ordering.
 Each relinearisation of the scale,
misalignment or bias relinearises every DVL or IMU factor of the mission, each call copying all the Values:
the cost per update grows with the mission (docs/results.md, "Online estimator": the full history on
paper-3d).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import RelinearizationThresholds
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import V, X, key_dim
from gtsam_dvl.core.states import (
    Estimate,
    block_states,
    read_estimates,
    relinearization,
    shared_keys,
)
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.gaps import Holds
from gtsam_dvl.estimators.models import weak_hold
from gtsam_dvl.estimators.models.epoch_states import (
    EpochEstimate,
    WindowMemory,
    WindowStep,
    enabled_epoch_states,
    window_thresholds,
)
from gtsam_dvl.factors import EarthImuFactor

# the joint of StateEstimate: pose, velocity and the calibration block (core/states.py: bias, scale, misalignment)
STATE_DIM = 6 + 3 + sum(s.dim for s in block_states())
RECENT = 5  # fixed lag: iSAM2 relinearises the newest RECENT states itself (see IncrementalSmoother._ordering)


# RelinearizationThresholds (its threshold_map() gives iSAM2's): gtsam_dvl.core.config, TOML [online.relinearization]


@dataclass(kw_only=True)
class EstimateExtras:
    """What an online estimate holds beside its state, bias and DVL scale and misalignment (StateEstimate and the
    user's OnlineEstimate): the DVL time offset dt_d (s) and its marginal sigma with dvl.estimate_time_offset (else
    0 and nan); predicted_from_t: nan for the estimate of the newest state at its time t, else the estimate at a
    ping at t between states, predicted from the newest state at predicted_from_t (s: online/between_pings.py
    predict_at_ping); calibration: the shared states by name (core/states.py)."""

    time_offset_s: float = 0.0
    time_offset_sigma_s: float = float("nan")
    predicted_from_t: float = float("nan")
    calibration: dict[str, Estimate] = field(default_factory=dict)


@dataclass
class StateEstimate(EstimateExtras):
    """The newest state, bias and calibration with their joint marginal covariance (SI, GTSAM tangents), and
    EstimateExtras."""

    index: int
    t: float
    pose: gtsam.Pose3
    n_v: np.ndarray
    bias: gtsam.imuBias.ConstantBias
    scale: float
    b_R_d: np.ndarray
    cov: np.ndarray  # (19, 19): pose (6), n_v (3), bias [accel, gyro] (6), scale (1), b_R_d (3)

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


class IncrementalSmoother:
    """iSAM2 over the epochs given to `add_epoch` (factors from the shared FactorMaker). `window_s` None
    keeps every state (full history); otherwise states older than window_s seconds behind the newest are
    marginalised (at least two states stay)."""

    def __init__(
        self,
        builder: FactorMaker,
        window_s: float | None,
        thresholds: RelinearizationThresholds,
        relinearize_skip: int = 1,
    ) -> None:
        self.builder = builder
        self.window_s = window_s
        self.thresholds = thresholds
        # the per-epoch states the configuration carries (estimators/models/epoch_states.py: the bias random walk,
        # the DVL's correlated error, the water current, ...), and what their links remember (the water current's
        # layer and the boundaries S(b) crossed so far: shared keys, never marginalised)
        self.epoch_states = enabled_epoch_states(builder.config)
        self.memory = {s.name: WindowMemory() for s in self.epoch_states}
        # the newest estimate's held calibration directions (weak_hold.py)
        self.hold: dict[str, Any] | None = None
        # relinearisation thresholds by symbol character: the states', the shared states' (core/states.py) and the
        # per-epoch states' (their own: epoch_states.py)
        self._threshold = {
            "x": np.asarray(thresholds.pose, dtype=float),
            "v": np.asarray(thresholds.velocity, dtype=float),
            **relinearization(builder.config, thresholds),
            **window_thresholds(builder.config, thresholds),
        }
        self.params = gtsam.ISAM2Params()
        self.params.setFactorization("QR")
        threshold_map = gtsam.ISAM2ThresholdMap()
        for char, limit in self._threshold.items():
            threshold_map.insert((char, limit))
        self.params.setRelinearizeThreshold(threshold_map)
        self.params.relinearizeSkip = relinearize_skip
        self.params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(0.0))
        # reuse the slots of removed factors: otherwise iSAM2's factor table grows by three empty slots per
        # epoch, and walking it (rebase) costs more the longer the mission
        self.params.findUnusedFactorSlots = window_s is not None
        self.isam = gtsam.ISAM2(self.params)
        self.first = 0  # oldest state in the window
        self.times: dict[int, float] = {}  # of the states in the window
        self.imus: dict[int, EarthImuFactor] = {}  # IMU factor from state i to i + 1, in the window
        self.n = 0  # epochs added
        self.t_last = -np.inf
        self.marginalised = 0
        self.rebases = 0
        # keys of the states older than the RECENT newest, oldest first
        self._frozen = gtsam.KeyList()
        self._frozen_until = 0  # states below this index are in _frozen (or marginalised)
        self._limits: dict[tuple[int, int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._last_imu: EarthImuFactor | None = None
        # a normal update re-eliminated states outside its elimination groups: the chain's time order, which
        # marginalizeLeaves needs, may be broken (see _update); the next marginalisation rebases first
        self._order_suspect = False

    # ----- updates -------------------------------------------------------------------------------
    def add_epoch(
        self,
        t: float,
        dvl_factors: list[gtsam.NonlinearFactor],
        pim: gtsam.PreintegratedImuMeasurements | None = None,
        params: gtsam.PreintegrationParams | None = None,
        first_values: gtsam.Values | None = None,
        held: Holds | None = None,
    ) -> None:
        """Add state n at time t with its DVL factors (built by the caller with builder.dvl_factors_for(n, ...),
        and any other factors on the states held: the keyframe factors of the pings since the previous state) and,
        for n > 0, the preintegration since the previous epoch; for n == 0, first_values (builder.
        first_state_values) seed the state, bias and calibration and the priors."""
        i, b = self.n, self.builder
        factors: list[gtsam.NonlinearFactor] = list(dvl_factors)
        values = gtsam.Values()
        if i == 0:
            if first_values is None:
                raise GtsamDvlError("the first epoch needs its initial values")
            values = first_values
            factors = b.prior_factors(values) + factors
            z0 = float(values.atPose3(X(0)).translation()[2])
            for s in self.epoch_states:  # their priors at the first state (epoch_states.py)
                if not s.first_shared:
                    s.insert(values, s.key(0), s.initial(b.config))
                    factors += s.prior_factors(b.config)
                s.window_start(b.config, z0, b.frame.height_m, self.memory[s.name])
        else:
            if pim is None or params is None:
                raise GtsamDvlError("an epoch after the first needs its preintegration")
            dt = t - self.t_last
            imu = b.new_imu_factor(i - 1, pim, params, dt, held)
            beside = [
                f
                for s in self.epoch_states
                if s.beside_imu
                for f in s.link_factors(b.config, i - 1, i, dt)
            ]
            factors = [imu.factor, *beside, *factors]
            prev = self.isam.calculateEstimate(
                list(
                    dict.fromkeys([X(i - 1), V(i - 1), b.bias_key(i - 1), *self._epoch_keys(i - 1)])
                )
            )
            pose, n_v = prev.atPose3(X(i - 1)), prev.atVector(V(i - 1))
            bias = prev.atConstantBias(b.bias_key(i - 1))
            self._reference_gravity(imu, pose.translation() + 0.5 * dt * n_v)
            self.imus[i - 1] = imu
            state = pim.predict(gtsam.NavState(pose, n_v), bias)
            values.insert(X(i), state.pose())
            values.insert(V(i), state.velocity())
            z_prev, z_new = float(pose.translation()[2]), float(state.pose().translation()[2])
            step = WindowStep(i, dt, z_prev, z_new, b.frame.height_m)
            for s in self.epoch_states:  # each state's prediction and link (epoch_states.py)
                s.insert(values, s.key(i), s.predict(b.config, prev, i, dt))
                if not s.beside_imu:
                    factors += s.window_links(b.config, step, values, self.memory[s.name])
        self.n, self.t_last = i + 1, t
        self.times[i] = t
        graph = gtsam.NonlinearFactorGraph()
        for f in factors:
            graph.add(f)
        self._update(graph, values)
        if self.window_s is not None:
            self._slide(t - self.window_s)

    def _epoch_keys(self, i: int) -> list[int]:
        """The per-epoch states' keys of state i."""
        return [s.key(i) for s in self.epoch_states]

    def extra_keys(self) -> list[int]:
        """The per-epoch states' extra variables created so far (the water current's layer boundaries S(b)): kept
        with the shared keys, never marginalised."""
        return [k for m in self.memory.values() for k in m.extra]

    @property
    def shear(self) -> list[int]:
        """The water current's layer boundaries b crossed so far (their keys S(b) among extra_keys)."""
        return [
            gtsam.Symbol(k).index() for k in self.extra_keys() if chr(gtsam.Symbol(k).chr()) == "s"
        ]

    def add_factors(self, factors: list[gtsam.NonlinearFactor]) -> None:
        """Factors on variables already held (a depth sample that came after the newest state): one update."""
        if not factors:
            return
        graph = gtsam.NonlinearFactorGraph()
        for f in factors:
            graph.add(f)
        self._update(graph, gtsam.Values())

    def _update(
        self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, rebase: bool = False
    ) -> None:
        try:
            if self.window_s is None:
                self.isam.update(graph, values)
            else:
                groups, frozen = self._ordering(rebase)
                result = self.isam.update(graph, values, [], groups, frozen)
                # iSAM2 orders the keys without a group (older states) as CCOLAMD likes; when it re-eliminated
                # more of them than the state just below the groups (a batch reorder, or a relinearisation
                # reaching old states, as after a gross DVL outlier), the oldest state may share a clique with
                # newer ones, and marginalizeLeaves would split it: iSAM2 corrupted (GTSAM issue #1101), an
                # IndexError from getDelta a few epochs later. A rebase restores the time order.
                if not rebase and (
                    result.getBatchReorderTriggered()
                    or result.getVariablesReeliminated() > groups.size() + len(self._state_keys(0))
                ):
                    self._order_suspect = True
        except RuntimeError as exc:
            raise GtsamDvlError(f"iSAM2 update at t = {self.t_last:.3f} s failed ({exc})") from None

    def _state_keys(self, i: int) -> tuple[int, ...]:
        return (X(i), V(i), *self._epoch_keys(i))

    def _ordering(self, rebase: bool) -> tuple[gtsam.KeyGroupMap, gtsam.KeyList]:
        """Elimination groups (states oldest first, the bias, scale and misalignment last) and the states iSAM2
        must not relinearise. The window's Bayes tree stays a chain with the oldest state alone at its leaf,
        which marginalizeLeaves removes without touching the rest (GTSAM issue #1101: splitting a clique whose
        keys are not in elimination order corrupts iSAM2), and the newest state with the shared keys at its
        root, so that a new epoch re-eliminates the top only. Hence only the newest RECENT states are
        relinearised by iSAM2 (a relinearised old state would re-eliminate the whole chain, in an order iSAM2
        chooses); older ones are relinearised by a rebase when they drift past their threshold. CCOLAMD wants
        every group number below the number of keys it orders, which only the rebase's full re-elimination
        allows for a long window: the normal update gives groups to the RECENT newest states only (an update
        re-eliminates at least the two newest states and the three shared keys)."""
        recent_from = self.first if rebase else max(self.first, self.n - RECENT)
        while self._frozen_until < recent_from:  # states that just left the RECENT ones
            for k in self._state_keys(self._frozen_until):
                self._frozen.push_back(k)
            self._frozen_until += 1
        groups = gtsam.KeyGroupMap()
        for i in range(recent_from, self.n):
            for k in self._state_keys(i):
                groups.insert2(k, i - recent_from)
        # (the current's layer boundaries too)
        for k in self.shared_keys(self.n - 1) + self.extra_keys():
            groups.insert2(k, self.n - recent_from)
        return groups, (gtsam.KeyList() if rebase else self._frozen)

    def _slide(self, t_oldest: float) -> None:
        """Marginalise the states older than t_oldest (keeping two at least), then rebase if a variable iSAM2
        does not relinearise moved from its linearisation point by more than its threshold."""
        if self._order_suspect and self.first < self.n - 2 and self.times[self.first] < t_oldest:
            self.rebase()
        while self.first < self.n - 2 and self.times[self.first] < t_oldest:
            s = self.first
            keys = gtsam.KeyList()
            for k in self._state_keys(s):
                keys.push_back(k)
            try:
                self.isam.marginalizeLeaves(keys)
            except RuntimeError:  # not a leaf after all: rebuild in time order, then it is
                self.rebase()
                self.isam.marginalizeLeaves(keys)
            del self.times[s]
            self.imus.pop(s, None)
            if self._frozen_until > s:
                for _ in self._state_keys(s):
                    self._frozen.pop_front()
            else:
                self._frozen_until = s + 1
            self.first = s + 1
            self.marginalised += 1
        if self._frozen_moved():
            self.rebase()

    def _frozen_moved(self) -> bool:
        """Whether the shared keys or a state older than the RECENT newest moved from its linearisation point by
        more than its relinearisation threshold (the shared keys are frozen by marginalizeLeaves, the old
        states by _ordering)."""
        # keys in sorted order: b, c, k, (t,) v, x (GTSAM symbols)
        delta = self.isam.getDelta().vector()
        n_states = self.n - self.first
        old = max(0, n_states - RECENT)
        extra = self.extra_keys()
        if (n_states, old, len(extra)) not in self._limits:
            # (key, whether iSAM2 leaves it alone): the states', old ones only, and the shared keys, always
            held = [(k, j < old) for j in range(n_states) for k in self._state_keys(self.first + j)]
            held += [(k, True) for k in shared_keys(self.builder.config, per_state=False)]
            held += [(k, True) for k in extra]
            held.sort()
            limits = [self._threshold[chr(k >> 56)] for k, _ in held]
            self._limits[(n_states, old, len(extra))] = (
                np.concatenate(limits),
                np.concatenate(
                    [
                        np.full(len(lim), frozen)
                        for lim, (_, frozen) in zip(limits, held, strict=True)
                    ]
                ),
            )
        lim, msk = self._limits[(n_states, old, len(extra))]
        if lim.shape != delta.shape:
            raise GtsamDvlError(
                f"internal: iSAM2 holds {delta.shape[0]} delta components, expected {lim.shape[0]}"
            )
        return bool(((np.abs(delta) > lim) & msk).any())

    def rebase(self) -> None:
        """A new iSAM2 holding the same factors (the window's and the marginal of what left it), linearised at
        the current estimate. ISAM2.marginalizeLeaves freezes the linearisation point of every variable of the
        marginal it keeps, the shared keys included, forever; this is how they get relinearised (the cost of
        one relinearisation of the scale in iSAM2 without a window: every factor of the window once)."""
        values = self.isam.calculateEstimate()
        theta = self.isam.getLinearizationPoint()
        factors = self.isam.getFactorsUnsafe()
        graph = gtsam.NonlinearFactorGraph()
        for j in range(factors.size()):
            f = factors.at(j)
            if isinstance(f, gtsam.LinearContainerFactor):
                # marginalizeLeaves' marginals carry no linearisation point: they are in iSAM2's delta around
                # its theta, which is about to change; pin them to it
                f = gtsam.LinearContainerFactor(f.linearize(theta), theta)
            if f is not None:
                graph.add(f)
        self.isam = gtsam.ISAM2(self.params)
        self._update(graph, values, rebase=True)
        self.rebases += 1
        self._order_suspect = False

    def _reference_gravity(self, imu: EarthImuFactor, n_p_mid: np.ndarray) -> None:
        """Local gravity model of a new IMU factor: the previous factor's while within its range (evaluating
        gravity and its gradient costs about a millisecond), else evaluated at n_p_mid."""
        last = self._last_imu
        if imu.gravity is not None:
            if last is not None and last.ref_p is not None and not last.needs_reference(n_p_mid):
                imu.set_reference(last.ref_p, last.ref_g, last.ref_G)
            else:
                g, G = self.builder.gravity_model(n_p_mid)
                imu.set_reference(n_p_mid, g, G)
        imu.set_gravity(n_p_mid)
        self._last_imu = imu

    def refresh_gravity(self) -> int:
        """Re-reference the gravity of the IMU factors whose mid position moved out of their reference's range
        (factors/imu_earth.py); returns how many."""
        stale = []
        for s, imu in self.imus.items():
            ends = self.isam.calculateEstimate([X(s), X(s + 1)])
            mid = 0.5 * (ends.atPose3(X(s)).translation() + ends.atPose3(X(s + 1)).translation())
            if imu.needs_reference(mid):
                stale.append((imu, mid))
        if stale:
            g, G = self.builder.gravity_model(np.array([m for _, m in stale]))
            for k, (imu, mid) in enumerate(stale):
                imu.set_reference(mid, g[k], G[k])
        return len(stale)

    def refine(self, max_updates: int = 10) -> int:
        """Extra iSAM2 updates without new data until no variable is relinearised (the end of a run);
        returns the number of updates made."""
        for k in range(max_updates):
            moved = self.window_s is not None and self._frozen_moved()
            if moved:
                self.rebase()
            result = self.isam.update()
            if not moved and result.getVariablesRelinearized() == 0:
                return k + 1
        return max_updates

    # ----- estimates -----------------------------------------------------------------------------
    def shared_keys(self, i: int) -> list[int]:
        """The keys of the shared states at state i (core/states.py; the random-walk bias B(i))."""
        return shared_keys(self.builder.config, i)

    def estimate(self, with_covariance: bool = True) -> StateEstimate:
        """The newest state, the bias and the calibration, with their joint marginal covariance."""
        i = self.n - 1
        shared = self.shared_keys(i)
        keys = [X(i), V(i), *shared]
        values = self.isam.calculateEstimate(keys)
        dim = 9 + sum(key_dim(k) for k in shared)
        cov = self.joint_covariance(keys) if with_covariance else np.full((dim, dim), np.nan)
        self.hold = None
        if (
            self.builder.calibration is None
            and (
                held := weak_hold.hold_joint(
                    self.builder.config, self.builder.mounting, values, keys, cov
                )
            )
            is not None
        ):
            # weakly determined calibration directions held (weak_hold.py)
            values, cov, self.hold = held
        key_cols, col = {}, 9
        for k in shared:
            key_cols[k] = slice(col, col + key_dim(k))
            col += key_dim(k)
        est = read_estimates(
            values, {k: cov[c, c] for k, c in key_cols.items()}, self.builder.config, i
        )
        offset = est.get("time_offset")
        return StateEstimate(
            index=i,
            t=self.t_last,
            pose=values.atPose3(X(i)),
            n_v=values.atVector(V(i)),
            bias=values.atConstantBias(self.builder.bias_key(i)),
            scale=float(est["scale"].value[0]),
            b_R_d=est["misalignment"].value,
            cov=cov[:STATE_DIM, :STATE_DIM],
            time_offset_s=0.0 if offset is None else float(offset.value[0]),
            time_offset_sigma_s=float("nan") if offset is None else float(offset.sigma[0]),
            calibration=est,
        )

    def epoch_estimates(self) -> dict[str, EpochEstimate]:
        """The per-epoch states' estimates at the newest state (those that report: epoch_states.py), with their
        marginal covariances."""
        i, out = self.n - 1, {}
        for s in self.epoch_states:
            if s.info_key is None or i < 0:
                continue
            value = s.read(self.isam.calculateEstimate([s.key(i)]), s.key(i))
            cov = self.joint_covariance([s.key(i)])
            out[s.name] = EpochEstimate(np.array([self.times[i]]), value[None, :], cov[None], False)
        return out

    def joint_covariance(self, keys: list[int]) -> np.ndarray:
        """Joint marginal covariance of keys (blocks in that order) from iSAM2's Bayes tree, by QR."""
        try:
            bn = self.isam.jointBayesNet(keys, gtsam.EliminateQR)
        except (
            RuntimeError,
            IndexError,
        ) as exc:  # IndexError: a key no longer in iSAM2 (left the window)
            raise GtsamDvlError(
                f"marginal covariance failed ({type(exc).__name__}: {exc})"
            ) from None
        return bayes_net_covariance(bn, keys)

    def size(self) -> tuple[int, int]:
        """(variables, factors) iSAM2 holds now: bounded in the fixed-lag mode."""
        factors = self.isam.getFactorsUnsafe()
        return self.isam.getLinearizationPoint().size(), sum(
            factors.at(j) is not None for j in range(factors.size())
        )


def bayes_net_covariance(bn: gtsam.GaussianBayesNet, keys: list[int]) -> np.ndarray:
    """Covariance of a (joint marginal) Gaussian Bayes net, blocks in the order of keys: the net's square-root
    information R (upper triangular in elimination order) is inverted."""
    order: list[int] = []
    conds = [bn.at(j) for j in range(bn.size())]
    for c in conds:
        ks = list(c.keys())
        order.extend(ks[: _frontal_count(c, ks)])
    offsets, off = {}, 0
    for k in order:
        offsets[k] = off
        off += key_dim(k)
    R = np.zeros((off, off))
    row = 0
    for c in conds:
        A, _ = c.jacobian()  # whitened [R S], columns in c.keys() order
        n_rows = A.shape[0]
        col = 0
        for k in c.keys():
            d = key_dim(k)
            R[row : row + n_rows, offsets[k] : offsets[k] + d] = A[:, col : col + d]
            col += d
        row += n_rows
    if row != off:
        raise GtsamDvlError(
            "marginal covariance: the Bayes net is not square (rank-deficient problem)"
        )
    # LU of a triangular matrix needs no row swaps; scipy's solve_triangular costs more a call
    Rinv = np.linalg.inv(R)
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
