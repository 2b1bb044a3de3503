"""simulate(): scenario -> LogData (IMU, DVL, truth, mounting, metadata). No file I/O, no GTSAM.

Steps: analytic motion in the local level -> geodetic position by quadrature -> true IMU increments ->
biases and noise -> truth in the map frame -> DVL -> depth and GNSS fixes (when the scenario has them).
Random streams are children of SeedSequence(seed) (PCG64), one per purpose, so switching white noise off keeps
the same biases: 0 IMU biases, 1 IMU white noise, 2 DVL white noise, 3 DVL dropouts and outliers, 4 depth, 5 GNSS,
6 the DVL's correlated (Gauss-Markov) error, 7 the DVL's water-track noise, 8 the DVL's truth calibration (when
drawn per seed), 9 the DVL's per-run constant error. A stream a scenario does not use is never drawn, so adding a
sensor or an error to a scenario leaves every other stream's numbers as they were.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.core.earth import depth_to_pressure, pressure_to_depth
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw
from gtsam_dvl.core.types import (
    DepthData,
    DvlData,
    GeoOrigin,
    ImuData,
    LogData,
    Mounting,
    TruthData,
)
from gtsam_dvl.sim import imu as sim_imu
from gtsam_dvl.sim import record
from gtsam_dvl.sim.dvl import (
    constant_error,
    correlated_error,
    drawn_calibration,
    dvl_measure,
    dvl_true,
    water_model,
    water_noise_rng,
)
from gtsam_dvl.sim.gnss import first_fix_frame, reframe_truth, simulate_gnss
from gtsam_dvl.sim.imu import ImuErrors, draw_biases, quantise, saturate, true_imu
from gtsam_dvl.sim.local_level import imu_truth
from gtsam_dvl.sim.motion import MotionProfile
from gtsam_dvl.sim.position import PositionStream, PositionTrack

if TYPE_CHECKING:
    from gtsam_dvl.core.earth import LocalFrame
    from gtsam_dvl.sim.scenario import Scenario


def simulate(
    scenario: Scenario,
    seed: int,
    *,
    white_noise: bool = True,
    progress: Callable[[float], None] | None = None,
) -> LogData:
    """Simulate the scenario's IMU (rate and specific force averaged over each sample), DVL and truth.

    white_noise=False drops IMU and DVL white noise, the DVL's correlated error, DVL dropouts and outliers, but
    keeps the biases, the IMU's quantisation, the DVL scale and misalignment, the mounting and the lever arm.
    It drops the DVL's per-run constant error too (an error of the DVL's output, as the correlated one); a drawn
    calibration is a truth, kept. Same seed, same arrays, bit for bit.
    """
    given_dvl = scenario.dvl
    scenario = with_drawn_calibration(scenario, seed)
    rates = scenario.rates
    rate = rates.imu_hz
    n = int(np.floor(scenario.duration_s * rate + 1e-6)) + 1  # stamps k / rate, k = 0..n-1
    frame = scenario.local_frame()
    motion = MotionProfile.from_scenario(scenario)
    # the whole run as one window of the stream sim/stream.py integrates chunk by chunk (the same bits)
    positions = PositionStream(motion, frame.lat0, frame.lon0, scenario.origin.height_m, rate, n)
    track = positions.window(0, n)
    if progress is not None:
        progress(0.1)
    bias_ss, imu_ss, dvl_ss, event_ss = np.random.SeedSequence(seed).spawn(4)
    imu, errors = _imu(scenario, motion, track, n, bias_ss, imu_ss, white_noise, progress)
    truth = _truth(motion, track, frame, n, int(round(rate / rates.truth_hz)), scenario)
    mounting = record.nominal_mounting(scenario)
    dvl, constant = _dvl(
        scenario, seed, white_noise, mounting, motion, track, float(imu.t[-1]), dvl_ss, event_ss
    )
    depth = (
        None
        if scenario.depth is None
        else _depth(scenario, motion, track, frame, n, seed, white_noise)
    )
    metadata = record.metadata(
        scenario,
        seed,
        white_noise,
        mounting,
        errors.gyro_bias0,
        errors.accel_bias0,
        _bias_series(scenario, errors, rate),
        given_dvl,
        constant,
    )
    gnss = None
    origin: GeoOrigin | None = record.map_origin(scenario)
    if scenario.gnss is not None:
        gnss = simulate_gnss(scenario.gnss, motion, track, rate, n, seed, white_noise)
        if not scenario.gnss.origin_in_log:  # the origin must come from the fixes (sim/gnss.py)
            fix_frame = record.map_from_first_fix(scenario, first_fix_frame(gnss), metadata)
            truth = reframe_truth(truth, frame, fix_frame)
            origin = None
    if progress is not None:
        progress(1.0)
    return record.log_data(
        scenario,
        seed,
        errors.gyro_bias0,
        errors.accel_bias0,
        metadata,
        origin,
        imu=imu,
        dvl=dvl,
        mounting=mounting,
        truth=truth,
        depth=depth,
        gnss=gnss,
    )


def _imu(
    scenario: Scenario,
    motion: MotionProfile,
    track: PositionTrack,
    n: int,
    bias_ss: np.random.SeedSequence,
    imu_ss: np.random.SeedSequence,
    white_noise: bool,
    progress: Callable[[float], None] | None,
) -> tuple[ImuData, ImuErrors]:
    """The n IMU samples: the true increments, the biases (stream bias_ss), the white noise (stream imu_ss,
    when white_noise), then quantised and saturated. Returns them with the drawn biases."""
    rate = scenario.rates.imu_hz
    b_omega, b_f = true_imu(motion, track, n, progress)
    errors = draw_biases(scenario.imu, n, rate, np.random.Generator(np.random.PCG64(bias_ss)))
    b_omega += errors.gyro_bias
    b_f += errors.accel_bias
    if white_noise:
        ng, na = sim_imu.white_noise(
            scenario.imu, n, rate, np.random.Generator(np.random.PCG64(imu_ss))
        )
        b_omega += ng
        b_f += na
    imu = ImuData(
        t=np.arange(n) / rate,
        b_omega=saturate(
            quantise(b_omega, scenario.imu.quantisation_gyro_rad_s),
            scenario.imu.saturation_gyro_rad_s,
        ),
        b_f=saturate(
            quantise(b_f, scenario.imu.quantisation_accel_m_s2), scenario.imu.saturation_accel_m_s2
        ),
    )
    return imu, errors


def _dvl(
    scenario: Scenario,
    seed: int,
    white_noise: bool,
    mounting: Mounting,
    motion: MotionProfile,
    track: PositionTrack,
    t_end: float,
    dvl_ss: np.random.SeedSequence,
    event_ss: np.random.SeedSequence,
) -> tuple[DvlData, np.ndarray | None]:
    """The DVL pings up to t_end (s): the true velocity (bottom or water track), its correlated and per-run
    constant errors, then the white noise (stream dvl_ss), dropouts and outliers (stream event_ss), all only
    when white_noise. Returns the pings with the constant error drawn (None: none)."""
    rates = scenario.rates
    t_meas, t_dvl = dvl_stamps(rates.dvl_hz, rates.dvl_time_offset_s, t_end)
    floor_h = scenario.origin.height_m - scenario.dvl.altitude_m
    water = water_model(scenario)
    y, d_u, ranges, water_pings = dvl_true(
        scenario.dvl, mounting.b_R_d0, mounting.b_l, motion, track, t_meas, floor_h, water
    )
    correlated = correlated_error(scenario.dvl, rates.dvl_hz, seed) if white_noise else None
    if correlated is not None:
        y = y + correlated.take(len(t_meas))
    constant = constant_error(scenario.dvl, seed) if white_noise else None
    if constant is not None:
        y = y + constant
    dvl = dvl_measure(
        scenario.dvl,
        t_dvl,
        y,
        d_u,
        ranges,
        np.random.Generator(np.random.PCG64(dvl_ss)) if white_noise else None,
        np.random.Generator(np.random.PCG64(event_ss)) if white_noise else None,
        water_pings,
        water_noise_rng(seed) if white_noise and water is not None else None,
    )
    return dvl, constant


def with_drawn_calibration(scenario: Scenario, seed: int) -> Scenario:
    """The scenario with this seed's truth DVL scale and misalignment (sim/dvl.py drawn_calibration; itself when
    its [dvl] table draws none)."""
    dvl = drawn_calibration(scenario.dvl, seed)
    return scenario if dvl is scenario.dvl else dataclasses.replace(scenario, dvl=dvl)


def depth_rng(seed: int) -> np.random.Generator:
    """The depth noise generator: SeedSequence(seed)'s fifth child, one draw per depth stamp."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed).spawn(5)[4]))


