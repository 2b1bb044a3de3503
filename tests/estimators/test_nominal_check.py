"""The nominal calibration's check (estimators/batch/smoother.py _hold_calibration, estimators/models/weak_hold.py
nominal_check):
where estimating the DVL scale and misalignment does not pay for its four states, the calibration is held at the
nominal with its prior's sigma; where it does, it is estimated. And the EKF's divergence watch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.summary import DIRECTION_NAMES, CalibrationHold
from gtsam_dvl.core.types import LogData, Mounting
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf.divergence import DIVERGENCE_NIS, DIVERGENCE_PINGS, DivergenceWatch
from gtsam_dvl.estimators.models import weak_hold
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict


def test_nominal_check_is_the_likelihood_ratio() -> None:
    """d' P^-1 d against chi^2(4)'s 95 % quantile, worked by hand on a diagonal P."""
    P = np.diag([1e-4, 4e-4, 1e-6, 9e-6])
    d = np.array([1e-2, 2e-2, 0.0, 0.0])  # 1 and 1 sigma: chi^2 2
    c = weak_hold.nominal_check(d, P)
    assert c["chi2_gain"] == pytest.approx(2.0) and c["chi2_limit"] == pytest.approx(
        chi2.ppf(0.95, 4)
    )
    assert not c["pays"]
    assert weak_hold.nominal_check(3 * d, P)["pays"]  # chi^2 18


def test_ekf_nominal_hold_in_the_one_shape() -> None:
    """The EKF's check as core/summary.py CalibrationHold (weak_hold.filter_nominal_hold): the directions of its
    calibration covariance against the prior, each with the information the filter added (here a diagonal P whose
    information is 0.5, 3, 0.1 and 0.2 prior units on scale, roll, pitch and yaw), all held when the check did not
    pay, none when it paid; a covariance that is not finite: the prior's axes, the information unknown (NaN)."""
    cfg = EstimatorConfig()
    _, _, P0 = weak_hold.calibration_prior(cfg, Mounting())
    lam = np.array([0.5, 3.0, 0.1, 0.2])
    joint = (
        np.eye(10) * 1e-8
    )  # [accel, gyro] bias, scale, misalignment (core/states.py block_states)
    joint[6:, 6:] = P0 / (1.0 + lam)
    check = {"chi2_gain": 0.6, "chi2_limit": chi2.ppf(0.95, 4), "level": 0.95, "pays": False}
    hold = CalibrationHold.model_validate(
        weak_hold.filter_nominal_hold(cfg, Mounting(), joint, check)
    )
    assert hold.reason == "nominal_check" and hold.nominal is not None and not hold.nominal.pays
    got = {h.mostly: h.information for h in hold.held}
    want = dict(zip(DIRECTION_NAMES, lam, strict=True))
    assert got == pytest.approx(want)
    assert hold.why.startswith(
        "held at the nominal calibration: the filtered calibration's chi^2 gain"
    )
    paid = CalibrationHold.model_validate(
        weak_hold.filter_nominal_hold(cfg, Mounting(), joint, {**check, "pays": True})
    )
    assert paid.reason == "none" and paid.held == [] and paid.lines() == []
    joint[6, 6] = np.nan
    diverged = CalibrationHold.model_validate(
        weak_hold.filter_nominal_hold(cfg, Mounting(), joint, check)
    )
    assert [h.mostly for h in diverged.held] == list(DIRECTION_NAMES)
    assert diverged.lines()[0].endswith(
        ": scale, misalignment roll, misalignment pitch, misalignment yaw"
    )


def _straight(scale: float) -> tuple[LogData, EstimatorConfig]:
    sc = load_scenario("straight-transect")
    raw = dict(sc.raw)
    raw["dvl"] = {**raw["dvl"], "scale": scale, "misalignment_deg": [0.0, 0.0, 0.0]}
    return simulate(scenario_from_dict(raw, name="straight"), 4), sc.estimator_configuration()


