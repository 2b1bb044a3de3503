"""The shared states: the registry of the variables that every estimator carries across the epochs of a log.

A shared state is one of the calibration and bias states that the states of a trajectory share: the DVL scale
factor k, the misalignment b_R_d, the IMU biases, the DVL time offset dt_d and the DVL lever arm b_l. Each is one
entry of STATES (SharedState): its name, its GTSAM key (core/keys.py) and where in that key's tangent it sits (the
bias key B holds [accel, gyro], GTSAM's ConstantBias), its tangent dimension and unit, the unit it is shown in with
the factor between the two, its prior from the configuration (initial value and covariance), the accuracy target
of the observability verdict ([observability]), whether the configuration estimates it, and whether it is a
property of the vehicle (a calibration carried across dives) or of one dive.

Everything that lists the shared states reads STATES: the priors and initial values (prior_factors,
initial_values), the elimination orderings and the iSAM2 window's shared keys (shared_keys), the filtering
timeline and the EKF's error state (columns, ekf_layout), the result's calibration (read_estimates,
NavResult.calibration) and the verdicts (analysis/observability.py). Adding a state is its key in core/keys.py,
an entry here and its factor. The states with a variable at every epoch (the random-walk bias's B(i) beyond B(0),
the DVL's correlated error E(i), the water current W(i)) are declared in the per-epoch registry,
estimators/models/epoch_states.py, which the estimators read beside this one.

STATES is in the order of the EKF's error state after the navigation error (gyro bias, accelerometer bias, scale,
misalignment, time offset); the keys, in the order of their first state, are B, K_SCALE, C_MISALIGN, T_OFFSET,
L_LEVER, the order of every elimination ordering's shared block.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Literal

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig, ObservabilityConfig, RelinearizationThresholds
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import (
    C_MISALIGN,
    K_SCALE,
    K_WATER,
    L_LEVER,
    T_OFFSET,
    B,
    E,
    V,
    W,
    X,
    key_dim,
)
from gtsam_dvl.core.types import Mounting
from gtsam_dvl.core.units import DEG_PER_H, UG

if TYPE_CHECKING:  # core/calibration.py reads STATES lazily; only the type is needed here
    from gtsam_dvl.core.calibration import VehicleCalibration

# How a key's value is held in gtsam.Values: a Vector, a Rot3 (its value here the 3x3 matrix, its tangent the
# right perturbation), or an imuBias.ConstantBias (tangent [accel, gyro]).
Kind = Literal["vector", "rot3", "bias"]


@dataclass(frozen=True)
class Prior:
    """A state's prior: its initial value (a vector; a rotation's 3x3 matrix) and its sigmas (SI), per axis of
    the axes it is shown in. cov is the covariance in the state's tangent: diag(sigma^2), or for a rotation with
    `axes` A (sigmas about body axes, the tangent on the right) A^T diag(sigma^2) A."""

    value: np.ndarray
    sigma: np.ndarray
    axes: np.ndarray | None = None
    # the sigmas as the configuration gives them, when in the display unit
    display_sigma: np.ndarray | None = None

    @property
    def cov(self) -> np.ndarray:
        d = np.diag(self.sigma**2)
        return d if self.axes is None else self.axes.T @ d @ self.axes


@dataclass
class Estimate:
    """A state's estimate (as Prior.value) and its marginal covariance in the state's tangent (SI)."""

    value: np.ndarray
    cov: np.ndarray

    @property
    def sigma(self) -> np.ndarray:
        """(dim,) marginal sigmas in the tangent, SI."""
        return np.sqrt(np.diag(self.cov))


def _always(config: EstimatorConfig) -> bool:
    return True


def _never(config: EstimatorConfig) -> bool:
    return False


def _random_walk(config: EstimatorConfig) -> bool:
    return config.imu.bias_model == "random_walk"


@dataclass(frozen=True)
class SharedState:
    """One shared state (module doc)."""

    name: str
    description: str  # for sentences: "DVL scale factor"
    key: int  # core/keys.py; with per_state, the key of the first state's variable
    kind: Kind
    dim: int  # tangent dimension
    unit: str  # SI unit of the tangent
    display_unit: str  # the unit it is shown in
    to_display: float  # display = tangent * to_display
    prior: Callable[[EstimatorConfig, Mounting], Prior]
    # accuracy target, display unit (None: no target)
    target: Callable[[ObservabilityConfig], float] | None
    vehicle: bool  # a property of the vehicle (calibration carried across dives), else of one dive
    # what each tangent component is, for verdicts: (suffix of its name, words); one ("", "") for a scalar
    components: tuple[tuple[str, str], ...]
    enabled: Callable[[EstimatorConfig], bool] = _always  # whether the configuration estimates it
    offset: int = 0  # where its tangent starts in its key's
    # a variable per state (the random-walk bias)
    per_state: Callable[[EstimatorConfig], bool] = _never
    # in the joint calibration block (NavResult.calib_joint_cov, the direction analysis)
    in_block: bool = False
    ekf: bool = True  # the EKF carries it in its error state
    # the online estimator's iSAM2 relinearises it past these (per tangent component); None: not estimated online
    relinearization: Callable[[RelinearizationThresholds], np.ndarray] | None = None
    # a variable of the DVL factor (factors/dvl.py): "ping" of every one, "motion" of a ping seen through the IMU
    # motion from a keyframe (the IMU biases), "water" of a water-track ping in place of the scale, "" of none
    dvl: Literal["ping", "motion", "water", ""] = ""

    def key_at(self, i: int, config: EstimatorConfig) -> int:
        """Its variable's key at state i (the shared key unless per_state)."""
        return gtsam.symbol(chr(self.key >> 56), i) if self.per_state(config) else self.key

    def display_jacobian(self, value: np.ndarray) -> np.ndarray:
        """d(display)/d(tangent) at a value: to_display I, for a rotation to_display b_R_d (its right tangent
        about body axes)."""
        return self.to_display * (np.asarray(value) if self.kind == "rot3" else np.eye(self.dim))

    def prior_display_sigma(
        self, config: EstimatorConfig, mounting: Mounting | None = None
    ) -> np.ndarray:
        """(dim,) prior sigmas in the display unit, about the display axes (the mounting moves a rotation's prior,
        not its sigmas)."""
        p = self.prior(config, mounting or Mounting())
        return (
            p.sigma * self.to_display
            if p.display_sigma is None
            else np.asarray(p.display_sigma, dtype=float)
        )

    def component_names(self) -> list[str]:
        return [f"{self.name}_{s}" if s else self.name for s, _ in self.components]

    def component_texts(self) -> list[str]:
        return [f"{self.description} {t}" if t else self.description for _, t in self.components]


