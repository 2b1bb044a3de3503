"""Shared simulator fixtures (sim_ prefix): simulated once per test session and worker."""

from __future__ import annotations

import pytest

from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario, load_scenario


@pytest.fixture(scope="session")
def sim_paper3d() -> Scenario:
    return load_scenario("paper-3d")


@pytest.fixture(scope="session")
def sim_paper3d_clean(sim_paper3d: Scenario) -> LogData:
    """paper-3d without white noise (biases, scale, misalignment kept)."""
    return simulate(sim_paper3d, seed=7, white_noise=False)


@pytest.fixture(scope="session")
def sim_paper2d_clean() -> LogData:
    return simulate(load_scenario("paper-2d"), seed=7, white_noise=False)


@pytest.fixture(scope="session")
def sim_paper3d_short() -> LogData:
    """paper-3d-short with noise (seed 11, as the fault matrix's): 840 s, the paper's manoeuvres shortened."""
    return simulate(load_scenario("paper-3d-short"), seed=11)
