"""Water-track pings and the water current (estimators/models/current.py): a stretch of a simulated log's pings turned
into water-track pings (the velocity relative to a known current, through the true attitude and calibration) is
used with the current as a state; the current comes back within its sigmas, the calibration within its sigmas."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.models.current import resolve_water_track, step_variance
from tests.support.water import N_C, T_WATER, with_water_track
from tests.support.water import water_config as _config


def _profile(res: NavResult) -> dict[str, Any]:
    """The result's water-current profile (NavResult.water_current) in its plain form."""
    assert res.water_current is not None
    return res.water_current.as_dict()


@pytest.fixture(scope="module")
def water_log(sim_paper3d_short: LogData) -> LogData:
    return with_water_track(sim_paper3d_short)


def test_auto_resolves_by_the_log(water_log: LogData, sim_paper3d_short: LogData) -> None:
    assert resolve_water_track(_config(water_log, "auto"), water_log).current.water_track == "use"
    assert (
        resolve_water_track(_config(water_log, "auto"), sim_paper3d_short).current.water_track
        == "refuse"
    )
    assert (
        resolve_water_track(_config(water_log, "refuse"), water_log).current.water_track == "refuse"
    )


def test_random_walk_variance() -> None:
    cfg = EstimatorConfig()
    c = cfg.current
    assert step_variance(cfg, 10.0, -30.0) == pytest.approx(
        c.time_rw_m_s_per_sqrt_s**2 * 10 + c.depth_rw_m_s_per_sqrt_m**2 * 30
    )


def test_batch_recovers_the_current(water_log: LogData) -> None:
    used = smooth_batch(water_log, _config(water_log, "auto"), timeline=True)
    assert used.config["current"]["water_track"] == "use"
    # the filtering timeline carries W(i) too: its last sigma is the smoother's
    assert used.timeline is not None
    assert used.timeline.scale_sigma[-1] == pytest.approx(
        used.calibration["scale"].sigma[0], rel=1e-6
    )
    wc = _profile(used)
    t = np.asarray(wc["t_s"])
    inside = (t > T_WATER[0] + 5) & (t < T_WATER[1] - 5)
    assert inside.sum() > 50 and wc["water_track_states"] >= inside.sum()
    for axis, truth in (("east", N_C[0]), ("north", N_C[1])):
        est, sig = (
            np.asarray(wc[f"{axis}_m_s"])[inside],
            np.asarray(wc[f"{axis}_sigma_m_s"])[inside],
        )
        # determined: bottom track on both sides ties the velocity
        assert np.all(sig < 0.02), sig.max()
        assert abs(est.mean() - truth) < 3 * sig.mean(), (axis, est.mean(), sig.mean())
    assert wc["determined_during_water_track"]
    assert used.info["counters"]["dvl_water_track"] == 0  # used, not refused
    truth = water_log.true_calibration
    assert truth is not None
    scale = used.calibration["scale"]
    assert abs(scale.value[0] - truth.scale) < 3 * scale.sigma[0]

    refused = smooth_batch(water_log, _config(water_log, "refuse"))
    assert refused.info["counters"]["dvl_water_track"] == int(water_log.dvl.water_track.sum())
    assert refused.water_current is None and "water_current" not in refused.info


def _assert_filtered_current(used: NavResult, log: LogData) -> None:
    """A filter's current at the end of the water-track stretch within 3 sigma of the truth (its sigma well below
    the prior's 0.5 m/s), no water-track ping refused, the scale within 3 sigma."""
    wc = _profile(used)
    t = np.asarray(wc["t_s"])
    end = int(np.flatnonzero(t < T_WATER[1] - 1)[-1])
    for axis, truth in (("east", N_C[0]), ("north", N_C[1])):
        est, sig = wc[f"{axis}_m_s"][end], wc[f"{axis}_sigma_m_s"][end]
        assert sig < 0.04 and abs(est - truth) < 3 * sig, (axis, est, sig)
    assert used.info["counters"].get("dvl_water_track", 0) == 0
    truth_cal = log.true_calibration
    assert truth_cal is not None
    scale = used.calibration["scale"]
    assert abs(scale.value[0] - truth_cal.scale) < 3 * scale.sigma[0]


def test_ekf_recovers_the_current(water_log: LogData) -> None:
    """The EKF carries the current as two more error-state components: at the end of the water-track stretch its
    filtered current is within 3 sigma of the truth; refusing the pings counts them."""
    from gtsam_dvl.estimators.ekf import run_ekf

    _assert_filtered_current(run_ekf(water_log, _config(water_log, "auto")), water_log)


def test_online_recovers_the_current(water_log: LogData) -> None:
    """The online estimator (fixed lag) carries W(i) in its window: the filtered current at the end of the
    water-track stretch within 3 sigma of the truth, and the calibration within its sigmas."""
    from gtsam_dvl.estimators.online import smooth_online
    from tests.support.logs import cut_log

    # (its first 180 s)
    used = smooth_online(cut_log(water_log, T_WATER[1] + 20.0), _config(water_log, "auto"))
    assert used.config["current"]["water_track"] == "use"
    _assert_filtered_current(used, water_log)