_BODY_AXES = (
    ("x", "along body x (forward)"),
    ("y", "along body y (left)"),
    ("z", "along body z (up)"),
)


# relinearisation threshold of the DVL time offset (s): it enters the DVL model as dt_d times the body's velocity
# rate (at most 0.2 m/s^2 on paper-3d), linearly given the other variables; a stale linearisation leaves its cross
# terms: with the scale dk dt_d |b_vdot| = 8e-5 m/s, with the attitude (through gravity) g dth dt_d = 1e-4 m/s at
# 20 ms and the thresholds of RelinearizationThresholds, within their budget (2e-4 m/s, 1 % of the DVL noise). A
# smaller threshold makes many more iSAM2 rebases in the first 30 min of a 5 Hz survey, where the offset is
# unobservable (static start) and wanders, for estimates a few hundredths of a sigma apart (docs/results.md,
# "Online estimator")
TIME_OFFSET_THRESHOLD_S = 2e-2


def _bias_prior(sigma: float, si_per_unit: float) -> Prior:
    return Prior(
        np.zeros(3), np.array([sigma * si_per_unit] * 3), display_sigma=np.array([sigma] * 3)
    )


def _misalignment_prior(sigma_deg: np.ndarray, mounting: Mounting) -> Prior:
    """Around the nominal mounting b_R_d0, sigmas about body axes (R_c on the left; b_R_d is perturbed on the
    right)."""
    b_R_d0 = np.asarray(mounting.b_R_d0)
    return Prior(b_R_d0, np.radians(sigma_deg), b_R_d0, display_sigma=sigma_deg)


