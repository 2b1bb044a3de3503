"""Shared simulator fixtures (sim_ prefix): simulated once per test session and worker; and the xdist grouping
of the modules that share a fixture between their tests."""

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


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under `--dist loadgroup` (make test), the tests of a module that share a module- or class-scoped fixture
    run on one xdist worker: spread over two, each worker would compute the fixture (a simulated log, an
    estimator's run) again. A test already in a group keeps it. Runs before xdist's own hook, which reads the
    marks."""
    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        info = getattr(item, "_fixtureinfo", None)
        defs = info.name2fixturedefs.values() if info is not None else ()
        if any(d and d[-1].scope in ("module", "class") for d in defs):
            item.add_marker(pytest.mark.xdist_group(name=item.nodeid.split("::")[0]))


class _GroupIds:
    """pytest-xdist 3.8 puts a test in its xdist_group by appending "@group" to item._nodeid, which pytest 9.2 no
    longer reads (a node's id is structured: Node._id, a NodeId): every xdist_group would be ignored and the
    tests of a group spread over the workers, each computing the group's shared runs (measured: test_node_core's
    tests on both workers). After xdist's own hook, the same suffix is given through the structured id; with a
    pytest whose ids xdist can still rename, nothing is done."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(
        self, config: pytest.Config, items: list[pytest.Item]
    ) -> None:
        if not getattr(config.option, "loadgroup", False):
            return
        try:
            from _pytest.nodeid import NodeId
        except ImportError:  # a pytest before structured ids: xdist's renaming works
            return
        for item in items:
            names = sorted(
                str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                for m in item.iter_markers("xdist_group")
            )
            if names and "@" not in item.nodeid:
                item._id = NodeId.parse(f"{item.nodeid}@{'_'.join(names)}")


def pytest_configure(config: pytest.Config) -> None:
    config.pluginmanager.register(_GroupIds(), "gtsam_dvl_xdist_group_ids")
