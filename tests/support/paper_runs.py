"""The paper's runs simulated and estimated with the paper's configuration, cached per test process: the batch
smoother's and the online estimator's results on the same (scenario, seed) are asked for by tests/estimators/
test_batch.py, test_online.py and test_robust.py, which share them (make test runs the three on one xdist worker:
their tests carry xdist_group GROUP, and the Makefile passes --dist loadgroup). Callers must not modify what
these return."""

from __future__ import annotations

import functools

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

GROUP = "paper_runs"


@functools.cache
def paper_log(name: str, seed: int) -> LogData:
    """The built-in scenario name simulated with seed (white noise on)."""
    return simulate(load_scenario(name), seed)


@functools.cache
def paper_batch(name: str, seed: int) -> NavResult:
    """The batch smoother on paper_log(name, seed) with EstimatorConfig.paper() (constant biases)."""
    return smooth_batch(paper_log(name, seed), EstimatorConfig.paper())


@functools.cache
def paper_online(name: str, seed: int) -> NavResult:
    """The online estimator (fixed lag, the paper configuration's default) on paper_log(name, seed)."""
    return smooth_online(paper_log(name, seed), EstimatorConfig.paper())