STATES: tuple[SharedState, ...] = (
    SharedState(
        "gyro_bias",
        "gyro bias",
        B(0),
        "bias",
        3,
        "rad/s",
        "deg/h",
        1.0 / DEG_PER_H,
        prior=lambda c, m: _bias_prior(c.imu.gyro_bias_sigma_deg_per_h, DEG_PER_H),
        target=lambda o: o.gyro_bias_deg_per_h,
        vehicle=False,
        components=(
            ("x", "about body x (forward)"),
            ("y", "about body y (left)"),
            ("z", "about body z (up, vertical)"),
        ),
        offset=3,
        per_state=_random_walk,
        in_block=True,
        relinearization=lambda th: np.asarray(th.bias[3:]),
        dvl="motion",
    ),
    SharedState(
        "accel_bias",
        "accelerometer bias",
        B(0),
        "bias",
        3,
        "m/s^2",
        "micro-g",
        1.0 / UG,
        prior=lambda c, m: _bias_prior(c.imu.accel_bias_sigma_ug, UG),
        target=lambda o: o.accel_bias_ug,
        vehicle=False,
        components=_BODY_AXES,
        per_state=_random_walk,
        in_block=True,
        relinearization=lambda th: np.asarray(th.bias[:3]),
        dvl="motion",
    ),
    SharedState(
        "scale",
        "DVL scale factor",
        K_SCALE,
        "vector",
        1,
        "1",
        "ppm",
        1e6,
        prior=lambda c, m: Prior(
            np.array([c.priors.scale_initial]), np.array([c.priors.scale_sigma])
        ),
        target=lambda o: o.scale_ppm,
        vehicle=True,
        components=(("", ""),),
        in_block=True,
        relinearization=lambda th: np.array([th.scale]),
        dvl="ping",
    ),
    SharedState(
        "misalignment",
        "DVL misalignment",
        C_MISALIGN,
        "rot3",
        3,
        "rad",
        "deg",
        float(np.degrees(1.0)),
        prior=lambda c, m: _misalignment_prior(
            np.asarray(c.priors.misalignment_sigma_deg, dtype=float), m
        ),
        target=lambda o: o.misalignment_deg,
        vehicle=True,
        components=(
            ("roll", "about body x, the thrust axis (roll)"),
            ("pitch", "about body y (pitch)"),
            ("yaw", "about body z (yaw)"),
        ),
        in_block=True,
        relinearization=lambda th: np.full(3, th.misalignment_rad),
        dvl="ping",
    ),
    SharedState(
        "time_offset",
        "DVL-IMU time offset",
        T_OFFSET,
        "vector",
        1,
        "s",
        "ms",
        1e3,
        prior=lambda c, m: Prior(
            np.array([c.dvl.time_offset_prior_s]), np.array([c.dvl.time_offset_sigma_s])
        ),
        target=None,
        vehicle=True,
        components=(("", ""),),
        enabled=lambda c: c.dvl.estimate_time_offset,
        relinearization=lambda th: np.array([TIME_OFFSET_THRESHOLD_S]),
        dvl="ping",
    ),
    SharedState(
        "lever_arm",
        "DVL lever arm",
        L_LEVER,
        "vector",
        3,
        "m",
        "m",
        1.0,
        # around the /tf_static value
        prior=lambda c, m: Prior(
            np.asarray(m.b_l, dtype=float), np.array([c.dvl.lever_arm_sigma_m] * 3)
        ),
        target=None,
        vehicle=True,
        components=_BODY_AXES,
        enabled=lambda c: c.dvl.estimate_lever_arm,
        ekf=False,
        dvl="ping",
    ),
    SharedState(
        "water_scale",
        "DVL water-track scale factor",
        K_WATER,
        "vector",
        1,
        "1",
        "ppm",
        1e6,
        # its information is the link to the scale, k_w - k ~ N(0, (water_track_scale_sigma k_0)^2) (prior_factors);
        # its own prior only keeps it defined (1: the scale's prior would count twice)
        prior=lambda c, m: Prior(np.array([c.priors.scale_initial]), np.array([1.0])),
        target=None,
        vehicle=True,
        components=(("", ""),),
        enabled=lambda c: c.current.water_track_scale and c.current.water_track == "use",
        ekf=False,
        relinearization=lambda th: np.array([th.scale]),
        dvl="water",
    ),
)
BY_NAME: dict[str, SharedState] = {s.name: s for s in STATES}


def required_states() -> list[SharedState]:
    """The states every configuration estimates (every result holds them)."""
    return [s for s in STATES if s.enabled is _always]


def enabled_states(config: EstimatorConfig) -> list[SharedState]:
    """The states the configuration estimates, in registry order."""
    return [s for s in STATES if s.enabled(config)]


def enabled(config: EstimatorConfig, name: str) -> bool:
    """Whether the configuration estimates the state `name`."""
    return BY_NAME[name].enabled(config)


