"""Simulation scenarios: a typed view of a scenario TOML file (origin, rates, motion, sensors, mounting).

Units in the files are the ones navigation people quote (degrees, deg/h, micro-g, deg/h/sqrt(Hz),
micro-g/sqrt(Hz), m/s, seconds) and every key name carries its unit. The dataclasses keep those units;
the simulator converts to SI. Built-in scenarios live in data/scenarios/, installed as the package
`gtsam_dvl.scenarios`.
"""

from __future__ import annotations

import copy
import importlib.resources
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.config import NAMED_CONFIGS, EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import Segment
from gtsam_dvl.core.units import DEG_PER_H, MICRO_G
from gtsam_dvl.sim.current import CurrentSpec, SeafloorSpec, current_spec, seafloor_spec
from gtsam_dvl.sim.schema import SEGMENT_KINDS, Reader, check_dvl_draws, parse_segments

# ROS time of t = 0 when the file gives none: fixed so logs are reproducible
DEFAULT_T0_S = 1_700_000_000

__all__ = [
    "DEG_PER_H",
    "MICRO_G",
    "SEGMENT_KINDS",
    "CurrentSpec",
    "DepthSpec",
    "DvlSpec",
    "GnssSpec",
    "ImuSpec",
    "InitialState",
    "MotionSegment",
    "MountingSpec",
    "OscillationSpec",
    "Origin",
    "Rates",
    "Scenario",
    "SeafloorSpec",
    "list_builtin_scenarios",
    "load_scenario",
    "scenario_from_dict",
]


@dataclass(frozen=True)
class Origin:
    """Geodetic origin of the map frame and the vehicle's start point (WGS84)."""

    lat_deg: float
    lon_deg: float
    height_m: float = 0.0


@dataclass(frozen=True)
class Rates:
    """Sensor and truth rates. The DVL measures at k / dvl_hz and stamps each ping dvl_time_offset_s earlier
    (dt_d > 0: the stamps are early; the ping stamped t measures the velocity at t + dt_d, docs/conventions.md)."""

    imu_hz: float = 100.0
    dvl_hz: float = 1.0
    truth_hz: float = 10.0
    dvl_time_offset_s: float = 0.0


@dataclass(frozen=True)
class InitialState:
    """Attitude of base_link in the local level (ENU; yaw counter-clockwise from east) and speed at t = 0."""

    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    speed_m_s: float = 0.0


@dataclass(frozen=True)
class MotionSegment:
    """One row of the motion table. Times are filled in by the loader from the durations.

    kind: static | level | straight | descent | ascent | turn | arc | square (see sim/schema.py).
    paper_type: the paper's segment type, "I", "II", "I+II" or "-".
    """

    kind: str
    start_s: float
    end_s: float
    paper_type: str
    speed_end_m_s: float | None = None  # level: speed at the end (None: unchanged)
    speed_bump_m_s: float = 0.0  # level: peak of a smooth surge added on top
    peak_vertical_speed_m_s: float = 0.0  # descent/ascent: peak sink/rise rate (positive)
    heading_change_deg: float = 0.0  # turn: positive = left (counter-clockwise seen from above)
    bank_deg: float = 0.0  # turn/square: peak roll into the turn
    turn_rate_deg_s: float = 0.0  # arc: constant turn rate, positive = left
    leg_duration_s: float = 0.0  # square
    turn_duration_s: float = 0.0  # square
    sides: int = 4  # square
    turn_first: bool = False  # square: start with a turn instead of a leg
    direction: str = "left"  # square

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True)
class ImuSpec:
    """IMU errors in file units. Biases: 1-sigma of a random constant per axis unless values are given.
    quantisation_*: the logged outputs' step per axis (a number for all three, or a list of 3; 0: none): each
    sample is rounded to a multiple of it, round(x / q) q, after the biases and the noise (a driver's fixed-point
    format, or an export with a fixed number of decimals). saturation_*: the output range per axis (0: none):
    every sample is clipped to +-it, after the quantisation (a sensor whose rate or specific force exceeds its
    range reports the range's limit, so a turn faster than the gyro's range logs a run of equal samples)."""

    gyro_bias_deg_per_h: float = 0.0
    accel_bias_micro_g: float = 0.0
    gyro_bias_values_deg_per_h: tuple[float, float, float] | None = None
    accel_bias_values_micro_g: tuple[float, float, float] | None = None
    gyro_noise_deg_per_h_per_sqrt_hz: float = 0.0
    accel_noise_micro_g_per_sqrt_hz: float = 0.0
    gyro_bias_walk_deg_per_h_per_sqrt_h: float = 0.0
    accel_bias_walk_micro_g_per_sqrt_h: float = 0.0
    quantisation_gyro_rad_s: float | tuple[float, float, float] = 0.0
    quantisation_accel_m_s2: float | tuple[float, float, float] = 0.0
    saturation_gyro_rad_s: float = 0.0
    saturation_accel_m_s2: float = 0.0


