"""What a simulated log records beside its samples: the metadata (the scenario, the seed, the truth and the
sensor specification) and the typed fields (the mounting, the map origin, the truth calibration and biases, the
segments). The same for simulate() and the chunked simulation (sim/stream.py), which write the same log."""

from __future__ import annotations

import copy
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import DvlCalibration, GeoOrigin, ImuBiases, LogData, Mounting

if TYPE_CHECKING:
    from gtsam_dvl.core.earth import LocalFrame
    from gtsam_dvl.sim.scenario import DvlSpec, Scenario

# the DvlSpec keys whose error is off at 0: left out of the metadata then (an older scenario's stays as it was)
_DVL_OPTIONAL = (
    "stated_noise_m_s",
    "constant_error_sigma_m_s",
    "draw_scale_sigma",
    "draw_misalignment_sigma_deg",
)


def nominal_mounting(scenario: Scenario) -> Mounting:
    """The log's nominal mounting (/tf_static) from the scenario's [mounting]: the DVL's rotation and lever arm."""
    mount = scenario.mounting
    return Mounting(
        b_R_d0=rpy_deg_to_matrix(mount.dvl_rpy_deg),
        b_p_dvl=np.asarray(mount.dvl_lever_arm_m, dtype=float),
    )


def metadata(
    scenario: Scenario,
    seed: int,
    white_noise: bool,
    mounting: Mounting,
    gyro_bias0: np.ndarray,
    accel_bias0: np.ndarray,
    bias_series: dict[str, Any] | None,
    given_dvl: DvlSpec,
    constant: np.ndarray | None,
) -> dict[str, Any]:
    """LogData.metadata of a run: the scenario and seed, the truth (the initial biases gyro_bias0 rad/s and
    accel_bias0 m/s^2, bias_series when they walk, the DVL's, the run's constant error) and the sensors'
    specification (given_dvl: the [dvl] table before a calibration drawn per seed)."""
    out = _base_metadata(
        scenario, seed, white_noise, mounting, gyro_bias0, accel_bias0, bias_series
    )
    _sensor_metadata(scenario, out)
    _drawn_metadata(out, given_dvl, constant)
    return out


def map_origin(scenario: Scenario) -> GeoOrigin:
    """The map origin the log states (the scenario's [origin])."""
    return GeoOrigin(
        float(scenario.origin.lat_deg),
        float(scenario.origin.lon_deg),
        float(scenario.origin.height_m),
    )


def map_from_first_fix(
    scenario: Scenario, fix_frame: LocalFrame | None, metadata: dict[str, Any]
) -> LocalFrame:
    """gnss.origin_in_log = false: the first fix's frame becomes the map (metadata without "origin", the truth's
    map origin recorded); an error without any fix."""
    if fix_frame is None:
        raise GtsamDvlError(
            f"{scenario.source}: key 'gnss.origin_in_log': false needs at least one fix, "
            "and the vehicle never surfaces while the receiver records"
        )
    metadata.pop("origin", None)
    metadata["truth"]["map_origin"] = {
        "lat_deg": fix_frame.lat_deg,
        "lon_deg": fix_frame.lon_deg,
        "height_m": fix_frame.height_m,
        "from": "first GNSS fix",
    }
    return fix_frame


def log_data(
    scenario: Scenario,
    seed: int,
    gyro_bias0: np.ndarray,
    accel_bias0: np.ndarray,
    metadata: dict[str, Any],
    origin: GeoOrigin | None,
    **data: Any,
) -> LogData:
    """The LogData of a simulation: its sensor data and truth (data) with the typed fields of the scenario."""
    # without white noise the DVL repeats its velocity bit for bit (DvlData.noise_free)
    if "dvl" in data:
        data["dvl"].noise_free = not metadata.get("white_noise", True)
    return LogData(
        t0_ns=scenario.t0_ns,
        metadata=metadata,
        source=f"simulated:{scenario.name}:seed={seed}",
        origin=origin,
        true_calibration=DvlCalibration(
            float(scenario.dvl.scale),
            tuple(float(a) for a in scenario.dvl.misalignment_deg),  # type: ignore[arg-type]
            float(scenario.rates.dvl_time_offset_s),
        ),
        true_imu_bias=ImuBiases(tuple(accel_bias0.tolist()), tuple(gyro_bias0.tolist())),  # type: ignore[arg-type]
        segments=scenario.segments_typed(),
        **data,
    )


