"""`plan`: covariance analysis of a scenario without noise, against the batch smoother on noisy logs."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from gtsam_dvl.analysis.planning import PlanResult, plan_mission
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

pytestmark = pytest.mark.slow


@functools.cache
def _plan(name: str) -> PlanResult:
    return plan_mission(load_scenario(name))


def test_plan_paper_3d_credits_the_descent_and_the_turns() -> None:
    """Against the default targets (scale 0.1 %, misalignment 0.1 deg) the paper's 60 s descent leaves the
    thrust-axis misalignment at 0.26 deg: informed by the descent, but weakly determined; the plan says No."""
    p = _plan("paper-3d")
    print(p.answer())
    assert p.answer().startswith("No") and "thrust axis" in p.answer().splitlines()[0]
    roll = p.report.state("misalignment_roll")
    assert (
        roll.verdict == "weakly determined"
        and 0.2 < roll.posterior_sigma < 0.3
        and roll.target_sigma == 0.1
    )
    assert any(c.startswith("descent 660-720") for c in roll.credited_segments)
    assert p.determined_at_s["misalignment_roll"] is None
    for axis in ("x", "y"):
        acc = p.report.state(f"accel_bias_{axis}")
        assert any(c.startswith("square 750-1970") for c in acc.credited_segments)
        assert (
            p.determined_at_s[f"accel_bias_{axis}"] is not None
            and p.determined_at_s[f"accel_bias_{axis}"] > 750
        )
    # 1000 ppm is reached in the square, not at 600 s
    assert (p.determined_at_s["scale"] or 0) > 660
    assert "this plan's rate" in p.answer() and "this log" not in p.answer()


def test_plan_paper_3d_with_the_targets_relaxed_says_yes() -> None:
    """The targets are configurable: at half the priors (0.5 deg, 25 % of the scale prior: the paper's reading of
    "converged") the same plan calibrates the DVL, the scale at 600-660 s (the first Type-I segment) and the roll
    during the descent (660-720 s), as the paper finds."""
    from gtsam_dvl.core.config import EstimatorConfig

    cfg = EstimatorConfig.paper()
    cfg.observability.misalignment_deg = 0.5
    cfg.observability.scale_ppm = 0.25 * cfg.priors.scale_sigma * 1e6
    p = plan_mission(load_scenario("paper-3d"), cfg)
    print(p.answer())
    assert p.answer().startswith("Yes")
    assert p.report.state("misalignment_roll").verdict == "determined"
    assert 600 < (p.determined_at_s["scale"] or 0) < 660
    assert 660 < (p.determined_at_s["misalignment_roll"] or 0) < 720


def test_plan_paper_2d_says_no_and_names_the_thrust_axis() -> None:
    p = _plan("paper-2d")
    print(p.answer())
    assert p.answer().startswith("No") and "thrust axis" in p.answer().splitlines()[0]
    assert p.report.state("misalignment_roll").verdict == "not determined"
    for key in ("scale", "misalignment_pitch", "misalignment_yaw", "accel_bias_x", "accel_bias_y"):
        assert p.report.state(key).verdict == "determined", key


@pytest.mark.parametrize("name", ["paper-3d", "paper-2d"])
def test_predicted_final_sigmas_match_batch_on_noisy_logs(name: str) -> None:
    """Sigmas of the plan (no noise) against the batch smoother on a noisy log: within 10 %."""
    p = _plan(name)
    res = smooth_batch(simulate(load_scenario(name), 13))
    pred = np.concatenate(
        [
            [p.result.scale_sigma],
            p.result.misalignment_sigma_deg,
            p.result.accel_bias_sigma_ug,
            p.result.gyro_bias_sigma_deg_per_h,
        ]
    )
    got = np.concatenate(
        [
            [res.scale_sigma],
            res.misalignment_sigma_deg,
            res.accel_bias_sigma_ug,
            res.gyro_bias_sigma_deg_per_h,
        ]
    )
    ratio = pred / got
    print(f"{name}: predicted / batch sigma = {np.round(ratio, 3)}; plan took {p.wall_s:.1f} s")
    assert np.all(np.abs(ratio - 1) < 0.10)
