"""estimators/models/correlated_fit.py: the DVL's correlated error fitted in the batch smoother's noise loop.

The fit's bounds and significance rule on synthetic residual series; the loop on a short simulated log whose DVL
carries a strong correlated error; with the fit off, or with nothing significant to fit, the results of the
configured level; the estimators that hold the level say so."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import noise_lines
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.models.correlated_fit import fit_enabled, fit_level, held_correlated_level
from gtsam_dvl.estimators.run import run_trajectory_estimator
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario, load_scenario, scenario_from_dict
from tests.support.numerical import gauss_markov


def _series(seed: int, sigma: float, n: int = 1200) -> tuple[np.ndarray, np.ndarray]:
    """n pings at 1 Hz of 3 axes: 7 mm/s white plus sigma over 60 s."""
    rng = np.random.default_rng(seed)
    r = np.column_stack(
        [
            rng.normal(0.0, 0.007, n) + (gauss_markov(n, 1.0, sigma, 60.0, rng) if sigma else 0.0)
            for _ in range(3)
        ]
    )
    return np.arange(n, dtype=float), r


def _fit_config(**noise: float | bool) -> EstimatorConfig:
    return EstimatorConfig.from_dict({"noise": {"fit_correlated": True, **noise}})


def test_fit_takes_a_significant_level_within_the_bounds() -> None:
    """4 mm/s over 60 s in 1200 s of 3 axes: the level within 35 % and tau within a factor 2.5 (the fit's scatter
    on 1200 s: sg about 15 %, tau a factor 1.6, 1 sigma; seed 2), significant; with bounds of 2 mm/s on the level
    and 100 s on tau below, both clipped to them and at_bound said."""
    t, r = _series(2, 0.004)
    fit = fit_level(t, r, _fit_config())
    assert fit.significant and not fit.at_bound and fit.rows == 3 * len(t)
    assert fit.sigma_m_s == pytest.approx(0.004, rel=0.35)
    assert 24.0 < fit.tau_s < 150.0
    clipped = fit_level(
        t, r, _fit_config(correlated_max_sigma_m_s=0.002, correlated_min_tau_s=100.0)
    )
    assert clipped.at_bound and clipped.sigma_m_s == 0.002 and clipped.tau_s >= 100.0


def test_white_residuals_keep_the_configured_level() -> None:
    """White residuals: the fit is not significant, the level and time constant stay the configured ones (2 mm/s
    over 60 s) and nothing moves."""
    t, r = _series(4, 0.0)
    cfg = _fit_config()
    fit = fit_level(t, r, cfg)
    assert not fit.significant
    assert (fit.sigma_m_s, fit.tau_s) == (cfg.dvl.correlated_sigma_m_s, cfg.dvl.correlated_tau_s)
    assert not fit.moves(
        cfg.dvl.correlated_sigma_m_s, cfg.dvl.correlated_tau_s, cfg.noise.correlated_tolerance
    )


@cache
def _scenario(sigma: float, duration_s: float) -> Scenario:
    """steady-turn shortened, its DVL's correlated error sigma over 30 s beside 5 mm/s white."""
    raw = dict(load_scenario("steady-turn").raw)
    raw["dvl"] = {
        **raw["dvl"],
        "correlated_sigma_m_s": sigma,
        "correlated_tau_s": 30.0,
        "noise_m_s": 0.005,
    }
    raw["segments"] = [{**raw["segments"][0], "duration_s": duration_s}]
    return scenario_from_dict(raw)


@cache
def _log(sigma: float, duration_s: float, seed: int) -> LogData:
    return simulate(_scenario(sigma, duration_s), seed)


def _config(sc: Scenario, fit: bool) -> EstimatorConfig:
    d = sc.estimator_configuration().to_dict()
    d["noise"] = {**d["noise"], "fit_correlated": fit}
    return EstimatorConfig.from_dict(d)


