"""The per-epoch states: the registry of the variables every estimator carries at each state of a trajectory,
beside the pose X(i) and velocity V(i) (core/keys.py) and apart from the shared states (core/states.py).

A per-epoch state is a vector process with a variable per state: x(i) under the key symbol(char, i). Each is one
entry of EPOCH_STATES (an EpochState) that declares once

- its key symbol `char`, its dimension `dim` and unit, and whether the configuration carries it (`enabled`);
- its prior at the first state (`prior_factors`; the bias's is the shared state's) and its initial value
  (`initial`, the prior's mean) and the prediction of the next state's value from the previous one (`predict`);
- its process model: x_j = phi x_i + w, w ~ N(0, q I), over dt seconds (and dz metres of height) between states
  i and j (`transition`), as the links of consecutive states in the graphs (`link_factors`, `graph_factors`
  over a whole trajectory, `window_links` in the online window) and as the EKF's propagation of its block of the
  error state (`ekf_prior_cov`, `ekf_propagate`; `ekf_noise` for a state inside the shared block, the bias);
- which factors read it (`reads`: words; the DVL factor's options error_variable / current_variable,
  factors/dvl.py, and core/states.py dvl_factor_keys put the keys in place);
- its iSAM2 relinearisation threshold (`thresholds`) and what the result reports (`report` into
  NavResult.info[info_key], from an EpochEstimate).

The estimators read the registry: the batch graph's initial values, factors and elimination ordering
(estimators/graph/log_graph.py), the filtering timeline's per-epoch columns (estimators/batch/timeline.py), the
online window's keys per state, links, thresholds and marginalisation (estimators/online/window.py), the EKF's
error state (estimators/ekf/filter.py, kalman.py: the epoch states' blocks after the shared states', in registry
order) and the results (estimators/batch/smoother.py, online/estimator.py, ekf/filter.py: `reports`).

The entries, in the order of each state's keys (X(i), V(i), then these):

- imu_bias (B(i), [accel, gyro], core/keys.py): the IMU biases' random walk ([imu] bias_model "random_walk"); B(0)
  and its prior are the shared states' (core/states.py gyro_bias, accel_bias), a BetweenFactor links B(i) to
  B(i + 1) beside the IMU factor (which reads it); the EKF carries the biases in the shared block, their random
  walk is process noise there (`ekf_noise`).
- dvl_error (E(i), dvl_link, m/s): the DVL's correlated error ([dvl] correlated_sigma_m_s > 0,
  estimators/models/correlated.py), read by every DVL factor.
- water_current (W(i), [east, north] m/s, map): the water current ([current] water_track "use",
  estimators/models/current.py), read by the water-track pings; with layers, the boundaries S(b) it crosses are
  extra keys ordered with the shared states (`extra_keys`, `window_links`). Its report is the typed
  NavResult.water_current (core/result.py WaterCurrentProfile), not an info entry.

Adding a state (docs/architecture.md, "Adding a per-epoch state"; tests/estimators/test_epoch_states.py adds a
toy one): a subclass of EpochState with its key symbol, dimension, `enabled`, `sigma0` and `transition` (the rest
has defaults for a vector Gauss-Markov process or random walk), appended to EPOCH_STATES; a factor that reads it
takes its key.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig, RelinearizationThresholds
from gtsam_dvl.core.keys import DIMS, S, V, X
from gtsam_dvl.core.states import correlated_error, water_current
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.models import correlated, current

if TYPE_CHECKING:
    from gtsam_dvl.estimators.ekf.strapdown import FilterState


@dataclass(frozen=True)
class StatePath:
    """The states of a trajectory as a graph builder knows them: stamps t (N,) s, heights z (N,) m above the
    map origin (the initial guess's), the heights that place them in the water current's layers (the depth
    sensor's when in use, estimators/graph/log_graph.py layer_heights) and the map origin's height height0 m."""

    t: np.ndarray
    z: np.ndarray
    z_layer: np.ndarray
    height0: float = 0.0


@dataclass
class EpochEstimate:
    """A per-epoch state's estimate as an estimator reports it: at the states stamped t (N,) s, values (N, dim)
    and marginal covariances (N, dim, dim). history: every state's (the smoother's); else the last state's
    alone (N = 1: the filters', whose earlier values are filtered ones)."""

    t: np.ndarray
    value: np.ndarray
    cov: np.ndarray
    history: bool


@dataclass
class WindowMemory:
    """What an epoch state's links in the online window remember between states (the water current's layer and
    the boundaries crossed so far)."""

    layer: int = 0
    extra: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class WindowStep:
    """The online window's new state i, dt s after state i - 1, at heights z_prev and z_new (m, map; the new one
    predicted); height0: the map origin's height (m)."""

    i: int
    dt: float
    z_prev: float
    z_new: float
    height0: float


_EYE = {d: np.eye(d) for d in (1, 2, 3, 6)}


def _eye(d: int) -> np.ndarray:
    return _EYE[d] if d in _EYE else np.eye(d)


class EpochState:
    """One per-epoch state (module doc). The defaults are those of a vector process x_j = phi x_i + w with a
    zero-mean prior of sigma0 per axis at the first state, whose links are GTSAM linear factors (exact, in C++)."""

    name: str = ""
    description: str = ""
    char: str = ""  # key symbol (core/keys.py)
    dim: int = 0
    unit: str = ""
    reads: str = "no factor"  # which factors read it
    info_key: str | None = None  # NavResult.info entry of its report (None: none)
    # state 0's variable is a shared state's (its prior and initial value there)
    first_shared: bool = False
    beside_imu: bool = False  # its link joins the IMU factor of an interval (the factor reads it)
    ekf_block: bool = True  # the EKF appends a block of its own to the error state

    def enabled(self, config: EstimatorConfig) -> bool:
        raise NotImplementedError

    def key(self, i: int) -> int:
        return gtsam.symbol(self.char, i)

    # ----- the process ---------------------------------------------------------------------------
    def sigma0(self, config: EstimatorConfig) -> float:
        """The prior's sigma per axis at the first state (unit)."""
        raise NotImplementedError

    def transition(
        self, config: EstimatorConfig, dt: float, dz: float = 0.0
    ) -> tuple[float, float]:
        """(phi, q): x_j = phi x_i + w over dt s and dz m, w's variance q per axis."""
        raise NotImplementedError

    def initial(self, config: EstimatorConfig) -> Any:
        """Its value at every state of an initial guess: the prior's mean."""
        return np.zeros(self.dim)

    def insert(self, values: gtsam.Values, key: int, value: Any) -> None:
        values.insert(key, value)

    def read(self, values: gtsam.Values, key: int) -> np.ndarray:
        return np.asarray(values.atVector(key), dtype=float)

    def predict(self, config: EstimatorConfig, prev: gtsam.Values, i: int, dt: float) -> Any:
        """State i's predicted value from state i - 1's in prev, dt s earlier: phi x_{i-1}."""
        phi, _ = self.transition(config, dt)
        return phi * prev.atVector(self.key(i - 1))

    # ----- the graph -----------------------------------------------------------------------------
    def prior_factors(self, config: EstimatorConfig) -> list[gtsam.NonlinearFactor]:
        """Its prior at the first state: x_0 ~ N(0, sigma0^2 I)."""
        return [
            gtsam.PriorFactorVector(
                self.key(0),
                np.zeros(self.dim),
                gtsam.noiseModel.Isotropic.Sigma(self.dim, self.sigma0(config)),
            )
        ]

    def link_factors(
        self, config: EstimatorConfig, i: int, j: int, dt: float, dz: float = 0.0
    ) -> list[gtsam.NonlinearFactor]:
        """x_j - phi x_i ~ N(0, q I) between states i and j (q floored at 1e-12 sigma0^2: two states at one stamp
        would make an infinitely stiff link)."""
        phi, q = self.transition(config, dt, dz)
        s = float(np.sqrt(max(q, 1e-12 * self.sigma0(config) ** 2)))
        eye = _eye(self.dim)
        jf = gtsam.JacobianFactor(
            self.key(i),
            -phi * eye / s,
            self.key(j),
            eye / s,
            np.zeros(self.dim),
            gtsam.noiseModel.Unit.Create(self.dim),
        )
        at = gtsam.Values()
        for k in (self.key(i), self.key(j)):
            at.insert(k, np.zeros(self.dim))
        return [gtsam.LinearContainerFactor(jf, at)]

    def graph_factors(
        self, config: EstimatorConfig, path: StatePath
    ) -> list[gtsam.NonlinearFactor]:
        """The prior and the links of a whole trajectory's states (the batch graph)."""
        dt, dz = np.diff(path.t), np.diff(path.z)
        out = self.prior_factors(config)
        for i in range(len(dt)):
            out += self.link_factors(config, i, i + 1, float(dt[i]), float(dz[i]))
        return out

    def extra_keys(self, config: EstimatorConfig, path: StatePath) -> list[int]:
        """Variables of its process beside the per-state ones (ordered with the shared states)."""
        return []

    def window_start(
        self, config: EstimatorConfig, z0: float, height0: float, memory: WindowMemory
    ) -> None:
        """The online window's first state at height z0 m."""

    def window_links(
        self, config: EstimatorConfig, step: WindowStep, values: gtsam.Values, memory: WindowMemory
    ) -> list[gtsam.NonlinearFactor]:
        """The online window's link from state step.i - 1 to the new state step.i (WindowStep); extra variables it
        creates go into values and memory.extra."""
        return self.link_factors(config, step.i - 1, step.i, step.dt, step.z_new - step.z_prev)

    def thresholds(
        self, config: EstimatorConfig, thresholds: RelinearizationThresholds
    ) -> dict[str, np.ndarray]:
        """iSAM2's relinearisation thresholds by key symbol: a tenth of sigma0 (the links are linear)."""
        return {self.char: np.full(self.dim, 0.1 * self.sigma0(config))}

    # ----- the EKF -------------------------------------------------------------------------------
    def ekf_prior_cov(self, config: EstimatorConfig) -> np.ndarray:
        return _eye(self.dim) * self.sigma0(config) ** 2

    def ekf_propagate(
        self, config: EstimatorConfig, fs: FilterState, dt: float, height0: float
    ) -> None:
        """Its block of the EKF's covariance and its estimate over dt s (the navigation error's propagated
        before): its rows and columns times phi, q I added to its block, the estimate times phi."""
        cols = fs.epoch_slices()[self.name]
        phi, q = self.transition(config, dt, 0.0)
        fs.P[cols, :] *= phi
        fs.P[:, cols] *= phi
        fs.P[cols, cols] += q * _eye(self.dim)
        fs.epoch[self.name] = phi * fs.epoch[self.name]

    def ekf_noise(self, config: EstimatorConfig) -> dict[str, float]:
        """Continuous process noise (variance per second) of shared states' columns (a state without a block)."""
        return {}

    # ----- the result ----------------------------------------------------------------------------
    def report(self, config: EstimatorConfig, est: EpochEstimate) -> dict[str, Any] | None:
        """NavResult.info[info_key]: its estimate and sigmas at the last state."""
        return {
            "t_s": float(est.t[-1]),
            "value": np.asarray(est.value[-1], dtype=float).tolist(),
            "sigma": np.sqrt(np.maximum(np.diag(est.cov[-1]), 0.0)).tolist(),
        }


class ImuBiasWalk(EpochState):
    """The IMU biases' random walk (module doc): B(i) = [accel, gyro], GTSAM's ConstantBias."""

    name, description, char, dim, unit = "imu_bias", "IMU bias random walk", "b", 6, "m/s^2, rad/s"
    reads = "the IMU factors (and a DVL factor seen through the IMU motion)"
    first_shared, beside_imu, ekf_block = True, True, False

    def enabled(self, config: EstimatorConfig) -> bool:
        return config.imu.bias_model == "random_walk"

    def _rates(self, config: EstimatorConfig) -> tuple[float, float]:
        """The accelerometer's and gyro's bias random walk (m/s^2, rad/s per sqrt(s))."""
        imu = config.imu
        return (
            imu.accel_bias_rw_ug_per_rth * UG / 60.0,
            imu.gyro_bias_rw_deg_per_h_per_rth * DEG_PER_H / 60.0,
        )

    def initial(self, config: EstimatorConfig) -> Any:
        return gtsam.imuBias.ConstantBias()

    def read(self, values: gtsam.Values, key: int) -> np.ndarray:
        return np.asarray(values.atConstantBias(key).vector(), dtype=float)

    def predict(self, config: EstimatorConfig, prev: gtsam.Values, i: int, dt: float) -> Any:
        return prev.atConstantBias(self.key(i - 1))

    def prior_factors(self, config: EstimatorConfig) -> list[gtsam.NonlinearFactor]:
        return []  # (B(0)'s prior: core/states.py prior_factors)

    def link_factors(
        self, config: EstimatorConfig, i: int, j: int, dt: float, dz: float = 0.0
    ) -> list[gtsam.NonlinearFactor]:
        """B_j - B_i ~ N(0, diag(q_a^2 dt, q_g^2 dt))."""
        q_a, q_g = self._rates(config)
        sig_a, sig_g = q_a * np.sqrt(dt), q_g * np.sqrt(dt)
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sig_a] * 3 + [sig_g] * 3))
        return [
            gtsam.BetweenFactorConstantBias(
                self.key(i), self.key(j), gtsam.imuBias.ConstantBias(), noise
            )
        ]

    def graph_factors(
        self, config: EstimatorConfig, path: StatePath
    ) -> list[gtsam.NonlinearFactor]:
        return []  # (its links sit beside the IMU factors: beside_imu)

    def thresholds(
        self, config: EstimatorConfig, thresholds: RelinearizationThresholds
    ) -> dict[str, np.ndarray]:
        return {}  # (the shared states': core/states.py relinearization)

    def ekf_noise(self, config: EstimatorConfig) -> dict[str, float]:
        q_a, q_g = self._rates(config)
        return {"gyro_bias": q_g**2, "accel_bias": q_a**2}

    def report(self, config: EstimatorConfig, est: EpochEstimate) -> dict[str, Any] | None:
        return None  # (the shared states' estimates at the last state: NavResult.calibration)


