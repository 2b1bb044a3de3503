"""Estimator configuration with documented defaults (the paper's sensors), loadable from TOML.

Every field carries its unit in its name. `EstimatorConfig.from_toml(path)` reads a file with the same
sections as the models: [imu], [dvl], [priors], [alignment], [solver] (the models, shared by every
estimator), [online] and [online.relinearization] (the iSAM2 estimator), [ekf] (the filter), [iodvlc]
(the ideal observer), [depth] (the depth sensor), [gnss] (GNSS fixes) and [observability] (accuracy targets).
It also reads the JSON of an effective configuration, as written with every result (config.json:
{"estimator": ..., "config": {...}}, or the bare configuration).

Each section is a pydantic model (base.py): unknown sections and keys, enumerations, types and ranges are
checked on load, the error one line naming the file, section, key, the bad value and what is allowed. An
optional field (`X | None`) takes None (JSON null) or, in a TOML file, which has no null, the string "none" or
no entry where None is its default. `validate()` checks a configuration built or changed in Python the same way;
the estimators call it when they start. `to_dict()` (None kept, for JSON) and `to_toml()` read back with
`from_dict` / `from_toml` to an equal configuration.

Sensor presets: `[imu] model = "..."` and `[dvl] model = "..."` name a preset (presets.py, `gtsam-dvl presets`) whose
datasheet values fill the noise, bias and scale-prior fields the configuration does not set itself; explicit values
win. `[priors] mounting_tolerance_deg` likewise sets the misalignment prior.

Modules: base.py (the checked model, one-line errors, TOML writing), sections.py (one model per TOML table),
presets.py (the sensor presets and their sources), noise.py ([noise]), estimator.py (EstimatorConfig, the named
configurations, loading), schema.py (the schema_version written files state and the one migration table that
brings an older configuration to this version).
"""

from gtsam_dvl.core.config.base import ConfigModel
from gtsam_dvl.core.config.estimator import (
    NAMED_CONFIGS,
    EstimatorConfig,
    estimator_overrides,
    recommended_config_name,
)
from gtsam_dvl.core.config.sections import (
    AlignmentConfig,
    BadMessages,
    BiasModel,
    CalibrationConfig,
    DepthConfig,
    DvlConfig,
    EarthModel,
    EkfConfig,
    GnssConfig,
    GnssUse,
    ImuConfig,
    IodvlcConfig,
    ObservabilityConfig,
    OnlineConfig,
    OnlineMode,
    PriorConfig,
    RelinearizationThresholds,
    RobustLoss,
    SolverConfig,
)

__all__ = [
    "NAMED_CONFIGS",
    "AlignmentConfig",
    "BadMessages",
    "BiasModel",
    "ConfigModel",
    "DepthConfig",
    "DvlConfig",
    "EarthModel",
    "EkfConfig",
    "EstimatorConfig",
    "GnssConfig",
    "GnssUse",
    "ImuConfig",
    "IodvlcConfig",
    "ObservabilityConfig",
    "OnlineConfig",
    "OnlineMode",
    "PriorConfig",
    "RelinearizationThresholds",
    "RobustLoss",
    "SolverConfig",
    "estimator_overrides",
    "recommended_config_name",
    "CalibrationConfig",
]
