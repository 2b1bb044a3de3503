"""The water current: a state of every epoch W(i) (core/keys.py) when water-track pings are used ([current],
core/config/current.py).

A water-track ping measures the vehicle's velocity relative to a water layer: the DVL model (factors/dvl_model.py)
at n_v - [c_east, c_north, 0] instead of n_v, with the same scale, misalignment and lever arm (factors/dvl.py
current_variable). The current W = [c_east, c_north] (m/s, map) is horizontal and moves as a random walk in time
and depth between states i and j = i + 1, dt s and dz m apart:

    W_j = W_i + w,   w ~ N(0, (q_t^2 dt + q_z^2 |dz|) I2),     W_0 ~ N(0, sigma_0^2 I2)

q_t = time_rw_m_s_per_sqrt_s, q_z = depth_rw_m_s_per_sqrt_m, sigma_0 = prior_sigma_m_s. dz is taken from the
initial guess of the trajectory (the depth sensor's or the DVL's vertical velocity integrated): the process noise
is fixed when the graph is built. The water-track pings of state i and those between it and the next state read
W(i). The links are linear in W, so they are GTSAM linear factors (LinearContainerFactor of a JacobianFactor
linearised at zero: exact), evaluated in C++ in the batch smoother and iSAM2 alike.

Layers ([current] layer_thickness_m = h > 0). The water column is cut into layers of thickness h from the surface
down (layer j: depths [j h, (j + 1) h), depth = -(z + h0) with h0 the map origin's height, as the depth sensor's,
estimators/inputs/depth.py), and the current is

    c(t, depth) = c_0 + sum of S(b) over the boundaries b between the first state's layer and depth's + D(t)

with S(b) ~ N(0, q_z^2 h I2) the change across boundary b (core/keys.py S: deeper minus shallower), independent,
and D a random walk in time shared by every layer (D(0) = 0). W(i) is still the current at state i, read by the
water-track pings; between states i and j = i + 1 whose layers differ, the link becomes

    W_j - W_i - sum_b s_b S(b) ~ N(0, q_t^2 dt I2)         (s_b = +1 crossing b downwards, -1 upwards)

and within one layer it is the random walk in time alone. A layer met on the descent and again on the ascent is
then one unknown: the pings of both passes inform it, where the random walk in depth (h = 0) would have let the
current of the ascent wander q_z sqrt(2 * 300 m) from the descent's. Only the boundaries
crossed get a variable; they sit with the shared states at the end of the elimination orderings. A link crossing
one boundary is a GTSAM linear factor on three keys; one crossing more (states farther apart than a layer is thick)
is a CustomFactor of the same residual (GTSAM's Python JacobianFactor takes three keys at most).

The current is determined only where something ties the vehicle's velocity over ground: bottom track, GNSS at the
surface, or the IMU carrying it from either; a water-track stretch far from both leaves W and the vehicle's
velocity free together (the verdict, `profile`, says where the current's sigma stays near its prior's).

Its entry in the per-epoch registry (estimators/models/epoch_states.py WaterCurrent) declares it to the estimators
with these functions (the boundaries S(b) as its extra keys); the profile is the result's typed water_current.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import S, W
from gtsam_dvl.core.result import WaterCurrentProfile
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.selection import within_layer_variance

if TYPE_CHECKING:
    from gtsam_dvl.estimators.ekf.strapdown import FilterState

_EYE2 = np.eye(2)


def resolve_water_track(config: EstimatorConfig, log: LogData) -> EstimatorConfig:
    """The configuration with [current] water_track "auto" resolved for a log: "use" when it has water-track pings,
    "refuse" otherwise (the result's configuration says which)."""
    if config.current.water_track != "auto":
        return config
    water = log.dvl.water_track
    use = water is not None and bool(
        np.any(np.asarray(water, dtype=bool) & np.isfinite(log.dvl.d_v).all(axis=1))
    )
    current = config.current.model_copy(update={"water_track": "use" if use else "refuse"})
    return config.model_copy(update={"current": current})


def water_pings(log: LogData) -> np.ndarray:
    """(M,) bool: the log's water-track pings."""
    water = log.dvl.water_track
    return np.zeros(len(log.dvl), dtype=bool) if water is None else np.asarray(water, dtype=bool)


def epochs_with_water(builder: Any) -> np.ndarray:
    """(N,) bool: the states of a LogGraph (estimators/graph/log_graph.py) whose own ping or a ping between it and the
    next
    is a water-track ping."""
    water = builder.water
    return np.array(
        [
            (ep.dvl_index >= 0 and bool(water[ep.dvl_index]))
            or any(bool(water[p.dvl_index]) for p in ep.between)
            for ep in builder.epochs
        ],
        dtype=bool,
    )


def step_variance(config: EstimatorConfig, dt: float, dz: float) -> float:
    """The variance per axis (m^2/s^2) of the current's change over dt s and dz m (module doc)."""
    c = config.current
    return c.time_rw_m_s_per_sqrt_s**2 * max(dt, 0.0) + c.depth_rw_m_s_per_sqrt_m**2 * abs(dz)


def _zeros(*keys: int) -> gtsam.Values:
    values = gtsam.Values()
    for k in keys:
        values.insert(k, np.zeros(2))
    return values


def link_factor(
    config: EstimatorConfig, i: int, j: int, dt: float, dz: float
) -> gtsam.NonlinearFactor:
    """W_j - W_i ~ N(0, q I2) between states i and j (module doc)."""
    # a floor: two states at one stamp and depth (dt = dz = 0) would make an infinitely stiff link
    q = max(step_variance(config, dt, dz), (1e-6 * config.current.prior_sigma_m_s) ** 2)
    s = float(np.sqrt(q))
    jf = gtsam.JacobianFactor(
        W(i), -_EYE2 / s, W(j), _EYE2 / s, np.zeros(2), gtsam.noiseModel.Unit.Create(2)
    )
    return gtsam.LinearContainerFactor(jf, _zeros(W(i), W(j)))


def prior_factor(config: EstimatorConfig, i: int = 0) -> gtsam.NonlinearFactor:
    """W_i ~ N(0, sigma_0^2 I2) at the first state."""
    return gtsam.PriorFactorVector(
        W(i), np.zeros(2), gtsam.noiseModel.Isotropic.Sigma(2, config.current.prior_sigma_m_s)
    )


def layered(config: EstimatorConfig) -> bool:
    """Whether the current is modelled per depth layer ([current] layer_thickness_m > 0, module doc)."""
    return config.current.layer_thickness_m > 0.0


def layer_index(config: EstimatorConfig, z: np.ndarray | float, height0: float = 0.0) -> np.ndarray:
    """The depth layer (0 at the surface) of heights z (m above the map origin, whose height is height0 m):
    floor(depth / h), depths above the surface in layer 0 (module doc, "Layers")."""
    depth = np.maximum(-(np.asarray(z, dtype=float) + height0), 0.0)
    return np.floor(depth / config.current.layer_thickness_m).astype(int)


def crossings(j_from: int, j_to: int) -> list[tuple[int, float]]:
    """The boundaries (b, sign) crossed going from layer j_from to j_to: +1 downwards, -1 upwards."""
    if j_to >= j_from:
        return [(b, 1.0) for b in range(j_from, j_to)]
    return [(b, -1.0) for b in range(j_from - 1, j_to - 1, -1)]


def boundaries(config: EstimatorConfig, z_states: np.ndarray, height0: float = 0.0) -> list[int]:
    """The boundaries the states at heights z_states cross, sorted (none without layers)."""
    if not layered(config) or len(z_states) == 0:
        return []
    j = layer_index(config, z_states, height0)
    return list(range(int(j.min()), int(j.max())))


def shear_prior(config: EstimatorConfig, b: int) -> gtsam.NonlinearFactor:
    """S(b) ~ N(0, q_z^2 h I2): the change of the current across one layer boundary (module doc)."""
    c = config.current
    return gtsam.PriorFactorVector(
        S(b),
        np.zeros(2),
        gtsam.noiseModel.Isotropic.Sigma(
            2, c.depth_rw_m_s_per_sqrt_m * float(np.sqrt(c.layer_thickness_m))
        ),
    )


def _linear_custom(keys: list[int], signs: list[float], s: float) -> gtsam.NonlinearFactor:
    """sum_k signs_k x_k ~ N(0, s^2 I2) over 2-vectors, any number of keys (a CustomFactor: module doc)."""
    blocks = [sign / s * _EYE2 for sign in signs]

    def error(
        _: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None
    ) -> np.ndarray:
        if H is not None:
            for k, block in enumerate(blocks):
                H[k] = block.copy()
        return sum(
            (block @ values.atVector(k) for k, block in zip(keys, blocks, strict=True)), np.zeros(2)
        )

    return gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(2), keys, error)


