"""The EKF's defences against a warm-up that lost track (estimators/ekf/warmup.py, divergence.py): the window's time
offset estimate moves the prior's centre only when the window's sigma and residuals support it; a filter whose
offset the bound holds is caught by the divergence watch; a centre the whole log contradicts goes back to the
configured prior. Fast: the decisions on stand-in window results."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any, cast

import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.estimators.ekf.divergence import BOUND_PINGS, DivergenceWatch
from gtsam_dvl.estimators.ekf.warmup import (
    WINDOW_GATED_MAX,
    WINDOW_RESIDUAL_MAX,
    contradicted,
    recentred_offset,
    with_offset_prior,
)

CONFIG = EstimatorConfig()  # time offset prior 0 +- 0.5 s


def _window(
    dt: float = 0.32,
    sigma: float = 0.04,
    nis: float = 1.02,
    pings: int = 594,
    gated: int = 0,
    bounded: int = 0,
    diverged_by: str | None = None,
) -> NavResult:
    """A stand-in for a filtered window's NavResult: what the decisions read."""
    counters = {"dvl_updates": pings, "dvl_gated": gated}
    if bounded:
        counters["time_offset_bounded"] = bounded
    filt: dict[str, Any] = {"mean_nis_per_dof": nis}
    if diverged_by:
        filt["diverged_by"] = diverged_by
    info = {"counters": counters, "filter": filt}
    return cast(NavResult, SimpleNamespace(time_offset_s=dt, time_offset_sigma_s=sigma, info=info))


def test_a_window_that_kept_track_centres_the_prior() -> None:
    """field-survey seed 3's window with the fix's uncertainty (measured: +0.322 +- 0.040 s, NIS 1.02, none
    gated): the prior moves there with its configured sigma."""
    info: dict[str, Any] = {}
    config, moved, supported = recentred_offset(CONFIG, _window(), info, 1, CONFIG, 1.0)
    assert supported and moved
    assert config.dvl.time_offset_prior_s == pytest.approx(0.32)
    assert config.dvl.time_offset_sigma_s == CONFIG.dvl.time_offset_sigma_s
    assert info["centre_s"] == pytest.approx(0.32) and info["configured_s"] == 0.0


@pytest.mark.parametrize(
    ("window", "words"),
    [
        # field-survey seed 3's window with its first position pinned at the fix (measured): the offset at the bound
        (_window(-1.452, 0.100, 61.2, 594, 461, 22), "held at its prior's bound"),
        # the same without the bound: 461 of 594 pings gated
        (_window(-1.452, 0.100, 61.2, 594, 461), "lost track"),
        # innovations 2.2x the stated noise, nothing gated
        (_window(nis=(WINDOW_RESIDUAL_MAX + 0.2) ** 2), "their stated noise"),
        # a straight run at constant speed: the window does not determine the offset
        (_window(sigma=0.3), "did not determine"),
    ],
)
def test_a_window_that_does_not_support_its_estimate_keeps_the_prior(
    window: NavResult, words: str
) -> None:
    info: dict[str, Any] = {}
    config, moved, supported = recentred_offset(CONFIG, window, info, 1, CONFIG, 1.0)
    assert not supported and not moved
    assert config.dvl.time_offset_prior_s == 0.0
    assert "centre_s" not in info
    assert words in info["why"] and info["why"].startswith("time offset prior kept at +0.000 s")


def test_gated_pings_within_the_limit_and_a_fitted_level_do_not_refuse() -> None:
    """Outliers gated below WINDOW_GATED_MAX, and innovations judged at the level the pass ran with relative to the
    stated one (a pass at 1.5x the stated noise with NIS 1 per dof: 1.5x, supported)."""
    few = int(WINDOW_GATED_MAX * 594)
    window_config = CONFIG.model_copy(
        update={"dvl": CONFIG.dvl.model_copy(update={"noise_multiplier": 1.5})}
    )
    _, _, supported = recentred_offset(CONFIG, _window(gated=few), {}, 1, window_config, 1.0)
    assert supported
    _, _, supported = recentred_offset(
        CONFIG, _window(nis=1.0), {}, 1, window_config, 0.5
    )  # 1.5 / 0.5 = 3x the stated noise
    assert not supported


def test_a_centre_the_next_window_contradicts_goes_back_to_the_configured_prior() -> None:
    info: dict[str, Any] = {}
    config, _, _ = recentred_offset(CONFIG, _window(dt=0.6), info, 1, CONFIG, 1.0)
    config, moved, supported = recentred_offset(
        config, _window(dt=-0.9, gated=300), info, 2, config, 1.0
    )
    assert not supported and moved  # another pass: the noise fit at the configured centre
    assert config.dvl.time_offset_prior_s == 0.0 and "centre_s" not in info


def test_the_divergence_watch_catches_an_offset_held_at_its_bound() -> None:
    watch = DivergenceWatch()
    # a filter converging from a far prior touches the bound and comes back
    assert not any(watch.held(float(t), True) for t in range(BOUND_PINGS - 1))
    assert not watch.held(100.0, False)
    found = [watch.held(200.0 + t, True) for t in range(BOUND_PINGS)]
    assert found == [False] * (BOUND_PINGS - 1) + [True]
    assert watch.diverged and watch.diverged_at_s == 200.0 + BOUND_PINGS - 1
    info = watch.info()
    assert info["diverged_by"] == "bound" and "held at its prior's bound" in info["why"]


def test_a_centre_the_whole_log_contradicts_is_refused() -> None:
    info = {"configured_s": 0.0, "centre_s": -1.649}
    config = with_offset_prior(CONFIG, -1.649)  # bound -0.149 s
    assert contradicted(_window(dt=-0.5), config, info) is None
    at_bound = contradicted(_window(dt=-0.160), config, info)
    assert at_bound is not None and "ended at that prior's bound" in at_bound
    caught = contradicted(_window(dt=-0.374, diverged_by="bound"), config, info)
    assert caught is not None and "held its offset at that prior's bound" in caught
    # a prior the warm-up did not move: nothing to go back to
    assert contradicted(_window(dt=-1.49), CONFIG, {"configured_s": 0.0}) is None