def block_states() -> list[SharedState]:
    """The states of the joint calibration block, in its order (by key, then place in the key's tangent):
    [accel bias, gyro bias, scale, misalignment]."""
    order = _unique(s.key for s in STATES)
    return sorted((s for s in STATES if s.in_block), key=lambda s: (order.index(s.key), s.offset))


def joint_states(config: EstimatorConfig, ekf: bool = False) -> list[SharedState]:
    """The enabled states of the shared joint covariance (NavResult.shared_joint_cov), in its order: by key in
    the order of their first state, then place in the key's tangent: [accel bias, gyro bias, scale,
    misalignment, time offset, lever arm] (those enabled). ekf: only those the EKF carries."""
    order = _unique(s.key for s in STATES)
    chosen = [s for s in enabled_states(config) if s.ekf or not ekf]
    return sorted(chosen, key=lambda s: (order.index(s.key), s.offset))


def joint_slices(config: EstimatorConfig, ekf: bool = False) -> dict[str, slice]:
    """Each state's columns in the shared joint covariance (joint_states' order)."""
    out: dict[str, slice] = {}
    col = 0
    for s in joint_states(config, ekf):
        out[s.name] = slice(col, col + s.dim)
        col += s.dim
    return out


def joint_columns(config: EstimatorConfig, ekf: bool = False) -> list[str]:
    """The name of each column of the shared joint covariance: "accel bias x", ..., "gyro bias z", "scale",
    "misalignment roll" (b_R_d's right tangent), ..., "time offset", "lever arm x", ..."""
    return [
        f"{s.name.replace('_', ' ')} {suffix}".strip()
        for s in joint_states(config, ekf)
        for suffix, _ in s.components
    ]


def _unique(keys: Iterable[int]) -> list[int]:
    out: list[int] = []
    for k in keys:
        if k not in out:
            out.append(k)
    return out


def shared_keys(
    config: EstimatorConfig, i: int = 0, per_state: bool = True, block: bool = False
) -> list[int]:
    """The keys of the enabled states at state i, in registry order (each once; the random-walk bias as B(i)).
    per_state=False: only the variables shared by every state (those an elimination ordering puts last);
    block=True: only the calibration block's (NavResult.calib_joint_cov)."""
    return _unique(
        s.key_at(i, config)
        for s in enabled_states(config)
        if (per_state or not s.per_state(config)) and (s.in_block or not block)
    )


def dvl_factor_keys(
    config: EstimatorConfig,
    i: int,
    motion: bool = False,
    water: bool = False,
    swap_scale: bool = True,
) -> list[int]:
    """The keys of a DVL factor on state i, in the order of its variables (factors/dvl.py DvlOptions.key_names):
    X(i), V(i), then the keys of the enabled states it reads (SharedState.dvl) in registry order: the IMU bias with
    motion (a ping seen through the IMU motion from state i), the scale, the misalignment, the time offset and the
    lever arm when estimated; then the DVL's correlated error E(i) when the configuration models it
    (correlated_error); last, the water current W(i) of a water-track ping (water) when the configuration uses
    them (water_current). A water-track ping reads the water-track scale K_WATER in the scale's place when the
    configuration estimates it (swap_scale; the batch smoother's bulk rows keep both, water_scale_key)."""
    wanted = ("ping", "motion") if motion else ("ping",)
    keys = [X(i), V(i)] + _unique(
        s.key_at(i, config) for s in enabled_states(config) if s.dvl in wanted
    )
    keys += [E(i)] if correlated_error(config) else []
    if not (water and water_current(config)):
        return keys
    if swap_scale and enabled(config, "water_scale"):
        keys[keys.index(K_SCALE)] = K_WATER
    return keys + [W(i)]


def water_scale_key(config: EstimatorConfig) -> int | None:
    """K_WATER when the configuration gives water-track pings their own scale factor, else None."""
    return K_WATER if enabled(config, "water_scale") else None


def water_current(config: EstimatorConfig) -> bool:
    """Whether the estimators use water-track pings and carry the horizontal water current W(i) per state
    ([current] water_track "use": "auto" resolved for a log by estimators/models/current.py resolve_water_track)."""
    return config.current.water_track == "use"


