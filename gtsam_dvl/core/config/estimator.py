"""The whole estimator configuration (EstimatorConfig: one section per TOML table), its named configurations,
and loading from TOML, from a result's config.json or from a name."""

from __future__ import annotations

import json
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Self

from pydantic import Field, model_validator

from gtsam_dvl.core.config.base import ConfigModel, toml_text
from gtsam_dvl.core.config.current import CurrentConfig
from gtsam_dvl.core.config.noise import NoiseConfig
from gtsam_dvl.core.config.presets import DVL_PRESETS
from gtsam_dvl.core.config.schema import SCHEMA_VERSION, migrated
from gtsam_dvl.core.config.sections import (
    AlignmentConfig,
    CalibrationConfig,
    DepthConfig,
    DvlConfig,
    EkfConfig,
    GnssConfig,
    ImuConfig,
    IodvlcConfig,
    ObservabilityConfig,
    OnlineConfig,
    PriorConfig,
    SolverConfig,
)
from gtsam_dvl.core.errors import GtsamDvlError

# Named configurations: the differences from the defaults, as a TOML file would give them. `-c NAME` on the
# command line, EstimatorConfig.named(NAME) in scripts, `preset = "NAME"` at the top of a TOML file (its own
# keys then override the preset's), and a scenario's estimator_config key (the configuration its runs are
# meant for, used by smooth and plan when no configuration is given).
NAMED_CONFIGS: dict[str, dict[str, dict[str, Any]]] = {
    "default": {},  # a real DVL: scale 1 +- 1 %, misalignment 1 deg per axis
    # Pan & Wu's runs: the scale starts at 0.8 with a 0.5 sigma so that its convergence can be watched
    # and their logs' stamps agree (no DVL time offset estimated); the noise is the paper's Table 1, as stated, and
    # its DVL error white; every calibration direction estimated, as theirs (the thrust axis's too on a level run)
    "paper": {
        "priors": {
            "scale_initial": 0.8,
            "scale_sigma": 0.5,
            "hold_weak_information": 0.0,
            "nominal_check": False,
        },
        "dvl": {
            "estimate_time_offset": False,
            "correlated_sigma_m_s": 0.0,
            "constant_error_sigma_m_s": 0.0,
        },
        "noise": {"from_data": False},
    },
}


# the keys of a result's config.json ({"schema_version", "estimator", "config"}; without schema_version before it)
RESULT_CONFIG_KEYS = {"schema_version", "estimator", "config"}


def recommended_config_name(metadata: Mapping[str, Any]) -> str:
    """The named configuration a log's metadata recommends: its scenario's estimator_config if that is a known
    name, else "default" (real logs)."""
    scenario = metadata.get("scenario")
    name = (
        scenario.get("estimator_config", "default") if isinstance(scenario, Mapping) else "default"
    )
    return name if isinstance(name, str) and name in NAMED_CONFIGS else "default"


def estimator_overrides(metadata: Mapping[str, Any]) -> dict[str, Any]:
    """A log's scenario's [estimator] table (what the scenario tells its estimators, e.g. the initial attitude),
    {} when it has none: the layer under a configuration given with -c (EstimatorConfig.load's under)."""
    scenario = metadata.get("scenario")
    table = scenario.get("estimator", {}) if isinstance(scenario, Mapping) else {}
    return dict(table) if isinstance(table, Mapping) else {}


