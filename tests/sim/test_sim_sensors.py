"""Simulated sensors: the DVL model computed independently from the truth, beams, noise statistics,
seeding, dropouts and outliers, and the LogData contract."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario, scenario_from_dict
from tests.support.scenarios import PAPER_SENSORS, with_tables

MOTION = [
    {"kind": "static", "duration_s": 20.0},
    {"kind": "level", "duration_s": 30.0, "speed_end_m_s": 1.5},
    {"kind": "turn", "duration_s": 40.0, "heading_change_deg": 90.0, "bank_deg": 15.0},
    {"kind": "descent", "duration_s": 30.0, "peak_vertical_speed_m_s": 0.4},
    {"kind": "turn", "duration_s": 40.0, "heading_change_deg": -120.0, "bank_deg": 10.0},
    {"kind": "straight", "duration_s": 40.0},
]


def _scenario(
    dvl: dict[str, Any] | None = None,
    mounting: dict[str, Any] | None = None,
    imu: dict[str, Any] | None = None,
    rates: dict[str, Any] | None = None,
) -> Scenario:
    raw = with_tables(
        PAPER_SENSORS,
        rates={"imu_hz": 100.0, "dvl_hz": 5.0, "truth_hz": 10.0, **(rates or {})},
        imu=imu,
        dvl=dvl,
        mounting=mounting or {},
        segments=MOTION,
    )
    return scenario_from_dict(raw, name="sensor-test")


def _truth_at(log: LogData, t: np.ndarray) -> np.ndarray:
    assert log.truth is not None
    i = np.searchsorted(log.truth.t, t - 1e-9)
    assert np.allclose(log.truth.t[i], t, atol=1e-9)
    return i


def _model_y(log: LogData, sc: Scenario, i: np.ndarray) -> np.ndarray:
    """y = k d_R_b (n_R_b^T n_v + b_omega x b_l), from the truth and the scenario, independently of sim/."""
    assert log.truth is not None
    roll, pitch, yaw = sc.dvl.misalignment_deg
    R_c = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix()
    r0, p0, y0 = sc.mounting.dvl_rpy_deg
    b_R_d = R_c @ Rotation.from_euler("ZYX", [y0, p0, r0], degrees=True).as_matrix()
    n_R_b = Rotation.from_quat(log.truth.n_q_b[i]).as_matrix()
    b_v = np.einsum("kji,kj->ki", n_R_b, log.truth.n_v[i])
    b_v += np.cross(log.truth.b_omega[i], np.asarray(sc.mounting.dvl_lever_arm_m))
    return sc.dvl.scale * b_v @ b_R_d


def test_dvl_noise_free_equals_model_paper3d(
    sim_paper3d_clean: LogData, sim_paper3d: Scenario
) -> None:
    log = sim_paper3d_clean
    y = _model_y(log, sim_paper3d, _truth_at(log, log.dvl.t))
    err = np.max(np.abs(log.dvl.d_v - y))
    print(f"paper-3d DVL vs model: {err:.2e} m/s over {len(log.dvl)} pings")
    assert err < 1e-12 and log.dvl.valid.all()
    np.testing.assert_array_equal(log.mounting.b_R_d0, np.eye(3))
    np.testing.assert_allclose(
        log.dvl.d_cov, np.broadcast_to(0.02**2 * np.eye(3), log.dvl.d_cov.shape)
    )


def test_dvl_180_roll_mounting_lever_arm_beams_and_ranges() -> None:
    lever = [0.8, -0.1, -0.4]
    sc = _scenario(
        dvl={
            "noise_model": "beam",
            "noise_m_s": 0.03,
            "face_axis": [0.0, 0.0, 1.0],
            "altitude_m": 30.0,
        },
        mounting={"dvl_rpy_deg": [180.0, 0.0, 0.0], "dvl_lever_arm_m": lever},
    )
    log = simulate(sc, 3, white_noise=False)
    assert log.truth is not None and log.dvl.beams is not None
    i = _truth_at(log, log.dvl.t)
    err = np.max(np.abs(log.dvl.d_v - _model_y(log, sc, i)))
    lever_effect = np.max(np.linalg.norm(np.cross(log.truth.b_omega[i], lever), axis=1))
    print(
        f"180 deg roll + lever arm: DVL vs model {err:.2e} m/s (lever-arm term up to {lever_effect:.2e} m/s)"
    )
    assert err < 1e-12 and lever_effect > 1e-3 and log.dvl.valid.all()
    np.testing.assert_allclose(log.mounting.b_p_dvl, lever)
    beams = log.dvl.beams
    d_u = beams.d_u
    assert np.max(np.abs(np.linalg.norm(d_u, axis=-1) - 1.0)) < 1e-15
    # face +z
    np.testing.assert_allclose(d_u[0] @ [0.0, 0.0, 1.0], np.cos(np.radians(30.0)), atol=1e-15)
    assert np.max(np.abs(beams.v - np.einsum("kbi,ki->kb", d_u, log.dvl.d_v))) < 1e-12
    # ranges: flat seafloor 30 m below the start, along the true beam directions from the DVL's position
    frame = sc.local_frame()
    lat, lon, h = frame.map_to_geodetic(log.truth.n_p[i])
    l_R_b = (
        np.swapaxes(frame.n_R_l(lat, lon), 1, 2)
        @ Rotation.from_quat(log.truth.n_q_b[i]).as_matrix()
    )
    roll, pitch, yaw = sc.dvl.misalignment_deg
    b_R_d = Rotation.from_euler("ZYX", [yaw, pitch, roll], degrees=True).as_matrix() @ np.diag(
        [1.0, -1.0, -1.0]
    )
    l_u = np.einsum("kij,bj->kbi", l_R_b, d_u[0] @ b_R_d.T)
    assert (l_u[..., 2] < -0.7).all()  # the beams look down although dvl_link's z points down too
    h_dvl = h + (l_R_b @ lever)[:, 2]
    expected = (h_dvl - (-100.0 - 30.0))[:, None] / -l_u[..., 2]
    err_r = np.max(np.abs(beams.range - expected))
    print(
        f"ranges {np.nanmin(beams.range):.2f}..{np.nanmax(beams.range):.2f} m, error {err_r:.2e} m"
    )
    assert err_r < 1e-6
    A = d_u[0]
    np.testing.assert_allclose(
        log.dvl.d_cov[0], 0.03**2 * np.linalg.inv(A.T @ A), rtol=1e-12, atol=1e-18
    )


def test_dvl_time_offset_is_a_clock_lag() -> None:
    """[rates] dvl_time_offset_s = dt_d: the DVL measures at k / dvl_hz and stamps the ping dt_d earlier, so the
    ping stamped t measures the velocity at t + dt_d (docs/conventions.md); the truth record carries dt_d."""
    for dt in (0.005, -0.3):
        sc = _scenario(rates={"dvl_hz": 1.0, "dvl_time_offset_s": dt})
        log = simulate(sc, 3, white_noise=False)
        assert log.truth is not None and log.true_calibration is not None
        assert log.true_calibration.time_offset_s == dt
        assert log.metadata["truth"]["dvl"]["time_offset_s"] == dt
        k0 = 1 if dt > 0 else 0
        np.testing.assert_allclose(log.dvl.t, np.arange(k0, k0 + len(log.dvl)) - dt, atol=1e-12)
        assert log.dvl.t[0] >= 0.0 and log.dvl.t[-1] <= sc.duration_s
        i = _truth_at(log, log.dvl.t + dt)  # the measurement times, on the truth grid
        err = np.max(np.abs(log.dvl.d_v - _model_y(log, sc, i)))
        print(f"dt_d {dt} s: ping vs the model at stamp + dt_d {err:.2e} m/s")
        assert err < 1e-9


@pytest.mark.parametrize("model", ["velocity", "beam"])
def test_noise_statistics_match_spec(model: str) -> None:
    sc = _scenario(dvl={"noise_model": model, "noise_m_s": 0.02}, rates={"dvl_hz": 10.0})
    noisy, clean = simulate(sc, 11), simulate(sc, 11, white_noise=False)
    assert noisy.dvl.beams is not None and clean.dvl.beams is not None
    e = noisy.dvl.d_v - clean.dvl.d_v
    expected = np.sqrt(np.diagonal(noisy.dvl.d_cov[0]))
    ratio = e.std(axis=0) / expected
    print(
        f"{model}: DVL error std / spec {ratio.round(4)} (spec {expected.round(4)} m/s, {len(e)} pings)"
    )
    assert np.all(np.abs(ratio - 1) < 0.05)
    if model == "beam":
        rb = (noisy.dvl.beams.v - clean.dvl.beams.v).std() / 0.02
        print(f"beam noise std / spec {rb:.4f}")
        assert abs(rb - 1) < 0.05
    rate = sc.rates.imu_hz
    for name, out, density in (
        ("gyro", "b_omega", 0.1 * np.pi / 180 / 3600),
        ("accel", "b_f", 10 * 9.80665e-6),
    ):
        d = getattr(noisy.imu, out) - getattr(clean.imu, out)
        r = d.std(axis=0) / (density * np.sqrt(rate))
        print(
            f"{name} noise std / (N sqrt(rate)) {r.round(4)}, mean/sigma {(d.mean(axis=0) / d.std(axis=0)).round(3)}"
        )
        assert np.all(np.abs(r - 1) < 0.05)


def test_biases_seeded_and_applied() -> None:
    sc = _scenario()
    zero = _scenario(
        imu={
            "gyro_bias_values_deg_per_h": [0.0, 0.0, 0.0],
            "accel_bias_values_micro_g": [0.0, 0.0, 0.0],
        }
    )
    a, b, c = (
        simulate(sc, 1, white_noise=False),
        simulate(sc, 1),
        simulate(sc, 2, white_noise=False),
    )
    ref = simulate(zero, 1, white_noise=False)
    bg, ba = (
        np.array(a.metadata["truth"]["imu"][k]) for k in ("gyro_bias_rad_s", "accel_bias_m_s2")
    )
    print(f"seed 1: gyro bias {np.degrees(bg) * 3600} deg/h, accel bias {ba / 9.80665e-6} micro-g")
    assert b.metadata["truth"]["imu"] == a.metadata["truth"]["imu"]  # noise on or off: same draw
    assert (
        c.metadata["truth"]["imu"]["gyro_bias_rad_s"]
        != a.metadata["truth"]["imu"]["gyro_bias_rad_s"]
    )
    # rounding of rates ~0.1 rad/s
    assert np.max(np.abs(a.imu.b_omega - ref.imu.b_omega - bg)) < 1e-16
    assert np.max(np.abs(a.imu.b_f - ref.imu.b_f - ba)) < 1e-14
    # explicit values are used as given
    fixed = _scenario(imu={"gyro_bias_values_deg_per_h": [0.01, -0.02, 0.03]})
    md = simulate(fixed, 5, white_noise=False).metadata["truth"]["imu"]
    np.testing.assert_allclose(
        np.degrees(md["gyro_bias_rad_s"]) * 3600, [0.01, -0.02, 0.03], rtol=1e-12
    )


def test_bias_random_walk_series_in_metadata() -> None:
    walk = {"gyro_bias_walk_deg_per_h_per_sqrt_h": 0.05, "accel_bias_walk_micro_g_per_sqrt_h": 20.0}
    sc = _scenario(imu=walk)
    zero = _scenario(
        imu={
            **walk,
            "gyro_bias_walk_deg_per_h_per_sqrt_h": 0.0,
            "accel_bias_walk_micro_g_per_sqrt_h": 0.0,
            "gyro_bias_values_deg_per_h": [0.0] * 3,
            "accel_bias_values_micro_g": [0.0] * 3,
        }
    )
    log, ref = simulate(sc, 4, white_noise=False), simulate(zero, 4, white_noise=False)
    series = log.metadata["truth"]["imu"]["bias_series"]
    k = np.round(np.array(series["t"]) * 100).astype(int)
    assert series["t"][:3] == [0.0, 1.0, 2.0] and series["t"][-1] == sc.duration_s
    np.testing.assert_allclose(
        log.imu.b_omega[k] - ref.imu.b_omega[k], series["gyro_rad_s"], atol=1e-18
    )
    np.testing.assert_allclose(log.imu.b_f[k] - ref.imu.b_f[k], series["accel_m_s2"], atol=1e-14)
    np.testing.assert_allclose(
        series["gyro_rad_s"][0], log.metadata["truth"]["imu"]["gyro_bias_rad_s"]
    )
    drift = np.degrees(np.array(series["gyro_rad_s"])[-1] - series["gyro_rad_s"][0]) * 3600
    print(f"gyro bias walked {drift} deg/h in {sc.duration_s} s")
    assert np.any(drift != 0.0)


def _arrays(log: LogData) -> list[np.ndarray]:
    assert log.truth is not None and log.dvl.beams is not None
    b = log.dvl.beams
    return [
        log.imu.t,
        log.imu.b_omega,
        log.imu.b_f,
        log.dvl.t,
        log.dvl.d_v,
        log.dvl.d_cov,
        log.dvl.valid,
        b.v,
        b.range,
        b.valid,
        log.truth.n_p,
        log.truth.n_q_b,
        log.truth.n_v,
        log.truth.b_omega,
    ]


def test_same_seed_same_arrays_different_seed_differs() -> None:
    sc = _scenario(dvl={"dropout_beam_prob": 0.05, "outlier_prob": 0.02})
    a, b, c = simulate(sc, 9), simulate(sc, 9), simulate(sc, 10)
    for x, y in zip(_arrays(a), _arrays(b), strict=True):
        np.testing.assert_array_equal(x, y)
    assert a.metadata == b.metadata
    assert not np.array_equal(a.imu.b_omega, c.imu.b_omega) and not np.array_equal(
        a.dvl.d_v, c.dvl.d_v
    )


@pytest.mark.parametrize("model", ["velocity", "beam"])
def test_dropouts_and_outliers_as_configured(model: str) -> None:
    p_ping, p_beam, p_out = 0.1, 0.05, 0.05
    sc = _scenario(
        dvl={
            "noise_model": model,
            "noise_m_s": 0.01,
            "dropout_ping_prob": p_ping,
            "dropout_beam_prob": p_beam,
            "outlier_prob": p_out,
            "outlier_m_s": 1.0,
        },
        rates={"dvl_hz": 20.0},
    )
    noisy, clean = simulate(sc, 21), simulate(sc, 21, white_noise=False)
    assert noisy.dvl.beams is not None and clean.dvl.beams is not None
    assert clean.dvl.valid.all()  # no dropouts without white noise
    M = len(noisy.dvl)

    def check(label: str, count: int, n: int, p: float) -> None:
        sigma = np.sqrt(n * p * (1 - p))
        print(f"{model}: {label} {count} of {n}, expected {n * p:.1f} +- {sigma:.1f}")
        assert abs(count - n * p) < 4 * sigma

    # two or more beams lost: no 3-D fix
    p_lost2 = 1 - (1 - p_beam) ** 4 - 4 * p_beam * (1 - p_beam) ** 3
    check("valid pings", int(noisy.dvl.valid.sum()), M, (1 - p_ping) * (1 - p_lost2))
    check("valid beams", int(noisy.dvl.beams.valid.sum()), 4 * M, (1 - p_ping) * (1 - p_beam))
    assert (
        np.isnan(noisy.dvl.d_v[~noisy.dvl.valid]).all()
        and not np.isnan(noisy.dvl.d_v[noisy.dvl.valid]).any()
    )
    if model == "velocity":
        v = noisy.dvl.valid
        big = np.linalg.norm(noisy.dvl.d_v[v] - clean.dvl.d_v[v], axis=1) > 0.5
        check("outlier pings", int(big.sum()), int(v.sum()), p_out)
    else:
        v = noisy.dvl.beams.valid
        big = np.abs(noisy.dvl.beams.v[v] - clean.dvl.beams.v[v]) > 0.5
        check("outlier beams", int(big.sum()), int(v.sum()), p_out)


def test_no_bottom_lock_beyond_max_range() -> None:
    log = simulate(_scenario(dvl={"altitude_m": 250.0, "max_range_m": 200.0}), 1)
    assert log.dvl.beams is not None
    assert (
        not log.dvl.valid.any()
        and np.isnan(log.dvl.d_v).all()
        and np.isnan(log.dvl.beams.range).all()
    )


def test_logdata_contract() -> None:
    sc = _scenario()
    seen: list[float] = []
    log = simulate(sc, 5, progress=seen.append)
    assert seen[-1] == 1.0 and seen == sorted(seen)
    assert log.truth is not None
    n = round(sc.duration_s * 100) + 1
    np.testing.assert_array_equal(log.imu.t, np.arange(n) / 100.0)
    assert np.isin(np.round(log.truth.t * 100), np.round(log.imu.t * 100)).all()
    np.testing.assert_allclose(np.diff(log.truth.t), 0.1, atol=1e-9)
    assert log.t0_ns == 1_700_000_000 * 10**9
    md = log.metadata
    assert set(md) == {
        "scenario_name",
        "scenario",
        "seed",
        "white_noise",
        "origin",
        "truth",
        "sensors",
        "generator",
    }
    assert (
        md["generator"].startswith("gtsam_dvl ") and md["seed"] == 5 and md["white_noise"] is True
    )
    assert set(md["truth"]["dvl"]) == {
        "scale",
        "misalignment_deg",
        "b_R_d0",
        "b_lever_arm_m",
        "time_offset_s",
    }
    assert md["truth"]["segments"] == sc.segment_table()
    assert md["sensors"]["imu"]["gyro_noise_deg_per_h_per_sqrt_hz"] == 0.1
    assert log.true_calibration is not None and log.true_calibration.scale == 0.9998
    json.dumps(md)
