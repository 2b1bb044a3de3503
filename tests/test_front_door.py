"""The package's front door (gtsam_dvl/__init__.py): the names a script needs, each the library's own object,
imported on first use (`import gtsam_dvl` loads neither the reader, the simulator, scipy nor matplotlib), and an
unknown name one clear AttributeError."""

from __future__ import annotations

import subprocess
import sys

import pytest

import gtsam_dvl


def test_import_is_light() -> None:
    code = (
        "import sys, gtsam_dvl; heavy = [m for m in ('matplotlib', 'scipy', 'gtsam_dvl.sim.simulate', "
        "'gtsam_dvl.io.reader') if m in sys.modules]; print(heavy)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_front_door_names_are_the_library_objects() -> None:
    from gtsam_dvl.analysis.evaluate import evaluate_result
    from gtsam_dvl.analysis.planning import plan_mission
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.core.result import NavResult
    from gtsam_dvl.estimators.online import OnlineEstimator
    from gtsam_dvl.estimators.run import run_estimator
    from gtsam_dvl.io.read_options import ReadOptions
    from gtsam_dvl.io.reader import read_log
    from gtsam_dvl.sim.scenario import load_scenario
    from gtsam_dvl.sim.simulate import simulate

    assert gtsam_dvl.smooth is run_estimator and gtsam_dvl.run_estimator is run_estimator
    assert gtsam_dvl.read_log is read_log and gtsam_dvl.simulate is simulate
    assert gtsam_dvl.load_scenario is load_scenario and gtsam_dvl.plan_mission is plan_mission
    assert gtsam_dvl.evaluate is evaluate_result and gtsam_dvl.EstimatorConfig is EstimatorConfig
    assert gtsam_dvl.NavResult is NavResult and gtsam_dvl.OnlineEstimator is OnlineEstimator
    assert gtsam_dvl.ReadOptions is ReadOptions
    assert set(gtsam_dvl.__all__) <= set(dir(gtsam_dvl))
    for name in gtsam_dvl.__all__:
        assert getattr(gtsam_dvl, name) is not None
    with pytest.raises(AttributeError, match="no attribute 'smooth_everything'"):
        gtsam_dvl.smooth_everything  # noqa: B018