def _base_metadata(
    scenario: Scenario,
    seed: int,
    white: bool,
    mounting: Mounting,
    gyro_bias0: np.ndarray,
    accel_bias0: np.ndarray,
    bias_series: dict[str, Any] | None,
) -> dict[str, Any]:
    """The metadata of the scenario's [imu] and [dvl] (the optional errors only when on), the truth and the
    rest of the run (bias_series: the biases once a second when they walk, else None)."""
    from gtsam_dvl import __version__

    o = scenario.origin
    imu_truth_md: dict[str, Any] = {
        "gyro_bias_rad_s": gyro_bias0.tolist(),
        "accel_bias_m_s2": accel_bias0.tolist(),
    }
    if bias_series is not None:
        imu_truth_md["bias_series"] = bias_series
    return {
        "scenario_name": scenario.name,
        "scenario": copy.deepcopy(scenario.raw),
        "seed": int(seed),
        "white_noise": bool(white),
        "origin": {
            "lat_deg": float(o.lat_deg),
            "lon_deg": float(o.lon_deg),
            "height_m": float(o.height_m),
        },
        "truth": {
            "dvl": {
                "scale": float(scenario.dvl.scale),
                "misalignment_deg": [float(a) for a in scenario.dvl.misalignment_deg],
                "b_R_d0": mounting.b_R_d0.tolist(),
                "b_lever_arm_m": mounting.b_l.tolist(),
                "time_offset_s": float(scenario.rates.dvl_time_offset_s),
            },
            "imu": imu_truth_md,
            "segments": scenario.segment_table(),
            **_water_truth(scenario),
        },
        "sensors": {  # the optional errors only when on (the metadata of a scenario without them stays as it was)
            "imu": _without(
                _listify_spec(asdict(scenario.imu)),
                tuple(
                    k
                    for k in (
                        "quantisation_gyro_rad_s",
                        "quantisation_accel_m_s2",
                        "saturation_gyro_rad_s",
                        "saturation_accel_m_s2",
                    )
                    if not np.any(getattr(scenario.imu, k))
                ),
            ),
            "dvl": _without(
                _listify_spec(asdict(scenario.dvl)),
                (
                    ("correlated_sigma_m_s", "correlated_tau_s")
                    if scenario.dvl.correlated_sigma_m_s == 0
                    else ()
                )
                + (("bottom_range_m", "water_track_noise_m_s") if scenario.seafloor is None else ())
                + tuple(k for k in _DVL_OPTIONAL if not np.any(getattr(scenario.dvl, k))),
            ),
            "rates": asdict(scenario.rates),
            "mounting": _listify_spec(asdict(scenario.mounting)),
        },
        "generator": f"gtsam_dvl {__version__}",
    }


def _sensor_metadata(scenario: Scenario, metadata: dict[str, Any]) -> None:
    """The [depth] and [gnss] specifications into metadata["sensors"], when the scenario has them."""
    if scenario.depth is not None:
        metadata["sensors"]["depth"] = _listify_spec(asdict(scenario.depth))
    if scenario.gnss is not None:
        metadata["sensors"]["gnss"] = _listify_spec(asdict(scenario.gnss))


def _drawn_metadata(metadata: dict[str, Any], given: DvlSpec, constant: np.ndarray | None) -> None:
    """A drawn calibration and a constant error in the metadata: "sensors" keeps the [dvl] table's scale and
    misalignment (the draw's mean; "truth" has the drawn ones), "truth" gets the run's constant error (m/s in
    dvl_link). Nothing changes for a scenario without them."""
    sensors, truth = metadata["sensors"]["dvl"], metadata["truth"]["dvl"]
    if sensors.get("draw_scale_sigma") or sensors.get("draw_misalignment_sigma_deg"):
        sensors["scale"], sensors["misalignment_deg"] = (
            float(given.scale),
            list(given.misalignment_deg),
        )
    if constant is not None:
        truth["constant_error_m_s"] = constant.tolist()


def _water_truth(scenario: Scenario) -> dict[str, Any]:
    """metadata["truth"]'s "current" and "seafloor" (sim/current.py), those the scenario has."""
    out: dict[str, Any] = {}
    if scenario.current is not None:
        out["current"] = _listify_spec(asdict(scenario.current))
    if scenario.seafloor is not None:
        out["seafloor"] = asdict(scenario.seafloor)
    return out


def _without(d: dict[str, Any], keys: tuple[str, ...]) -> dict[str, Any]:
    """d without keys (the settings of an error that is off)."""
    return {k: v for k, v in d.items() if k not in keys}


def _listify_spec(d: dict[str, Any]) -> dict[str, Any]:
    """A specification's dict with its tuples as lists (as JSON and TOML write them)."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}