def crossing_link(
    config: EstimatorConfig, i: int, j: int, dt: float, j_from: int, j_to: int
) -> gtsam.NonlinearFactor:
    """W_j - W_i - sum_b s_b S(b) ~ N(0, q_t^2 dt I2) between states i and j in layers j_from and j_to (module
    doc, "Layers"); the random walk in time alone within one layer."""
    cross = crossings(j_from, j_to)
    if len(cross) == 0:
        return link_factor(config, i, j, dt, 0.0)
    s = float(
        np.sqrt(max(step_variance(config, dt, 0.0), (1e-6 * config.current.prior_sigma_m_s) ** 2))
    )
    if len(cross) == 1:
        ((b, sign),) = cross
        jf = gtsam.JacobianFactor(
            W(i),
            -_EYE2 / s,
            W(j),
            _EYE2 / s,
            S(b),
            -sign * _EYE2 / s,
            np.zeros(2),
            gtsam.noiseModel.Unit.Create(2),
        )
        return gtsam.LinearContainerFactor(jf, _zeros(W(i), W(j), S(b)))
    return _linear_custom(
        [W(i), W(j)] + [S(b) for b, _ in cross], [-1.0, 1.0] + [-sign for _, sign in cross], s
    )


def factors(
    config: EstimatorConfig, t_states: np.ndarray, z_states: np.ndarray, height0: float = 0.0
) -> list[gtsam.NonlinearFactor]:
    """The prior on W(0) and the links of the states at stamps t_states (s) and heights z_states (m, map up; the
    map origin at height0 m); with layers, the priors of the boundaries crossed (module doc)."""
    dt = np.diff(np.asarray(t_states, dtype=float))
    z = np.asarray(z_states, dtype=float)
    if not layered(config):
        return [prior_factor(config)] + [
            link_factor(config, i, i + 1, float(a), float(b))
            for i, (a, b) in enumerate(zip(dt, np.diff(z), strict=True))
        ]
    j = layer_index(config, z, height0)
    return (
        [prior_factor(config)]
        + [shear_prior(config, b) for b in boundaries(config, z, height0)]
        + [
            crossing_link(config, i, i + 1, float(dt[i]), int(j[i]), int(j[i + 1]))
            for i in range(len(dt))
        ]
    )