def test_health_counts_water_track_and_flags_false_lock(water_log: LogData) -> None:
    """The health notes the water-track stretch and judges its residuals with the current (no warning on a
    consistent log); bottom-track pings that report the velocity relative to the water (a false lock, 200-210 s)
    are flagged as such."""
    from gtsam_dvl.analysis.health import assess_health

    clean = smooth_batch(water_log, _config(water_log, "auto"))
    health = assess_health(clean, water_log)
    fig = health.figures["water_track"]
    assert (
        fig["used"]
        and fig["pings"] == int(water_log.dvl.water_track.sum())
        and len(fig["stretches"]) == 1
    )
    assert fig["whitened_rms"] < 1.5 and fig["false_lock_pings"] == 0
    assert any("water-track pings in 1 stretch" in n for n in health.notes)
    assert not any("water" in w for w in health.warnings), health.warnings

    # bottom-track pings at 200-210 s that measured the velocity relative to the water (the current unchanged)
    lock = with_water_track(water_log)  # (its water stretch unchanged)
    dvl, truth = lock.dvl, lock.truth
    assert truth is not None and lock.true_calibration is not None
    k, b_R_d = lock.true_calibration.scale, lock.true_calibration.b_R_d(lock.mounting.b_R_d0)
    bad = (dvl.t > 200.0) & (dvl.t < 210.0)
    idx = np.searchsorted(truth.t, dvl.t)
    d_v = water_log.dvl.d_v.copy()
    for j in np.flatnonzero(bad):
        d_v[j] = d_v[j] - k * b_R_d.T @ quat_xyzw_to_matrix(truth.n_q_b[idx[j]]).T @ N_C
    lock = dataclasses.replace(lock, dvl=dataclasses.replace(water_log.dvl, d_v=d_v))
    health = assess_health(smooth_batch(lock, _config(lock, "auto")), lock)
    assert health.figures["water_track"]["false_lock_pings"] >= int(bad.sum()) - 1
    assert any("false bottom lock" in w for w in health.warnings), health.warnings


def test_water_track_scale(water_log: LogData) -> None:
    """[current] water_track_scale: water-track pings whose scale is 1 % above bottom track's get their own scale
    factor (batch and online), found within 3 sigma, the bottom-track scale unmoved; the EKF refuses it."""
    from gtsam_dvl.core.errors import GtsamDvlError
    from gtsam_dvl.estimators.ekf import run_ekf
    from gtsam_dvl.estimators.online import smooth_online
    from tests.support.logs import cut_log

    truth = water_log.true_calibration
    assert truth is not None and water_log.dvl.water_track is not None
    water = water_log.dvl.water_track
    d_v = water_log.dvl.d_v.copy()
    d_v[water] *= 1.01  # the water-track pings at scale 1.01 k
    log = dataclasses.replace(water_log, dvl=dataclasses.replace(water_log.dvl, d_v=d_v))
    cfg = _config(log, "auto")
    cfg = cfg.model_copy(
        update={"current": cfg.current.model_copy(update={"water_track_scale": True})}
    )
    for res in (smooth_batch(log, cfg), smooth_online(cut_log(log, T_WATER[1] + 20.0), cfg)):
        k, k_w = res.calibration["scale"], res.calibration["water_scale"]
        # within 3 sigma, and informed by the 100 s of water track (its prior: 0.01 about the scale)
        assert abs(k_w.value[0] - 1.01 * truth.scale) < 3 * k_w.sigma[0] and k_w.sigma[0] < 0.007, (
            res.estimator,
            k_w,
        )
        assert abs(k.value[0] - truth.scale) < 3 * k.sigma[0], (res.estimator, k)
    with pytest.raises(GtsamDvlError, match="water_track_scale is batch and online only"):
        run_ekf(log, cfg)


def test_water_track_scale_without_water_track_pings(sim_paper3d_short: LogData) -> None:
    """water_track "use" with water_track_scale on a log without water-track pings: the water-track scale stays at
    its link to the scale (its sigma the link's 1 % and the scale's combined), nothing fails."""
    from tests.support.logs import cut_log

    log = cut_log(sim_paper3d_short, 200.0)
    cfg = _config(log, "use")
    cfg = cfg.model_copy(
        update={"current": cfg.current.model_copy(update={"water_track_scale": True})}
    )
    res = smooth_batch(log, cfg)
    k, k_w = res.calibration["scale"], res.calibration["water_scale"]
    assert abs(k_w.value[0] - k.value[0]) < 0.01 * k_w.sigma[0]  # (within the solver's tolerance)
    assert k_w.sigma[0] == pytest.approx(
        np.hypot(k.sigma[0], 0.01 * cfg.priors.scale_initial), rel=0.02
    )
