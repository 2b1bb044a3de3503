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

The current is determined only where something ties the vehicle's velocity over ground: bottom track, GNSS at the
surface, or the IMU carrying it from either; a water-track stretch far from both leaves W and the vehicle's
velocity free together (the verdict, `info`, says where the current's sigma stays near its prior's).
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import W
from gtsam_dvl.core.types import LogData

_EYE2 = np.eye(2)


def resolve_water_track(config: EstimatorConfig, log: LogData) -> EstimatorConfig:
    """The configuration with [current] water_track "auto" resolved for a log: "use" when it has water-track pings,
    "refuse" otherwise (the result's configuration says which)."""
    if config.current.water_track != "auto":
        return config
    water = log.dvl.water_track
    use = water is not None and bool(np.any(np.asarray(water, dtype=bool) & np.isfinite(log.dvl.d_v).all(axis=1)))
    current = config.current.model_copy(update={"water_track": "use" if use else "refuse"})
    return config.model_copy(update={"current": current})


def water_pings(log: LogData) -> np.ndarray:
    """(M,) bool: the log's water-track pings."""
    water = log.dvl.water_track
    return np.zeros(len(log.dvl), dtype=bool) if water is None else np.asarray(water, dtype=bool)


def epochs_with_water(builder: Any) -> np.ndarray:
    """(N,) bool: the states of a LogGraph (estimators/graph.py) whose own ping or a ping between it and the next
    is a water-track ping."""
    water = builder.water
    return np.array([(ep.dvl_index >= 0 and bool(water[ep.dvl_index])) or any(bool(water[p.dvl_index])
                                                                               for p in ep.between)
                     for ep in builder.epochs], dtype=bool)


def step_variance(config: EstimatorConfig, dt: float, dz: float) -> float:
    """The variance per axis (m^2/s^2) of the current's change over dt s and dz m (module doc)."""
    c = config.current
    return c.time_rw_m_s_per_sqrt_s**2 * max(dt, 0.0) + c.depth_rw_m_s_per_sqrt_m**2 * abs(dz)


def _zeros(*keys: int) -> gtsam.Values:
    values = gtsam.Values()
    for k in keys:
        values.insert(k, np.zeros(2))
    return values


def link_factor(config: EstimatorConfig, i: int, j: int, dt: float, dz: float) -> gtsam.NonlinearFactor:
    """W_j - W_i ~ N(0, q I2) between states i and j (module doc)."""
    # a floor: two states at one stamp and depth (dt = dz = 0) would make an infinitely stiff link
    q = max(step_variance(config, dt, dz), (1e-6 * config.current.prior_sigma_m_s)**2)
    s = float(np.sqrt(q))
    jf = gtsam.JacobianFactor(W(i), -_EYE2 / s, W(j), _EYE2 / s, np.zeros(2), gtsam.noiseModel.Unit.Create(2))
    return gtsam.LinearContainerFactor(jf, _zeros(W(i), W(j)))


def prior_factor(config: EstimatorConfig, i: int = 0) -> gtsam.NonlinearFactor:
    """W_i ~ N(0, sigma_0^2 I2) at the first state."""
    return gtsam.PriorFactorVector(W(i), np.zeros(2), gtsam.noiseModel.Isotropic.Sigma(
        2, config.current.prior_sigma_m_s))


def factors(config: EstimatorConfig, t_states: np.ndarray, z_states: np.ndarray) -> list[gtsam.NonlinearFactor]:
    """The prior on W(0) and the links of the states at stamps t_states (s) and heights z_states (m, map up)."""
    dt = np.diff(np.asarray(t_states, dtype=float))
    dz = np.diff(np.asarray(z_states, dtype=float))
    return [prior_factor(config)] + [link_factor(config, i, i + 1, float(a), float(b))
                                     for i, (a, b) in enumerate(zip(dt, dz, strict=True))]


def initial_values(values: gtsam.Values, n_states: int) -> None:
    """W(i) = 0 for states 0..n_states-1 (the prior's mean), into values."""
    for i in range(n_states):
        values.insert(W(i), np.zeros(2))


def ekf_propagate(config: EstimatorConfig, P: np.ndarray, cols: slice, dt: float, dz: float) -> np.ndarray:
    """The EKF's covariance with the current's random walk over dt s and dz m added to its block (module doc)."""
    out = P.copy()
    out[cols, cols] += step_variance(config, dt, dz) * _EYE2
    return out


def profile(t: np.ndarray, z: np.ndarray, n_c: np.ndarray, cov: np.ndarray, config: EstimatorConfig,
            water: np.ndarray | None = None) -> dict[str, Any]:
    """NavResult.info["water_current"]: the current per state (t s, depth m = -z, east and north m/s, their
    sigmas) and the verdict: determined where its sigma is below half the prior's (something tied the velocity
    over ground), with the stretches that are not. water (N,) bool: the states with water-track pings."""
    sig = np.sqrt(np.maximum(np.einsum("nii->ni", np.asarray(cov)), 0.0))
    prior = config.current.prior_sigma_m_s
    determined = sig.max(axis=1) < 0.5 * prior
    speed = np.hypot(n_c[:, 0], n_c[:, 1])
    out: dict[str, Any] = {
        "t_s": np.asarray(t, dtype=float).tolist(), "depth_m": (-np.asarray(z, dtype=float)).tolist(),
        "east_m_s": n_c[:, 0].tolist(), "north_m_s": n_c[:, 1].tolist(),
        "east_sigma_m_s": sig[:, 0].tolist(), "north_sigma_m_s": sig[:, 1].tolist(),
        "determined": determined.tolist(),
        "prior_sigma_m_s": prior, "time_rw_m_s_per_sqrt_s": config.current.time_rw_m_s_per_sqrt_s,
        "depth_rw_m_s_per_sqrt_m": config.current.depth_rw_m_s_per_sqrt_m,
        "water_track_sigma_m_s": config.current.water_track_sigma_m_s or "from the messages",
    }
    if water is not None:
        w = np.asarray(water, dtype=bool)
        out["water_track_states"] = int(w.sum())
        out["determined_during_water_track"] = bool(determined[w].all()) if w.any() else True
    out["max_speed_m_s"] = float(speed.max()) if len(speed) else 0.0
    out["verdict"] = verdict(determined, water)
    return out


def verdict(determined: np.ndarray, water: np.ndarray | None) -> str:
    """One sentence: whether the current was determined where the water-track pings needed it."""
    w = np.ones_like(determined) if water is None else np.asarray(water, dtype=bool)
    if not w.any():
        return "no water-track pings: the current was not needed"
    frac = float(determined[w].mean())
    if frac == 1.0:
        return "determined over every water-track stretch (bottom track or GNSS tied the velocity over ground)"
    return (f"determined over {100 * frac:.0f} % of the water-track states; elsewhere the current and the "
            "vehicle's velocity are not separable (no bottom track or GNSS near enough): the position there "
            "leans on the IMU alone")
