"""The EKF's first position when the map origin is the log's first GNSS fix (estimators/inputs/gnss.py
origin_is_first_fix: a log that records no origin, the reader takes the first fix for it).

The fix is the antenna's position with the fix's own uncertainty (a survey receiver: 2 m horizontally, 4 m
vertically), not the vehicle's position known to [priors] position_sigma_m (1 cm, right only when the origin is
defined by the first state). The filter takes no fixes, so the first state's position prior is the origin fix's
covariance, as the batch smoother's is when no fix aids (gnss.first_position_cov), and its mean the fix less the
antenna's offset (gnss.first_position). Pinned at 1 cm, a first fix 5 m off in height (1.3 of its sigmas) made
the depth sensor's first samples 5 m innovations: gated, then forced in once the gate reopened, they threw the
vertical velocity to -0.9 m/s at the surface, and the filter's warm-up window lost track (field-survey seed 3:
time offset -1.65 s on a truth of +0.3 s, health "failed")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.ekf.strapdown import POS, FilterState
from gtsam_dvl.estimators.inputs.gnss import (
    antenna_lever,
    fix_covariances,
    origin_is_first_fix,
    valid_fixes,
)


@dataclass(frozen=True)
class OriginFix:
    """The first good fix that defines the map origin: its covariance (map axes, m^2) and the antenna in
    base_link (m)."""

    cov: np.ndarray
    b_p_antenna: np.ndarray

    def place(self, fs: FilterState, carried: bool) -> None:
        """The filter's first state: base_link is the antenna's offset away from the fix (turned by the first
        state's attitude: the first ping follows the first fix by a fraction of a second); a position not carried
        from the fix (alignment.first_state: the first ping at the fix's time) gets the fix's covariance here."""
        fs.nav.n_p = fs.nav.n_p - fs.nav.n_R_b @ self.b_p_antenna
        if not carried:
            fs.P[POS, :] = 0.0
            fs.P[:, POS] = 0.0
            fs.P[POS, POS] = self.cov


def origin_fix(log: LogData, config: EstimatorConfig, frame: LocalFrame) -> OriginFix | None:
    """The origin fix of the log (module doc), None when the origin is not a fix (configured, or the log's)."""
    if not origin_is_first_fix(log, config):
        return None
    gnss = log.gnss
    assert gnss is not None
    i = int(np.flatnonzero(valid_fixes(gnss))[0])
    cov = fix_covariances(gnss, config, frame)[i]
    return OriginFix(np.asarray(cov, dtype=float), antenna_lever(gnss, config))
