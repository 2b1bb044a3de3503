"""The error-state EKF's divergence watch (filter.py): the running NIS per degree of freedom of its DVL updates, the
time offset held at its bound, and the states frozen once it has diverged."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.estimators.ekf.strapdown import CALIBRATION, LAYOUT

# The filter has diverged when the mean NIS per degree of freedom of its last DIVERGENCE_PINGS updates exceeds
# DIVERGENCE_NIS and is growing, after the warm-up window (a consistent filter: 1, with a spread of 0.15 over 30
# three-axis pings; a ping far off is gated or down-weighted, so only a filter whose own state is wrong gets there).
# From then on its IMU biases, DVL calibration and time offset take no more DVL updates: a filter that chases its own
# error with them runs them away (seen: a 38 deg/s turn with stamps 1 s early took the offset to -1.84 s and a
# lateral accelerometer bias to -1372 micro-g).
DIVERGENCE_PINGS = 30
DIVERGENCE_NIS = 6.0
# A filter whose time offset the bound holds (filter.py: the prior +- 3 prior sigmas) for this many of its updates in
# a row after the warm-up window has diverged as well, whatever its NIS: every update pushes the offset beyond the
# bound and the clip puts it back, so the offset is the bound's, not the data's, and the rest of the state absorbs
# the difference (field-survey seed 3 with a warm-up that lost track: 839 updates at the bound, the offset 6 sigma
# off, its NIS per dof 0.35 behind a DVL noise fitted at 4.6x the stated). A filter converging from a far prior
# touches the bound for a few updates and comes back.
BOUND_PINGS = DIVERGENCE_PINGS
# (and the time offset, OFFSET, when estimated: its slot exists only then)
FROZEN_ON_DIVERGENCE = np.r_[
    np.arange(LAYOUT["gyro_bias"].start, LAYOUT["gyro_bias"].stop),
    np.arange(LAYOUT["accel_bias"].start, LAYOUT["accel_bias"].stop),
    CALIBRATION,
]


@dataclass
class DivergenceWatch:
    """The running mean of the NIS per degree of freedom over the last DIVERGENCE_PINGS updates, and when it first
    passed DIVERGENCE_NIS."""

    recent: list[float] = field(default_factory=list)
    diverged_at_s: float | None = None
    at_bound: int = 0  # updates in a row with the time offset held at its bound
    # what diverged: "nis" (DIVERGENCE_NIS) or "bound" (BOUND_PINGS)
    reason: str = ""

    @property
    def diverged(self) -> bool:
        return self.diverged_at_s is not None

    def add(self, t: float, nis_per_dof: float) -> bool:
        """One update's NIS per dof at t (s); True when this one is where the filter is found diverged: the mean of
        the last DIVERGENCE_PINGS above DIVERGENCE_NIS and above the mean of the DIVERGENCE_PINGS before them (a
        filter converging from a wrong prior, a mounting tens of degrees off, has a large but falling NIS)."""
        self.recent = (self.recent + [nis_per_dof])[-2 * DIVERGENCE_PINGS :]
        if self.diverged or len(self.recent) < 2 * DIVERGENCE_PINGS:
            return False
        before, last = (
            float(np.mean(self.recent[:DIVERGENCE_PINGS])),
            float(np.mean(self.recent[DIVERGENCE_PINGS:])),
        )
        if last > DIVERGENCE_NIS and last > before:
            self.diverged_at_s, self.reason = t, "nis"
            return True
        return False

    def held(self, t: float, at_bound: bool) -> bool:
        """One update at t (s), its time offset held at the bound or not; True when this one is where the filter is
        found diverged: BOUND_PINGS updates in a row held there."""
        self.at_bound = self.at_bound + 1 if at_bound else 0
        if self.diverged or self.at_bound < BOUND_PINGS:
            return False
        self.diverged_at_s, self.reason = t, "bound"
        return True

    def info(self) -> dict[str, Any]:
        return (
            {}
            if self.diverged_at_s is None
            else {
                "diverged_at_s": self.diverged_at_s,
                "diverged_by": self.reason,
                "why": f"the EKF diverged at {self.diverged_at_s:.1f} s ({self._what()}): its biases, "
                "calibration and time offset were frozen there",
            }
        )

    def _what(self) -> str:
        if self.reason == "bound":
            return f"its time offset held at its prior's bound for {BOUND_PINGS} updates in a row"
        return f"mean NIS per dof over {DIVERGENCE_PINGS} pings above {DIVERGENCE_NIS:g}"