def _depth(
    scenario: Scenario,
    motion: MotionProfile,
    track: PositionTrack,
    frame: LocalFrame,
    n: int,
    seed: int,
    white_noise: bool,
) -> DepthData:
    """The pressure sensor (DepthSpec): depth of the sensor below the surface at h = 0, with bias and noise,
    as absolute pressure. Its random stream is SeedSequence(seed)'s fifth child: the other four, and so every
    other sensor's bytes, are those of a scenario without [depth]."""
    spec = scenario.depth
    assert spec is not None
    k = np.arange(0, n, int(round(scenario.rates.imu_hz / spec.rate_hz)))
    return depth_at(scenario, motion, track, frame, k, depth_rng(seed) if white_noise else None)


def depth_at(
    scenario: Scenario,
    motion: MotionProfile,
    track: PositionTrack,
    frame: LocalFrame,
    k: np.ndarray,
    rng: np.random.Generator | None,
) -> DepthData:
    """The depth samples at the stamps k / rate (IMU sample indices), noise from rng (None: none)."""
    spec = scenario.depth
    assert spec is not None
    t = k / track.rate
    lat, _, h = track.at_samples(k)
    _, _, l_R_b, _ = imu_truth(motion.evaluate(t), lat, h)
    lever = np.asarray(spec.lever_arm_m, dtype=float)
    d_true = -(h + l_R_b[:, 2, :] @ lever)
    d = d_true + spec.bias_m
    if rng is not None and spec.noise_m > 0:
        d = d + spec.noise_m * rng.standard_normal(len(t))
    p = depth_to_pressure(d, frame.lat0, spec.water_density_kg_m3, spec.atmospheric_pa)
    _, dd_dp = pressure_to_depth(p, frame.lat0, spec.water_density_kg_m3, spec.atmospheric_pa)
    var_pa = np.full(len(t), (spec.noise_m / dd_dp) ** 2 if spec.noise_m > 0 else 0.0)
    return DepthData(
        t=t,
        depth_m=d,
        variance_m2=np.full(len(t), spec.noise_m**2),
        pressure_pa=p,
        pressure_variance_pa2=var_pa,
        b_p_sensor=lever.copy(),
    )