@dataclass(frozen=True)
class DvlSpec:
    """DVL truth calibration, beam geometry, noise and bottom-lock model (file units). The velocity error is the
    white ping noise (noise_m_s) plus, when correlated_sigma_m_s > 0, a first-order Gauss-Markov error per DVL
    axis of stationary std correlated_sigma_m_s and time constant correlated_tau_s (sim/dvl.py
    gauss_markov), added to the velocity in dvl_link before the beams are formed."""

    scale: float = 1.0
    misalignment_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # roll, pitch, yaw of R_c (FLU)
    # "velocity": 3-D white noise; "beam": per-beam noise + least squares
    noise_model: str = "velocity"
    noise_m_s: float = 0.0  # 1 sigma, per axis ("velocity") or per beam ("beam")
    beam_angle_deg: float = 30.0  # from the face axis
    face_axis: tuple[float, float, float] = (0.0, 0.0, -1.0)  # in dvl_link, towards the bottom
    altitude_m: float = 30.0  # flat seafloor this far below the starting height
    max_range_m: float = 200.0  # beams longer than this lose bottom lock
    dropout_ping_prob: float = 0.0
    dropout_beam_prob: float = 0.0
    outlier_prob: float = 0.0  # per ping ("velocity") or per beam ("beam")
    outlier_m_s: float = 1.0  # size of a gross error
    correlated_sigma_m_s: float = 0.0  # Gauss-Markov error: stationary 1 sigma per axis (0: none)
    correlated_tau_s: float = 60.0  # its time constant
    # with a [seafloor] table (sim/current.py): bottom lock while the DVL's altitude is at most bottom_range_m (0: the
    # max_range_m, which a preset fills with its maximum altitude), water track beyond, with its own white noise
    # (per axis, or per beam with noise_model "beam"). 1 cm/s, typical of the class: a water-track ping measures the
    # Doppler of the scatterers in a water layer a few metres below the DVL (Water Linked's water-tracking page:
    # 1.5-4.5 m), weaker and more diffuse than a seafloor echo, so it is noisier than the same DVL's bottom track
    bottom_range_m: float = 0.0
    water_track_noise_m_s: float = 0.01
    # what the messages' covariance states, 1 sigma per axis (or per beam); 0: noise_m_s. A real DVL's stated
    # noise is often several times its ping-to-ping scatter (a datasheet's long-term accuracy, or a driver's fixed
    # covariance), so an estimator that fits the scatter weights the DVL above its slow errors (issue 31)
    stated_noise_m_s: float = 0.0
    # a constant velocity error per dvl_link axis, drawn per seed (its own random stream, sim/dvl.py): 1 sigma
    # (0: none). Beside the Gauss-Markov error, what a DVL's long-term accuracy leaves in a run
    constant_error_sigma_m_s: float = 0.0
    # the truth calibration drawn per seed around scale and misalignment_deg (sim/dvl.py draw_calibration): the
    # scale's 1 sigma and the misalignment's about body x, y, z (deg, a number or a list of 3), drawn as a
    # rotation vector in body axes as the estimators' prior states it (core/states.py); 0: the table's values
    draw_scale_sigma: float = 0.0
    draw_misalignment_sigma_deg: float | tuple[float, float, float] = 0.0
    # a DVL preset (core/config/presets.py DVL_PRESETS, "" none): fills the keys the table does not set, the ping
    # noise (noise_m_s: per axis, or per beam with noise_model "beam"), the correlated error, the bottom-track range
    # (max_range_m) and the beam angle (dvl_preset_values); the truth scale stays the table's
    model: str = ""


