"""estimators/models/epoch_states.py: a per-epoch state added in this test alone reaches every trajectory estimator.

A toy state, a 3-D random walk that no measurement reads, x_0 ~ N(0, SIGMA0^2 I), x_j = x_i + w with
w ~ N(0, Q^2 dt I), is appended to the registry (monkeypatched: no estimator is edited) and each estimator run
through gtsam_dvl.estimators.run.run_estimator on a 40 s simulated log. Since nothing reads it, its estimate at the
last state must stay at the prior's mean and its sigma must be the random walk's own, sqrt(SIGMA0^2 + Q^2 T) with T
the time from the estimator's first state to its last; and the navigation must not move. An estimator that ignored
the registry would report no toy state (or the prior's sigma alone, were it carried without its links)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import DIMS
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.models import epoch_states
from gtsam_dvl.estimators.models.epoch_states import EpochState
from gtsam_dvl.estimators.run import run_estimator
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

SIGMA0, Q = 0.5, 0.1  # the toy state's prior sigma (1) and random walk (1 per sqrt(s))
MODES = ("batch", "online", "online-full", "ekf")


class ToyWalk(EpochState):
    """A 3-D random walk read by no factor (the recipe of docs/architecture.md, "Adding a per-epoch state")."""

    name, description, char, dim, unit = "toy_walk", "toy random walk", "y", 3, "1"
    info_key = "toy_walk"

    def enabled(self, config: EstimatorConfig) -> bool:
        return True

    def sigma0(self, config: EstimatorConfig) -> float:
        return SIGMA0

    def transition(
        self, config: EstimatorConfig, dt: float, dz: float = 0.0
    ) -> tuple[float, float]:
        return 1.0, Q**2 * max(dt, 0.0)


@cache
def _log() -> tuple[LogData, EstimatorConfig]:
    """steady-turn cut to 40 s (an underway start: every estimator starts at once)."""
    raw = dict(load_scenario("steady-turn").raw)
    raw["segments"] = [{**raw["segments"][0], "duration_s": 40.0}]
    scenario = scenario_from_dict(raw)
    return simulate(scenario, 3), scenario.estimator_configuration()


@cache
def _run(mode: str, toy: bool) -> NavResult:
    log, config = _log()
    with pytest.MonkeyPatch.context() as mp:
        if toy:
            mp.setattr(epoch_states, "EPOCH_STATES", [*epoch_states.EPOCH_STATES, ToyWalk()])
            mp.setitem(DIMS, ToyWalk.char, ToyWalk.dim)
        result = run_estimator(log, mode, config, timeline=mode == "batch")
    assert isinstance(result, NavResult)
    return result


@pytest.mark.parametrize("mode", MODES)
def test_a_toy_state_reaches_every_estimator(mode: str) -> None:
    """The toy state's reported estimate at the last state is the prior's mean (to 1e-9) and its sigma the random
    walk's prediction from the first state to the last (to 1e-6 relative: the smoothers' marginals of a linear
    chain are exact, the EKF's sum of steps too); the navigation is the run's without it (to 1e-9 m, m/s; its
    covariance to 1e-6 relative)."""
    with_toy, without = _run(mode, True), _run(mode, False)
    assert "toy_walk" not in without.info
    report = with_toy.info["toy_walk"]
    np.testing.assert_allclose(report["value"], np.zeros(3), atol=1e-9)
    elapsed = report["t_s"] - float(with_toy.t[0])
    assert report["t_s"] == pytest.approx(float(with_toy.t[-1])) and elapsed > 30.0
    expected = np.sqrt(SIGMA0**2 + Q**2 * elapsed)
    np.testing.assert_allclose(report["sigma"], np.full(3, expected), rtol=1e-6)
    assert expected > 1.2 * SIGMA0  # (the random walk visible against the prior alone)
    np.testing.assert_allclose(with_toy.n_p, without.n_p, rtol=0, atol=1e-9)
    np.testing.assert_allclose(with_toy.n_v, without.n_v, rtol=0, atol=1e-9)
    # (iSAM2 eliminates the toy's keys in the cliques of the navigation's: its covariances move by rounding, 1.3e-8
    # relative at most on small cross terms measured on online-full)
    np.testing.assert_allclose(with_toy.pose_cov, without.pose_cov, rtol=1e-6, atol=1e-15)
