"""The online estimator over a whole log (smooth_online: `smooth --mode online`), and the result every online run
reports (run_result: smooth_online's and the ROS 2 node's)."""

from __future__ import annotations

import math
import time

import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig, OnlineConfig
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.gaps import screened_losses
from gtsam_dvl.estimators.inputs.prepare import prepare
from gtsam_dvl.estimators.models import weak_hold
from gtsam_dvl.estimators.models.constant_error import consider_constant_error
from gtsam_dvl.estimators.models.epoch_states import reports
from gtsam_dvl.estimators.online.estimator import OnlineEstimator
from gtsam_dvl.estimators.online.feed import feed_log


def run_result(estimator: OnlineEstimator, config: EstimatorConfig, t0_ns: int = 0) -> NavResult:
    """estimator.result(t0_ns) with what every online run reports beside it: the correlated DVL error's settings,
    the weak directions held, the run-constant DVL error's consider term on the calibration's covariance and the
    water current. smooth_online and the ROS 2 node (app/node: the calibration file it saves) both call it, so a
    live run's calibration is the one `smooth --mode online` gives for the same messages."""
    result = estimator.result(t0_ns)
    # the per-epoch states' reports at the newest state (epoch_states.py)
    if estimator.smoother is not None:
        result.info.update(reports(config, estimator.smoother.epoch_estimates()))
    if estimator.smoother is not None and estimator.smoother.hold is not None:  # (weak_hold.py)
        result.info["calibration_hold"] = weak_hold.report(estimator.smoother.hold, math.nan)
    # (constant_error.py; none with a vehicle calibration file as prior)
    consider_constant_error(result, config, estimator.calibration is not None)
    # the water current at each state as it left the window (or at the end)
    if estimator.current_history:
        result.water_current = estimator.current_profile()
    return result


def smooth_online(
    log: LogData,
    config: EstimatorConfig | None = None,
    *,
    mode: str | None = None,
    window_s: float | None = None,
    progress: ProgressFn | None = None,
    options: OnlineConfig | None = None,
    calibration: VehicleCalibration | None = None,
) -> NavResult:
    """Run the online estimator over a whole log, message by message, and return its NavResult with the
    timeline of filtering sigmas at every epoch. options (default: config.online, TOML section [online]);
    mode ("fixed_lag" or "full") and window_s override those of options. config None: the one the log's
    scenario names, else the defaults (EstimatorConfig.for_log). calibration: a vehicle's calibration, inflated
    for its age, as the joint prior of the states it holds (core/states.py calibration_prior)."""
    # the configuration checked, what the online estimator does not do refused, the IMU screened when the reader
    # did not (inputs/prepare.py); the estimator resolves [current] water_track itself (OnlineEstimator.for_log)
    prepared = prepare(log, config, "online", calibration)
    log, config = prepared.log, prepared.stated
    options = (options if options is not None else config.online).model_copy()
    if mode is not None:
        options.mode = mode  # type: ignore[assignment]  # any str: checked by value in OnlineEstimator
    if window_s is not None:
        options.window_s = window_s
    t_start = time.perf_counter()
    estimator = OnlineEstimator.for_log(log, config, options, calibration)
    feed_log(estimator, log, progress)
    result = run_result(estimator, config, log.t0_ns)
    total = time.perf_counter() - t_start
    result.timing_s = {"updates": float(np.sum(estimator.latencies_s)), "total": total}
    result.info["real_time_factor"] = (
        float((log.imu.t[-1] - log.imu.t[0]) / total) if total > 0 else None
    )
    # what the screen of an in-memory log found (gaps.py)
    if (screened := screened_losses(log)) is not None:
        result.info["screened_losses"] = screened
    if progress is not None:
        progress(1.0)
    return result