def dvl_preset_values(model: str, noise_model: str) -> dict[str, float]:
    """The DvlSpec keys a DVL preset gives (DvlSpec.model)."""
    from gtsam_dvl.core.config.presets import DVL_PRESETS

    p = DVL_PRESETS[model]
    return {
        "noise_m_s": p.beam_noise_m_s() if noise_model == "beam" else p.ping_noise_m_s,
        "correlated_sigma_m_s": p.correlated_sigma_m_s,
        "correlated_tau_s": p.correlated_tau_s,
        "max_range_m": p.max_altitude_m,
        "beam_angle_deg": p.beam_angle_deg,
    }


@dataclass(frozen=True)
class OscillationSpec:
    """Small sinusoidal motion added to the whole trajectory (optional [oscillation] table; sim/motion.py):
    amplitude * sin(2 pi t / period) on roll, pitch and yaw (deg) and on the height (heave, m); each key a number
    or a list (a sum of sinusoids: as many periods as amplitudes). A real vehicle never holds a perfectly constant
    rate: its slow motions and its vibration keep a quantised IMU's outputs crossing their steps, so that the
    rounding error is white. The truth, the IMU and the DVL all include the oscillation."""

    roll_deg: tuple[float, ...] = (0.0,)
    roll_period_s: tuple[float, ...] = (7.0,)
    pitch_deg: tuple[float, ...] = (0.0,)
    pitch_period_s: tuple[float, ...] = (11.0,)
    yaw_deg: tuple[float, ...] = (0.0,)
    yaw_period_s: tuple[float, ...] = (13.0,)
    heave_m: tuple[float, ...] = (0.0,)
    heave_period_s: tuple[float, ...] = (9.0,)

    def channels(self) -> list[tuple[str, tuple[float, ...], tuple[float, ...]]]:
        """(channel, amplitudes, periods) of roll, pitch, yaw (deg) and heave (m)."""
        return [
            (
                c,
                getattr(self, f"{c}_{'m' if c == 'heave' else 'deg'}"),
                getattr(self, f"{c}_period_s"),
            )
            for c in ("roll", "pitch", "yaw", "heave")
        ]


