"""The one step every estimator takes before its own work: `prepare` makes a log and a configuration ready
for the estimator named `mode`, or refuses them with one line.

In order:
1. the configuration: the one given, else the one the log's scenario names, else the defaults
   (EstimatorConfig.for_log), checked by value; `stated` keeps it as given (what the result's configuration
   records, so that reading it back with -c reproduces the run);
2. [current] water_track "auto" resolved for the log (estimators/models/current.py: "use" when it has
   water-track pings);
3. what no estimator does (the combinations refused for every mode: the time offset with single beams,
   single beams on water-track pings), then what this estimator does not (`supports`), once, here;
4. the IMU screened when the log did not come through the reader (estimators/inputs/gaps.py
   screened_in_memory: a step in the IMU's stamps judged by the DVL's timing across it, a clock step undone,
   saturated samples dropped and counted).

What an estimator supports: every shared state the batch smoother estimates; the online estimator those that
core/states.py gives an iSAM2 relinearisation threshold; the EKF those in its error state (SharedState.ekf); a
vehicle calibration as the prior for every trajectory estimator, not IO-DVLC (it estimates from the Type-I
segments alone). IO-DVLC reads the DVL scale and misalignment only, by its own model (estimators/iodvlc.py):
the other states a configuration estimates are not its business, and its result lists what it estimated.
Alignment and the noise levels taken from the data come after, each estimator's own (the online estimator
aligns as messages come).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.states import STATES, SharedState, enabled
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.gaps import screened_in_memory
from gtsam_dvl.estimators.models.current import resolve_water_track, water_pings

TRAJECTORY_MODES = ("batch", "online", "online-full", "ekf")
CALIBRATION_PRIOR = "a vehicle calibration as the prior"
# the setting that makes a configuration estimate a shared state that not every estimator does, as a user
# writes it (the others: "the" and the state's description)
SETTINGS = {
    "time_offset": "[dvl] estimate_time_offset",
    "lever_arm": "[dvl] estimate_lever_arm",
    "water_scale": "[current] water_track_scale",
}


def supports_state(mode: str, state: SharedState) -> bool:
    """Whether the estimator named mode estimates the shared state (module doc)."""
    if mode in ("online", "online-full"):
        return state.relinearization is not None
    if mode == "ekf":
        return state.ekf
    return True  # batch; io-dvlc by its own model


def supports_calibration_prior(mode: str) -> bool:
    """Whether the estimator named mode takes a vehicle calibration as the prior."""
    return mode in TRAJECTORY_MODES


def _modes_words(modes: list[str]) -> str:
    """'batch', 'batch and online', 'batch, online and ekf' (online-full said once, as online)."""
    names = [m for m in modes if m != "online-full" or "online" not in modes]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def unsupported(
    mode: str, config: EstimatorConfig, calibration: VehicleCalibration | None
) -> list[str]:
    """What the configuration and the call ask of the estimator named mode that it does not do, one phrase
    each: '[dvl] estimate_lever_arm is batch only' (the estimators that do it named)."""
    out = []
    for s in STATES:
        if s.enabled(config) and not supports_state(mode, s):
            who = [m for m in TRAJECTORY_MODES if supports_state(m, s)]
            setting = SETTINGS.get(s.name, f"the {s.description}")
            out.append(f"{setting} is {_modes_words(who)} only")
    if calibration is not None and not supports_calibration_prior(mode):
        out.append(f"{CALIBRATION_PRIOR} is {_modes_words(list(TRAJECTORY_MODES))} only")
    return out


def refuse_unsupported(
    mode: str, config: EstimatorConfig, calibration: VehicleCalibration | None
) -> None:
    """One GtsamDvlError naming everything the estimator named mode is asked and does not do (unsupported)."""
    if missing := unsupported(mode, config, calibration):
        raise GtsamDvlError(f"{'; '.join(missing)}: not --mode {mode}")


def refuse_combinations(config: EstimatorConfig, log: LogData | None) -> None:
    """What no estimator does, one line: the DVL time offset with single beams (its model is the 3-D
    velocity's), single beams on water-track pings (their beams see the water, not the bottom)."""
    if enabled(config, "time_offset") and config.dvl.use_beams:
        raise GtsamDvlError(
            "[dvl] estimate_time_offset works with the 3-D velocity only, not with use_beams"
        )
    if (
        log is not None
        and config.dvl.use_beams
        and config.current.water_track == "use"
        and bool(np.any(water_pings(log)))
    ):
        raise GtsamDvlError(
            "[dvl] use_beams with water-track pings: not supported; set [current] water_track = "
            '"refuse" or use_beams = false'
        )


@dataclass(frozen=True)
class Prepared:
    """A log and a configuration ready for one estimator (module doc): `config` with [current] water_track
    resolved, `stated` as given (what the result's configuration records), `log` screened."""

    log: LogData
    config: EstimatorConfig
    stated: EstimatorConfig


def prepare(
    log: LogData,
    config: EstimatorConfig | None,
    mode: str,
    calibration: VehicleCalibration | None = None,
) -> Prepared:
    """The log and configuration ready for the estimator named mode, or one GtsamDvlError (module doc)."""
    stated = (config or EstimatorConfig.for_log(log.metadata)).validate()
    config = resolve_water_track(stated, log)
    refuse_combinations(config, log)
    refuse_unsupported(mode, config, calibration)
    return Prepared(screened_in_memory(log, config.dvl.time_offset_prior_s), config, stated)