def ekf_start(config: EstimatorConfig, fs: FilterState, height0: float) -> None:
    """With layers, the EKF's state starts in the layer of its nominal height and without boundaries."""
    if layered(config) and fs.current is not None:
        fs.shear, fs.shear_ids = np.zeros((0, 2)), []
        fs.layer = int(layer_index(config, float(fs.nav.n_p[2]), height0))


def ekf_propagate(config: EstimatorConfig, fs: FilterState, dt: float, height0: float) -> None:
    """The EKF's current over a step of dt s (the nominal state already propagated): its random walk added to its
    covariance, in time and depth (dz from the vertical velocity), or with layers in time alone and then carried
    across the boundaries between the previous layer and the nominal height's: a boundary met for the first time
    enters the state with its prior (independent of everything), and each crossing is the exact linear map
    W <- W + s S(b) of the state and its covariance (module doc, "Layers")."""
    wc = fs.current_slice()
    if wc is None or fs.current is None:
        return
    dz = 0.0 if layered(config) else float(fs.nav.n_v[2]) * dt
    fs.P[wc, wc] += step_variance(config, dt, dz) * _EYE2
    if not layered(config) or fs.shear is None:
        return
    j = int(layer_index(config, float(fs.nav.n_p[2]), height0))
    for b, sign in crossings(fs.layer, j):
        if b not in fs.shear_ids:
            at = len(fs.P) - fs.epoch_dims()  # the end of the boundaries' block
            P = np.insert(np.insert(fs.P, [at, at], 0.0, axis=0), [at, at], 0.0, axis=1)
            c = config.current
            P[at : at + 2, at : at + 2] = c.depth_rw_m_s_per_sqrt_m**2 * c.layer_thickness_m * _EYE2
            fs.P, fs.shear, fs.shear_ids = (
                P,
                np.vstack([fs.shear, np.zeros((1, 2))]),
                [*fs.shear_ids, b],
            )
        sh, wc = fs.shear_slice(), fs.current_slice()
        assert sh is not None and wc is not None
        r = fs.shear_ids.index(b)
        cols = slice(sh.start + 2 * r, sh.start + 2 * r + 2)
        # T P T^T with T = I + sign E(wc, cols): rows, then columns
        fs.P[wc, :] += sign * fs.P[cols, :]
        fs.P[:, wc] += sign * fs.P[:, cols]
        fs.epoch["water_current"] = fs.current + sign * fs.shear[r]
    fs.layer = j