@dataclass(frozen=True)
class MountingSpec:
    """Nominal DVL mounting in base_link (what /tf_static says) and lever arm from the IMU."""

    dvl_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # b_R_d0 = Rz Ry Rx
    dvl_lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class DepthSpec:
    """Pressure sensor (optional [depth] table; a scenario without it has no /depth/pressure). The water surface
    is at ellipsoidal height 0: the sensor at height h is at depth -h, and measures the absolute pressure
    atmospheric_pa + water_density_kg_m3 * g_column * depth (core/earth.py depth_to_pressure) plus a constant
    bias_m and white noise_m (both in metres of depth, converted to Pa). Stamps k / rate_hz, which must divide
    the IMU rate. lever_arm_m: the sensor in base_link."""

    rate_hz: float = 1.0
    noise_m: float = 0.05
    bias_m: float = 0.0
    water_density_kg_m3: float = 1025.0
    atmospheric_pa: float = 101325.0
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class GnssSpec:
    """GNSS receiver (optional [gnss] table; a scenario without it has no /gnss/fix). Fixes of the antenna
    (antenna_lever_arm_m in base_link) at k / rate_hz (must divide the IMU rate) while the vehicle is at the
    surface, i.e. base_link's depth below the surface at ellipsoidal height 0 is under max_depth_m, and
    within [start_s, end_s] (None: the whole run). White noise horizontal_sigma_m per horizontal axis and
    vertical_sigma_m up, in ENU at the antenna; status 0; covariance diag(h^2, h^2, v^2). origin_in_log =
    false: the log records no map origin, as on a real vehicle; the reader then takes the first fix as the
    origin, and the simulated truth is expressed in that fix's ENU frame (sim/gnss.py)."""

    rate_hz: float = 1.0
    horizontal_sigma_m: float = 2.0
    vertical_sigma_m: float = 4.0
    antenna_lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.5)
    max_depth_m: float = 0.5
    start_s: float | None = None
    end_s: float | None = None
    origin_in_log: bool = True


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario. raw keeps the TOML dict (goes into the log metadata unchanged)."""

    name: str
    description: str
    origin: Origin
    rates: Rates
    initial: InitialState
    imu: ImuSpec
    dvl: DvlSpec
    mounting: MountingSpec
    segments: tuple[MotionSegment, ...]
    raw: dict[str, Any]
    source: str = "<dict>"
    t0_ns: int = DEFAULT_T0_S * 1_000_000_000
    depth: DepthSpec | None = None  # the [depth] table, if the scenario has one
    gnss: GnssSpec | None = None  # the [gnss] table, if the scenario has one
    # the named estimator configuration (core/config/estimator.py NAMED_CONFIGS) this scenario's runs are meant for:
    # smooth and plan use it when no configuration is given (the paper's runs: "paper")
    estimator_config: str = "default"
    oscillation: OscillationSpec | None = None  # the [oscillation] table, if the scenario has one
    # the [estimator] table: a partial estimator configuration (EstimatorConfig's tables) applied over the named
    # one, e.g. what is known about this log (its initial attitude); empty: none
    estimator: dict[str, Any] = field(default_factory=dict)
    # the [current] table, if the scenario has one (sim/current.py)
    current: CurrentSpec | None = None
    # the [seafloor] table: bottom lock by altitude and water track
    seafloor: SeafloorSpec | None = None

    def estimator_configuration(self) -> EstimatorConfig:
        """The configuration this scenario's runs are meant for: estimator_config's named configuration with the
        [estimator] table's overrides (EstimatorConfig.for_scenario)."""
        return EstimatorConfig.for_scenario(self.raw)

    @property
    def duration_s(self) -> float:
        return self.segments[-1].end_s

    def local_frame(self) -> LocalFrame:
        """The map frame: ENU at the origin."""
        return LocalFrame(self.origin.lat_deg, self.origin.lon_deg, self.origin.height_m)

    def segments_typed(self) -> list[Segment]:
        """segment_table() as Segment values (LogData.segments of a simulated log)."""
        return [Segment.from_dict(row) for row in self.segment_table()]

    def segment_table(self) -> list[dict[str, Any]]:
        """Rows {start_s, end_s, kind, type} with the paper's segment type (Table 1). Consecutive pieces of
        the same kind and type (e.g. a speed-up then a surge, both level Type I) form one row, as the
        paper's table counts segments by motion."""
        rows: list[dict[str, Any]] = []
        for s in self.segments:
            if (
                rows
                and rows[-1]["kind"] == s.kind
                and rows[-1]["type"] == s.paper_type
                and s.kind != "static"
            ):
                rows[-1]["end_s"] = s.end_s
            else:
                rows.append(
                    {"start_s": s.start_s, "end_s": s.end_s, "kind": s.kind, "type": s.paper_type}
                )
        return rows


def list_builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped with the package."""
    files = importlib.resources.files("gtsam_dvl.scenarios")
    return sorted(p.name[: -len(".toml")] for p in files.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name ("paper-3d") or a scenario TOML file by path."""
    text: str
    if isinstance(name_or_path, str) and name_or_path in list_builtin_scenarios():
        res = importlib.resources.files("gtsam_dvl.scenarios") / f"{name_or_path}.toml"
        text, source, stem = res.read_text(encoding="utf-8"), f"{name_or_path}.toml", name_or_path
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise GtsamDvlError(
                f"scenario '{name_or_path}' not found: no such file and not a built-in "
                f"({', '.join(list_builtin_scenarios())})"
            )
        text, source, stem = path.read_text(encoding="utf-8"), str(path), path.stem
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise GtsamDvlError(f"{source}: invalid TOML: {exc}") from exc
    return scenario_from_dict(raw, name=stem, source=source)