def correlated_error(config: EstimatorConfig) -> bool:
    """Whether the estimators model the DVL's correlated (first-order Gauss-Markov) velocity error: a 3-vector
    E(i) per state in dvl_link ([dvl] correlated_sigma_m_s > 0; estimators/models/correlated.py)."""
    return config.dvl.correlated_sigma_m_s > 0


def columns(keys: Iterable[int], config: EstimatorConfig, start: int = 0) -> dict[str, slice]:
    """Each enabled state's columns in the stacked tangents of keys (e.g. shared_keys(config, i)), from start."""
    key_start: dict[int, int] = {}
    col = start
    for k in keys:
        key_start[gtsam.symbol(chr(k >> 56), 0)] = col
        col += key_dim(k)
    return {
        s.name: slice(key_start[s.key] + s.offset, key_start[s.key] + s.offset + s.dim)
        for s in enabled_states(config)
        if s.key in key_start
    }


def relinearization(
    config: EstimatorConfig, thresholds: RelinearizationThresholds
) -> dict[str, np.ndarray]:
    """iSAM2's relinearisation thresholds of the enabled states' keys, by symbol character (the key's tangent)."""
    out = {}
    for key, group in _by_key(enabled_states(config)):
        parts = [s.relinearization(thresholds) for s in group if s.relinearization is not None]
        if len(parts) == len(group):
            out[chr(key >> 56)] = np.concatenate(parts).astype(float)
    return out


def ekf_layout(config: EstimatorConfig | None, start: int) -> dict[str, slice]:
    """The EKF's error-state columns of the enabled states it carries (registry order), after `start` navigation
    ones; config None: of every state it can carry."""
    out: dict[str, slice] = {}
    for s in STATES if config is None else enabled_states(config):
        if s.ekf:
            out[s.name] = slice(start, start + s.dim)
            start += s.dim
    return out


# ----- the graph: priors, initial values, estimates ---------------------------------------------------------


def _by_key(states: list[SharedState]) -> list[tuple[int, list[SharedState]]]:
    """The states grouped by key (registry order of the keys), each group in the key's tangent order."""
    return [
        (k, sorted((s for s in states if s.key == k), key=lambda s: s.offset))
        for k in _unique(s.key for s in states)
    ]


def _key_priors(
    config: EstimatorConfig, mounting: Mounting, calibration: VehicleCalibration | None = None
) -> list[tuple[int, Kind, np.ndarray, Prior, bool]]:
    """Per key of the enabled states: key, kind, value (the states' values joined) and the joined Prior; the
    states a calibration holds (calibration_states) at its values."""
    held = {s.name for s in calibration_states(config, calibration)}
    out = []
    for key, group in _by_key(enabled_states(config)):
        priors = [s.prior(config, mounting) for s in group]
        if calibration is not None and all(s.name in held for s in group):
            priors = [
                replace(p, value=np.asarray(calibration.values[s.name], dtype=float))
                for s, p in zip(group, priors, strict=True)
            ]
        kind = group[0].kind
        value = priors[0].value if kind == "rot3" else np.concatenate([p.value for p in priors])
        axes = [p.axes for p in priors if p.axes is not None]
        joined = Prior(value, np.concatenate([p.sigma for p in priors]), axes[0] if axes else None)
        out.append((key, kind, value, joined, bool(axes)))
    return out


def prior_factors(
    config: EstimatorConfig, mounting: Mounting, calibration: VehicleCalibration | None = None
) -> list[gtsam.NonlinearFactor]:
    """The priors of the enabled states, one factor per key: diagonal sigmas (isotropic when equal), a full
    covariance where the sigmas are about other axes (the misalignment). calibration: a vehicle's calibration
    (core/calibration.py, already inflated for its age): the states it holds that the configuration estimates
    (calibration_states) take ONE joint prior from it instead (calibration_prior), the others keep theirs."""
    held = {s.key for s in calibration_states(config, calibration)}
    out: list[gtsam.NonlinearFactor] = []
    for key, kind, value, prior, rotated in _key_priors(config, mounting):
        if key in held:
            continue
        noise = (
            gtsam.noiseModel.Gaussian.Covariance(prior.cov)
            if rotated
            else gtsam.noiseModel.Diagonal.Sigmas(prior.sigma)
        )
        if kind == "rot3":
            out.append(gtsam.PriorFactorRot3(key, gtsam.Rot3(value), noise))
        elif kind == "bias":
            out.append(
                gtsam.PriorFactorConstantBias(
                    key, gtsam.imuBias.ConstantBias(value[:3], value[3:]), noise
                )
            )
        else:
            out.append(gtsam.PriorFactorVector(key, value, noise))
    # the water-track scale differs from the bottom track's by a fraction
    if enabled(config, "water_scale"):
        k0 = config.priors.scale_initial
        s = config.current.water_track_scale_sigma * k0
        link = gtsam.JacobianFactor(
            K_WATER,
            np.array([[1.0 / s]]),
            K_SCALE,
            np.array([[-1.0 / s]]),
            np.zeros(1),
            gtsam.noiseModel.Unit.Create(1),
        )
        at = gtsam.Values()
        at.insert(K_WATER, np.array([k0]))
        at.insert(K_SCALE, np.array([k0]))
        out.append(gtsam.LinearContainerFactor(link, at))  # (linear in the two scales: exact)
    joint = calibration_prior(config, calibration)
    return out if joint is None else out + [joint]


