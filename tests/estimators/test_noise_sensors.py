"""The depth sensor's and the GNSS fixes' variance components fitted by the batch smoother with the DVL's
(estimators/models/noise_levels.py, batch/solve.py fit_dvl_noise): a stated noise three times too small or too large is
found
within the sampling error of its rows, the bounds hold, and a log without depth or fixes gives the same result as
without these fits."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import noise_lines
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import surface_dive_raw

DEPTH_M = 0.05  # the simulated depth sensor's white noise (m)
GNSS_M = 2.0  # the simulated fixes' white noise per axis (m)
DEPTH_ROWS = 1298  # 5 Hz depth over the 260 s dive, on states within 0.5 s
# 1 Hz fixes at the surface (60 s static and away, 40 s at the end), 3 rows each
GNSS_ROWS = 3 * 167


def _tolerance(rows: int, bias: float) -> float:
    """3 sigma of a sigma factor fitted from rows rows (the variance's relative sigma is sqrt(2 / rows), the
    sigma's half of it) plus the fit's redundancy bias (the states absorb a part of the residual: measured over
    six seeds -0.5 % for the 5 Hz depth, -2.4 % +- 1.3 % for the fixes, whose intervals' positions take 3 rows
    each)."""
    return 3.0 * math.sqrt(2.0 / rows) / 2.0 + bias


@pytest.fixture(scope="module")
def dive() -> LogData:
    """A 260 s dive from the surface and back: 60 s static at the surface, away at 2 m/s, down to about 15 m, a
    banked 90 deg turn, up again and 40 s on at the surface; 5 Hz depth (5 cm), 1 Hz fixes at the surface (2 m per
    axis), the map origin in the log."""
    raw = surface_dive_raw(
        [
            {"kind": "static", "duration_s": 60.0},
            {"kind": "level", "duration_s": 20.0, "speed_end_m_s": 2.0},
            {"kind": "level", "duration_s": 30.0, "speed_bump_m_s": 0.5},
            {"kind": "descent", "duration_s": 40.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "turn", "duration_s": 30.0, "heading_change_deg": 90.0, "bank_deg": 15.0},
            {"kind": "ascent", "duration_s": 40.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "straight", "duration_s": 40.0},
        ],
        depth={"rate_hz": 5.0, "noise_m": DEPTH_M},
        gnss={
            "rate_hz": 1.0,
            "horizontal_sigma_m": GNSS_M,
            "vertical_sigma_m": GNSS_M,
            "origin_in_log": True,
        },
    )
    return simulate(scenario_from_dict(raw, name="dive"), 1)


def _config(depth_m: float, gnss_m: float, **noise: Any) -> EstimatorConfig:
    """Every fix aids ([gnss] use = "all"), depth and fixes stated at depth_m and gnss_m."""
    return EstimatorConfig.from_dict(
        {
            "depth": {"noise_m": depth_m},
            "gnss": {"noise_m": gnss_m, "use": "all"},
            "noise": dict(noise),
        }
    )


@pytest.mark.parametrize("factor", [3.0, 1.0 / 3.0])
def test_batch_fits_the_depth_and_gnss_noise(dive: LogData, factor: float) -> None:
    """Depth and fixes simulated at factor times their stated sigma: each fitted factor is factor within
    _tolerance of its rows (depth 6.9 %, fixes 11.9 %), reported with the configured level, the rows and the
    passes; the result's configuration is the one given, its noise_config carries the fitted factors."""
    r = smooth_batch(dive, _config(DEPTH_M / factor, GNSS_M / factor))
    noise = r.info["noise"]
    depth, gnss = noise["depth"], noise["gnss"]
    print(
        f"\nx {factor:.3g}: depth x {depth['multiplier']:.4f} ({depth['rows']} rows), "
        f"GNSS x {gnss['multiplier']:.4f} ({gnss['rows']} rows), DVL x {noise['dvl']['multiplier']:.4f}"
    )
    assert depth["rows"] == pytest.approx(DEPTH_ROWS, abs=10)
    assert gnss["rows"] == pytest.approx(GNSS_ROWS, abs=12)
    # the white fit finds the simulated level; a level stated too large is held (nothing observes the sensors'
    # slow errors: estimators/models/noise_levels.py honest_multiplier), one stated too small is raised to the fit
    used_factor = max(factor, 1.0)
    for entry, rows, bias, sigma in (
        (depth, DEPTH_ROWS, 0.01, DEPTH_M),
        (gnss, GNSS_ROWS, 0.024, GNSS_M),
    ):
        assert entry["white_sigma"] == pytest.approx(sigma, rel=_tolerance(rows, bias))
        assert entry["multiplier"] == pytest.approx(used_factor, rel=_tolerance(rows, bias))
        assert entry["sigma_m"] == pytest.approx(
            sigma * used_factor / factor, rel=_tolerance(rows, bias)
        )
        assert not entry["at_bound"] and 1 <= entry["passes"] <= 4
        assert (factor < 1.0) == ("held at the stated level" in entry["why"])
    assert depth["configured"] == 1.0 and depth["configured_sigma_m"] == pytest.approx(
        DEPTH_M / factor
    )
    # the DVL, stated at its simulated 2 cm/s, stays near 1 (its 780 rows: 7.6 % at 3 sigma)
    assert noise["dvl"]["multiplier"] == pytest.approx(1.0, rel=0.076)
    assert (
        r.config["depth"]["noise_multiplier"] == 1.0 and r.config["gnss"]["noise_multiplier"] == 1.0
    )
    used = r.noise_config
    assert used is not None
    assert (
        used.depth.noise_multiplier == depth["multiplier"]
        and used.gnss.noise_multiplier == gnss["multiplier"]
    )
    # the console's lines (the summary's noise_levels): one per sensor
    lines = noise_lines(noise)
    assert any(line.startswith("depth noise fitted from") for line in lines)
    assert any(line.startswith("GNSS noise fitted from") for line in lines)


def test_fitted_factors_stay_within_their_bounds(dive: LogData) -> None:
    """Depth stated three times too small against a bound of 2: the factor ends at its bound, said so; fixes three
    times too large against a bound of 0.5: held at the stated level, said so; the health is degraded (the model
    does not fit its data). With
    the DVL's fit off (its entry empty) the depth and GNSS fits run alone."""
    from gtsam_dvl.analysis.health import assess_health

    r = smooth_batch(
        dive,
        _config(
            DEPTH_M / 3.0,
            GNSS_M * 3.0,
            depth_max_multiplier=2.0,
            gnss_min_multiplier=0.5,
            fit_dvl=False,
        ),
    )
    assert r.info["noise"]["dvl"] == {}
    depth, gnss = r.info["noise"]["depth"], r.info["noise"]["gnss"]
    assert (
        depth["multiplier"] == 2.0 and depth["at_bound"] and "at the bound [0.1, 2]" in depth["why"]
    )
    # the fixes, stated three times too large, keep their stated level (not the fit's 1/3, nor the bound)
    assert (
        gnss["multiplier"] == 1.0
        and not gnss["at_bound"]
        and "held at the stated level" in gnss["why"]
    )
    health = assess_health(r, dive)
    assert health.status == "degraded"
    assert any("depth noise fitted" in w for w in health.warnings)


def test_pinned_and_off_take_the_configured_level(dive: LogData) -> None:
    """fit_depth and fit_gnss off: the depth and the fixes at [depth] / [gnss] noise_multiplier (here the
    truth's factor, pinned), nothing fitted or reported for them."""
    r = smooth_batch(
        dive,
        EstimatorConfig.from_dict(
            {
                "depth": {"noise_m": DEPTH_M / 3.0, "noise_multiplier": 3.0},
                "gnss": {"use": "all"},
                "noise": {"fit_depth": False, "fit_gnss": False},
            }
        ),
    )
    assert "depth" not in r.info["noise"] and "gnss" not in r.info["noise"]
    used = r.noise_config
    assert used is not None and used.depth.noise_multiplier == 3.0


def test_a_log_without_depth_or_fixes_is_unchanged(dive: LogData) -> None:
    """The same dive without its depth and GNSS data: the depth and GNSS fits on (the default) or off give the
    same result bit for bit, and the noise report has no entry for them (as before these fits)."""
    bare = dataclasses.replace(dive, depth=None, gnss=None)
    on = smooth_batch(bare, EstimatorConfig())
    off = smooth_batch(
        bare, EstimatorConfig.from_dict({"noise": {"fit_depth": False, "fit_gnss": False}})
    )
    for name in ("n_p", "n_v", "n_R_b", "pose_cov", "calib_joint_cov"):
        assert np.array_equal(getattr(on, name), getattr(off, name)), name
    assert on.info["noise"] == off.info["noise"]
    assert set(on.info["noise"]) == {"imu", "dvl"}
    assert on.info["solver"]["final_error"] == off.info["solver"]["final_error"]


def test_online_and_ekf_say_they_hold_the_configured_depth_level(dive: LogData) -> None:
    """The online estimator and the EKF do not fit the depth: it stays at its configured level, and the report
    and the console say so (no GNSS entry: neither takes fixes); a log without depth, or the depth fit off, has no
    such entry. (The online estimator as set up for the log; the EKF's entry is made the same way.)"""
    from gtsam_dvl.estimators.models.noise_levels import held_depth_level
    from gtsam_dvl.estimators.online.estimator import OnlineEstimator

    cfg = _config(DEPTH_M / 3.0, GNSS_M)
    noise = OnlineEstimator.for_log(dive, cfg).noise.as_dict()
    assert noise["depth"]["held"] and noise["depth"]["multiplier"] == 1.0 and "gnss" not in noise
    assert any("the online estimator holds it" in line for line in noise_lines(noise))
    assert "the EKF holds it" in held_depth_level(dive, cfg, "EKF")["why"]
    assert held_depth_level(dataclasses.replace(dive, depth=None), cfg, "EKF") == {}
    assert held_depth_level(dive, _config(DEPTH_M, GNSS_M, fit_depth=False), "EKF") == {}
