"""gtsam_dvl: self-calibrating IMU + DVL navigation on GTSAM.

The front door: what a script needs, imported when first used (`import gtsam_dvl` stays light: the reader,
the simulator, scipy and matplotlib load with the first name that needs them).

    import gtsam_dvl as gd
    log = gd.read_log("dive.mcap")                      # or gd.simulate(gd.load_scenario("paper-3d"), seed=1)
    # other topics, damage: gd.read_log("dive.mcap", gd.ReadOptions(dvl_topic="/dvl/twist", repair=True))
    result = gd.smooth(log, "batch", gd.EstimatorConfig())
    print(result.scale, result.misalignment_deg)
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import (
    BeamData,
    DvlCalibration,
    DvlData,
    ImuData,
    LogData,
    Mounting,
    TruthData,
)

if TYPE_CHECKING:  # the lazy names' types, for mypy and editors
    from gtsam_dvl.analysis.evaluate import evaluate_result as evaluate
    from gtsam_dvl.analysis.planning import plan_mission
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.core.result import NavResult
    from gtsam_dvl.estimators.online import OnlineEstimator
    from gtsam_dvl.estimators.run import run_estimator
    from gtsam_dvl.estimators.run import run_estimator as smooth
    from gtsam_dvl.io.read_options import ReadOptions
    from gtsam_dvl.io.reader import read_log
    from gtsam_dvl.sim.scenario import load_scenario
    from gtsam_dvl.sim.simulate import simulate

__version__ = "0.1.0"

# name -> (module, attribute): imported on first access (PEP 562 module __getattr__)
_LAZY = {
    "read_log": ("gtsam_dvl.io.reader", "read_log"),
    "ReadOptions": ("gtsam_dvl.io.read_options", "ReadOptions"),
    "smooth": ("gtsam_dvl.estimators.run", "run_estimator"),
    "run_estimator": ("gtsam_dvl.estimators.run", "run_estimator"),
    "simulate": ("gtsam_dvl.sim.simulate", "simulate"),
    "load_scenario": ("gtsam_dvl.sim.scenario", "load_scenario"),
    "plan_mission": ("gtsam_dvl.analysis.planning", "plan_mission"),
    "evaluate": ("gtsam_dvl.analysis.evaluate", "evaluate_result"),
    "EstimatorConfig": ("gtsam_dvl.core.config", "EstimatorConfig"),
    "NavResult": ("gtsam_dvl.core.result", "NavResult"),
    "OnlineEstimator": ("gtsam_dvl.estimators.online", "OnlineEstimator"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value  # once
        return value
    raise AttributeError(f"module 'gtsam_dvl' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "BeamData",
    "DvlCalibration",
    "DvlData",
    "EstimatorConfig",
    "GtsamDvlError",
    "ImuData",
    "LogData",
    "Mounting",
    "NavResult",
    "OnlineEstimator",
    "ReadOptions",
    "TruthData",
    "__version__",
    "evaluate",
    "load_scenario",
    "plan_mission",
    "read_log",
    "run_estimator",
    "simulate",
    "smooth",
]