class DvlCorrelatedError(EpochState):
    """The DVL's correlated error E(i) (estimators/models/correlated.py)."""

    name, description, char, dim, unit = "dvl_error", "DVL correlated error", "e", 3, "m/s"
    reads = "every DVL factor (factors/dvl.py error_variable)"
    info_key = "dvl_correlated_error"

    def enabled(self, config: EstimatorConfig) -> bool:
        return correlated_error(config)

    def sigma0(self, config: EstimatorConfig) -> float:
        return config.dvl.correlated_sigma_m_s

    def transition(
        self, config: EstimatorConfig, dt: float, dz: float = 0.0
    ) -> tuple[float, float]:
        return correlated.transition(config, dt)

    def prior_factors(self, config: EstimatorConfig) -> list[gtsam.NonlinearFactor]:
        return [correlated.prior_factor(config)]

    def link_factors(
        self, config: EstimatorConfig, i: int, j: int, dt: float, dz: float = 0.0
    ) -> list[gtsam.NonlinearFactor]:
        return [correlated.link_factor(config, i, j, dt)]

    def graph_factors(
        self, config: EstimatorConfig, path: StatePath
    ) -> list[gtsam.NonlinearFactor]:
        return correlated.factors(config, path.t)

    def report(self, config: EstimatorConfig, est: EpochEstimate) -> dict[str, Any] | None:
        return correlated.info(config, est.value if est.history else None)


