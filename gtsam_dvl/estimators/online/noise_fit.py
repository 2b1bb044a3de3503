"""The online estimator's fit of the DVL noise ([noise] fit_dvl, estimators/models/noise_levels.py): the whitened
residuals of the DVL factors of the pings in the warm-up window ([noise] warmup_s from the first ping), each
evaluated lag_s after its ping, at iSAM2's estimate then (the smoother's residual: the states around the ping
updated by the lag_s of pings that followed, as the batch smoother's are by the whole log), fitted once the
window's last ping is lag_s old, and held from then on: the factors added later take the fitted factor, those
already in iSAM2 keep theirs."""

from __future__ import annotations

from collections import deque
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.estimators.models.noise_levels import WarmupFit


class OnlineNoiseFit:
    """Collects the warm-up pings' DVL factors and fits when due (module doc)."""

    def __init__(self, config: EstimatorConfig, lag_s: float) -> None:
        self.fit = WarmupFit(config)
        self.lag_s = lag_s
        self.done = False
        self._pending: deque[tuple[float, list[gtsam.NonlinearFactor]]] = deque()

    def record(self, t: float, factors: list[gtsam.NonlinearFactor], sigma_m_s: float) -> None:
        """The DVL factors of a ping at t (s), the median ping sigma for the report (m/s)."""
        if self.done or not factors:
            return
        if not np.isfinite(self.fit.t_first):
            self.fit.start(t, sigma_m_s)
        if t <= self.fit.t_end:
            self._pending.append((t, factors))

    def after_epoch(self, t_epoch: float, isam: gtsam.ISAM2) -> float | None:
        """Evaluate the pings now lag_s old; the fitted multiplier when the fit is due (once), else None."""
        if self.done:
            return None
        due: list[gtsam.NonlinearFactor] = []
        while self._pending and self._pending[0][0] <= t_epoch - self.lag_s:
            due += self._pending.popleft()[1]
        if due:
            keys = sorted({k for f in due for k in f.keys()})
            values = isam.calculateEstimate(keys)
            for f in due:
                self.fit.add_whitened(np.asarray(f.whitenedError(values), dtype=float))  # type: ignore[attr-defined]
        if np.isfinite(self.fit.t_first) and t_epoch > self.fit.t_end + self.lag_s:
            return self.finish()
        return None

    def finish(self) -> float:
        self.done = True
        self._pending.clear()
        return self.fit.finish(
            f"the online smoother's residuals, {self.lag_s:g} s after each ping,"
        )

    @property
    def report(self) -> dict[str, Any]:
        return self.fit.report
