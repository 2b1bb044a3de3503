"""GNSS fixes in the batch smoother (estimators/inputs/gnss.py): the roles of the fixes (status, depth gate, surface
intervals, use modes, time to a state), and a dive that starts and ends at the surface, written to MCAP without
an origin and read back (origin from the first fix): the estimated antenna at the held-out final fixes within
3 sigma of the truth, in "start" and "origin" mode. Each test prints the numbers it measured."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.core.types import DepthData, GeoOrigin, GnssData, LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.inputs.gnss import plan_fixes
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import surface_dive_raw

LEVER = np.array([0.0, 0.0, 0.5])


def dive_raw(origin_in_log: bool = False) -> dict[str, Any]:
    """90 s static at the surface, away at 2 m/s, a dive to about 24 m, a square of four banked turns, up
    again and 60 s on at the surface (585 s, about 850 m); 1 Hz fixes at the surface (2 m horizontal, 4 m
    vertical), a pressure sensor."""
    return surface_dive_raw(
        [
            {"kind": "static", "duration_s": 90.0},
            {"kind": "level", "duration_s": 15.0, "speed_end_m_s": 2.0},
            {"kind": "level", "duration_s": 30.0, "speed_bump_m_s": 0.5},
            {"kind": "descent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
            {
                "kind": "square",
                "leg_duration_s": 30.0,
                "turn_duration_s": 30.0,
                "bank_deg": 15.0,
                "sides": 4,
                "turn_first": True,
            },
            {"kind": "level", "duration_s": 30.0, "speed_bump_m_s": 0.4},
            {"kind": "ascent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "straight", "duration_s": 60.0},
        ],
        depth={"rate_hz": 1.0, "noise_m": 0.05},
        gnss={
            "rate_hz": 1.0,
            "antenna_lever_arm_m": LEVER.tolist(),
            "origin_in_log": origin_in_log,
        },
    )


@pytest.fixture(scope="module")
def dive_log(tmp_path_factory: pytest.TempPathFactory) -> LogData:
    path = Path(tmp_path_factory.mktemp("gnss")) / "dive.mcap"
    write_log(path, simulate(scenario_from_dict(dive_raw(), name="dive"), 4))
    return read_log(path)


@pytest.fixture(scope="module")
def smoothed(dive_log: LogData) -> dict[str, NavResult]:
    """The dive smoothed in each [gnss] use mode."""
    out = {}
    for use in ("start", "origin", "all"):
        cfg = EstimatorConfig()
        cfg.gnss.use = use  # type: ignore[assignment]
        out[use] = smooth_batch(dive_log, cfg)
    return out


def _antenna_errors(res: NavResult, log: LogData, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Estimated minus true antenna position (map, m) at the states at times t, and the estimate's sigmas
    (translation and the rotation's lever-arm term, map axes)."""
    assert log.truth is not None
    i = np.searchsorted(res.t, t)
    np.testing.assert_allclose(res.t[i], t, atol=1e-6)
    k = np.searchsorted(log.truth.t, t)
    R_true = quat_xyzw_to_matrix(log.truth.n_q_b[k])
    true = log.truth.n_p[k] + R_true @ LEVER
    est = res.n_p[i] + res.n_R_b[i] @ LEVER
    sig = res.position_sigma_m[i]  # the lever arm's attitude term is below 1e-4 m here
    return est - true, sig


@pytest.mark.slow
def test_dive_held_out_final_fixes_within_3_sigma(
    dive_log: LogData, smoothed: dict[str, NavResult]
) -> None:
    log = dive_log
    g = log.gnss
    assert g is not None and log.origin is not None
    assert (log.origin.lat_deg, log.origin.lon_deg, log.origin.height_m) == (
        g.lat_deg[0],
        g.lon_deg[0],
        g.height_m[0],
    )
    out = {}
    for use in ("start", "origin"):
        res = smoothed[use]
        c = res.info["counters"]
        plan = plan_fixes(
            log,
            EstimatorConfig.from_dict(res.config),
            LocalFrame(log.origin.lat_deg, log.origin.lon_deg, log.origin.height_m),
            res.t,
        )
        assert plan is not None
        held = plan.mask("held_out") & (plan.interval == plan.n_intervals - 1)
        err, sig = _antenna_errors(res, log, plan.t[held])
        z = np.abs(err) / sig
        e0, s0 = _antenna_errors(res, log, res.t[:1])
        print(
            f"\n{use}: counters used {c['gnss_used']} held out {c['gnss_held_out']} rejected {c['gnss_rejected']}; "
            f"first state error {np.round(e0[0], 3)} sigma {np.round(s0[0], 3)} m; at the {held.sum()} final "
            f"fixes max |err|/sigma {np.round(z.max(axis=0), 2)}, sigma {np.round(sig[0], 3)} m, error "
            f"{np.round(err[0], 3)} m; {res.info['solver']['iterations']} iterations"
        )
        assert held.sum() >= 60 and res.info["solver"]["converged"]
        assert np.all(z < 3.0)
        assert np.all(np.abs(e0[0]) < 3 * s0[0])
        out[use] = (c, sig[0])
    c_start, sig_start = out["start"]
    c_origin, sig_origin = out["origin"]
    # start: the first surface interval (0 to about 145 s) aids; origin: only the origin fix, as X(0)'s prior
    # here (the fix at t = 0 is before the first state: counted too far)
    assert (
        c_start["gnss_used"] > 130
        and c_start["gnss_held_out"] >= 60
        and c_start["gnss_surface_intervals"] == 2
    )
    assert c_origin["gnss_used"] + c_origin["gnss_too_far"] >= 1 and c_origin["gnss_used"] <= 1
    assert c_origin["gnss_held_out"] >= c_start["gnss_held_out"] + 130
    # 145 fixes of 2 m place the start to about 0.2 m, the origin fix alone to its 2 m
    assert np.all(sig_start[:2] < 0.5 * sig_origin[:2]) and np.all(sig_origin[:2] > 1.9)