def test_batch_loop_finds_the_part_of_a_strong_error_the_imu_separates() -> None:
    """200 s with 6 mm/s over 30 s, the fit from the default 2 mm/s over 60 s: significant, settled, the level
    between 0.4 and 1.0 of the simulated (the navigation solution follows the error's slow part, so the residuals
    show less of it: 0.45, 0.60, 0.65 on seeds 1-3, whatever the start: 3x above and below the simulated level
    end within 15 % of these), tau within the bounds; the result, its configuration read back with the levels
    used (NavResult.noise_config) and its info say the same level."""
    sc = _scenario(0.006, 200.0)
    res = smooth_batch(_log(0.006, 200.0, 1), _config(sc, True))
    entry = res.info["noise"]["dvl_correlated"]
    assert entry["significant"] and "not settled" not in entry["how"]
    assert 0.4 * 0.006 < entry["sigma_m_s"] < 0.006
    assert 5.0 <= entry["tau_s"] <= 600.0
    assert res.info["dvl_correlated_error"]["sigma_m_s"] == entry["sigma_m_s"]
    used = res.noise_config
    assert used is not None and used.dvl.correlated_sigma_m_s == entry["sigma_m_s"]
    assert (
        res.estimator_config is not None and res.estimator_config.dvl.correlated_sigma_m_s == 0.002
    )
    assert entry["why"].startswith("DVL correlated error fitted from")
    # (the summary's and the console's noise lines)
    assert entry["why"] in noise_lines(res.info["noise"])


def test_nothing_to_fit_gives_the_configured_results() -> None:
    """60 s of a white DVL with the default level (2 mm/s over 60 s) modelled: the fit finds nothing significant,
    and the estimates and sigmas are those of the fit off to the last bit; the report says the level holds."""
    sc = _scenario(0.0, 60.0)
    log = _log(0.0, 60.0, 3)
    on, off = smooth_batch(log, _config(sc, True)), smooth_batch(log, _config(sc, False))
    entry = on.info["noise"]["dvl_correlated"]
    assert not entry["significant"] and entry["sigma_m_s"] == 0.002 and entry["tau_s"] == 60.0
    assert "as configured" in entry["why"]
    assert "dvl_correlated" not in off.info["noise"]
    np.testing.assert_array_equal(on.n_p, off.n_p)
    np.testing.assert_array_equal(on.pose_cov, off.pose_cov)
    assert on.scale == off.scale and on.scale_sigma == off.scale_sigma


def test_held_by_the_online_estimator_and_the_ekf() -> None:
    """With the fit on, the estimators that hold the level say so (the EKF on 60 s of the log above, in its
    info["noise"]); with it off (the default), or the error white, nothing is said."""
    sc = _scenario(0.0, 60.0)
    ekf = run_trajectory_estimator(_log(0.0, 60.0, 3), "ekf", _config(sc, True), timeline=False)
    assert ekf.info["noise"]["dvl_correlated"]["held"]
    on = held_correlated_level(_fit_config(), "EKF")
    assert on["held"] and on["sigma_m_s"] == 0.002 and "the EKF holds it" in on["why"]
    assert held_correlated_level(EstimatorConfig(), "EKF") == {}
    white = EstimatorConfig.from_dict(
        {"noise": {"fit_correlated": True}, "dvl": {"correlated_sigma_m_s": 0.0}}
    )
    assert held_correlated_level(white, "EKF") == {}


def test_off_by_default_and_never_in_the_paper_configuration() -> None:
    """The defaults leave the fit off; the paper configuration (its DVL error white, from_data off) has nothing to
    fit even with fit_correlated on, so its runs (make demo's tables) take the path they always took."""
    assert not fit_enabled(EstimatorConfig())
    paper = EstimatorConfig.named("paper")
    on = paper.model_copy(update={"noise": paper.noise.model_copy(update={"fit_correlated": True})})
    assert not fit_enabled(on)
    white = on.model_copy(update={"noise": on.noise.model_copy(update={"from_data": True})})
    assert white.dvl.correlated_sigma_m_s == 0.0 and not fit_enabled(white)
