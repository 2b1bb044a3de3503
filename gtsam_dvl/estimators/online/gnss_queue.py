"""The online estimator's GNSS fixes at the surface (OnlineEstimator.push_gnss; [gnss], estimators/inputs/gnss.py).

The batch smoother's roles, decided as the fixes come: a fix is converted as the batch converts it (fixes_in_map,
fix_covariances: the antenna's position in map with its covariance in map axes) and waits until the state nearest
to it in time is known (the first state at or after its stamp, or finish()), then
- "rejected_status": not a fix (status < 0, non-finite);
- "rejected_depth": the depth sensor says deeper than [gnss] max_depth_m at its time (the depth samples pushed so
  far, interpolated; the last one before it when none after has come);
- "used": with [gnss] use "start", a good fix of the first surface interval (good fixes less than surface_gap_s
  apart from the first on) before the first dive (a depth sample deeper than max_depth_m); "all": every good fix;
  "origin": the origin fix alone. Its factor (FactorMaker.gnss_factors_for, the batch's) goes on the antenna of the
  nearest of the states held, within max_time_to_state_s (else "too_far"), bridged by the state's velocity;
- "held_out": a good fix that does not aid (the surfacing error of `evaluate`).
Causal where the batch sees the whole log: the first surface interval ends at the first dive (the batch keeps
using its fixes after a dive shorter than surface_gap_s).

The map origin's fix (when the origin is the first fix: OnlineEstimator.origin_t) is the first state's position
prior instead of a factor (first_prior: its covariance, the antenna's offset taken off the carried position), the
same information as the batch smoother's loose prior and factor on that fix. Counters "gnss_used" (the origin fix
included), "gnss_held_out", "gnss_rejected" (and its reasons), as the batch counts them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.types import GnssData, ImuData
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.alignment import given_covariance
from gtsam_dvl.estimators.inputs.depth import nearest_states
from gtsam_dvl.estimators.inputs.gnss import (
    antenna_lever,
    fix_covariances,
    fixes_in_map,
    valid_fixes,
)
from gtsam_dvl.estimators.inputs.selection import Ping

ORIGIN_TOL_S = 1e-6  # a fix this close to origin_t is the origin's


class GnssQueue:
    """GNSS fixes (t s, antenna in map m, covariance m^2) waiting for their nearest state (module doc). b_p_antenna:
    the antenna in base_link (m; [gnss] lever_arm_m overrides it). counters: the estimator's."""

    def __init__(
        self,
        config: EstimatorConfig,
        frame: LocalFrame,
        b_p_antenna: np.ndarray | None,
        counters: dict[str, int],
    ) -> None:
        self.config, self.frame, self.counters = config, frame, counters
        empty = np.zeros(0)
        self.lever = antenna_lever(
            GnssData(
                empty, empty, empty, empty, np.zeros((0, 3, 3)), empty, b_p_antenna=b_p_antenna
            ),
            config,
        )
        self.waiting: deque[tuple[float, np.ndarray, np.ndarray]] = deque()
        self.depth: deque[tuple[float, float]] = deque()  # (t s, depth m below the surface)
        self.first_dive_s = np.inf  # the first depth sample deeper than max_depth_m
        self.last_good_s: float | None = None  # the previous good fix
        self.interval = -1  # surface interval of the previous good fix
        self.origin_cov: np.ndarray | None = (
            None  # the origin fix's covariance (map axes), once pushed
        )

    def __len__(self) -> int:
        return len(self.waiting)

    def push(
        self,
        t: float,
        lat_deg: float,
        lon_deg: float,
        height_m: float,
        cov_enu: Any,
        status: int,
        origin_t: float | None,
    ) -> None:
        """Convert one fix (NavSatFix: geodetic, ENU covariance m^2, None or NaN: unknown, status) and queue it; one
        that is not a fix is counted ("gnss_rejected_status"); the fix at origin_t (s; None: the origin is no fix)
        is the map origin's (first_prior)."""
        for name in (
            "gnss_used",
            "gnss_held_out",
            "gnss_rejected",
        ):  # reported even when zero, as by the batch
            self.counters.setdefault(name, 0)
        cov_enu = np.full((3, 3), np.nan) if cov_enu is None else cov_enu
        data = GnssData(
            np.array([t]),
            np.array([lat_deg], dtype=float),
            np.array([lon_deg], dtype=float),
            np.array([height_m], dtype=float),
            np.asarray(cov_enu, dtype=float).reshape(1, 3, 3),
            np.array([status]),
        )
        if not valid_fixes(data)[0]:
            self._rejected("gnss_rejected_status")
            return
        cov = fix_covariances(data, self.config, self.frame)[0]
        if origin_t is not None and abs(t - origin_t) <= ORIGIN_TOL_S:
            self.origin_cov = cov
            self._count("gnss_used", 1)
            self._good(t)
            return
        self.waiting.append((float(t), fixes_in_map(data, self.frame)[0], cov))

    def push_depth(self, t: float, depth_m: float) -> None:
        """A depth sample (m below the surface, the batch's: -(z_meas + origin height)): the depth gate and the
        first dive."""
        self.depth.append((t, depth_m))
        if depth_m > self.config.gnss.max_depth_m:
            self.first_dive_s = min(self.first_dive_s, t)
        keep_s = self.waiting[0][0] if self.waiting else t
        while len(self.depth) > 2 and self.depth[1][0] < keep_s - 10.0:
            self.depth.popleft()

    def first_prior(self, origin_t: float | None) -> np.ndarray | None:
        """The first state's position covariance (map axes, m^2) when the map origin is a fix (at origin_t, s): the
        origin fix's (module doc), or with no such fix pushed yet, the configured fix noise; None when the origin is
        no fix (origin_t None)."""
        if origin_t is None:
            return None
        if self.origin_cov is not None:
            return self.origin_cov
        g = self.config.gnss
        sigma = (g.noise_m if g.noise_m > 0 else g.default_noise_m) * g.noise_multiplier
        return np.eye(3) * sigma**2

    def carry_to_first(
        self, maker: FactorMaker, imu: ImuData, t1: float, ping: Ping, origin_t: float | None
    ) -> None:
        """The given attitude and map origin carried to the first state at t1 (FactorMaker.carry_to_first, from
        origin_t), the origin fix's covariance the position's at the fix (first_prior) and the antenna's offset
        taken off: the body is at -n_R_b b_p_antenna when the antenna is at the origin."""
        pos_cov = self.first_prior(origin_t)
        cov0 = None
        if pos_cov is not None:
            cov0 = given_covariance(maker.alignment, maker.config)
            cov0[3:, 3:] = pos_cov
        first = maker.carry_to_first(
            imu, t1, ping.d_v if ping.valid else None, ping.d_cov, cov0, origin_t
        )
        if pos_cov is not None:
            first.n_p = first.n_p - first.alignment.n_R_b @ self.lever
            first.carried = (
                True  # (FactorMaker.prior_factors takes first.cov, with the fix's covariance)
            )

    def factors(
        self, maker: FactorMaker, held: Mapping[int, float], i: int, t_i: float, final: bool = False
    ) -> list[gtsam.NonlinearFactor]:
        """GNSS factors of the waiting fixes whose nearest state is now known (those stamped at or before the new
        state i at t_i; all with final), each on the nearest of the states held (state index -> time, s) and
        state i, within max_time_to_state_s; the roles counted (module doc)."""
        out: list[gtsam.NonlinearFactor] = []
        if not self.waiting or (self.waiting[0][0] > t_i and not final):
            return out
        others = sorted(k for k in held if k != i)
        index = np.array(others + [i])
        t_states = np.array([held[k] for k in others] + [t_i])
        while self.waiting and (final or self.waiting[0][0] <= t_i):
            t, z, cov = self.waiting.popleft()
            role = self._role(t)
            if role != "used":
                self._rejected(role) if role.startswith("gnss_rejected") else self._count(role, 1)
                continue
            near, dt = nearest_states(t_states, np.array([t]), self.config.gnss.max_time_to_state_s)
            if near[0] < 0:
                self._rejected("gnss_too_far")
                continue
            self._count("gnss_used", 1)
            out += maker.gnss_factors_for(int(index[near[0]]), z, cov, self.lever, float(dt[0]))
        return out

    def _role(self, t: float) -> str:
        """ "used", "gnss_held_out" or "gnss_rejected_depth" for a good fix at t (module doc)."""
        g = self.config.gnss
        if self.depth:
            td = np.array([d[0] for d in self.depth])
            if td[0] <= t and np.interp(t, td, [d[1] for d in self.depth]) > g.max_depth_m:
                return "gnss_rejected_depth"
        interval = self._good(t)
        if g.use == "all" or (g.use == "start" and interval == 0 and t < self.first_dive_s):
            return "used"
        return "gnss_held_out"

    def _good(self, t: float) -> int:
        """A good fix at t: its surface interval."""
        if self.last_good_s is None or t - self.last_good_s > self.config.gnss.surface_gap_s:
            self.interval += 1
            self._count("gnss_surface_intervals", 1)
        self.last_good_s = t
        return self.interval

    def _count(self, kind: str, n: int) -> None:
        self.counters[kind] = self.counters.get(kind, 0) + n

    def _rejected(self, kind: str) -> None:
        self._count(kind, 1)
        self._count("gnss_rejected", 1)
