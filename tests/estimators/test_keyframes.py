"""Keyframes that keep every ping's information ([solver] keyframe_spacing_s; estimators/keyframes.py,
factors/dvl_keyframe.py): on a 5 Hz DVL version of paper-3d-short, the batch smoother with 1 s keyframes (a
fifth of the states, the other pings as factors on the keyframe before them through the IMU motion) against a
state per ping:

- the calibration sigmas (scale, misalignment, biases) within 5 % of the state-per-ping solution, and the
  estimates (scale, misalignment, biases, final position) within 0.2 of its sigma;
- both within 3 sigma of the simulated truth;
- every usable ping used (keyframes + pings between them = usable pings).

On the paper's 1 Hz logs 1 s keyframes make a state of every ping: the same epochs as keyframe_spacing_s = 0.
"""

from __future__ import annotations

import dataclasses
import time
from functools import cache

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.batch import smooth_batch
from gtsam_dvl.estimators.graph import LogGraph
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

SEED = 7


@cache
def run_log(dvl_hz: float) -> LogData:
    """paper-3d-short (120 s static, 60 s legs, the paper's sensors) with the DVL at dvl_hz."""
    raw = dict(load_scenario("paper-3d-short").raw)
    raw["rates"] = {**raw["rates"], "dvl_hz": dvl_hz}
    return simulate(scenario_from_dict(raw), SEED)


def config(spacing_s: float) -> EstimatorConfig:
    cfg = EstimatorConfig.paper()
    return dataclasses.replace(cfg, solver=dataclasses.replace(cfg.solver, keyframe_spacing_s=spacing_s))


@cache
def solve(spacing_s: float) -> tuple[NavResult, float]:
    t0 = time.perf_counter()
    r = smooth_batch(run_log(5.0), config(spacing_s))
    return r, time.perf_counter() - t0


def estimates(r: NavResult) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(values, sigmas, names): scale, misalignment (deg), accelerometer bias (micro-g), gyro bias (deg/h), final
    position (m, map axes)."""
    n_R_b = r.n_R_b[-1]
    pos_sigma = np.sqrt(np.diag(n_R_b @ r.pose_cov[-1][3:, 3:] @ n_R_b.T))  # translation tangent in body axes
    values = np.concatenate([[r.scale], r.misalignment_deg, r.accel_bias / UG, r.gyro_bias / DEG_PER_H, r.n_p[-1]])
    sigmas = np.concatenate([[r.scale_sigma], r.misalignment_sigma_deg, r.accel_bias_sigma_ug,
                             r.gyro_bias_sigma_deg_per_h, pos_sigma])
    names = (["scale", "mis_roll", "mis_pitch", "mis_yaw"] + [f"b_a_{a}" for a in "xyz"]
             + [f"b_g_{a}" for a in "xyz"] + [f"p_{a}" for a in "xyz"])
    return values, sigmas, names


def truth(log: LogData, r: NavResult) -> np.ndarray:
    tc, tb, tr = log.true_calibration, log.true_imu_bias, log.truth
    assert tc is not None and tb is not None and tr is not None
    j = int(np.argmin(np.abs(tr.t - r.t[-1])))
    return np.concatenate([[tc.scale], tc.misalignment_deg, np.array(tb.accel_m_s2) / UG,
                           np.array(tb.gyro_rad_s) / DEG_PER_H, tr.n_p[j]])


def test_one_second_keyframes_match_a_state_per_ping_on_a_5_hz_dvl() -> None:
    log = run_log(5.0)
    (per_ping, wall_ping), (keyed, wall_key) = solve(0.0), solve(1.0)
    c = keyed.info["counters"]
    usable = per_ping.info["counters"]["keyframes"]
    print(f"\n5 Hz DVL, {len(log.dvl)} pings: state per ping {len(per_ping.t)} states in {wall_ping:.1f} s; "
          f"1 s keyframes {len(keyed.t)} states ({c['keyframes']} keyframes + {c['states_without_ping']} without "
          f"ping, {c['pings_between_keyframes']} pings between) in {wall_key:.1f} s "
          "(wall times on a shared machine)")
    assert c["keyframes"] + c["pings_between_keyframes"] == usable  # every usable ping is used
    assert len(keyed.t) < 0.25 * len(per_ping.t)
    assert np.all(np.diff(keyed.t)[:-1] > 0.9)  # the last usable ping is a keyframe too
    v0, s0, names = estimates(per_ping)
    v1, s1, _ = estimates(keyed)
    true = truth(log, per_ping)
    sigma_ratio = s1 / s0 - 1.0
    shift = (v1 - v0) / s0
    for k, name in enumerate(names):
        print(f"  {name:10s} per ping {v0[k]:+.6g} +- {s0[k]:.3g}, keyframes {v1[k]:+.6g} +- {s1[k]:.3g}: "
              f"sigma {100 * sigma_ratio[k]:+.3f} %, shift {shift[k]:+.4f} sigma; truth {true[k]:+.6g} "
              f"({(v0[k] - true[k]) / s0[k]:+.2f} / {(v1[k] - true[k]) / s1[k]:+.2f} sigma)")
    calibration = slice(0, 10)  # scale, misalignment, biases
    assert np.all(np.abs(sigma_ratio[calibration]) < 0.05)
    assert np.all(np.abs(shift) < 0.2)
    assert np.all(np.abs(v0 - true) < 3 * s0)
    assert np.all(np.abs(v1 - true) < 3 * s1)


def test_health_checks_every_ping_with_keyframes() -> None:
    """The health's DVL residuals take every usable ping, those between keyframes too (interpolated between
    states), and stay near 1 (whitened) as with a state per ping."""
    from gtsam_dvl.analysis.health import dvl_residuals

    log = run_log(5.0)
    per_ping, keyed = solve(0.0)[0], solve(1.0)[0]
    r0 = dvl_residuals(per_ping, log, config(0.0).dvl)
    r1 = dvl_residuals(keyed, log, config(1.0).dvl)
    n0, n1 = int((r0.dof > 0).sum()), int((r1.dof > 0).sum())
    print(f"\nhealth residuals: per ping {n0} pings, rms {r0.rms():.3f}; keyframes {n1} pings, rms {r1.rms():.3f}")
    assert n1 == n0 == per_ping.info["counters"]["keyframes"]
    assert abs(r1.rms() - r0.rms()) < 0.02 * r0.rms()
    assert 0.8 < r0.rms() < 1.2


def test_one_hz_log_with_one_second_keyframes_has_a_state_per_ping() -> None:
    log = run_log(1.0)
    g0, g1 = LogGraph(log, config(0.0)), LogGraph(log, config(1.0))
    assert [e.t for e in g0.epochs] == [e.t for e in g1.epochs]
    assert [e.dvl_index for e in g0.epochs] == [e.dvl_index for e in g1.epochs]
    assert g1.counters["pings_between_keyframes"] == 0 and not any(e.between for e in g1.epochs)


def test_spacing_beyond_the_state_spacing_is_refused() -> None:
    cfg = config(2.0)
    with pytest.raises(GtsamDvlError, match="keyframe_spacing_s"):
        LogGraph(run_log(1.0), cfg)