class WaterCurrent(EpochState):
    """The water current W(i), with layers the boundaries S(b) (estimators/models/current.py)."""

    name, description, char, dim, unit = "water_current", "water current", "w", 2, "m/s"
    reads = "the water-track pings' DVL factors (factors/dvl.py current_variable)"

    def enabled(self, config: EstimatorConfig) -> bool:
        return water_current(config)

    def sigma0(self, config: EstimatorConfig) -> float:
        return config.current.prior_sigma_m_s

    def transition(
        self, config: EstimatorConfig, dt: float, dz: float = 0.0
    ) -> tuple[float, float]:
        return 1.0, current.step_variance(config, dt, dz)

    def predict(self, config: EstimatorConfig, prev: gtsam.Values, i: int, dt: float) -> Any:
        return prev.atVector(self.key(i - 1))

    def prior_factors(self, config: EstimatorConfig) -> list[gtsam.NonlinearFactor]:
        return [current.prior_factor(config)]

    def link_factors(
        self, config: EstimatorConfig, i: int, j: int, dt: float, dz: float = 0.0
    ) -> list[gtsam.NonlinearFactor]:
        return [current.link_factor(config, i, j, dt, dz)]

    def graph_factors(
        self, config: EstimatorConfig, path: StatePath
    ) -> list[gtsam.NonlinearFactor]:
        z = path.z_layer if current.layered(config) else path.z
        return current.factors(config, path.t, z, path.height0)

    def extra_keys(self, config: EstimatorConfig, path: StatePath) -> list[int]:
        return [S(b) for b in current.boundaries(config, path.z_layer, path.height0)]

    def window_start(
        self, config: EstimatorConfig, z0: float, height0: float, memory: WindowMemory
    ) -> None:
        memory.layer = (
            int(current.layer_index(config, z0, height0)) if current.layered(config) else 0
        )

    def window_links(
        self, config: EstimatorConfig, step: WindowStep, values: gtsam.Values, memory: WindowMemory
    ) -> list[gtsam.NonlinearFactor]:
        """The random walk in time and depth, or with layers across the boundaries crossed: a boundary met for the
        first time gets its variable (zero: its prior's mean) and prior (current.py, "Layers")."""
        if not current.layered(config):
            return super().window_links(config, step, values, memory)
        i, j = step.i, int(current.layer_index(config, step.z_new, step.height0))
        out: list[gtsam.NonlinearFactor] = []
        for b, _ in current.crossings(memory.layer, j):
            if S(b) not in memory.extra:
                memory.extra.append(S(b))
                values.insert(S(b), np.zeros(2))
                out.append(current.shear_prior(config, b))
        out.append(current.crossing_link(config, i - 1, i, step.dt, memory.layer, j))
        memory.layer = j
        return out

    def thresholds(
        self, config: EstimatorConfig, thresholds: RelinearizationThresholds
    ) -> dict[str, np.ndarray]:
        # the water current enters the DVL factor linearly but for its cross terms with the attitude and scale
        # ((k dtheta + dk) dW: 2e-4 m/s at 1e-2 and 0.02 m/s, 2 % of a water-track ping's sigma): twice that sigma
        limit = np.full(2, 2.0 * config.current.water_track_default_sigma_m_s)
        return {"w": limit, "s": limit.copy()}

    def ekf_propagate(
        self, config: EstimatorConfig, fs: FilterState, dt: float, height0: float
    ) -> None:
        current.ekf_propagate(config, fs, dt, height0)

    def report(self, config: EstimatorConfig, est: EpochEstimate) -> dict[str, Any] | None:
        return None  # (NavResult.water_current: each estimator's profile, current.py)


