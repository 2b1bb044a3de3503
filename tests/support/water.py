"""Water-track pings made from a simulated log's bottom-track pings and a known current, shared by the water-current
tests (tests/estimators/test_water_current.py, test_water_layers.py, tests/app/test_water_outputs.py)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.core.types import LogData

N_C = np.array([0.3, -0.2, 0.0])  # m/s, east, north (map)
T_WATER = (60.0, 160.0)  # s: the water-track stretch


def with_water_track(
    log: LogData,
    t_water: tuple[float, float] = T_WATER,
    n_c_at: Callable[[int], np.ndarray] = lambda _: N_C,
) -> LogData:
    """The log with its pings in t_water turned into water-track pings: y - k d_R_b n_R_b^T n_c (an independent
    evaluation of the model's change, at the truth's attitude and calibration); n_c_at(k): the current (3,) m/s
    in map at the truth's sample k (the constant N_C by default)."""
    dvl, truth = log.dvl, log.truth
    assert truth is not None and log.true_calibration is not None
    k = log.true_calibration.scale
    b_R_d = log.true_calibration.b_R_d(log.mounting.b_R_d0)
    water = (dvl.t > t_water[0]) & (dvl.t < t_water[1])
    idx = np.searchsorted(truth.t, dvl.t).clip(0, len(truth.t) - 1)
    assert np.abs(truth.t[idx[water]] - dvl.t[water]).max() < 1e-9  # truth at the ping stamps
    d_v = dvl.d_v.copy()
    for j in np.flatnonzero(water):
        d_v[j] = d_v[j] - k * b_R_d.T @ quat_xyzw_to_matrix(truth.n_q_b[idx[j]]).T @ n_c_at(
            int(idx[j])
        )
    return dataclasses.replace(log, dvl=dataclasses.replace(dvl, d_v=d_v, water_track=water))


def water_config(log: LogData, water_track: str) -> EstimatorConfig:
    """The log's configuration, water track as given; the water-track pings' noise is the log's (paper-3d's
    2 cm/s: the pings were bottom-track pings)."""
    cfg = EstimatorConfig.for_log(log.metadata)
    return cfg.model_copy(
        update={
            "current": cfg.current.model_copy(
                update={"water_track": water_track, "water_track_sigma_m_s": 0.02}
            )
        }
    )
