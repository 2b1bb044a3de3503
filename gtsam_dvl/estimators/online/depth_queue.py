"""The online estimator's depth samples (OnlineEstimator.push_depth; [depth], estimators/inputs/depth.py).

Each sample is converted as the batch smoother converts it (depth_samples) and waits until the state nearest to
it in time is known, i.e. until the first state at or after its stamp exists (or finish(), for samples after the
newest state); its factor goes in with that state's update, the time between them bridged by the state's velocity
(factors/depth.py), the same factor as the batch smoother's on the same state. Counters "depth_used",
"depth_too_far" (farther than [depth] max_time_to_state_s from the nearest state still held), "depth_invalid".
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping

import gtsam
import numpy as np

from gtsam_dvl.core.config import DepthConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.types import DepthData
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.depth import depth_samples, nearest_states

CountFn = Callable[[str, int], None]


class DepthQueue:
    """Depth samples (t s, z_meas m down, sigma m) waiting for their nearest state (module doc). b_p_sensor: the
    pressure sensor's position in base_link (m; [depth] lever_arm_m overrides it). count(kind, n): the
    estimator's counters."""

    def __init__(
        self, cfg: DepthConfig, frame: LocalFrame, b_p_sensor: np.ndarray | None, count: CountFn
    ) -> None:
        self.cfg, self.frame, self.b_p_sensor, self._count = cfg, frame, b_p_sensor, count
        self.waiting: deque[tuple[float, float, float]] = deque()
        self.lever = np.zeros(3)  # the sensor's lever arm the factors use (m, base_link)

    def __len__(self) -> int:
        return len(self.waiting)

    def push(
        self,
        t: float,
        depth_m: float,
        variance_m2: float,
        pressure_pa: float | None,
        pressure_variance_pa2: float,
    ) -> None:
        """Convert one sample (depth, or absolute pressure when pressure_pa is given) and queue it; a non-finite
        one is counted ("depth_invalid")."""
        pressure = pressure_pa is not None
        data = DepthData(
            np.array([t]),
            np.array([float(depth_m)]),
            np.array([float(variance_m2)]),
            np.array([float(pressure_pa)]) if pressure_pa is not None else None,
            np.array([float(pressure_variance_pa2)]) if pressure else None,
            b_p_sensor=self.b_p_sensor,
        )
        invalid: dict[str, int] = {}
        s = depth_samples(data, self.cfg, self.frame, invalid)
        self._count("depth_invalid", invalid.get("depth_invalid", 0))
        if len(s.t):
            self.waiting.append((float(s.t[0]), float(s.z_meas[0]), float(s.sigma[0])))
            self.lever = s.b_p_sensor

    def factors(
        self, maker: FactorMaker, held: Mapping[int, float], i: int, t_i: float, final: bool = False
    ) -> list[gtsam.NonlinearFactor]:
        """Depth factors of the waiting samples whose nearest state is now known: those stamped at or before
        the new state i at t_i (all of them with final: i is the newest state), each on the nearest of the
        states held (state index -> time, s) and state i, within max_time_to_state_s (else "depth_too_far")."""
        if not self.waiting or (self.waiting[0][0] > t_i and not final):
            return []
        ready: list[tuple[float, float, float]] = []
        while self.waiting and (final or self.waiting[0][0] <= t_i):
            ready.append(self.waiting.popleft())
        others = sorted(k for k in held if k != i)
        index = np.array(others + [i])
        t_states = np.array([held[k] for k in others] + [t_i])
        t_s = np.array([r[0] for r in ready])
        near, dt = nearest_states(t_states, t_s, self.cfg.max_time_to_state_s)
        self._count("depth_used", int((near >= 0).sum()))
        self._count("depth_too_far", int((near < 0).sum()))
        out: list[gtsam.NonlinearFactor] = []
        for k in np.flatnonzero(near >= 0).tolist():
            out += maker.depth_factors_for(
                int(index[near[k]]), ready[k][1], ready[k][2], self.lever, float(dt[k])
            )
        return out