def dvl_stamps(dvl_hz: float, offset_s: float, t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """(measurement times, stamps): the DVL measures at k / dvl_hz (integer k keeps them exact multiples) and
    stamps each ping offset_s earlier: dt_d = offset_s, stamps early when > 0 (docs/conventions.md: the ping stamped
    t measures the velocity at t + dt_d). Both within [0, t_end]."""
    j0 = int(np.ceil(max(0.0, offset_s) * dvl_hz - 1e-9))
    j1 = int(np.floor(min(t_end, t_end + offset_s) * dvl_hz + 1e-9))
    t_meas = np.arange(j0, j1 + 1) / dvl_hz
    return t_meas, t_meas - offset_s


def _truth(
    motion: MotionProfile,
    track: PositionTrack,
    frame: LocalFrame,
    n: int,
    step: int,
    scenario: Scenario,
) -> TruthData:
    """Truth of base_link in the map frame at every step-th IMU stamp."""
    return truth_at(motion, track, frame, np.arange(0, n, step), scenario)


def truth_at(
    motion: MotionProfile,
    track: PositionTrack,
    frame: LocalFrame,
    k: np.ndarray,
    scenario: Scenario,
) -> TruthData:
    """Truth of base_link in the map frame at the stamps k / rate (IMU sample indices), with the current at its
    depth when the scenario has one."""
    t = k / track.rate
    lat, lon, h = track.at_samples(k)
    m = motion.evaluate(t)
    b_omega_ib, _, l_R_b, _ = imu_truth(m, lat, h)
    n_R_l = frame.n_R_l(lat, lon)
    n_R_b = n_R_l @ l_R_b
    n_v = np.einsum("kij,kj->ki", n_R_l, m.l_v())
    b_omega = b_omega_ib - np.einsum("kji,j->ki", n_R_b, frame.n_omega_ie)  # relative to map
    n_c = None if scenario.current is None else scenario.current.at(-h, t)
    return TruthData(
        t=t,
        n_p=frame.geodetic_to_map(lat, lon, h),
        n_q_b=matrix_to_quat_xyzw(n_R_b),
        n_v=n_v,
        b_omega=b_omega,
        n_c=n_c,
    )


def _bias_series(scenario: Scenario, errors: ImuErrors, rate: float) -> dict[str, Any] | None:
    """The biases once a second (metadata truth "bias_series") when they walk, else None."""
    spec = scenario.imu
    if not (spec.gyro_bias_walk_deg_per_h_per_sqrt_h or spec.accel_bias_walk_micro_g_per_sqrt_h):
        return None
    k = np.arange(0, errors.gyro_bias.shape[0], int(round(rate)))
    return {
        "t": (k / rate).tolist(),
        "gyro_rad_s": errors.gyro_bias[k].tolist(),
        "accel_m_s2": errors.accel_bias[k].tolist(),
    }
