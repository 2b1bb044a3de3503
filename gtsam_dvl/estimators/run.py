"""One estimator on a log by its name: the dispatcher the command line (`smooth --mode`), the demo and the Monte
Carlo runs (analysis/montecarlo.py) share."""

from __future__ import annotations

from typing import Any

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.types import LogData

MODES = ("batch", "online", "online-full", "ekf", "io-dvlc")


def run_estimator(log: LogData, mode: str, config: EstimatorConfig | None, progress: ProgressFn | None = None,
                  timeline: bool = True) -> Any:
    """NavResult (batch, online, online-full, ekf) or IoDvlcResult (io-dvlc). config: an EstimatorConfig (None:
    the one the log's scenario names, else the defaults), checked by value here; each estimator reads its own
    section of it. timeline: the batch smoother's filtering timeline (the filters always keep theirs)."""
    if config is not None:
        config.validate()
    if mode == "batch":
        from gtsam_dvl.estimators.batch import smooth_batch

        return smooth_batch(log, config, progress=progress, timeline=timeline)
    if mode in ("online", "online-full"):
        from gtsam_dvl.estimators.online import smooth_online

        return smooth_online(log, config, mode="full" if mode == "online-full" else "fixed_lag", progress=progress)
    if mode == "ekf":
        from gtsam_dvl.estimators.ekf import run_ekf

        return run_ekf(log, config, progress=progress)
    if mode == "io-dvlc":
        from gtsam_dvl.estimators.iodvlc import run_iodvlc

        return run_iodvlc(log, config)
    raise GtsamDvlError(f"unknown mode '{mode}' (available: {', '.join(MODES)})")