# the top-level keys of a scenario file (tables and values)
_TOP_KEYS = (
    "name",
    "description",
    "t0_s",
    "origin",
    "rates",
    "initial",
    "imu",
    "dvl",
    "mounting",
    "segments",
    "depth",
    "gnss",
    "estimator_config",
    "oscillation",
    "estimator",
    "current",
    "seafloor",
)


def scenario_from_dict(
    raw: dict[str, Any], name: str = "custom", source: str = "<dict>"
) -> Scenario:
    """Build a Scenario from a dict shaped like a scenario file (tests and scripts use this). Each table is read,
    then checked, in the order of the file's layout: the first error found is the one raised."""
    r = Reader(raw, source)
    r.check_keys("", list(_TOP_KEYS))
    estimator_config = raw.get("estimator_config", "default")
    r.require(
        isinstance(estimator_config, str) and estimator_config in NAMED_CONFIGS,
        "estimator_config",
        f"must be the name of a built-in configuration ({', '.join(NAMED_CONFIGS)})",
    )
    origin, rates, initial = _origin_rates_initial(r)
    imu = ImuSpec(
        **r.table(
            "imu",
            _defaults(ImuSpec),
            vectors=("gyro_bias_values_deg_per_h", "accel_bias_values_micro_g"),
            per_axis=("quantisation_gyro_rad_s", "quantisation_accel_m_s2"),
        )
    )
    dvl = _dvl_spec(r)
    _check_imu(r, imu)
    _check_dvl(r, dvl)
    mounting = MountingSpec(
        **r.table("mounting", _defaults(MountingSpec), vectors=("dvl_rpy_deg", "dvl_lever_arm_m"))
    )
    segments = tuple(MotionSegment(**row) for row in parse_segments(r, initial.speed_m_s))
    depth = _depth_spec(r, rates.imu_hz) if "depth" in raw else None
    gnss = _gnss_spec(r, rates.imu_hz) if "gnss" in raw else None
    oscillation = _oscillation_spec(r, rates.imu_hz) if "oscillation" in raw else None
    estimator = raw.get("estimator", {})
    r.require(
        isinstance(estimator, dict),
        "estimator",
        "expected a table of estimator configuration tables",
    )
    # checked now: a bad key fails at load
    EstimatorConfig.for_scenario(raw, source=f"{source}: [estimator]")
    t0 = raw.get("t0_s", DEFAULT_T0_S)
    r.number("t0_s", t0)
    t0_ns = t0 * 1_000_000_000 if isinstance(t0, int) else int(round(t0 * 1e9))  # ints stay exact
    return Scenario(
        name=str(raw.get("name", name)),
        description=str(raw.get("description", "")),
        origin=origin,
        rates=rates,
        initial=initial,
        imu=imu,
        dvl=dvl,
        mounting=mounting,
        segments=segments,
        raw=raw,
        source=source,
        t0_ns=t0_ns,
        depth=depth,
        estimator_config=estimator_config,
        gnss=gnss,
        oscillation=oscillation,
        estimator=copy.deepcopy(estimator),
        current=current_spec(r) if "current" in raw else None,
        seafloor=seafloor_spec(r) if "seafloor" in raw else None,
    )


def _origin_rates_initial(r: Reader) -> tuple[Origin, Rates, InitialState]:
    """The [origin], [rates] and [initial] tables, checked (the truth rate divides the IMU rate)."""
    origin = Origin(**r.table("origin", {"lat_deg": None, "lon_deg": None, "height_m": 0.0}))
    r.require(abs(origin.lat_deg) < 90.0, "origin.lat_deg", "must be in (-90, 90)")
    rates = Rates(**r.table("rates", _defaults(Rates)))
    for key in ("imu_hz", "dvl_hz", "truth_hz"):
        r.require(getattr(rates, key) > 0, f"rates.{key}", "must be positive")
    ratio = rates.imu_hz / rates.truth_hz
    r.require(abs(ratio - round(ratio)) < 1e-9, "rates.truth_hz", "must divide rates.imu_hz")
    initial = InitialState(**r.table("initial", _defaults(InitialState)))
    r.require(initial.speed_m_s >= 0, "initial.speed_m_s", "must be >= 0")
    return origin, rates, initial


