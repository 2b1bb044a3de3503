"""Coarse alignment on the initial static segment (gtsam_dvl/estimators/inputs/alignment.py): gravity levelling and
gyrocompassing against the simulated truth attitude, static-segment detection, window means, the configured
attitude, and the errors.

The error model the tests hold the alignment to (first order, static vehicle, map = ENU at the origin). With
accelerometer bias b_a and gyro bias b_g (in body axes; n_b = n_R_b b), gravity g and latitude lat, the
estimated attitude is exp([phi]x) n_R_b with, in map axes (east, north, up):
    phi_e = n_b_a,north / g,   phi_n = -n_b_a,east / g            (levelling: the tilt that hides the bias)
    phi_u = n_b_g,east / (Omega cos lat) + tan(lat) phi_n          (gyrocompassing: the bias seen as Earth rate,
                                                                    plus the vertical Earth rate leaking through
                                                                    the tilt)
so the levelling error is |b_a,horizontal| / g (paper sensors, 50 micro-g: 5e-5 rad, 0.003 deg) and the heading
error |b_g,east| / (Omega cos lat) (0.01 deg/h at 30 deg: 7.7e-4 rad, 0.044 deg). White noise adds, over a T s
static segment, sigma_a / sqrt(T) / g to the tilt and sigma_g / sqrt(T) / (Omega cos lat) to the heading.
Every test prints what it measured.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.config import AlignmentConfig
from gtsam_dvl.core.earth import OMEGA_IE, LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix, so3_log
from gtsam_dvl.core.types import DvlData, ImuData, LogData
from gtsam_dvl.estimators.inputs.alignment import (
    STATIC_MARGIN_S,
    align,
    coarse_alignment,
    detect_static_end,
    dvl_motion_start,
    window_means,
)
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario, scenario_from_dict

UG = 9.80665e-6  # m/s^2 per micro-g (the simulator's unit)
DEG_PER_H = np.radians(1.0) / 3600.0  # rad/s per deg/h
LAT = 30.0
# biases of about the paper's 1-sigma size (Table 1: 50 micro-g, 0.01 deg/h), signs mixed, given explicitly so
# that the truth is in this file
ACCEL_BIAS_UG = (50.0, -30.0, 20.0)
GYRO_BIAS_DEG_H = (0.01, -0.02, 0.005)
ACCEL_NOISE = 10.0  # micro-g/sqrt(Hz), Table 1
GYRO_NOISE = 0.1  # deg/h/sqrt(Hz), Table 1


def _scenario(
    rpy: tuple[float, float, float] = (3.0, 0.0, 10.0),
    gyro_bias: tuple[float, ...] = (0.0, 0.0, 0.0),
    accel_bias: tuple[float, ...] = (0.0, 0.0, 0.0),
    noise: bool = False,
    lat: float = LAT,
    static_s: float = 120.0,
    moving: bool = True,
) -> Scenario:
    """static_s seconds at rest, then (moving) a 15 s level acceleration to 2 m/s."""
    segments: list[dict[str, Any]] = [{"kind": "static", "duration_s": static_s}]
    if moving:
        segments.append({"kind": "level", "duration_s": 15.0, "speed_end_m_s": 2.0})
    return scenario_from_dict(
        {
            "origin": {"lat_deg": lat, "lon_deg": 114.0, "height_m": -100.0},
            "initial": {"roll_deg": rpy[0], "pitch_deg": rpy[1], "yaw_deg": rpy[2]},
            "imu": {
                "gyro_bias_values_deg_per_h": list(gyro_bias),
                "accel_bias_values_micro_g": list(accel_bias),
                "gyro_noise_deg_per_h_per_sqrt_hz": GYRO_NOISE if noise else 0.0,
                "accel_noise_micro_g_per_sqrt_hz": ACCEL_NOISE if noise else 0.0,
            },
            "dvl": {"noise_m_s": 0.02},
            "segments": segments,
        },
        name="alignment-test",
    )


@functools.cache
def _log(seed: int = 1, **kw: Any) -> tuple[LogData, LocalFrame]:
    sc = _scenario(**kw)
    return simulate(sc, seed, white_noise=bool(kw.get("noise", False))), sc.local_frame()


def _attitude_error(n_R_b: np.ndarray, log: LogData, t: float) -> np.ndarray:
    """Rotation vector phi (rad, map axes) with n_R_b = exp([phi]x) n_R_b_true at time t."""
    assert log.truth is not None
    k = int(np.argmin(np.abs(log.truth.t - t)))
    return so3_log(n_R_b @ quat_xyzw_to_matrix(log.truth.n_q_b[k]).T)


def _predicted_error(n_R_b: np.ndarray, g: float, lat_deg: float) -> np.ndarray:
    """First-order error (module doc) for the biases ACCEL_BIAS_UG, GYRO_BIAS_DEG_H."""
    n_ba = n_R_b @ (np.array(ACCEL_BIAS_UG) * UG)
    n_bg = n_R_b @ (np.array(GYRO_BIAS_DEG_H) * DEG_PER_H)
    lat = np.radians(lat_deg)
    phi_n = -n_ba[0] / g
    return np.array([n_ba[1] / g, phi_n, n_bg[0] / (OMEGA_IE * np.cos(lat)) + np.tan(lat) * phi_n])


# ----- window_means -----------------------------------------------------------------------------------


def test_window_means_against_hand_computed_means() -> None:
    """100 Hz samples of x = t: window k holds t = k, k + 0.01, ..., k + 0.99, mean k + 0.495, end k + 1 (relative
    to the first sample), except the last, which ends with the data (9.99 s); windows without samples are left
    out; any time base."""
    t = np.arange(1000) / 100.0
    x = np.stack([t, 2.0 * t + 1.0], axis=1)
    ends, means = window_means(t, x)
    np.testing.assert_allclose(ends, [*range(1, 10), 9.99])
    np.testing.assert_allclose(means[:, 0], np.arange(10) + 0.495, atol=1e-12)
    np.testing.assert_allclose(means[:, 1], 2.0 * (np.arange(10) + 0.495) + 1.0, atol=1e-12)
    ends2, means2 = window_means(t, x, window_s=2.0)
    np.testing.assert_allclose(ends2, [2, 4, 6, 8, 9.99])
    np.testing.assert_allclose(means2[:, 0], 2.0 * np.arange(5) + 0.995, atol=1e-12)
    gap = (t < 3.0) | (t >= 5.0)  # no samples in [3, 5): windows ending at 4 and 5 are left out
    ends3, means3 = window_means(t[gap], x[gap])
    np.testing.assert_allclose(ends3, [1, 2, 3, 6, 7, 8, 9, 9.99])
    np.testing.assert_allclose(means3[:, 0], np.array([0, 1, 2, 5, 6, 7, 8, 9]) + 0.495, atol=1e-12)
    t0 = 1_700_000.25  # a real log's clock
    ends4, means4 = window_means(t + t0, x)
    np.testing.assert_allclose(ends4, t0 + np.array([*range(1, 10), 9.99]), rtol=0, atol=1e-6)
    np.testing.assert_allclose(means4, means, atol=1e-12)


# ----- static-segment detection -----------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_static_end_found_just_before_the_motion(seed: int) -> None:
    """600 s at rest, then a level acceleration, with the paper's noise: the first 1 s window seen moving is
    [600, 601) (the acceleration exceeds the 2 mm/s^2 threshold 0.3 s after 600 s; noise in a 1 s mean is 0.1
    mm/s^2), so the static segment ends STATIC_MARGIN_S before 601 s: never after the true 600 s (a static segment
    holding motion would tilt the levelling), at most 6 s before it. Measured 596 s for every seed."""
    log, _ = _log(
        seed, gyro_bias=GYRO_BIAS_DEG_H, accel_bias=ACCEL_BIAS_UG, noise=True, static_s=600.0
    )
    t_end = detect_static_end(log.imu, log.dvl, AlignmentConfig())
    print(f"\nseed {seed}: static segment ends at {t_end} s (motion from 600 s)")
    assert 600.0 - STATIC_MARGIN_S - 1.0 <= t_end <= 600.0


def test_static_end_on_paper3d(sim_paper3d_clean: LogData) -> None:
    """paper-3d (static 0-600 s): measured 596 s."""
    t_end = detect_static_end(sim_paper3d_clean.imu, sim_paper3d_clean.dvl, AlignmentConfig())
    print(f"\npaper-3d: static segment ends at {t_end} s")
    assert 594.0 <= t_end <= 600.0


def test_static_end_from_the_dvl_and_the_cap() -> None:
    """The IMU at rest throughout (noise-free), but the DVL reports 0.5 m/s from 50 s (a vehicle drifting in a
    current): the static segment ends STATIC_MARGIN_S before the first fast valid ping, at 45 s exactly; an invalid
    ping (no bottom lock) at 20 s, however fast, does not count. max_static_s caps the segment."""
    log, _ = _log(static_s=120.0, moving=False)
    d_v, valid = log.dvl.d_v.copy(), log.dvl.valid.copy()
    d_v[log.dvl.t >= 50.0] = [0.5, 0.0, 0.0]
    k20 = int(np.argmin(np.abs(log.dvl.t - 20.0)))
    d_v[k20], valid[k20] = [5.0, 0.0, 0.0], False
    dvl = dataclasses.replace(log.dvl, d_v=d_v, valid=valid)
    cfg = AlignmentConfig()
    assert detect_static_end(log.imu, dvl, cfg) == pytest.approx(50.0 - STATIC_MARGIN_S, abs=1e-9)
    assert detect_static_end(
        log.imu, log.dvl, cfg.model_copy(update={"max_static_s": 40.0})
    ) == pytest.approx(40.0)
    assert detect_static_end(
        log.imu, dvl, cfg.model_copy(update={"max_static_s": 40.0})
    ) == pytest.approx(40.0)


def test_single_fast_pings_neither_end_nor_abort_the_static_segment() -> None:
    """Gross DVL outliers during the static phase (1.5 m/s at 20 s, 3 m/s at 60 s, and at 100 s, 4 s before the
    data end): none starts a run of mostly fast pings (DVL_MOTION_PINGS), so the segment is the IMU's, as
    without them, and the alignment is the same; 5 % of the pings fast at random (seeded) do not end it either.
    A real start of motion is a run: 8 of 10 pings fast from 50 s (two slow ones inside) ends it at 45 s."""
    log, frame = _log(static_s=104.0, moving=False)
    cfg = AlignmentConfig()
    t_ref = detect_static_end(log.imu, log.dvl, cfg)
    d_v = log.dvl.d_v.copy()
    for t_out, speed in ((20.0, 1.5), (60.0, 3.0), (100.0, 2.0)):
        d_v[int(np.argmin(np.abs(log.dvl.t - t_out)))] = [speed, 0.0, 0.0]
    outliers = dataclasses.replace(log.dvl, d_v=d_v)
    t_end = detect_static_end(log.imu, outliers, cfg)
    print(
        f"\nstatic segment without outliers ends at {t_ref} s, with three single fast pings at {t_end} s"
    )
    assert t_end == t_ref == float(log.imu.t[-1])
    np.testing.assert_array_equal(
        align(log.imu, outliers, frame, cfg).n_R_b, align(log.imu, log.dvl, frame, cfg).n_R_b
    )
    rng = np.random.default_rng(5)
    d_v5 = log.dvl.d_v.copy()
    k = rng.choice(len(d_v5), len(d_v5) // 20, replace=False)
    d_v5[k] = rng.uniform(0.5, 2.0, (len(k), 1)) * np.array([1.0, 0.0, 0.0])
    assert detect_static_end(log.imu, dataclasses.replace(log.dvl, d_v=d_v5), cfg) == t_ref
    run = log.dvl.d_v.copy()
    moving = log.dvl.t >= 50.0
    run[moving] = [0.5, 0.0, 0.0]
    run[np.flatnonzero(moving)[[3, 7]]] = 0.0  # two slow pings inside the run: 8 of 10 are fast
    assert dvl_motion_start(
        dataclasses.replace(log.dvl, d_v=run), cfg.dvl_speed_threshold_m_s
    ) == pytest.approx(50.0)
    assert detect_static_end(log.imu, dataclasses.replace(log.dvl, d_v=run), cfg) == pytest.approx(
        45.0
    )


def test_static_end_of_a_log_that_never_moves_is_its_last_sample() -> None:
    log, _ = _log(static_s=25.0, moving=False)
    t_end = detect_static_end(log.imu, log.dvl, AlignmentConfig())
    print(f"\nat rest 0-{log.imu.t[-1]:.0f} s: static segment ends at {t_end} s")
    assert t_end <= log.imu.t[-1]


# ----- coarse alignment against the truth -------------------------------------------------------------


@pytest.mark.parametrize("rpy", [(3.0, 0.0, 10.0), (-5.0, 8.0, 200.0), (0.0, -20.0, -90.0)])
def test_alignment_without_sensor_errors_is_exact(rpy: tuple[float, float, float]) -> None:
    """No biases, no noise: the static specific force is exactly -gravity and the gyro exactly the Earth rate, so
    levelling and gyrocompassing give the truth attitude to rounding (bound 1e-10 rad; measured about 3e-14)."""
    log, frame = _log(rpy=rpy)
    a = align(log.imu, log.dvl, frame, AlignmentConfig())
    err = _attitude_error(a.n_R_b, log, a.t_static_end)
    print(f"\ninitial rpy {rpy} deg: alignment error {err} rad (static until {a.t_static_end} s)")
    assert a.method == "static" and 114.0 <= a.t_static_end <= 120.0
    assert np.all(np.abs(err) < 1e-10)
    assert a.b_f_mean is not None and a.b_omega_mean is not None
    assert np.linalg.norm(a.b_omega_mean) == pytest.approx(OMEGA_IE, rel=1e-9)


@pytest.mark.parametrize("rpy", [(3.0, 0.0, 10.0), (-5.0, 8.0, 200.0)])
def test_alignment_error_is_the_bias_error_model(rpy: tuple[float, float, float]) -> None:
    """Noise-free, biases ACCEL_BIAS_UG and GYRO_BIAS_DEG_H: the error is the first-order model of the module
    doc, component by component, within 1 % of its size (measured 0.14 %; the rest is second order), and inside
    the bounds levelling <= |b_a,h| / g, heading <= |b_g,e| / (Omega cos lat) + tan(lat) tilt."""
    log, frame = _log(rpy=rpy, gyro_bias=GYRO_BIAS_DEG_H, accel_bias=ACCEL_BIAS_UG)
    a = align(log.imu, log.dvl, frame, AlignmentConfig())
    err = _attitude_error(a.n_R_b, log, a.t_static_end)
    assert a.b_f_mean is not None
    g = float(np.linalg.norm(a.b_f_mean))
    # the bias's map components need the attitude only to zeroth order: the estimate will do
    R = a.n_R_b
    pred = _predicted_error(R, g, LAT)
    print(
        f"\nrpy {rpy}: error {err} rad, predicted {pred} rad (levelling {np.degrees(np.hypot(*err[:2])):.5f} deg, "
        f"heading {np.degrees(err[2]):.4f} deg)"
    )
    assert np.all(np.abs(err - pred) < 0.01 * np.linalg.norm(pred))
    n_ba = R @ (np.array(ACCEL_BIAS_UG) * UG)
    n_bg = R @ (np.array(GYRO_BIAS_DEG_H) * DEG_PER_H)
    tilt = float(np.hypot(err[0], err[1]))
    assert tilt <= 1.01 * np.hypot(n_ba[0], n_ba[1]) / g
    assert abs(err[2]) <= 1.01 * (
        abs(n_bg[0]) / (OMEGA_IE * np.cos(np.radians(LAT))) + np.tan(np.radians(LAT)) * tilt
    )


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_alignment_with_the_paper_sensors_within_the_noise_bound(seed: int) -> None:
    """The paper's sensors on a 600 s static segment: the error is the bias model's within 4 sigma of white noise
    averaged over the segment (T = 596 s: tilt sigma 10 micro-g/sqrt(T)/g = 4e-7 rad, heading sigma
    0.1 deg/h/sqrt(T)/(Omega cos 30) = 3.1e-4 rad); overall the heading is within 0.1 deg and the levelling within
    0.005 deg of the truth (the paper's IMU)."""
    log, frame = _log(
        seed, gyro_bias=GYRO_BIAS_DEG_H, accel_bias=ACCEL_BIAS_UG, noise=True, static_s=600.0
    )
    a = align(log.imu, log.dvl, frame, AlignmentConfig())
    err = _attitude_error(a.n_R_b, log, a.t_static_end)
    assert a.b_f_mean is not None
    g = float(np.linalg.norm(a.b_f_mean))
    pred = _predicted_error(a.n_R_b, g, LAT)
    T = a.t_static_end - log.imu.t[0]
    sigma_tilt = ACCEL_NOISE * UG / np.sqrt(T) / g
    sigma_heading = GYRO_NOISE * DEG_PER_H / np.sqrt(T) / (OMEGA_IE * np.cos(np.radians(LAT)))
    sigma_heading = float(np.hypot(sigma_heading, np.tan(np.radians(LAT)) * sigma_tilt))
    z = (err - pred) / np.array([sigma_tilt, sigma_tilt, sigma_heading])
    print(
        f"\nseed {seed}: error {np.degrees(err)} deg, bias model {np.degrees(pred)} deg; (error - model) / noise "
        f"sigma {np.round(z, 2)}"
    )
    assert np.all(np.abs(z) < 4.0)
    assert np.degrees(abs(err[2])) < 0.1 and np.degrees(np.hypot(err[0], err[1])) < 0.005


# ----- configured attitude ----------------------------------------------------------------------------


def test_configured_attitude_skips_the_static_segment() -> None:
    """alignment.initial_attitude_deg = [roll, pitch, yaw] (the paper's 3, 0, 10 deg, yaw ENU): no data needed
    (the online estimator passes empty arrays); the attitude is Rz(yaw) Ry(pitch) Rx(roll), built here by hand,
    and it is the simulator's initial attitude for the same numbers (to 1e-12)."""
    empty_imu = ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
    empty_dvl = DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, dtype=bool))
    log, frame = _log(rpy=(3.0, 0.0, 10.0))
    cfg = AlignmentConfig(initial_attitude_deg=(3.0, 0.0, 10.0))
    a = align(empty_imu, empty_dvl, frame, cfg)
    r, y = np.radians(3.0), np.radians(10.0)
    Rz = np.array([[np.cos(y), -np.sin(y), 0.0], [np.sin(y), np.cos(y), 0.0], [0.0, 0.0, 1.0]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(r), -np.sin(r)], [0.0, np.sin(r), np.cos(r)]])
    assert (
        a.method == "configured"
        and a.t_static_end == 0.0
        and a.b_f_mean is None
        and a.b_omega_mean is None
    )
    np.testing.assert_allclose(a.n_R_b, Rz @ Rx, atol=1e-15)
    assert np.all(np.abs(_attitude_error(a.n_R_b, log, 0.0)) < 1e-12)
    # the configured attitude wins even on a log that could be aligned (and on one that could not)
    assert align(log.imu, log.dvl, frame, cfg).method == "configured"


