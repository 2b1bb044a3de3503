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
from gtsam_dvl.core.config.noise import NoiseConfig
from gtsam_dvl.core.config.presets import DVL_PRESETS
from gtsam_dvl.core.config.sections import (
    AlignmentConfig,
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
    # and their logs' stamps agree (no DVL time offset estimated)
    # and their logs' stamps agree (no DVL time offset estimated); the noise is the paper's Table 1, as stated
    "paper": {"priors": {"scale_initial": 0.8, "scale_sigma": 0.5}, "dvl": {"estimate_time_offset": False},
              "noise": {"from_data": False}},
}


def recommended_config_name(metadata: Mapping[str, Any]) -> str:
    """The named configuration a log's metadata recommends: its scenario's estimator_config if that is a known
    name, else "default" (real logs)."""
    scenario = metadata.get("scenario")
    name = scenario.get("estimator_config", "default") if isinstance(scenario, Mapping) else "default"
    return name if isinstance(name, str) and name in NAMED_CONFIGS else "default"


class EstimatorConfig(ConfigModel):
    """Every estimator's configuration: the models ([imu], [dvl], [priors], [alignment], [solver]) shared by
    every estimator, [online] (the iSAM2 estimator), [ekf], [iodvlc], [depth], [gnss] and [observability]."""

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

    @model_validator(mode="after")
    def _dvl_scale_accuracy(self) -> Self:
        """A DVL preset's scale accuracy is the scale prior's sigma unless [priors] scale_sigma is set (the
        presets' other values are filled by their own sections)."""
        if self.dvl.model is not None and "scale_sigma" not in self.priors.model_fields_set:
            self.priors.__dict__["scale_sigma"] = DVL_PRESETS[self.dvl.model].scale_accuracy  # not counted as set
        return self

    def to_dict(self) -> dict[str, Any]:
        """Nested plain dict (tuples stay tuples, None stays None): json.dumps writes it, from_dict reads it."""
        return self.model_dump()

    def to_toml(self) -> str:
        """The configuration as TOML text (from_toml reads it back to an equal configuration)."""
        return toml_text(self)

    @classmethod
    def named(cls, name: str) -> EstimatorConfig:
        """A named configuration (NAMED_CONFIGS: "default", "paper")."""
        if name not in NAMED_CONFIGS:
            raise GtsamDvlError(f"no configuration named '{name}' (named configurations: {', '.join(NAMED_CONFIGS)})")
        return cls.from_dict(NAMED_CONFIGS[name], source=f"configuration '{name}'")

    @classmethod
    def paper(cls) -> EstimatorConfig:
        """The paper's configuration (scale prior 0.8 +- 0.5): NAMED_CONFIGS["paper"]."""
        return cls.named("paper")

    @classmethod
    def for_log(cls, metadata: Mapping[str, Any]) -> EstimatorConfig:
        """The configuration a log's scenario names (its estimator_config key: a simulated paper run names
        "paper"), else the defaults: what every estimator uses when no configuration is given."""
        return cls.named(recommended_config_name(metadata))

    @classmethod
    def load(cls, spec: Path | str) -> EstimatorConfig:
        """A configuration from the command line's -c: a file (TOML, or a result's config.json), else the
        name of a named configuration."""
        if not Path(spec).exists() and str(spec) in NAMED_CONFIGS:
            return cls.named(str(spec))
        if not Path(spec).exists():
            raise GtsamDvlError(f"{spec}: no such configuration file, and not a named configuration "
                                f"({', '.join(NAMED_CONFIGS)})")
        return cls.from_toml(spec)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "config") -> EstimatorConfig:
        """Sections from a dict shaped like the TOML file. A top-level key preset = "NAME" starts from that
        named configuration instead of the defaults."""
        if not isinstance(data, Mapping):
            raise GtsamDvlError(f"{source}: a configuration is a table of sections, got {data!r}")
        if "preset" in data:
            preset = data["preset"]
            if not isinstance(preset, str) or preset not in NAMED_CONFIGS:
                raise GtsamDvlError(f"{source}: preset must be the name of a named configuration "
                                    f"({', '.join(NAMED_CONFIGS)}), got {preset!r}")
            data = _merged(NAMED_CONFIGS[preset], {k: v for k, v in data.items() if k != "preset"})
        return cls.checked(data, source)

    @classmethod
    def from_toml(cls, path: Path | str) -> EstimatorConfig:
        """A TOML configuration file, or (*.json) the effective configuration written with a result."""
        if str(path).lower().endswith(".json"):
            return cls.from_json(path)
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except tomllib.TOMLDecodeError as exc:
            raise GtsamDvlError(f"{path}: not valid TOML ({exc})") from None
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_json(cls, path: Path | str) -> EstimatorConfig:
        """The config.json of a result ({"estimator": ..., "config": {...}}) or a bare configuration dict."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise GtsamDvlError(f"{path}: not valid JSON ({exc})") from None
        if isinstance(data, dict) and "config" in data and set(data) <= {"estimator", "config"}:
            data = data["config"]
        return cls.from_dict(data, source=str(path))


def _merged(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """base with override's keys, tables merged key by key."""
    out = dict(base)
    for key, value in override.items():
        old = out.get(key)
        out[key] = _merged(old, value) if isinstance(old, Mapping) and isinstance(value, Mapping) else value
    return out