def _dvl_spec(r: Reader) -> DvlSpec:
    """The [dvl] table, its values not yet checked (_check_dvl): a named model's preset fills the keys the table
    does not give; bottom_range_m 0 means max_range_m."""
    dvl_table = r.table(
        "dvl",
        _defaults(DvlSpec),
        vectors=("misalignment_deg", "face_axis"),
        strings=("noise_model", "model"),
        per_axis=("draw_misalignment_sigma_deg",),
    )
    if dvl_table["model"]:
        from gtsam_dvl.core.config.presets import DVL_PRESETS

        r.require(
            dvl_table["model"] in DVL_PRESETS,
            "dvl.model",
            f"{dvl_table['model']!r} is not one of {', '.join(DVL_PRESETS)}",
        )
        given = r.raw.get("dvl", {})
        dvl_table.update(
            {
                k: v
                for k, v in dvl_preset_values(dvl_table["model"], dvl_table["noise_model"]).items()
                if k not in given
            }
        )
    if not dvl_table["bottom_range_m"]:
        dvl_table["bottom_range_m"] = dvl_table["max_range_m"]
    return DvlSpec(**dvl_table)


def _check_imu(r: Reader, imu: ImuSpec) -> None:
    """The [imu] values in range: 1-sigma values, quantisation steps and saturation limits >= 0."""
    for key in (
        "gyro_bias_deg_per_h",
        "accel_bias_micro_g",
        "gyro_noise_deg_per_h_per_sqrt_hz",
        "accel_noise_micro_g_per_sqrt_hz",
        "gyro_bias_walk_deg_per_h_per_sqrt_h",
        "accel_bias_walk_micro_g_per_sqrt_h",
    ):
        r.require(getattr(imu, key) >= 0, f"imu.{key}", "must be >= 0 (a 1-sigma value)")
    for key in ("quantisation_gyro_rad_s", "quantisation_accel_m_s2"):
        r.require(
            min(np.atleast_1d(getattr(imu, key))) >= 0,
            f"imu.{key}",
            "must be >= 0 (0: not quantised)",
        )
    for key in ("saturation_gyro_rad_s", "saturation_accel_m_s2"):
        r.require(getattr(imu, key) >= 0, f"imu.{key}", "must be >= 0 (0: no saturation)")


def _check_dvl(r: Reader, dvl: DvlSpec) -> None:
    """The [dvl] values in range: scale, ranges and noises, the drawn calibration, the beam geometry and the
    probabilities of dropouts and outliers."""
    for key in ("scale", "altitude_m", "max_range_m", "outlier_m_s"):
        r.require(getattr(dvl, key) > 0, f"dvl.{key}", "must be positive")
    r.require(dvl.noise_m_s >= 0, "dvl.noise_m_s", "must be >= 0")
    r.require(dvl.water_track_noise_m_s >= 0, "dvl.water_track_noise_m_s", "must be >= 0")
    r.require(dvl.bottom_range_m > 0, "dvl.bottom_range_m", "must be positive (0: max_range_m)")
    r.require(
        dvl.correlated_sigma_m_s >= 0,
        "dvl.correlated_sigma_m_s",
        "must be >= 0 (0: no correlated error)",
    )
    r.require(dvl.correlated_tau_s > 0, "dvl.correlated_tau_s", "must be positive")
    check_dvl_draws(r, dvl)
    r.require(
        dvl.noise_model in ("velocity", "beam"), "dvl.noise_model", "must be 'velocity' or 'beam'"
    )
    r.require(0.0 < dvl.beam_angle_deg < 90.0, "dvl.beam_angle_deg", "must be in (0, 90)")
    r.require(sum(c * c for c in dvl.face_axis) > 0, "dvl.face_axis", "must be non-zero")
    for key in ("dropout_ping_prob", "dropout_beam_prob", "outlier_prob"):
        r.require(0.0 <= getattr(dvl, key) <= 1.0, f"dvl.{key}", "must be in [0, 1]")