def initial_values(
    config: EstimatorConfig, mounting: Mounting, calibration: VehicleCalibration | None = None
) -> gtsam.Values:
    """The enabled states' keys (at the first state) at their priors' values; those a calibration holds
    (calibration_states) at its values."""
    values = gtsam.Values()
    for key, kind, value, _, _ in _key_priors(config, mounting, calibration):
        if kind == "rot3":
            values.insert(key, gtsam.Rot3(value))
        elif kind == "bias":
            values.insert(key, gtsam.imuBias.ConstantBias(value[:3], value[3:]))
        else:
            values.insert(key, np.asarray(value, dtype=float))
    return values


# ----- a vehicle's calibration as the prior ----------------------------------------------------------------


def calibration_states(
    config: EstimatorConfig, calibration: VehicleCalibration | None
) -> list[SharedState]:
    """The states of a vehicle's calibration (core/calibration.py) that the configuration estimates, one variable
    per log (not the random-walk bias), in the calibration's order: those that take its joint prior. A key only
    partly held (e.g. the bias key's accelerometer half without its gyro half) is a one-line GtsamDvlError."""
    if calibration is None:
        return []
    out = [
        BY_NAME[n]
        for n in calibration.states
        if n in BY_NAME and BY_NAME[n].enabled(config) and not BY_NAME[n].per_state(config)
    ]
    names = {s.name for s in out}
    for s in enabled_states(config):
        if s.name not in names and any(o.key == s.key for o in out):
            raise GtsamDvlError(
                f"calibration of {calibration.vehicle!r}: it holds part of the {s.description}'s "
                f"variable but not the {s.description}; give both or neither"
            )
    return out


def calibration_prior(
    config: EstimatorConfig, calibration: VehicleCalibration | None
) -> gtsam.NonlinearFactor | None:
    """ONE Gaussian prior over the keys of calibration_states, with the calibration's joint covariance (the block
    of those states; a marginal of a Gaussian is its block) and its mean at the calibration's values; None when
    it holds none of the estimated states.

    Its error is e = S [Local(x0_k, x_k)]_k, the stacked local coordinates of each key at the file's value x0_k
    (a vector's difference; for the misalignment Log(b_R_d0^T b_R_d), b_R_d's right perturbation, as the file's
    covariance; the bias [accel, gyro]) reordered by S into the calibration's order, whitened by its covariance:
    0.5 e^T Sigma^-1 e is the exact Gaussian on the manifold around the file's values (its Jacobian the inverse
    right Jacobian of SO(3) for the rotation). A CustomFactor: GTSAM's Python JacobianFactor takes at most three
    keys, the calibration may hold four (scale, misalignment, time offset, lever arm)."""
    states = calibration_states(config, calibration)
    if calibration is None or not states:
        return None
    keys = _unique(s.key for s in states)
    kinds = {s.key: s.kind for s in states}
    start = dict(zip(keys, np.cumsum([0] + [key_dim(k) for k in keys]).tolist(), strict=False))
    cols = np.concatenate([start[s.key] + s.offset + np.arange(s.dim) for s in states])
    # row r (the calibration's order) reads column cols[r] of the keys'
    S = np.zeros((len(cols), len(cols)))
    S[np.arange(len(cols)), cols] = 1.0
    x0 = {k: _key_value(states, k, calibration.values) for k in keys}
    noise = gtsam.noiseModel.Gaussian.Covariance(calibration.block([s.name for s in states]))

    def error(
        this: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None
    ) -> np.ndarray:
        parts, jacs = [], []
        for k in keys:
            d, J = _local(kinds[k], x0[k], values, k)
            parts.append(d)
            jacs.append(J)
        if H is not None:
            for i, k in enumerate(keys):
                H[i] = S[:, start[k] : start[k] + key_dim(k)] @ jacs[i]
        return np.asarray(S @ np.concatenate(parts))

    return gtsam.CustomFactor(noise, keys, error)


