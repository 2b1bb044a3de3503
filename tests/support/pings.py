"""The DVL ping selection's first pass for the tests: the pings classify_pings finds usable on a whole log."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.selection import USABLE, beam_arrays, classify_pings


def first_pass_usable(log: LogData, cfg: DvlConfig, beams: bool) -> np.ndarray:
    """Indices of the pings classify_pings finds usable over the IMU's span (usable_pings' first pass, before the
    screen). beams: with the log's beam arrays (beam_arrays), else with none."""
    beam_valid, beam_finite = beam_arrays(log.dvl) if beams else (None, None)
    code = classify_pings(
        log.dvl.t,
        log.dvl.d_v,
        log.dvl.valid,
        beam_valid,
        beam_finite,
        cfg,
        float(log.imu.t[0]),
        float(log.imu.t[-1]),
    )
    return np.flatnonzero(code == USABLE)
