"""The summary of a run as one typed model: what `gtsam-dvl smooth --summary` writes, a result's summary.json, and
what read_result gives back (StoredResult.summary).

``Summary`` is the trajectory estimators' (batch, online, online-full, ekf; also the planner's and a fleet's runs),
``IoDvlcSummary`` io-dvlc's (the calibration alone). Every estimator's summary is built through them
(analysis/metrics.py build_summary; io-dvlc's in app/commands.py), and ``to_json_dict`` is the dict written: the keys
the builder set, a key set to None written as null. ``parse_summary`` and ``read_summary`` read one back: migrated
from the schema_version it was written with (core/config/schema.py; a summary without the key was written before
version 8), then validated, a summary that does not fit being one GtsamDvlError line. ``summary_schema`` is the
JSON Schema of both, kept in docs/summary-schema.json (tests/core/test_summary.py regenerates and compares it).

Every model forbids keys it does not know. Three parts stay open (``dict[str, Any]``) for now, as they hold what one
estimator or one reader case reports and are read by no console or evaluation code as fields: ``Summary.info`` (the
estimator's internals, NavResult.info), ``HealthSummary.figures`` (the health's supporting numbers) and the per-topic
records of ``Losses.clock_steps`` and ``Losses.saturation``. Numbers may be NaN or infinite (written as the tokens
NaN and Infinity, as Python's json module does).

The calibration hold (``CalibrationHold``) has one shape for every estimator and every reason: ``reason`` says why
what is ``held`` is held ("nominal_check": estimating the scale and misalignment did not pay for their four states,
so every direction is held at the nominal; "weak_directions": the directions the run informs less than [priors]
hold_weak_information of their prior's information are held at the prior; "none": nothing held, ``released`` the
weak directions the batch smoother let go because pinning them cost too much chi^2), ``why`` says it in words, and
each held direction is a ``HeldDirection``: the direction (one prior sigma along it, in the calibration's units),
the data's information along it in units of its prior's, and the component it is mostly made of.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from gtsam_dvl.core.config.schema import SCHEMA_VERSION, checked_version
from gtsam_dvl.core.errors import GtsamDvlError

# the versions before the summary stated its schema_version (it was first written at version 8)
UNVERSIONED = 7

DirectionName = Literal["scale", "misalignment roll", "misalignment pitch", "misalignment yaw"]
DIRECTION_NAMES: tuple[DirectionName, ...] = (
    "scale",
    "misalignment roll",
    "misalignment pitch",
    "misalignment yaw",
)
HoldReason = Literal["nominal_check", "weak_directions", "none"]
HealthStatus = Literal["ok", "warn", "degraded", "failed"]


class SummaryModel(BaseModel):
    """A part of the summary whose shape is ours: unknown keys refused."""

    model_config = ConfigDict(extra="forbid")


class ValueSigma(SummaryModel):
    """A scalar estimate and its marginal sigma."""

    value: float
    sigma: float


class VectorSigma(SummaryModel):
    """A vector estimate (per axis) and its marginal sigmas."""

    value: list[float]
    sigma: list[float] = Field(default_factory=list)


class Misalignment(VectorSigma):
    """The DVL misalignment [roll, pitch, yaw] (deg) with its sigmas and the convention it is stated in."""

    convention: str = ""


# ----- the calibration hold (estimators/models/weak_hold.py) ----------------------------------------------------


class NominalCheck(SummaryModel):
    """The nominal calibration's check (weak_hold.py nominal_check): the chi^2 the estimated scale and misalignment
    gain over the nominal, its limit (the level's quantile of chi^2 with 4 dof) and whether they pay for it."""

    chi2_gain: float
    chi2_limit: float
    level: float
    pays: bool


class HeldDirection(SummaryModel):
    """A direction of the DVL scale and misalignment (held or released): ``direction`` one prior sigma along it
    (scale; misalignment deg), ``information`` the data's information along it in units of its prior's (lambda),
    ``mostly`` its largest component in prior sigmas. ``information`` and ``direction`` are None only in a summary
    written before schema version 8 by the EKF, which named the states it held ("scale", "misalignment") and
    nothing more; ``information`` is NaN when the EKF's covariance was not finite (its directions then the prior's
    axes)."""

    mostly: DirectionName
    information: float | None
    direction: dict[DirectionName, float] | None

    def label(self) -> str:
        """The direction for a console: "misalignment yaw 0.05" (its information), or its name alone when the
        information is not known."""
        if not self.informed:
            return self.mostly
        return f"{self.mostly} {self.information:.2f}"

    @property
    def informed(self) -> bool:
        """Whether the direction's information is known (a finite number)."""
        return self.information is not None and math.isfinite(self.information)


class CalibrationHold(SummaryModel):
    """What of the DVL scale and misalignment was held, and why (module doc): the same shape for the batch
    smoother, the online estimator and the EKF. threshold ([priors] hold_weak_information) and information (the
    data's information along each eigen-direction of the calibration, in prior units) where the estimator computed
    them; nominal: the nominal calibration's check, when made; chi2_increase, chi2_limit_99, consistent: what
    pinning the held directions cost in chi^2 against its 99 % limit (the batch smoother; None where not solved
    again)."""

    reason: HoldReason
    why: str
    held: list[HeldDirection]
    released: list[HeldDirection] = Field(default_factory=list)
    threshold: float | None = None
    information: list[float] | None = None
    nominal: NominalCheck | None = None
    chi2_increase: float | None = None
    chi2_limit_99: float | None = None
    consistent: bool | None = None

    def lines(self, indent: str = "  ") -> list[str]:
        """The console lines: what was held (or released) and why; none when nothing was held or released."""
        if self.held:
            what = {
                "nominal_check": "held at the nominal calibration",
                "weak_directions": "held at the prior (the run informs them little)",
                "none": "held",
            }[self.reason]
            dirs = self.held
        elif self.released:
            what, dirs = "released (estimated, not held)", self.released
        else:
            return []
        if all(d.informed for d in dirs):
            what += " (the data's information along each direction, in units of its prior's)"
        return [
            f"{indent}{what}: " + ", ".join(d.label() for d in dirs),
            f"{indent}  why: {self.why}",
        ]


def hold_why(
    reason: HoldReason,
    held: list[HeldDirection],
    threshold: float | None,
    nominal: NominalCheck | None,
    chi2_increase: float | None,
    chi2_limit_99: float | None,
) -> str:
    """The words of a hold whose estimator gave none of its own (the online estimator's; a summary migrated from
    before version 8)."""
    if reason == "nominal_check" and nominal is not None:
        return (
            f"held at the nominal calibration: the estimate's chi^2 gain over the nominal is {nominal.chi2_gain:.1f}, "
            f"not more than {nominal.chi2_limit:.1f} ({nominal.level:.0%} of chi^2 with 4 dof): estimating the DVL "
            "scale and misalignment does not pay for its four states; the nominal's sigmas are its prior's"
        )
    below = f"{threshold:g}" if threshold is not None else "[priors] hold_weak_information"
    if reason == "weak_directions":
        cost = (
            f"; pinning them cost chi^2 {chi2_increase:.1f} (99 % limit {chi2_limit_99:.1f})"
            if chi2_increase is not None and chi2_limit_99 is not None
            else ""
        )
        return (
            f"held at the prior: the run informs {', '.join(h.mostly for h in held)} less than {below} of their "
            f"prior's information ([priors] hold_weak_information){cost}"
        )
    pays = (
        f"; estimating the scale and misalignment pays (chi^2 gain {nominal.chi2_gain:.1f} > {nominal.chi2_limit:.1f})"
        if nominal is not None and nominal.pays
        else ""
    )
    return (
        f"nothing held: the run informs every direction of the DVL scale and misalignment at least {below} of its "
        f"prior's information{pays}"
    )


# ----- the verdicts of states a run may not determine (analysis/observability.py) ------------------------------


class TimeOffsetVerdict(SummaryModel):
    """The DVL time offset dt_d (s) with its sigma, whether the log determined it, the verdict and the value in
    words, and the sign convention (words and convention "" in a result written before they were)."""

    value: float
    sigma: float
    determined: bool
    verdict: str = ""
    words: str = ""
    convention: str = ""


class LeverArmVerdict(SummaryModel):
    """The DVL lever arm (m, base_link) with its sigmas and the prior's, the /tf_static value it started from, and
    per axis whether the log determined it (None without a configuration to judge by) and the verdict."""

    value: list[float]
    sigma: list[float]
    prior_sigma: float
    frame: str
    tf_static: list[float] | None = None
    determined: list[bool] | None = None
    verdict: list[str] | None = None
    note: str | None = None


# ----- the water current (analysis/metrics.py current_summary) ------------------------------------------------


class CurrentByDepth(SummaryModel):
    """The determined current's mean over a 50 m depth band."""

    depth_m: list[float]
    east_m_s: float
    north_m_s: float
    sigma_m_s: float
    speed_m_s: float
    states: int


class LayerShear(SummaryModel):
    """The change of the current across one layer boundary (estimators/models/current.py layer_shear)."""

    boundary: int
    depth_m: float
    east_m_s: float
    north_m_s: float
    east_sigma_m_s: float
    north_sigma_m_s: float


class CurrentLayers(SummaryModel):
    thickness_m: float
    boundaries: int
    shear: list[LayerShear]


class CurrentErrors(SummaryModel):
    rms_m_s: float
    max_abs_z: float


class WaterCurrentSummary(SummaryModel):
    """The water current: the verdict, the states and the share determined, the water-track pings used, the
    current per 50 m of depth, the layers ([current] layer_thickness_m) and the errors against a simulated truth."""

    verdict: str
    states: int
    determined_share: float
    water_track_pings: int
    by_depth: list[CurrentByDepth]
    layers: CurrentLayers | None = None
    errors: CurrentErrors | None = None


# ----- errors against a simulated truth (analysis/metrics.py truth_errors) --------------------------------------


class TruthErrors(SummaryModel):
    """The errors against the log's truth (estimate - truth) with their ``_nsigma`` companions; each present when
    the truth and the estimate have it (io-dvlc: the calibration's alone)."""

    scale_ppm: float | None = None
    scale_nsigma: float | None = None
    misalignment_deg: list[float] | None = None
    misalignment_nsigma: list[float] | None = None
    dvl_time_offset_s: float | None = None
    dvl_time_offset_nsigma: float | None = None
    dvl_lever_arm_m: list[float] | None = None
    dvl_lever_arm_nsigma: list[float] | None = None
    gyro_bias_deg_per_h: list[float] | None = None
    accel_bias_ug: list[float] | None = None
    gyro_bias_nsigma: list[float] | None = None
    accel_bias_nsigma: list[float] | None = None
    final_horizontal_position_m: float | None = None
    final_horizontal_position_pct_distance: float | None = None
    position_rmse_m: float | None = None
    position_rmse_axes_m: list[float] | None = None
    velocity_rmse_m_s: float | None = None
    velocity_rmse_axes_m_s: list[float] | None = None
    attitude_rmse_deg: list[float] | None = None
    final_attitude_deg: list[float] | None = None


# ----- health, geometry, the calibration file's verdict --------------------------------------------------------


class HealthSummary(SummaryModel):
    """The run's health (analysis/health.py): status, warnings and notes in words. figures: the numbers behind
    them (solver, DVL residuals, counters, losses, geometry, prior n-sigma, ...), open: each check adds its own."""

    status: HealthStatus
    warnings: list[str] = Field(default_factory=list)
    notes: list[str] = Field(default_factory=list)
    figures: dict[str, Any] = Field(default_factory=dict)


class Motion(SummaryModel):
    """What the trajectory did (analysis/geometry.py MotionSummary)."""

    kind: Literal["straight", "steady turn", "varied", "static"]
    level: bool
    heading_change_deg: float = 0.0
    speed_m_s: float = 0.0
    speed_spread: float = 0.0
    turn_rate_deg_s: float = 0.0
    depth_change_m: float = 0.0
    distance_m: float = 0.0


class GeometryFinding(SummaryModel):
    """A weak calibration direction (analysis/geometry.py Finding)."""

    column: str
    ratio: float
    partner: str
    correlation: float
    motion: str
    manoeuvre: str
    track_shift_m: float
    track_shift_pct: float
    severity: Literal["warn", "note"]
    message: str


class GeometrySummary(SummaryModel):
    motion: Motion
    findings: list[GeometryFinding] = Field(default_factory=list)


class ShiftComponent(SummaryModel):
    """One component's shift since a calibration file (analysis/calibration_check.py ComponentShift)."""

    name: str
    shift: float
    unit: str
    nsigma: float
    information_added: float


class CalibrationCheckSummary(SummaryModel):
    """The verdict on a run against its calibration file's prior (analysis/calibration_check.py)."""

    vehicle: str
    date: str
    chi2: float
    dof: int
    threshold: float
    p_value: float
    moved: bool
    components: list[ShiftComponent] = Field(default_factory=list)
    verdict: str = ""


# ----- what the reader lost (io/reader.py metadata["reader_losses"]) -------------------------------------------


class RepairCount(SummaryModel):
    """Messages of a topic dropped by --repair, by reason, of how many."""

    dropped: int
    nan: int
    duplicate: int
    backwards: int
    of: int


class StampGaps(SummaryModel):
    """A topic's gaps (io/stamps.py stamp_gaps)."""

    count: int
    seconds: float
    period_s: float | None = None
    longest_s: float
    spans_s: list[list[float]]


class Truncation(SummaryModel):
    file: str
    at_byte: int
    data_end_s: float | None


class SalvageLosses(SummaryModel):
    """What --salvage could not read (io/storage/salvage.py salvage_losses)."""

    chunks_total: int
    chunks_kept: int
    chunks_lost: int
    messages_lost: int
    messages_lost_exact: bool
    messages_lost_per_topic: dict[str, int]
    lost_spans_s: list[list[float]]
    seconds_lost: float
    truncated: list[Truncation]
    end_unreadable: bool
    anything_lost: bool


class Losses(SummaryModel):
    """What reading the log lost or changed. clock_steps and saturation (per topic, core/imu_faults.py) are open."""

    repair: dict[str, RepairCount] = Field(default_factory=dict)
    gaps: dict[str, StampGaps] = Field(default_factory=dict)
    messages_lost: dict[str, int] = Field(default_factory=dict)
    clock_steps: dict[str, Any] | None = None
    saturation: dict[str, Any] | None = None
    salvage: SalvageLosses | None = None


# ----- the summaries -------------------------------------------------------------------------------------------


class SummaryBase(SummaryModel):
    """What every estimator's summary has."""

    schema_version: int
    estimator: str
    log: str = ""
    scale: ValueSigma
    misalignment_deg: Misalignment
    timing_s: dict[str, float] = Field(default_factory=dict)
    errors: TruthErrors | None = None
    health: HealthSummary | None = None
    losses: Losses = Field(default_factory=Losses)

    def to_json_dict(self) -> dict[str, Any]:
        """The dict written as JSON: the keys set (by the builder, or in the file read), None as null."""
        return self.model_dump(exclude_unset=True)


class Summary(SummaryBase):
    """A trajectory estimator's summary (docs/command-line.md, "The summary JSON"). Units: degrees, deg/h,
    micro-g, m, s. info is open (module doc)."""

    gyro_bias_deg_per_h: VectorSigma
    accel_bias_ug: VectorSigma
    distance_travelled_m: float
    final_horizontal_position_sigma_m: float
    duration_s: float
    states: int
    real_time_factor: float | None = None
    info: dict[str, Any] = Field(default_factory=dict)
    noise_levels: list[str] = Field(default_factory=list)
    dvl_time_offset_s: TimeOffsetVerdict | None = None
    dvl_lever_arm_m: LeverArmVerdict | None = None
    calibration_hold: CalibrationHold | None = None
    water_current: WaterCurrentSummary | None = None
    geometry: GeometrySummary | None = None
    calibration_check: CalibrationCheckSummary | None = None


class SegmentSpan(SummaryModel):
    """An IO-DVLC Type-I segment: its span (s), the acceleration's axis and the quiet stretch of its reference."""

    start_s: float
    end_s: float
    axis: list[float]
    reference_s: list[float] | None = None


class SegmentCalibration(SummaryModel):
    """IO-DVLC's calibration from one segment alone."""

    start_s: float
    end_s: float
    scale: float
    scale_sigma: float
    misalignment_deg: list[float]
    misalignment_sigma_deg: list[float]


class IoDvlcSummary(SummaryBase):
    """io-dvlc's summary: the calibration alone, per segment and over all, with the DVL noise it used."""

    estimator: Literal["io-dvlc"]
    segments: list[SegmentSpan] = Field(default_factory=list)
    per_segment: list[SegmentCalibration] = Field(default_factory=list)
    dvl_noise_m_s: float | None = None


AnySummary = Summary | IoDvlcSummary


# ----- reading back: migration and validation ------------------------------------------------------------------


def _held_entries(held: Any) -> list[Any]:
    """Held directions as objects: the EKF's names of before version 8 ("scale", "misalignment") as the
    directions they stand for, their information and direction unknown (None)."""
    out: list[Any] = []
    for h in held if isinstance(held, list) else []:
        if h == "misalignment":
            out += [
                {"mostly": n, "information": None, "direction": None} for n in DIRECTION_NAMES[1:]
            ]
        elif isinstance(h, str):
            out.append({"mostly": h, "information": None, "direction": None})
        else:
            out.append(h)
    return out


def hold_in_one_shape(hold: dict[str, Any]) -> dict[str, Any]:
    """A calibration hold written before version 8 in the one shape: the EKF's held names as directions, the
    reason from what was held (every direction with the nominal check failed: "nominal_check"), and the words
    where none were written (the online estimator's, the batch smoother's weak directions)."""
    if "reason" in hold:
        return hold
    held = _held_entries(hold.get("held"))
    nominal = hold.get("nominal") if isinstance(hold.get("nominal"), dict) else None
    reason: HoldReason = (
        "none"
        if not held
        else "nominal_check"
        if nominal is not None and nominal.get("pays") is False
        else "weak_directions"
    )
    out = {**hold, "reason": reason, "held": held, "released": hold.get("released") or []}
    if not out.get("why"):
        typed = CalibrationHold.model_validate({**out, "why": ""})
        out["why"] = hold_why(
            reason,
            typed.held,
            typed.threshold,
            typed.nominal,
            typed.chi2_increase,
            typed.chi2_limit_99,
        )
    return out


def _v8_summary(data: dict[str, Any]) -> dict[str, Any]:
    """Version 8: calibration_hold in one shape (hold_in_one_shape)."""
    hold = data.get("calibration_hold")
    return {**data, "calibration_hold": hold_in_one_shape(hold)} if isinstance(hold, dict) else data


# (version, the summary of version - 1 -> one of version): the summary's steps of core/config/schema.py MIGRATIONS
SUMMARY_MIGRATIONS: tuple[tuple[int, Callable[[dict[str, Any]], dict[str, Any]]], ...] = (
    (8, _v8_summary),
)


def migrated_summary(data: dict[str, Any], source: str) -> dict[str, Any]:
    """A summary dict brought to SCHEMA_VERSION: from the schema_version it states (checked_version: a newer one is
    one error line), else from before version 8; every later step of SUMMARY_MIGRATIONS applied in order."""
    version = (
        checked_version(data["schema_version"], f"{source}: summary")
        if "schema_version" in data
        else UNVERSIONED
    )
    for step, migrate in SUMMARY_MIGRATIONS:
        if step > version:
            data = migrate(data)
    return {**data, "schema_version": SCHEMA_VERSION}


def _error_line(exc: ValidationError, source: str) -> str:
    """The first error of exc as one line: where in the summary, what is wrong."""
    err = exc.errors()[0]
    where = ".".join(str(p) for p in err["loc"]) or "the summary"
    got = (
        ""
        if err["type"] == "missing"
        else f", got {json.dumps(err.get('input'), default=str)[:80]}"
    )
    return f"{source}: the summary's {where}: {err['msg'].lower()}{got}; smooth the log again"


def parse_summary(data: Any, source: str = "summary") -> AnySummary:
    """A summary dict as written (a --summary file, a result's summary.json), migrated and validated: io-dvlc's as
    IoDvlcSummary, any other estimator's as Summary; one GtsamDvlError line when it does not fit."""
    if not isinstance(data, dict):
        raise GtsamDvlError(f"{source}: the summary is not a JSON object; smooth the log again")
    data = migrated_summary(data, source)
    model: type[Summary] | type[IoDvlcSummary] = (
        IoDvlcSummary if data.get("estimator") == "io-dvlc" else Summary
    )
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise GtsamDvlError(_error_line(exc, source)) from None


def read_summary(data: Any, source: str = "summary") -> Summary:
    """parse_summary for a trajectory estimator's summary (a result's: io-dvlc writes no result)."""
    parsed = parse_summary(data, source)
    if not isinstance(parsed, Summary):
        raise GtsamDvlError(f"{source}: an io-dvlc summary, not a trajectory estimator's")
    return parsed


def summary_schema() -> dict[str, Any]:
    """The JSON Schema of a summary (Summary or IoDvlcSummary), as kept in docs/summary-schema.json."""
    schema = TypeAdapter(AnySummary).json_schema()
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "gtsam_dvl summary",
        "description": (
            f"The summary JSON of `gtsam-dvl smooth --summary` and a result's summary.json, schema_version "
            f"{SCHEMA_VERSION} (gtsam_dvl/core/summary.py; docs/command-line.md). Numbers may be NaN or Infinity."
        ),
        **schema,
    }


def schema_text() -> str:
    """summary_schema as the text of docs/summary-schema.json."""
    return json.dumps(summary_schema(), indent=2) + "\n"