def _depth_spec(r: Reader, imu_hz: float) -> DepthSpec:
    """The [depth] table, checked (its rate divides the IMU rate)."""
    depth = DepthSpec(**r.table("depth", _defaults(DepthSpec), vectors=("lever_arm_m",)))
    for key in ("rate_hz", "water_density_kg_m3"):
        r.require(getattr(depth, key) > 0, f"depth.{key}", "must be positive")
    r.require(depth.noise_m >= 0, "depth.noise_m", "must be >= 0")
    r.require(depth.atmospheric_pa >= 0, "depth.atmospheric_pa", "must be >= 0")
    dr = imu_hz / depth.rate_hz
    r.require(abs(dr - round(dr)) < 1e-9, "depth.rate_hz", "must divide rates.imu_hz")
    return depth


def _oscillation_spec(r: Reader, imu_hz: float) -> OscillationSpec:
    """The [oscillation] table, checked: each key a number or a list of numbers, as many periods as amplitudes,
    periods of at least 4 IMU samples (the IMU quadrature's accuracy), angles within +-10 deg."""
    d = r.raw["oscillation"]
    if not isinstance(d, dict):
        raise r.fail("oscillation", "expected a table")
    defaults = _defaults(OscillationSpec)
    r.check_keys("oscillation", list(defaults), d)
    values: dict[str, tuple[float, ...]] = {}
    for key, default in defaults.items():
        v = d.get(key, list(default))
        items = v if isinstance(v, list) else [v]
        r.require(len(items) > 0, f"oscillation.{key}", "expected a number or a list of numbers")
        values[key] = tuple(r.number(f"oscillation.{key}", x) for x in items)
    spec = OscillationSpec(**values)
    for channel, amplitudes, periods in spec.channels():
        key = f"oscillation.{channel}_period_s"
        r.require(
            len(periods) == len(amplitudes),
            key,
            f"give one period per amplitude ({len(amplitudes)})",
        )
        r.require(
            min(periods) >= 4.0 / imu_hz,
            key,
            f"must be at least 4 IMU samples ({4.0 / imu_hz:g} s)",
        )
        if channel != "heave":
            r.require(
                max(abs(a) for a in amplitudes) <= 10.0,
                f"oscillation.{channel}_deg",
                "must be within +-10 deg (a small oscillation)",
            )
    return spec


def _gnss_spec(r: Reader, imu_hz: float) -> GnssSpec:
    """The [gnss] table, checked (the optional window and the origin flag read apart from the numbers)."""
    d = r.raw["gnss"]
    if not isinstance(d, dict):
        raise r.fail("gnss", "expected a table")
    r.check_keys("gnss", list(_defaults(GnssSpec)), d)
    extra: dict[str, Any] = {}
    for key in ("start_s", "end_s"):
        if key in d:
            extra[key] = r.number(f"gnss.{key}", d[key])
    if "origin_in_log" in d:
        r.require(
            isinstance(d["origin_in_log"], bool), "gnss.origin_in_log", "must be true or false"
        )
        extra["origin_in_log"] = d["origin_in_log"]
    numbers = {
        k: v
        for k, v in _defaults(GnssSpec).items()
        if k not in ("start_s", "end_s", "origin_in_log")
    }
    rest = {k: v for k, v in d.items() if k in numbers}
    spec = GnssSpec(
        **Reader({"gnss": rest}, r.source).table("gnss", numbers, vectors=("antenna_lever_arm_m",)),
        **extra,
    )
    r.require(spec.rate_hz > 0, "gnss.rate_hz", "must be positive")
    ratio = imu_hz / spec.rate_hz
    r.require(abs(ratio - round(ratio)) < 1e-9, "gnss.rate_hz", "must divide rates.imu_hz")
    for key in ("horizontal_sigma_m", "vertical_sigma_m", "max_depth_m"):
        r.require(getattr(spec, key) >= 0, f"gnss.{key}", "must be >= 0")
    if spec.start_s is not None and spec.end_s is not None:
        r.require(spec.end_s >= spec.start_s, "gnss.end_s", "must be >= gnss.start_s")
    return spec


def _defaults(cls: type) -> dict[str, Any]:
    """Field defaults of a dataclass, as the Reader's table of optional keys."""
    return {k: v.default for k, v in cls.__dataclass_fields__.items()}  # type: ignore[attr-defined]