class EstimatorConfig(ConfigModel):
    """Every estimator's configuration: the models ([imu], [dvl], [priors], [alignment], [solver]) shared by
    every estimator, [online] (the iSAM2 estimator), [ekf], [iodvlc], [depth], [gnss], [observability] and
    [calibration] (a vehicle's calibration file as the prior)."""

    imu: ImuConfig = Field(default_factory=ImuConfig)
    dvl: DvlConfig = Field(default_factory=DvlConfig)
    priors: PriorConfig = Field(default_factory=PriorConfig)
    alignment: AlignmentConfig = Field(default_factory=AlignmentConfig)
    solver: SolverConfig = Field(default_factory=SolverConfig)
    online: OnlineConfig = Field(default_factory=OnlineConfig)
    ekf: EkfConfig = Field(default_factory=EkfConfig)
    iodvlc: IodvlcConfig = Field(default_factory=IodvlcConfig)
    depth: DepthConfig = Field(default_factory=DepthConfig)
    observability: ObservabilityConfig = Field(default_factory=ObservabilityConfig)
    gnss: GnssConfig = Field(default_factory=GnssConfig)
    noise: NoiseConfig = Field(default_factory=NoiseConfig)
    current: CurrentConfig = Field(default_factory=CurrentConfig)
    calibration: CalibrationConfig = Field(default_factory=CalibrationConfig)

    @model_validator(mode="after")
    def _dvl_scale_accuracy(self) -> Self:
        """A DVL preset's scale accuracy is the scale prior's sigma unless [priors] scale_sigma is set (the
        presets' other values are filled by their own sections)."""
        if self.dvl.model is not None and "scale_sigma" not in self.priors.model_fields_set:
            self.priors.__dict__["scale_sigma"] = DVL_PRESETS[
                self.dvl.model
            ].scale_accuracy  # not counted as set
        return self

    def to_dict(self) -> dict[str, Any]:
        """Nested plain dict (tuples stay tuples, None stays None): json.dumps writes it, from_dict reads it."""
        return self.model_dump()

    def to_toml(self) -> str:
        """The configuration as TOML text, schema_version first (from_toml reads it back to an equal
        configuration)."""
        return f"schema_version = {SCHEMA_VERSION}\n\n{toml_text(self)}"

    @classmethod
    def named(cls, name: str) -> EstimatorConfig:
        """A named configuration (NAMED_CONFIGS: "default", "paper")."""
        if name not in NAMED_CONFIGS:
            raise GtsamDvlError(
                f"no configuration named '{name}' (named configurations: {', '.join(NAMED_CONFIGS)})"
            )
        return cls.from_dict(NAMED_CONFIGS[name], source=f"configuration '{name}'")

    @classmethod
    def paper(cls) -> EstimatorConfig:
        """The paper's configuration (scale prior 0.8 +- 0.5): NAMED_CONFIGS["paper"]."""
        return cls.named("paper")

    @classmethod
    def for_log(cls, metadata: Mapping[str, Any]) -> EstimatorConfig:
        """The configuration a log's scenario names (its estimator_config key: a simulated paper run names
        "paper") with its [estimator] overrides (for_scenario), else the defaults: what every estimator uses when
        no configuration is given."""
        return cls.for_scenario(metadata.get("scenario"), source="the log's scenario [estimator]")

    @classmethod
    def for_scenario(cls, scenario: Any, source: str = "scenario [estimator]") -> EstimatorConfig:
        """A scenario's configuration (scenario: its TOML tables as a dict): the named configuration its
        estimator_config names (else "default"), with its [estimator] table (a partial configuration: tables and
        keys of EstimatorConfig, e.g. [estimator.alignment] initial_attitude_deg) over it."""
        raw = scenario if isinstance(scenario, Mapping) else {}
        overrides = raw.get("estimator", {})
        if not isinstance(overrides, Mapping) or "preset" in overrides:
            raise GtsamDvlError(
                f"{source}: expected tables of estimator configuration keys (the named "
                "configuration is the scenario's estimator_config key, not a preset)"
            )
        name = recommended_config_name({"scenario": raw})
        return cls.from_dict(_merged(NAMED_CONFIGS[name], overrides), source=source)

    @classmethod
    def load(cls, spec: Path | str, under: Mapping[str, Any] | None = None) -> EstimatorConfig:
        """A configuration from the command line's -c: a file (TOML, or a result's config.json), else the
        name of a named configuration. under: keys the configuration's own keys override (a scenario's [estimator]
        table, estimator_overrides): applied below the -c configuration, above the defaults."""
        if not Path(spec).exists() and str(spec) in NAMED_CONFIGS:
            return cls.from_dict(
                {"preset": str(spec)}, source=f"configuration '{spec}'", under=under
            )
        if not Path(spec).exists():
            raise GtsamDvlError(
                f"{spec}: no such configuration file, and not a named configuration "
                f"({', '.join(NAMED_CONFIGS)})"
            )
        return cls.from_toml(spec, under=under)

    @classmethod
    def from_dict(
        cls, data: Mapping[str, Any], source: str = "config", under: Mapping[str, Any] | None = None
    ) -> EstimatorConfig:
        """Sections from a dict shaped like the TOML file. A top-level key preset = "NAME" starts from that
        named configuration instead of the defaults. under: keys below data's (and its preset's), above the
        defaults. A top-level schema_version brings data from that version to this one (schema.py)."""
        if not isinstance(data, Mapping):
            raise GtsamDvlError(f"{source}: a configuration is a table of sections, got {data!r}")
        data = migrated(dict(data), source, detect=False)
        if "preset" in data:
            preset = data["preset"]
            if not isinstance(preset, str) or preset not in NAMED_CONFIGS:
                raise GtsamDvlError(
                    f"{source}: preset must be the name of a named configuration "
                    f"({', '.join(NAMED_CONFIGS)}), got {preset!r}"
                )
            data = _merged(NAMED_CONFIGS[preset], {k: v for k, v in data.items() if k != "preset"})
        if under:
            data = _merged(under, data)
        return cls.checked(data, source)

    @classmethod
    def from_toml(cls, path: Path | str, under: Mapping[str, Any] | None = None) -> EstimatorConfig:
        """A TOML configuration file, or (*.json) the effective configuration written with a result."""
        if str(path).lower().endswith(".json"):
            return cls.from_json(path, under=under)
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except tomllib.TOMLDecodeError as exc:
            raise GtsamDvlError(f"{path}: not valid TOML ({exc})") from None
        return cls.from_dict(migrated(data, str(path)), source=str(path), under=under)

    @classmethod
    def from_json(cls, path: Path | str, under: Mapping[str, Any] | None = None) -> EstimatorConfig:
        """The config.json of a result ({"estimator": ..., "config": {...}}) or a bare configuration dict."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise GtsamDvlError(f"{path}: not valid JSON ({exc})") from None
        if isinstance(data, dict) and "config" in data and set(data) <= RESULT_CONFIG_KEYS:
            version = {"schema_version": data["schema_version"]} if "schema_version" in data else {}
            data = (
                {**data["config"], **version}
                if isinstance(data["config"], dict)
                else data["config"]
            )
        return cls.from_dict(migrated(data, str(path)), source=str(path), under=under)


def _merged(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """base with override's keys, tables merged key by key."""
    out = dict(base)
    for key, value in override.items():
        old = out.get(key)
        out[key] = (
            _merged(old, value)
            if isinstance(old, Mapping) and isinstance(value, Mapping)
            else value
        )
    return out
