"""How a log is read (ReadOptions): its topics, the frame conventions of some of them, and what to do about damage.

One typed, validated object from the command line (app/cli_options.py) to io/reader.py read_log, and recorded
with every result ("gtsam_dvl_result" metadata, read_options: ``record()``) so that `evaluate` reads the source
log again as smooth did (``from_record``). A bad value is one GtsamDvlError line, e.g.
"read options: salvage must be true or false, got 'yes'".

Topic options that default to None look for their sensor's usual topic and read it when the log has it; the
string "none" (or "") reads no such sensor.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any, ClassVar, Self

from pydantic import BaseModel, ConfigDict, Strict, ValidationError, field_validator

from gtsam_dvl.core.config.base import allowed_text
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io.attitude import FRAMES

Topic = Annotated[str, Strict()]
Flag = Annotated[bool, Strict()]


class ReadOptions(BaseModel):
    """The options of io/reader.py read_log, each with its default (docs/own-logs.md):

    imu_topic: the IMU (sensor_msgs/msg/Imu). dvl_topic: the DVL (marine_acoustic_msgs/msg/Dvl or a twist;
    None: /dvl/data if the log has it, else /dvl/twist). dvl_water_topic: water-track pings on a topic of their
    own (a twist, io/water_track.py; None: none). truth_topic: the ground-truth odometry, read when the log has it
    as nav_msgs/msg/Odometry. tf_topic: the mounting (the IMU's, DVL's, depth sensor's and GNSS antenna's poses
    in base_link; without it: identity, warned).
    depth_topic: None reads /depth/pressure if the log has it; "none" (or "") reads no depth; a named topic is
    sensor_msgs/msg/FluidPressure, or a PoseWithCovarianceStamped / Odometry whose z is up (depth = -z), or down
    with depth_z_down.
    gnss_topic: None reads /gnss/fix if the log has it; "none" reads none; a named topic is
    sensor_msgs/msg/NavSatFix.
    attitude_topic: None takes the IMU topic's own orientation when its covariance says it is valid; "none" reads
    none; else the named topic (sensor_msgs/msg/Imu, nav_msgs/msg/Odometry or PoseWithCovarianceStamped).
    attitude_frame: "enu" (REP-103) or "ned" (an AHRS publishing NED orientation of an FRD body).
    salvage: recover the intact chunks of a damaged MCAP. repair: drop (and count) NaN, duplicate or backwards
    messages and shift the IMU stamps back across a clock step.

    Frozen: ``replace`` gives a changed copy (checked). ``model_fields_set`` names the options given explicitly:
    ``over`` lets those override another set (`evaluate`: the options given on its command line over the ones
    smooth recorded)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    imu_topic: Topic = "/imu/data_raw"
    dvl_topic: Topic | None = None
    dvl_water_topic: Topic | None = None
    truth_topic: Topic = "/ground_truth/odometry"
    tf_topic: Topic = "/tf_static"
    depth_topic: Topic | None = None
    depth_z_down: Flag = False
    gnss_topic: Topic | None = None
    attitude_topic: Topic | None = None
    attitude_frame: Topic = "enu"
    salvage: Flag = False
    repair: Flag = False

    # recorded with every result whatever their value; the others when they differ from their default
    ALWAYS_RECORDED: ClassVar[tuple[str, ...]] = ("imu_topic", "dvl_topic", "salvage", "repair")

    def __init__(self, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise GtsamDvlError(_one_line(exc, data, "read options")) from None

    # marked as pydantic's own __init__ (as core/config/base.py ConfigModel): model_validate (from_record) then
    # validates without it and names its own source
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    @field_validator("attitude_frame")
    @classmethod
    def _known_frame(cls, frame: str) -> str:
        if frame not in FRAMES:
            raise ValueError(f"attitude_frame must be one of {', '.join(FRAMES)}, got {frame!r}")
        return frame

    def replace(self, **changes: Any) -> Self:
        """A copy with changes (option names and values), checked; the options given are self's and changes'."""
        given = {name: getattr(self, name) for name in self.model_fields_set}
        return type(self)(**{**given, **changes})

    def over(self, base: ReadOptions) -> Self:
        """base's options with the ones given explicitly here (model_fields_set) in their place."""
        return type(self)(**{**base.model_dump(), **self.model_dump(include=self.model_fields_set)})

    def record(self) -> dict[str, Any]:
        """The options as a result records them (JSON-ready): ALWAYS_RECORDED, then every other option whose value
        differs from its default."""
        fields = type(self).model_fields
        changed = {
            name: getattr(self, name)
            for name in fields
            if name not in self.ALWAYS_RECORDED and getattr(self, name) != fields[name].default
        }
        return {**{name: getattr(self, name) for name in self.ALWAYS_RECORDED}, **changed}

    @classmethod
    def from_record(cls, record: Mapping[str, Any], source: str = "read options") -> Self:
        """The options a result recorded (``record()``); keys this version does not know are ignored (a newer
        version's options), a bad value is one GtsamDvlError line naming source."""
        known = {k: v for k, v in record.items() if k in cls.model_fields}
        try:
            return cls.model_validate(known)
        except ValidationError as exc:
            raise GtsamDvlError(_one_line(exc, known, source)) from None


def _one_line(exc: ValidationError, data: Mapping[str, Any], source: str) -> str:
    """The first error of exc as one line: an unknown option (with the known ones), a validator's own message, or
    what the option allows and the value given."""
    err = sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden")[0]
    name = str(err["loc"][0]) if err["loc"] else ""
    fields = ReadOptions.model_fields
    if err["type"] == "extra_forbidden":
        return f"{source}: unknown option '{name}' (known: {', '.join(fields)})"
    if err["type"] == "value_error":
        return f"{source}: {err['ctx']['error']}"
    if name in fields:
        return f"{source}: {name} {allowed_text(fields[name], data.get(name))}"
    return f"{source}: {err['msg']}"