def calibration_info(config: EstimatorConfig, calibration: VehicleCalibration) -> dict[str, Any]:
    """The prior a run took from a calibration (NavResult.info["calibration_prior"], plain JSON): its vehicle, date,
    method and sources, the states that took it (calibration_states), their values (SI; the misalignment as b_R_d)
    and their joint covariance, for the verdict on the new estimate (analysis/calibration_check.py)."""
    names = [s.name for s in calibration_states(config, calibration)]
    return {
        "vehicle": calibration.vehicle,
        "date": calibration.date,
        "method": calibration.method,
        "config_hash": calibration.config_hash,
        "sources": [{"path": s.path, "sha256": s.sha256} for s in calibration.sources],
        "states": names,
        "values": {n: np.asarray(calibration.values[n], dtype=float).tolist() for n in names},
        "cov": calibration.block(names).tolist(),
    }


def calibration_in_layout(
    config: EstimatorConfig, calibration: VehicleCalibration | None, layout: dict[str, slice]
) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """A filter's start from a calibration (the EKF's error state, ekf_layout): the values of the states it holds
    that the layout carries (calibration_states), their columns in the layout and their joint covariance (empty
    without a calibration)."""
    held = [s.name for s in calibration_states(config, calibration) if s.name in layout]
    if calibration is None or not held:
        return {}, np.zeros(0, dtype=int), np.zeros((0, 0))
    idx = np.concatenate([np.arange(layout[n].start, layout[n].stop) for n in held])
    return (
        {n: np.asarray(calibration.values[n], dtype=float) for n in held},
        idx,
        calibration.block(held),
    )


def _key_value(states: list[SharedState], key: int, mean: dict[str, np.ndarray]) -> np.ndarray:
    """A key's value (a vector; a rotation's 3x3 matrix) from its states' values."""
    group = sorted((s for s in states if s.key == key), key=lambda s: s.offset)
    if group[0].kind == "rot3":
        return np.asarray(mean[group[0].name], dtype=float)
    return np.concatenate([np.asarray(mean[s.name], dtype=float).ravel() for s in group])


def _local(
    kind: Kind, x0: np.ndarray, values: gtsam.Values, key: int
) -> tuple[np.ndarray, np.ndarray]:
    """The local coordinates of a key's value at x0 and their Jacobian in the value's own tangent."""
    if kind == "rot3":
        d = gtsam.Rot3.Logmap(gtsam.Rot3(x0).between(values.atRot3(key)))
        return np.asarray(d, dtype=float), np.asarray(gtsam.Rot3.LogmapDerivative(d))
    return _read(values, key, kind) - x0, np.eye(len(x0))


def _read(values: gtsam.Values, key: int, kind: Kind) -> np.ndarray:
    if kind == "rot3":
        return np.asarray(values.atRot3(key).matrix())
    if kind == "bias":
        return np.asarray(values.atConstantBias(key).vector(), dtype=float)
    return np.asarray(values.atVector(key), dtype=float)


def read_values(values: gtsam.Values, config: EstimatorConfig, i: int = 0) -> dict[str, np.ndarray]:
    """The enabled states' values at state i (as Prior.value)."""
    out: dict[str, np.ndarray] = {}
    for s in enabled_states(config):
        value = _read(values, s.key_at(i, config), s.kind)
        out[s.name] = value if s.kind == "rot3" else value[s.offset : s.offset + s.dim]
    return out


def read_estimates(
    values: gtsam.Values, covariances: dict[int, np.ndarray], config: EstimatorConfig, i: int = 0
) -> dict[str, Estimate]:
    """The enabled states' estimates at state i from the values and each key's marginal covariance."""
    out: dict[str, Estimate] = {}
    for name, value in read_values(values, config, i).items():
        s = BY_NAME[name]
        part = slice(s.offset, s.offset + s.dim)
        out[name] = Estimate(value, np.asarray(covariances[s.key_at(i, config)])[part, part])
    return out
