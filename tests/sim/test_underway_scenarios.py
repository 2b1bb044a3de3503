"""The built-in underway scenarios straight-transect and steady-turn: they load with the settings their files state,
simulate a 400 s log at the stated speed and turn rate with no static start, whose DVL stamps are 1.0 s early
(dt_d = +1.0 s) and whose IMU samples are quantised; their [estimator] table (the initial attitude) reaches the
configuration the estimators use, under a -c configuration; and (slow) the batch smoother ends within 3 sigma of
the truth on each."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig, estimator_overrides
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import list_builtin_scenarios, load_scenario, scenario_from_dict

# what the issue asks of each: speed m/s, turn rate deg/s, heading at t = 0 (ENU deg), yaw misalignment deg
STATED = {
    "straight-transect": {"speed": 1.9, "rate": 0.0, "yaw0": 30.0, "yaw_mis": 0.2},
    "steady-turn": {"speed": 1.86, "rate": 0.57, "yaw0": 0.0, "yaw_mis": -0.2},
}
NAMES = list(STATED)


@functools.cache
def _log(name: str, white_noise: bool = True) -> LogData:
    return simulate(load_scenario(name), 1, white_noise=white_noise)


def _rpy_deg(n_q_b: np.ndarray) -> np.ndarray:
    """roll, pitch, yaw (deg, ZYX) of quaternions (x, y, z, w)."""
    return Rotation.from_quat(n_q_b).as_euler("ZYX", degrees=True)[..., ::-1]


@pytest.mark.parametrize("name", NAMES)
def test_scenario_states_its_sensors_and_calibration(name: str) -> None:
    sc = load_scenario(name)
    assert name in list_builtin_scenarios()
    assert sc.duration_s == 400.0 and sc.estimator_config == "default"
    assert (
        all(s.kind != "static" for s in sc.segments)
        and sc.initial.speed_m_s == STATED[name]["speed"]
    )
    assert (sc.rates.imu_hz, sc.rates.dvl_hz, sc.rates.dvl_time_offset_s) == (100.0, 1.0, 1.0)
    assert sc.imu.quantisation_gyro_rad_s == 1e-4 and sc.imu.quantisation_accel_m_s2 == 1e-4
    # navigation grade (CONVENTIONS.md): 0.01 deg/h, 0.1 deg/h/sqrt(Hz), 50 micro-g, 10 micro-g/sqrt(Hz)
    assert (sc.imu.gyro_bias_deg_per_h, sc.imu.gyro_noise_deg_per_h_per_sqrt_hz) == (0.01, 0.1)
    assert (sc.imu.accel_bias_micro_g, sc.imu.accel_noise_micro_g_per_sqrt_hz) == (50.0, 10.0)
    assert (sc.dvl.noise_m_s, sc.dvl.correlated_sigma_m_s, sc.dvl.correlated_tau_s) == (
        0.007,
        0.002,
        60.0,
    )
    assert sc.dvl.scale == 1.0 and sc.dvl.misalignment_deg == (0.0, 0.0, STATED[name]["yaw_mis"])
    assert sc.oscillation is not None


@pytest.mark.parametrize("name", NAMES)
def test_truth_has_the_stated_duration_speed_and_turn_rate(name: str) -> None:
    log = _log(name, white_noise=False)
    truth = log.truth
    assert truth is not None
    speed = np.linalg.norm(truth.n_v[:, :2], axis=1)
    yaw = np.unwrap(np.radians(_rpy_deg(truth.n_q_b)[:, 2]))
    rate_deg_s = np.degrees(np.polyfit(truth.t, yaw, 1)[0])
    turned = np.degrees(yaw[-1] - yaw[0])
    distance = np.linalg.norm(np.diff(truth.n_p, axis=0), axis=1).sum()
    print(
        f"{name}: {truth.t[-1]:.0f} s, horizontal speed {speed.min():.4f}-{speed.max():.4f} m/s, turn rate "
        f"{rate_deg_s:.4f} deg/s, {turned:.1f} deg turned, {distance:.0f} m"
    )
    assert truth.t[0] == 0.0 and truth.t[-1] == 400.0 and log.imu.t[-1] == 400.0
    # underway from the first sample
    np.testing.assert_allclose(speed, STATED[name]["speed"], atol=1e-3)
    assert abs(rate_deg_s - STATED[name]["rate"]) < 0.002
    assert abs(turned - 400.0 * STATED[name]["rate"]) < 1.0  # the yaw oscillation: 0.2 deg
    assert abs(_rpy_deg(truth.n_q_b[0])[2] - STATED[name]["yaw0"]) < 1e-9


@pytest.mark.parametrize("name", NAMES)
def test_dvl_stamps_are_one_second_early(name: str) -> None:
    """The ping stamped t measures the truth's velocity at t + 1 s (dt_d = +1.0 s): the noise-free DVL velocity is
    the truth's at t + 1 seen through the misalignment, and not the truth's at t."""
    log = _log(name, white_noise=False)
    truth, dvl = log.truth, log.dvl
    assert truth is not None and log.true_calibration is not None
    assert log.true_calibration.time_offset_s == 1.0
    assert dvl.t[0] == 0.0 and dvl.t[-1] == 399.0 and len(dvl) == 400

    def expected(t: np.ndarray) -> np.ndarray:
        i = np.searchsorted(truth.t, t - 1e-9)
        assert np.allclose(truth.t[i], t)
        n_R_b = Rotation.from_quat(truth.n_q_b[i]).as_matrix()
        b_v = np.einsum("kji,kj->ki", n_R_b, truth.n_v[i])
        # rows (d_R_b b_v)^T, scale 1
        return b_v @ rpy_deg_to_matrix((0.0, 0.0, STATED[name]["yaw_mis"]))

    at_measurement = np.abs(dvl.d_v - expected(dvl.t + 1.0)).max()
    at_stamp = np.abs(dvl.d_v - expected(dvl.t)).max()
    print(
        f"{name}: DVL minus truth at stamp + 1 s {at_measurement:.1e} m/s, at the stamp {at_stamp:.1e} m/s"
    )
    assert at_measurement < 1e-9 and at_stamp > 1e-3


@pytest.mark.parametrize("name", NAMES)
def test_imu_samples_are_quantised(name: str) -> None:
    imu = _log(name).imu
    for x in (imu.b_omega, imu.b_f):
        assert np.abs(x / 1e-4 - np.round(x / 1e-4)).max() < 1e-6


@pytest.mark.parametrize("name", NAMES)
def test_estimator_overrides_reach_the_configuration(name: str, tmp_path: Path) -> None:
    """The [estimator] table: the initial attitude (the truth at the first IMU stamp) and its sigmas go over the
    defaults in the configuration the estimators take for the log, and under a -c configuration."""
    log = _log(name)
    assert log.truth is not None
    cfg = EstimatorConfig.for_log(log.metadata)
    truth_rpy = _rpy_deg(log.truth.n_q_b[0])
    assert cfg.alignment.initial_attitude_deg is not None
    np.testing.assert_allclose(cfg.alignment.initial_attitude_deg, truth_rpy, atol=1e-9)
    assert (cfg.priors.roll_pitch_sigma_deg, cfg.priors.yaw_sigma_deg) == (0.05, 0.1)
    assert cfg.priors.scale_sigma == EstimatorConfig().priors.scale_sigma  # the rest: the defaults
    assert load_scenario(name).estimator_configuration() == cfg

    user = tmp_path / "user.toml"
    user.write_text("[priors]\nscale_sigma = 0.004\nyaw_sigma_deg = 0.5\n")
    layered = EstimatorConfig.load(user, under=estimator_overrides(log.metadata))
    # the scenario's, below
    assert layered.alignment.initial_attitude_deg == cfg.alignment.initial_attitude_deg
    assert (layered.priors.scale_sigma, layered.priors.yaw_sigma_deg) == (
        0.004,
        0.5,
    )  # the -c keys win
    assert layered.priors.roll_pitch_sigma_deg == 0.05
    paper = EstimatorConfig.load("paper", under=estimator_overrides(log.metadata))
    assert paper.priors.scale_initial == 0.8 and paper.alignment.initial_attitude_deg is not None
    # no scenario: nothing below
    assert EstimatorConfig.load(user).alignment.initial_attitude_deg is None


def test_bad_estimator_tables_fail_at_load() -> None:
    raw = load_scenario("straight-transect").raw
    for table, text in (
        ({"priors": {"no_such_key": 1.0}}, "no_such_key"),
        ({"preset": "paper"}, "not a preset"),
        ({"alignment": {"initial_attitude_deg": [0.0, 0.0]}}, "initial_attitude_deg"),
    ):
        with pytest.raises(GtsamDvlError, match=text) as exc:
            scenario_from_dict({**raw, "estimator": table}, source="x.toml")
        assert "\n" not in str(exc.value) and "x.toml" in str(exc.value)


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_batch_ends_within_three_sigma(name: str) -> None:
    """The batch smoother with the configuration the log names (the defaults with the scenario's initial attitude)
    ends within 3 sigma (its reported horizontal sigma, hypot of east and north) of the truth."""
    log = _log(name)
    s = summary(smooth_batch(log), log)
    err, sigma = s["errors"]["final_horizontal_position_m"], s["final_horizontal_position_sigma_m"]
    e = s["errors"]
    print(
        f"{name} seed 1 batch: final horizontal error {err:.2f} m = "
        f"{e['final_horizontal_position_pct_distance']:.2f} % of {s['distance_travelled_m']:.0f} m, "
        f"{err / sigma:.2f} sigma (sigma {sigma:.2f} m); scale {e['scale_ppm'] / 1e4:+.2f} % "
        f"(sigma {s['scale']['sigma'] * 100:.2f} %), misalignment {np.round(e['misalignment_deg'], 2)} deg "
        f"(sigma {np.round(s['misalignment_deg']['sigma'], 2)}); dt_d {s['dvl_time_offset_s']['value']:.4f} s; "
        f"health {s['health']['status']}; " + "; ".join(s["noise_levels"])
    )
    assert err < 3.0 * sigma
    assert abs(s["dvl_time_offset_s"]["value"] - 1.0) < 3.0 * s["dvl_time_offset_s"]["sigma"]
