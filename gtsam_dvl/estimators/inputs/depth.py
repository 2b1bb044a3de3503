"""Depth samples for the factor graph: conversion to the map's vertical axis and association with states.

A depth sample (LogData.depth) is the pressure sensor's depth d below the water surface, which is taken at
ellipsoidal height 0: the sensor is at height -d, i.e. z_meas = -d - h0 above the map origin's height h0.
A pressure sample is converted here with the [depth] section (water density, atmospheric pressure) and the
mean normal gravity of the water column at the origin's latitude (core/earth.py pressure_to_depth); its
variance is carried through dd/dp. The noise is [depth] noise_m if > 0, else the message's, else
default_noise_m, times [depth] noise_multiplier (the variance component the batch smoother fits: [noise] fit_depth).

Each sample goes to the state nearest in time (estimators/graph/log_graph.py); the time between them, at most
[depth] max_time_to_state_s, is bridged by the state's vertical velocity in the factor (factors/depth.py).
Farther samples are not used ("depth_too_far" in the counters), nor are non-finite ones ("depth_invalid").
Every estimator takes depth: the batch smoother and the online estimator as factors, the EKF as updates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import DepthConfig
from gtsam_dvl.core.earth import LocalFrame, pressure_to_depth
from gtsam_dvl.core.types import DepthData


@dataclass(frozen=True)
class DepthSamples:
    """Depth samples ready for factors: stamps, measured heights above the origin's height (m, up) and sigmas."""

    t: np.ndarray
    z_meas: np.ndarray
    sigma: np.ndarray
    b_p_sensor: np.ndarray  # (3,) the sensor in base_link, m


def depth_samples(
    depth: DepthData, cfg: DepthConfig, frame: LocalFrame, counters: dict[str, int] | None = None
) -> DepthSamples:
    """The usable samples of a log's depth data as heights in map (module doc)."""
    if depth.pressure_pa is not None:
        d, dd_dp = pressure_to_depth(
            depth.pressure_pa, frame.lat0, cfg.water_density_kg_m3, cfg.atmospheric_pa
        )
        pvar = (
            np.full(len(depth), np.nan)
            if depth.pressure_variance_pa2 is None
            else np.asarray(depth.pressure_variance_pa2, dtype=float)
        )
        var = pvar * dd_dp**2
    else:
        d, var = np.asarray(depth.depth_m, dtype=float), np.asarray(depth.variance_m2, dtype=float)
    if cfg.noise_m > 0:
        sigma = np.full(len(d), cfg.noise_m)
    else:
        ok_var = np.isfinite(var) & (var > 0)
        sigma = np.where(ok_var, np.sqrt(np.where(ok_var, var, 1.0)), cfg.default_noise_m)
    # the fitted (or pinned) variance component ([noise] fit_depth)
    sigma = sigma * cfg.noise_multiplier
    ok = np.isfinite(d) & np.isfinite(depth.t)
    if counters is not None:
        counters["depth_invalid"] = int((~ok).sum())
    if cfg.lever_arm_m is not None:
        lever = np.asarray(cfg.lever_arm_m, dtype=float)
    elif depth.b_p_sensor is not None:
        lever = np.asarray(depth.b_p_sensor, dtype=float)
    else:
        lever = np.zeros(3)
    return DepthSamples(
        np.asarray(depth.t, dtype=float)[ok], -d[ok] - frame.height_m, sigma[ok], lever
    )


def nearest_states(
    t_states: np.ndarray, t_samples: np.ndarray, max_dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """For each sample, the index of the nearest state (-1 if farther than max_dt) and sample - state time."""
    t_states = np.asarray(t_states, dtype=float)
    if not len(t_states):
        return np.full(len(t_samples), -1), np.zeros(len(t_samples))
    j = np.clip(np.searchsorted(t_states, t_samples), 1, max(len(t_states) - 1, 1))
    lo = np.maximum(j - 1, 0)
    hi = np.minimum(j, len(t_states) - 1)
    near = np.where(np.abs(t_samples - t_states[lo]) <= np.abs(t_states[hi] - t_samples), lo, hi)
    dt = t_samples - t_states[near]
    return np.where(np.abs(dt) <= max_dt + 1e-9, near, -1), dt