def test_straight_run_at_nominal_is_held_there() -> None:
    """A straight run whose DVL is at its nominal (scale 1, misalignment 0): the check finds no gain worth four
    states, the calibration is the nominal exactly with the prior's sigmas, the result says why, and the final
    position is within 3 sigma of the truth."""
    log, cfg = _straight(1.0)
    r = smooth_batch(log, cfg)
    hold = r.info["calibration_hold"]
    assert not hold["nominal"]["pays"] and "held at the nominal calibration" in hold["why"]
    assert r.calibration["scale"].value[0] == pytest.approx(1.0, abs=1e-6)
    assert r.calibration["scale"].sigma[0] == pytest.approx(cfg.priors.scale_sigma, rel=0.01)
    np.testing.assert_allclose(r.calibration["misalignment"].value, log.mounting.b_R_d0, atol=1e-7)
    truth = log.truth
    assert truth is not None
    e = r.n_p[-1, :2] - [np.interp(r.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)]
    assert np.all(np.abs(e) < 3 * r.position_sigma_m[-1, :2])


def test_a_scale_the_run_shows_is_estimated() -> None:
    """paper-3d-short (speed changes, a descent, turns) with the DVL's scale 3 % off (3 prior sigmas) and the
    default configuration: the gain pays, the scale is estimated, the truth is within 3 of its sigmas, which are
    below half the prior's. (On the straight run above a scale is not observable and stays held.)"""
    sc = load_scenario("paper-3d-short")
    raw = dict(sc.raw)
    raw["dvl"] = {**raw["dvl"], "scale": 1.03}
    raw.pop("estimator_config", None)
    log = simulate(scenario_from_dict(raw, name="off"), 4)
    cfg = EstimatorConfig()
    r = smooth_batch(log, cfg)
    hold = r.info["calibration_hold"]
    assert hold["nominal"]["pays"]
    k, sk = r.calibration["scale"].value[0], r.calibration["scale"].sigma[0]
    assert abs(k - 1.03) < 3 * sk and sk < 0.5 * cfg.priors.scale_sigma


def test_divergence_watch() -> None:
    """Consistent NIS (1 per dof) never trips it, nor a large NIS that falls (a filter converging from a wrong
    prior); a growing run at twice the threshold trips it once, where the running mean crosses."""
    w = DivergenceWatch()
    rng = np.random.default_rng(0)
    assert not any(w.add(float(t), float(x)) for t, x in enumerate(rng.chisquare(3, 1000) / 3))
    falling = DivergenceWatch()
    assert not any(falling.add(float(t), 100.0 * 0.97**t) for t in range(300))
    tripped = [w.add(1000.0 + t, 2 * DIVERGENCE_NIS) for t in range(2 * DIVERGENCE_PINGS)]
    assert sum(tripped) == 1 and w.diverged and "frozen" in w.info()["why"]
    assert 1000.0 < w.diverged_at_s < 1000.0 + DIVERGENCE_PINGS  # type: ignore[operator]


def test_ekf_holds_the_nominal_as_consider_states() -> None:
    """The EKF on the straight run at nominal: its final calibration's chi^2 gain does not pay, so it filters again
    with the scale and misalignment as consider states: they end exactly at the nominal with the prior's sigmas,
    and the position is within 3 sigma of the truth."""
    from gtsam_dvl.estimators.ekf.filter import run_ekf

    log, cfg = _straight(1.0)
    r = run_ekf(log, cfg)
    hold = r.info["calibration_hold"]
    assert not hold["nominal"]["pays"] and "consider states" in hold["why"]
    assert r.calibration["scale"].value[0] == pytest.approx(1.0, abs=1e-12)
    assert r.calibration["scale"].sigma[0] == pytest.approx(cfg.priors.scale_sigma, rel=1e-6)
    np.testing.assert_allclose(r.calibration["misalignment"].value, log.mounting.b_R_d0, atol=1e-12)
    truth = log.truth
    assert truth is not None
    e = r.n_p[-1, :2] - [np.interp(r.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)]
    assert np.all(np.abs(e) < 3 * r.position_sigma_m[-1, :2])