@pytest.mark.slow
def test_all_mode_uses_every_good_fix(dive_log: LogData, smoothed: dict[str, NavResult]) -> None:
    res = smoothed["all"]
    c = res.info["counters"]
    print(f"\nall: {c}")
    assert c["gnss_held_out"] == 0 and c["gnss_used"] >= 200
    err, sig = _antenna_errors(res, dive_log, res.t[-60:])
    assert np.all(np.abs(err) < 3 * sig)


def test_log_with_its_own_origin_keeps_the_pinned_first_state() -> None:
    """The simulator's origin in the log: X(0) stays pinned at it (priors.position_sigma_m), the fixes aid."""
    raw = dive_raw(origin_in_log=True)
    raw["segments"] = raw["segments"][:3]  # 135 s at the surface
    log = simulate(scenario_from_dict(raw), 2)
    res = smooth_batch(log, EstimatorConfig())
    sig0 = res.position_sigma_m[0]
    print(f"\nown origin: first sigma {np.round(sig0, 4)} m, counters {res.info['counters']}")
    assert np.all(sig0 < 0.011) and np.allclose(res.n_p[0], 0.0, atol=0.03)
    assert res.info["counters"]["gnss_used"] >= 130


def _gnss(t: np.ndarray, status: np.ndarray | None = None) -> GnssData:
    k = len(t)
    cov = np.broadcast_to(np.diag([4.0, 4.0, 16.0]), (k, 3, 3)).copy()
    return GnssData(
        t,
        np.full(k, 30.0),
        np.full(k, 114.0),
        np.zeros(k),
        cov,
        np.zeros(k, dtype=int) if status is None else status,
    )


def test_roles_of_fixes() -> None:
    """Status, depth gate, surface intervals, modes and time to a state on hand-made fixes."""
    from gtsam_dvl.core.types import DvlData, ImuData

    t = np.array([0.0, 1.0, 2.0, 3.0, 50.0, 51.0, 52.0, 100.0, 101.5])
    status = np.array([0, -1, 0, 0, 0, 0, 0, 0, 0])
    empty = LogData(
        ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))),
        DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, bool)),
        origin=GeoOrigin(30.0, 114.0, 0.0),
        gnss=_gnss(t, status),
        depth=DepthData(
            np.array([0.0, 40.0, 50.5, 51.5, 60.0]),
            np.array([0.0, 3.0, 3.0, 0.2, 0.1]),
            np.full(5, 0.01),
        ),
    )
    frame = LocalFrame(30.0, 114.0, 0.0)
    states = np.arange(0.0, 102.0)
    roles = {}
    for use in ("origin", "start", "all"):
        cfg = EstimatorConfig()
        cfg.gnss.use = use  # type: ignore[assignment]
        plan = plan_fixes(empty, cfg, frame, states)
        assert plan is not None
        roles[use] = plan.role.tolist()
        assert plan.origin_from_gnss and plan.origin_index == 0
    # fix 1: no fix; fixes 4, 5: at 3 m and 1.6 m depth (interpolated); 101.5 s: 0.5 s from a state, within
    # max_time_to_state_s; three surface intervals (0-3 s, 52 s, 100-101.5 s)
    assert roles["all"] == [
        "used",
        "rejected_status",
        "used",
        "used",
        "rejected_depth",
        "rejected_depth",
        "used",
        "used",
        "used",
    ]
    assert roles["start"][:4] == ["used", "rejected_status", "used", "used"]
    assert roles["start"][6:] == ["held_out"] * 3
    assert (
        roles["origin"]
        == ["used", "rejected_status"]
        + ["held_out"] * 2
        + ["rejected_depth"] * 2
        + ["held_out"] * 3
    )
    cfg = EstimatorConfig()
    cfg.gnss.max_time_to_state_s = 0.2
    plan = plan_fixes(empty, cfg, frame, states)
    assert plan is not None and plan.role[-1] == "too_far"
    assert plan.counters()["gnss_rejected"] == 4 and plan.n_intervals == 3
    # the origin given in the configuration: the fixes do not define it
    cfg = EstimatorConfig()
    cfg.alignment.origin_lat_deg = 30.0
    plan = plan_fixes(empty, cfg, frame, states)
    assert plan is not None and not plan.origin_from_gnss