EPOCH_STATES: list[EpochState] = [ImuBiasWalk(), DvlCorrelatedError(), WaterCurrent()]
for _s in EPOCH_STATES:
    DIMS[_s.char] = _s.dim


def enabled_epoch_states(config: EstimatorConfig) -> list[EpochState]:
    """The per-epoch states the configuration carries, in registry order (the order of each state's keys)."""
    return [s for s in EPOCH_STATES if s.enabled(config)]


def state_keys(config: EstimatorConfig, i: int) -> list[int]:
    """The keys of state i: X(i), V(i), then the enabled per-epoch states'."""
    return [X(i), V(i)] + [s.key(i) for s in enabled_epoch_states(config)]


def ekf_states(config: EstimatorConfig) -> list[EpochState]:
    """The enabled states with a block of their own in the EKF's error state, in its order (after the shared
    states' and the layer boundaries')."""
    return [s for s in enabled_epoch_states(config) if s.ekf_block]


def window_thresholds(
    config: EstimatorConfig, thresholds: RelinearizationThresholds
) -> dict[str, np.ndarray]:
    """The enabled states' iSAM2 relinearisation thresholds by key symbol."""
    out: dict[str, np.ndarray] = {}
    for s in enabled_epoch_states(config):
        out.update(s.thresholds(config, thresholds))
    return out


def reports(config: EstimatorConfig, estimates: dict[str, EpochEstimate]) -> dict[str, Any]:
    """The result's info entries of the enabled states (their `report`), from their estimates by name."""
    out: dict[str, Any] = {}
    for s in enabled_epoch_states(config):
        if s.info_key is None or s.name not in estimates:
            continue
        entry = s.report(config, estimates[s.name])
        if entry is not None:
            out[s.info_key] = entry
    return out


def graph_estimates(
    config: EstimatorConfig, values: gtsam.Values, covariances: dict[int, np.ndarray], t: np.ndarray
) -> dict[str, EpochEstimate]:
    """A smoother's estimates of the enabled states that report (info_key) at every state stamped t (N,) s: the
    values and each variable's marginal covariance."""
    out: dict[str, EpochEstimate] = {}
    for s in enabled_epoch_states(config):
        if s.info_key is None:
            continue
        keys = [s.key(i) for i in range(len(t))]
        out[s.name] = EpochEstimate(
            np.asarray(t, dtype=float),
            np.array([s.read(values, k) for k in keys]),
            np.array([covariances[k] for k in keys]),
            True,
        )
    return out
