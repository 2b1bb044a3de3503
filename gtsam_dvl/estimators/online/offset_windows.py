"""The online estimator's DVL time offset ([dvl] estimate_time_offset): the IMU windows of each ping's factor.

T_OFFSET is a shared variable with its prior, like the scale, and each ping's factor is the batch smoother's
make_dvl_factor with an OffsetInput of the IMU constants of FactorMaker.velocity_rate_input over the IMU samples
of [t, t + dt_c] (widened to 2 time_offset_window_s about its middle when shorter), dt_c the current estimate of
the offset (clipped to the prior +- 3
prior sigmas): the batch smoother's second pass re-centres its windows on its first estimate, the online
estimator on the estimate it has when the ping is processed. A ping therefore waits for the IMU to reach
t + max(0, dt_c) + time_offset_window_s: a causal delay of that much (0.25 s at dt_c <= 0; the epochs after it
wait behind it); at finish() a ping still waiting takes the IMU there is. Not with use_beams (as in the batch
smoother). The estimate and its marginal sigma are NavResult.time_offset_s / time_offset_sigma_s, as the batch
smoother reports them.
"""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.online.dvl_factors import RateInput

ImuChunk = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # stamps (s), gyro (rad/s), specific force (m/s^2)


class OffsetWindows:
    """The IMU samples of the last seconds, which the velocity-rate windows of the next pings can reach, and the
    windows' centre (module doc). recentre: the windows centred on the current estimate (default), else on the
    prior (to measure what the re-centring gives)."""

    def __init__(self, cfg: DvlConfig, counters: dict[str, int] | None = None) -> None:
        self.cfg = cfg
        self.recentre = True
        self._recent: list[ImuChunk] = []
        # the estimator's counters: "time_offset_window_clipped" counts the pings whose window was held at the bound
        self.counters = {} if counters is None else counters

    def push(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> None:
        """IMU samples in time order (base_link)."""
        self._recent.append((t, w, f))

    def centre(self, estimate_s: float | None) -> float:
        """The offset the windows are centred on (s): the current estimate estimate_s (the prior before the first
        epoch, None, or without recentre), clipped to the prior +- 3 prior sigmas."""
        prior = self.cfg.time_offset_prior_s
        if not self.recentre or estimate_s is None:
            return prior
        bound = 3.0 * self.cfg.time_offset_sigma_s
        return float(np.clip(estimate_s, prior - bound, prior + bound))

    def wait_s(self, estimate_s: float | None) -> float:
        """How long after its stamp a ping waits for the IMU (s): the window after t + max(0, dt_c)."""
        return max(0.0, self.centre(estimate_s)) + self.cfg.time_offset_window_s

    def samples(self) -> ImuChunk:
        """The IMU samples kept, as one chunk."""
        if len(self._recent) > 1:
            self._recent = [tuple(np.concatenate(c) for c in zip(*self._recent, strict=True))]  # type: ignore[list-item]
        return (
            self._recent[0] if self._recent else (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
        )

    def rate_input(
        self,
        maker: FactorMaker,
        t: float,
        estimate_s: float | None,
        bias: tuple[np.ndarray, np.ndarray] | None = None,
        n_R_b: np.ndarray | None = None,
    ) -> RateInput:
        """The time-offset model's IMU constants of a ping at t (FactorMaker.velocity_rate_input) over the samples
        kept, the window centred on centre(estimate_s), the current IMU bias estimate (accelerometer m/s^2, gyro
        rad/s) taken off the samples and the Earth rate removed at the current attitude n_R_b (None before the first
        estimate: no bias, the alignment's attitude); a ping whose window the bound held is counted in
        counters["time_offset_window_clipped"]."""
        T, W, F = self.samples()
        centre = self.centre(estimate_s)
        # reported (analysis/health.py)
        if estimate_s is not None and self.recentre and centre != estimate_s:
            self.counters["time_offset_window_clipped"] = (
                self.counters.get("time_offset_window_clipped", 0) + 1
            )
        return maker.velocity_rate_input(t, T, F, W, centre, bias=bias, n_R_b=n_R_b)

    def trim(self, t_epoch: float) -> None:
        """Keep what the windows of the epochs after t_epoch (s) can reach: the prior's offset, 3 prior sigmas
        and the window, and a second more."""
        cfg = self.cfg
        reach = (
            abs(cfg.time_offset_prior_s) + 3.0 * cfg.time_offset_sigma_s + cfg.time_offset_window_s
        )
        T, W, F = self.samples()
        k0 = int(np.searchsorted(T, t_epoch - reach - 1.0))
        self._recent = [(T[k0:], W[k0:], F[k0:])]
