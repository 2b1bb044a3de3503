"""The estimators by name: one interface (Estimator), one registry (ESTIMATORS, its names MODES) and the
dispatcher the command line (`smooth --mode`), the demo and the Monte Carlo runs (campaign/montecarlo.py) share.

Adding an estimator is one entry in ESTIMATORS: an Estimator (a name, a description and run()), e.g. a
RegisteredEstimator around a function. Each function imports its estimator when called, so that listing the modes
loads no solver.

A vehicle's calibration (core/calibration.py VehicleCalibration, already inflated for its age) reaches every
trajectory estimator through run_estimator's `calibration`: the joint prior of the states it holds (core/states.py
calibration_prior; the EKF's initial mean and covariance), recorded in the result's info["calibration_prior"].

Results: every estimator returns an EstimatorResult (core/result.py): its name, the shared states it estimated
by name (`calibration`: state name -> Estimate, value and marginal covariance) and its wall times. The
trajectory estimators (batch, online, online-full, ekf) return a NavResult, which adds the trajectory, the biases
and their covariances. IO-DVLC returns an IoDvlcResult: it estimates the DVL scale and misalignment from the
Type-I segments alone, with no trajectory and no IMU biases, and adds their timelines over the DVL epochs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol, TypedDict, Unpack, overload

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import EstimatorResult, NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.prepare import refuse_unsupported
from gtsam_dvl.estimators.iodvlc import IoDvlcResult


@dataclass(frozen=True)
class RunRequest:
    """What run_estimator hands an estimator: the log and run_estimator's arguments (its docstring). config: an
    EstimatorConfig, already checked (None: the one the log's scenario names, else the defaults); each estimator
    reads its own sections of it. progress: called with the fraction done, 0 to 1. timeline: keep the filtering
    timeline where it costs extra (the batch smoother's; the filters always keep theirs). calibration: a vehicle's
    calibration as the prior (module doc)."""

    log: LogData
    config: EstimatorConfig | None
    progress: ProgressFn | None = None
    timeline: bool = True
    calibration: VehicleCalibration | None = None


class Estimator(Protocol):
    """An estimator run on a whole log (RunRequest)."""

    @property
    def name(self) -> str: ...

    @property
    def description(self) -> str: ...

    def run(self, request: RunRequest) -> EstimatorResult: ...


RunFn = Callable[[RunRequest], EstimatorResult]


@dataclass(frozen=True)
class RegisteredEstimator:
    """An Estimator made of its name, its description and the function that runs it (which imports the
    estimator's module when called)."""

    name: str
    description: str
    runner: RunFn

    def run(self, request: RunRequest) -> EstimatorResult:
        return self.runner(request)


def _batch(r: RunRequest) -> NavResult:
    from gtsam_dvl.estimators.batch.smoother import smooth_batch

    return smooth_batch(
        r.log, r.config, progress=r.progress, timeline=r.timeline, calibration=r.calibration
    )


def _online(mode: Literal["fixed_lag", "full"]) -> RunFn:
    def run(r: RunRequest) -> NavResult:
        from gtsam_dvl.estimators.online import smooth_online

        return smooth_online(
            r.log, r.config, mode=mode, progress=r.progress, calibration=r.calibration
        )

    return run


def _ekf(r: RunRequest) -> NavResult:
    from gtsam_dvl.estimators.ekf import run_ekf

    return run_ekf(r.log, r.config, progress=r.progress, calibration=r.calibration)


def _iodvlc(r: RunRequest) -> IoDvlcResult:
    from gtsam_dvl.estimators.iodvlc import run_iodvlc

    return run_iodvlc(r.log, r.config)  # (no calibration prior: run_estimator refused one)


ESTIMATORS: dict[str, Estimator] = {
    e.name: e
    for e in (
        RegisteredEstimator(
            "batch", "batch smoother: the whole log in one factor graph (Gauss-Newton)", _batch
        ),
        RegisteredEstimator(
            "online",
            "online iSAM2 smoother, fixed lag (bounded cost per ping)",
            _online("fixed_lag"),
        ),
        RegisteredEstimator(
            "online-full", "online iSAM2 smoother keeping every state", _online("full")
        ),
        RegisteredEstimator("ekf", "error-state EKF over the same pings", _ekf),
        RegisteredEstimator(
            "io-dvlc",
            "the paper's ideal observer: DVL scale and misalignment from the Type-I "
            "segments (no trajectory)",
            _iodvlc,
        ),
    )
}
# the estimators' names, the command line's --mode values
MODES: tuple[str, ...] = tuple(ESTIMATORS)


def get_estimator(mode: str) -> Estimator:
    """The estimator named mode, else a one-line GtsamDvlError listing MODES."""
    try:
        return ESTIMATORS[mode]
    except KeyError:
        raise GtsamDvlError(f"unknown mode '{mode}' (available: {', '.join(MODES)})") from None


class RunOptions(TypedDict, total=False):
    """run_estimator's optional keywords, as RunRequest holds them (its docstring)."""

    progress: ProgressFn | None
    timeline: bool
    calibration: VehicleCalibration | None


@overload
def run_estimator(
    log: LogData,
    mode: Literal["io-dvlc"],
    config: EstimatorConfig | None,
    **options: Unpack[RunOptions],
) -> IoDvlcResult: ...


@overload
def run_estimator(
    log: LogData,
    mode: Literal["batch", "online", "online-full", "ekf"],
    config: EstimatorConfig | None,
    **options: Unpack[RunOptions],
) -> NavResult: ...


@overload
def run_estimator(
    log: LogData, mode: str, config: EstimatorConfig | None, **options: Unpack[RunOptions]
) -> EstimatorResult: ...


def run_estimator(
    log: LogData,
    mode: str,
    config: EstimatorConfig | None,
    *,
    progress: ProgressFn | None = None,
    timeline: bool = True,
    calibration: VehicleCalibration | None = None,
) -> EstimatorResult:
    """Run the estimator named mode (ESTIMATORS) on a log: a NavResult, or an IoDvlcResult for io-dvlc (module
    doc). config: an EstimatorConfig (None: the one the log's scenario names, else the defaults), checked by value
    here; each estimator reads its own section of it. timeline: the batch smoother's filtering timeline (the
    filters always keep theirs). calibration: a vehicle's calibration, inflated for its age, as the prior of the
    states it holds (module doc)."""
    estimator = get_estimator(mode)
    # what the estimator does not do, refused once, here, before any work (estimators/inputs/prepare.py)
    refuse_unsupported(
        mode, (config or EstimatorConfig.for_log(log.metadata)).validate(), calibration
    )
    return estimator.run(RunRequest(log, config, progress, timeline, calibration))


def run_trajectory_estimator(
    log: LogData, mode: str, config: EstimatorConfig | None, **options: Unpack[RunOptions]
) -> NavResult:
    """run_estimator for a mode that estimates a trajectory (a NavResult: every mode but io-dvlc), else a one-line
    GtsamDvlError."""
    result = run_estimator(log, mode, config, **options)
    if not isinstance(result, NavResult):
        raise GtsamDvlError(f"--mode {mode} estimates the calibration only, not a trajectory")
    return result