# ----- errors -----------------------------------------------------------------------------------------


def test_too_short_static_segment_is_a_clear_error() -> None:
    """20 s at rest, then motion: the first window seen moving is [20, 21), so the static segment is 16 s, shorter
    than alignment.min_static_s (30 s): an error with method = "static" (method "auto" aligns in motion then:
    tests/estimators/test_alignment_motion.py)."""
    log, frame = _log(static_s=20.0)
    with pytest.raises(
        GtsamDvlError,
        match=r"no static segment of at least 30 s .*found 16 s.*initial_attitude_deg",
    ):
        align(log.imu, log.dvl, frame, AlignmentConfig(method="static"))
    # a lower minimum accepts it, and the attitude is still the truth (noise-free, no biases)
    a = align(log.imu, log.dvl, frame, AlignmentConfig(min_static_s=10.0))
    assert a.t_static_end == pytest.approx(16.0) and np.all(
        np.abs(_attitude_error(a.n_R_b, log, 0.0)) < 1e-10
    )


def test_log_starting_in_motion_is_a_clear_error() -> None:
    """A log that starts at 1.5 m/s (DVL faster than dvl_speed_threshold_m_s from the first ping): no static
    segment at all: an error with method = "static"."""
    sc = scenario_from_dict(
        {
            "origin": {"lat_deg": LAT, "lon_deg": 114.0},
            "initial": {"speed_m_s": 1.5},
            "dvl": {"noise_m_s": 0.02},
            "segments": [
                {"kind": "straight", "duration_s": 60.0},
                {"kind": "turn", "duration_s": 30.0, "heading_change_deg": 45.0},
            ],
        }
    )
    log = simulate(sc, 1, white_noise=False)
    assert detect_static_end(log.imu, log.dvl, AlignmentConfig()) == log.imu.t[0]
    with pytest.raises(GtsamDvlError, match=r"no static segment of at least 30 s .*found 0 s"):
        align(log.imu, log.dvl, sc.local_frame(), AlignmentConfig(method="static"))


