"""`plan`: covariance analysis of a scenario without noise, against the batch smoother on noisy logs."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from gtsam_dvl.analysis.planning import PlanResult, plan_mission
from gtsam_dvl.estimators.batch import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario


@functools.cache
def _plan(name: str) -> PlanResult:
    return plan_mission(load_scenario(name))


def test_plan_paper_3d_credits_the_descent_and_the_turns() -> None:
    p = _plan("paper-3d")
    print(p.answer())
    assert p.answer().startswith("Yes")
    roll = p.report.state("misalignment_roll")
    assert roll.verdict == "determined" and any(c.startswith("descent 660-720") for c in roll.credited_segments)
    for axis in ("x", "y"):
        acc = p.report.state(f"accel_bias_{axis}")
        assert any(c.startswith("square 750-1970") for c in acc.credited_segments)
        assert p.determined_at_s[f"accel_bias_{axis}"] is not None and p.determined_at_s[f"accel_bias_{axis}"] > 750
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
    pred = np.concatenate([[p.result.scale_sigma], p.result.misalignment_sigma_deg, p.result.accel_bias_sigma_ug,
                           p.result.gyro_bias_sigma_deg_per_h])
    got = np.concatenate([[res.scale_sigma], res.misalignment_sigma_deg, res.accel_bias_sigma_ug,
                          res.gyro_bias_sigma_deg_per_h])
    ratio = pred / got
    print(f"{name}: predicted / batch sigma = {np.round(ratio, 3)}; plan took {p.wall_s:.1f} s")
    assert np.all(np.abs(ratio - 1) < 0.10)