def seen_velocity(fs: FilterState, water: bool) -> np.ndarray:
    """The velocity (m/s, map) an EKF's ping sees: over ground, or for a water-track ping relative to the water,
    n_v - [c_east, c_north, 0]."""
    if not water:
        return fs.nav.n_v
    assert fs.current is not None
    return fs.nav.n_v - np.array([*fs.current, 0.0])


def ekf_shear(fs: FilterState) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """The EKF's layer boundaries: b -> (S(b), its covariance) (profile)."""
    sh = fs.shear_slice()
    if sh is None or fs.shear is None:
        return {}
    return {
        b: (
            fs.shear[r],
            fs.P[sh.start + 2 * r : sh.start + 2 * r + 2, sh.start + 2 * r : sh.start + 2 * r + 2],
        )
        for r, b in enumerate(fs.shear_ids)
    }


def profile(
    t: np.ndarray,
    z: np.ndarray,
    n_c: np.ndarray,
    cov: np.ndarray,
    config: EstimatorConfig,
    water: np.ndarray | None = None,
    shear: dict[int, tuple[np.ndarray, np.ndarray]] | None = None,
) -> WaterCurrentProfile:
    """NavResult.water_current: the current per state (t s, depth m = -z, east and north m/s, their sigmas) and the
    verdict: determined where its sigma is below half the prior's (something tied the velocity over ground), with
    the stretches that are not. water (N,) bool: the states with water-track pings. shear: with layers, each
    boundary crossed, b -> (S(b), its covariance): the change of the current across it (deeper minus
    shallower)."""
    # (with layers, the current at a state's depth: its layer's and the spread within the layer, selection.py)
    sig = np.sqrt(
        np.maximum(np.einsum("nii->ni", np.asarray(cov)), 0.0) + within_layer_variance(config)
    )
    prior = config.current.prior_sigma_m_s
    determined = sig.max(axis=1) < 0.5 * prior
    speed = np.hypot(n_c[:, 0], n_c[:, 1])
    out = WaterCurrentProfile(
        t_s=np.asarray(t, dtype=float),
        depth_m=-np.asarray(z, dtype=float),
        east_m_s=n_c[:, 0],
        north_m_s=n_c[:, 1],
        east_sigma_m_s=sig[:, 0],
        north_sigma_m_s=sig[:, 1],
        determined=determined,
        prior_sigma_m_s=prior,
        time_rw_m_s_per_sqrt_s=config.current.time_rw_m_s_per_sqrt_s,
        depth_rw_m_s_per_sqrt_m=config.current.depth_rw_m_s_per_sqrt_m,
        water_track_sigma_m_s=config.current.water_track_sigma_m_s or "from the messages",
        max_speed_m_s=float(speed.max()) if len(speed) else 0.0,
        verdict=verdict(determined, water),
    )
    if water is not None:
        w = np.asarray(water, dtype=bool)
        out.water_track_states = int(w.sum())
        out.determined_during_water_track = bool(determined[w].all()) if w.any() else True
    if layered(config):
        out.layer_thickness_m = config.current.layer_thickness_m
        out.layer_boundaries = sorted(shear or {})
        out.layer_shear = [
            layer_shear(b, shear[b], out.layer_thickness_m) for b in out.layer_boundaries if shear
        ]
    return out


def layer_shear(b: int, s: tuple[np.ndarray, np.ndarray], h: float) -> dict[str, Any]:
    """The change of the current across boundary b (at depth (b + 1) h m) from S(b) and its covariance."""
    return {
        "boundary": b,
        "depth_m": (b + 1) * h,
        "east_m_s": float(s[0][0]),
        "north_m_s": float(s[0][1]),
        "east_sigma_m_s": float(np.sqrt(max(s[1][0, 0], 0.0))),
        "north_sigma_m_s": float(np.sqrt(max(s[1][1, 1], 0.0))),
    }


def verdict(determined: np.ndarray, water: np.ndarray | None) -> str:
    """One sentence: whether the current was determined where the water-track pings needed it."""
    w = np.ones_like(determined) if water is None else np.asarray(water, dtype=bool)
    if not w.any():
        return "no water-track pings: the current was not needed"
    frac = float(determined[w].mean())
    if frac == 1.0:
        return "determined over every water-track stretch (bottom track or GNSS tied the velocity over ground)"
    return (
        f"determined over {100 * frac:.0f} % of the water-track states; elsewhere the current and the "
        "vehicle's velocity are not separable (no bottom track or GNSS near enough): the position there "
        "leans on the IMU alone"
    )