def test_gyrocompassing_fails_clearly_when_the_earth_rate_is_hidden() -> None:
    """A gyro whose bias cancels 90 % of the horizontal Earth rate (13 deg/h at 30 deg): the horizontal rate left
    (1.3 deg/h) is below 20 % of the expected, and gyrocompassing refuses rather than return a heading."""
    frame = LocalFrame(LAT, 114.0, 0.0)
    g = 9.79
    w_earth = frame.n_omega_ie  # body = map (level, facing east)
    bias = np.array([0.0, -0.9 * w_earth[1], 0.0])
    with pytest.raises(GtsamDvlError, match="gyrocompassing failed.*initial_attitude_deg"):
        coarse_alignment(np.array([0.0, 0.0, g]), w_earth + bias, frame)
    np.testing.assert_allclose(
        coarse_alignment(np.array([0.0, 0.0, g]), w_earth, frame), np.eye(3), atol=1e-12
    )


def test_gyrocompassing_near_a_pole_raises_rather_than_return_the_bias_direction() -> None:
    log, frame = _log(lat=89.99, gyro_bias=(0.01, 0.0, 0.0))
    try:
        a = align(log.imu, log.dvl, frame, AlignmentConfig())
    except GtsamDvlError as exc:
        assert "gyrocompassing failed" in str(exc)
        return
    err = _attitude_error(a.n_R_b, log, a.t_static_end)
    print(
        f"\nlatitude 89.99 deg, gyro bias 0.01 deg/h: heading error {np.degrees(err[2]):.1f} deg, no error raised"
    )
    assert abs(np.degrees(err[2])) < 1.0
