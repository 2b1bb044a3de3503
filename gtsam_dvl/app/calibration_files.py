"""A vehicle's calibration file at `smooth`: read as the prior of a dive, and a dive's posterior made into one.

`smooth LOG --calibration FILE` (calibration_prior): the file (io/calibration_file.py) with its covariance inflated
for the days from its date to the log's start, [calibration] inflation_per_day of each variance per day
(core/calibration.py VehicleCalibration.inflated; a dive before the file's date: none). Every estimator takes it
as the joint prior of the states it holds (estimators/run.py); the result's info["calibration_prior"] records it
with the file and the inflation, and the verdict on the new estimate (analysis/calibration_check.py) is in the
health and the summary.

`smooth LOG --calibration-out FILE` (calibration_of_run): the run's posterior of the vehicle's states
(core/calibration.py from_result) with the log as its source (path and SHA-256) after the prior file's sources
when there was one (its information is in the posterior), dated at the log's start.

The vehicle's name: `--vehicle NAME`, else the prior file's, else the name of the log's folder (one folder of
logs per vehicle). A prior file of another vehicle than --vehicle is refused.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from gtsam_dvl.core.calibration import SourceLog, VehicleCalibration, from_result, iso_date
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.calibration_file import read_calibration
from gtsam_dvl.io.result_writer import file_sha256


def vehicle_name(
    log_path: Path | str, vehicle: str | None, prior: VehicleCalibration | None = None
) -> str:
    """--vehicle, else the prior's vehicle, else the log's folder name (module doc)."""
    if vehicle:
        return vehicle
    if prior is not None and prior.vehicle:
        return prior.vehicle
    return Path(log_path).absolute().parent.name or "vehicle"


def calibration_prior(
    path: Path | str, log: LogData, config: EstimatorConfig, vehicle: str | None = None
) -> tuple[VehicleCalibration, dict[str, Any]]:
    """The file's calibration inflated for the days from its date to the log's start (module doc), and what to
    record of it (file, days, per_day, the variances' factor)."""
    cal = read_calibration(path)
    if vehicle and cal.vehicle and vehicle != cal.vehicle:
        raise GtsamDvlError(
            f"{path}: a calibration of vehicle {cal.vehicle!r}, not of {vehicle!r} (--vehicle)"
        )
    inflated, inflation = inflated_for(cal, log, config)
    return inflated, {"file": str(path), **inflation}


def inflated_for(
    cal: VehicleCalibration, log: LogData, config: EstimatorConfig
) -> tuple[VehicleCalibration, dict[str, Any]]:
    """A calibration inflated for the days from its date to the log's start ([calibration] inflation_per_day),
    and the inflation (days, per_day, the variances' factor)."""
    return inflated_at(cal, log.t0_ns, config)


def inflated_at(
    cal: VehicleCalibration, t0_ns: int, config: EstimatorConfig
) -> tuple[VehicleCalibration, dict[str, Any]]:
    """inflated_for a dive that starts at t0_ns (ns since the Unix epoch): the ROS 2 node's start."""
    days = cal.days_before(iso_date(t0_ns))
    per_day = config.calibration.inflation_per_day
    return cal.inflated(days, per_day), {
        "days": days,
        "per_day": per_day,
        "variance_factor": 1.0 + per_day * max(days, 0.0),
    }


def calibration_data(path: Path | str) -> dict[str, Any]:
    """A calibration file as plain data (its parsed TOML, checked by read_calibration), to ship to a campaign's
    workers (calibration_from_dict reads it back)."""
    read_calibration(path)
    return tomllib.loads(Path(path).read_text())


def record_prior(result: NavResult, inflation: dict[str, Any]) -> None:
    """Add the file and its inflation to the run's info["calibration_prior"] (the estimator's record of it)."""
    prior = result.info.get("calibration_prior")
    if isinstance(prior, dict):
        prior["inflation"] = inflation


def calibration_of_run(
    result: NavResult,
    log_path: Path | str,
    config: EstimatorConfig,
    vehicle: str,
    prior: VehicleCalibration | None = None,
) -> VehicleCalibration:
    """The run's posterior of the vehicle's states as a calibration (module doc)."""
    source = SourceLog(str(log_path), file_sha256(log_path))
    earlier = prior.sources if prior is not None else ()
    return from_result(
        result, config, vehicle, sources=(*earlier, source), ekf=result.estimator == "ekf"
    )


def prior_line(info: dict[str, Any]) -> str | None:
    """The console line of the prior a run took from a calibration file (a summary's info), None for a run that
    took none."""
    prior = info.get("calibration_prior")
    if not isinstance(prior, dict):
        return None
    infl = prior.get("inflation") or {}
    age = (
        f", {infl['days']:.0f} days before this dive: variances x{infl['variance_factor']:.3g}"
        if infl.get("days", 0) > 0
        else ""
    )
    where = f" ({infl['file']})" if infl.get("file") else ""
    return (
        f"  prior of {', '.join(prior.get('states', []))}: {prior.get('vehicle') or 'the vehicle'}'s calibration "
        f"of {str(prior.get('date', ''))[:10]}{where}{age}"
    )
