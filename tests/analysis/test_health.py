"""Self-diagnosis after every run (analysis/health.py): "ok" on clean simulated runs for every estimator,
"degraded" with the time window named when 30 s of DVL velocities are corrupted, and each check on its own."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.health import assess_health, assess_log_health, dvl_residuals, loss_lines
from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

ESTIMATORS: dict[str, Callable[[LogData], NavResult]] = {
    "batch": smooth_batch,
    "online": smooth_online,
    "ekf": run_ekf,
}


@pytest.fixture(scope="module")
def logs() -> dict[str, LogData]:
    return {name: simulate(load_scenario(name), 3) for name in ("paper-3d", "paper-2d")}


@pytest.fixture(scope="module")
def batch_2d(logs: dict[str, LogData]) -> NavResult:
    return smooth_batch(logs["paper-2d"])


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["paper-3d", "paper-2d"])
@pytest.mark.parametrize("estimator", ["batch", "online", "ekf"])
def test_clean_runs_are_ok(
    scenario: str, estimator: str, logs: dict[str, LogData], batch_2d: NavResult
) -> None:
    log = logs[scenario]
    result = (
        batch_2d if (scenario, estimator) == ("paper-2d", "batch") else ESTIMATORS[estimator](log)
    )
    health = assess_health(result, log)
    f = health.figures
    chi2 = f["solver"].get("chi2_per_dof")
    rms = f["dvl_residuals"]["whitened_rms"]
    worst = max(w["whitened_rms"] for w in f["dvl_residuals"]["windows"])
    print(
        f"{scenario} {estimator}: {health.status}, chi2/dof {chi2}, whitened DVL residual RMS {rms:.3f}, "
        f"worst 30 s window {worst:.3f}, notes {health.notes}"
    )
    assert health.status == "ok", health.warnings
    assert health.warnings == []
    assert 0.8 < rms < 1.2 and worst < 2.0
    if estimator == "online":
        assert chi2 is None  # iSAM2 reports no chi^2: the residuals are its check
    else:
        assert 0.8 < chi2 < 1.2
    if estimator == "batch":
        assert f["solver"]["converged"] and f["solver"]["dof"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["batch", "ekf"])
def test_corrupted_dvl_window_is_degraded_and_named(
    estimator: str, logs: dict[str, LogData]
) -> None:
    log = copy.deepcopy(logs["paper-2d"])
    bad = (log.dvl.t >= 1200.0) & (log.dvl.t < 1230.0)
    log.dvl.d_v[bad, 0] += 0.5
    health = assess_health(ESTIMATORS[estimator](log), log)
    print(estimator, health.status, health.figures["solver"].get("chi2_per_dof"), health.warnings)
    assert health.status == "degraded"
    windows = [w for w in health.warnings if w.startswith("DVL residuals")]
    assert windows and "between 1200 and " in windows[0] and "bottom lock lost?" in windows[0]
    first = health.figures["dvl_residuals"]["bad_windows"][0]
    assert first["start_s"] == 1200.0 and first["whitened_rms"] > 3.0
    if estimator == "batch":  # the smoother confines the misfit to the corrupted window
        assert "between 1200 and 1230 s" in windows[0]


@pytest.mark.slow
def test_residuals_follow_the_noise_rule(logs: dict[str, LogData], batch_2d: NavResult) -> None:
    """A configured noise_m_s twice the simulated 0.02 m/s halves the whitened RMS; beams give their own."""
    log = logs["paper-2d"]
    per_message = dvl_residuals(batch_2d, log, DvlConfig()).rms()
    doubled = dvl_residuals(batch_2d, log, DvlConfig(noise_m_s=0.04)).rms()
    assert doubled == pytest.approx(per_message / 2, rel=0.05)
    beams = dvl_residuals(batch_2d, log, DvlConfig(use_beams=True, beam_noise_m_s=0.02))
    assert beams.dof.max() == 4 and 0.5 < beams.rms() < 1.5


@pytest.mark.slow
def test_solver_not_converged_and_non_finite(batch_2d: NavResult, logs: dict[str, LogData]) -> None:
    log = logs["paper-2d"]
    info = copy.deepcopy(batch_2d.info)
    info["solver"].update(converged=False, iterations=30)
    health = assess_health(dataclasses.replace(batch_2d, info=info), log)
    assert health.status == "degraded"
    assert any(
        "did not converge in 30 iterations" in w and "max_iterations" in w for w in health.warnings
    )
    n_p = batch_2d.n_p.copy()
    n_p[5] = np.nan
    health = assess_health(dataclasses.replace(batch_2d, n_p=n_p), log)
    assert health.status == "failed" and any("NaN" in w for w in health.warnings)
    info = copy.deepcopy(batch_2d.info)
    info["solver"]["final_error"] = 500.0 * info["solver"]["dof"]
    health = assess_health(dataclasses.replace(batch_2d, info=info), log)
    assert health.status == "failed" and health.figures["solver"]["chi2_per_dof"] == pytest.approx(
        1000.0
    )


def test_static_log_has_nothing_calibratable() -> None:
    raw: dict[str, Any] = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = [{"kind": "static", "duration_s": 60.0}]
    log = simulate(scenario_from_dict(raw, "static"), 1)
    health = assess_health(smooth_batch(log), log)
    assert health.status == "degraded"
    assert any(w.startswith("nothing calibratable: the log never moves") for w in health.warnings)
    assert health.figures["dvl_speed_p95_m_s"] < 0.1


@pytest.mark.slow
def test_losses_and_rejections(logs: dict[str, LogData], batch_2d: NavResult) -> None:
    log = logs["paper-2d"]
    meta = dict(log.metadata)
    meta["reader_losses"] = {
        "repair": {
            "/imu/data_raw": {"dropped": 2, "nan": 1, "duplicate": 1, "backwards": 0, "of": 204001}
        },
        "gaps": {
            "/imu/data_raw": {
                "count": 1,
                "seconds": 24.0,
                "period_s": 0.01,
                "longest_s": 24.01,
                "spans_s": [[1030.5, 1054.51]],
            }
        },
        "salvage": {
            "chunks_total": 44,
            "chunks_kept": 43,
            "chunks_lost": 1,
            "messages_lost": 1678,
            "messages_lost_exact": True,
            "messages_lost_per_topic": {"/imu/data_raw": 1499},
            "lost_spans_s": [[1030.52, 1054.49]],
            "seconds_lost": 23.97,
            "truncated": [],
            "end_unreadable": False,
            "anything_lost": True,
        },
        "messages_lost": {"/imu/data_raw": 1501},
    }
    meta["reader_warnings"] = [
        "no /tf_static in the log: identity mounting assumed (IMU and DVL frames = base_link)"
    ]
    damaged = dataclasses.replace(log, metadata=meta)
    health = assess_log_health(damaged)
    print(health.lines())
    assert health.status == "degraded"
    assert any(
        "--salvage dropped 1 damaged chunk(s) with 1678 message(s) (/imu/data_raw 1499)" in w
        and "1030.5 to 1054.5 s (24.0 s of data)" in w
        for w in health.warnings
    )
    assert any("/imu/data_raw: 24.0 s of data missing" in w for w in health.warnings)
    # 1e-5 of them: a note
    assert any("--repair dropped 2 of 204001 /imu/data_raw" in n for n in health.notes)
    assert any("identity mounting" in n for n in health.notes)
    assert health.figures["losses"]["messages_lost"] == {"/imu/data_raw": 1501}
    assert len(loss_lines(meta["reader_losses"])) == 3
    # rejected pings: a note below 5 % of the pings, degraded above; the ping at the first IMU stamp is none
    assert (
        batch_2d.info["counters"]["dvl_before_imu"] == 1
        and batch_2d.info["counters"]["dvl_unusable"] == 0
    )
    assert not any("DVL ping" in x for x in assess_health(batch_2d, log).notes)
    for rejected, status in ((20, "ok"), (200, "degraded")):
        info = copy.deepcopy(batch_2d.info)
        info["counters"]["dvl_too_fast"] = rejected
        health = assess_health(dataclasses.replace(batch_2d, info=info), log)
        assert health.status == status
        assert any(
            f"{rejected} of {len(log.dvl)} DVL pings rejected ({rejected} too fast)" in x
            for x in health.notes + health.warnings
        )
    # water track and pings outside the IMU's span in their own words, not as rejections
    info = copy.deepcopy(batch_2d.info)
    info["counters"].update(dvl_water_track=30, dvl_before_imu=3, dvl_after_imu=2)
    health = assess_health(dataclasses.replace(batch_2d, info=info), log)
    assert health.status == "ok" and not any("rejected" in n for n in health.notes)
    assert (
        f"30 of {len(log.dvl)} DVL pings are water track (velocity relative to the water, not over ground): "
        'refused ([current] water_track = "refuse"; "auto" uses them with the current as a state)'
        in health.notes
    )
    assert (
        "5 DVL pings outside the IMU's time span (3 at or before its first sample, 2 after its last): not "
        "used" in health.notes
    )


def test_residuals_use_the_pings_the_estimator_used(
    logs: dict[str, LogData], batch_2d: NavResult
) -> None:
    """Each result records the usable pings its estimator used (NavResult.dvl_pings: the selection's, before keyframe
    thinning); a result without them (a file written without them) has them selected again, counted and said."""
    from gtsam_dvl.estimators.inputs.selection import usable_pings

    log = logs["paper-2d"]
    cfg = batch_2d.estimator_config
    assert cfg is not None and batch_2d.dvl_pings is not None
    expected = usable_pings(log.dvl, log.imu, cfg.dvl, {})
    np.testing.assert_array_equal(batch_2d.dvl_pings, expected)
    ekf = run_ekf(log)
    assert ekf.dvl_pings is not None
    np.testing.assert_array_equal(ekf.dvl_pings, expected)
    own = dvl_residuals(batch_2d, log, cfg.dvl)
    bare = copy.copy(batch_2d)
    bare.dvl_pings = None
    again = dvl_residuals(bare, log, cfg.dvl)
    assert own.selected_again == 0 and again.selected_again == len(expected)
    np.testing.assert_array_equal(again.chi2, own.chi2)
    health = assess_health(bare, log)
    assert health.figures["dvl_residuals"]["pings_selected_again"] == len(expected)
    assert any("selected again" in n for n in health.notes)
    assert "pings_selected_again" not in assess_health(batch_2d, log).figures["dvl_residuals"]
