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

import copy
import dataclasses
from collections.abc import Callable
from dataclasses import asdict
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.core.earth import depth_to_pressure, pressure_to_depth
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, rpy_deg_to_matrix
from gtsam_dvl.core.types import (
    DepthData,
    DvlCalibration,
    DvlData,
    GeoOrigin,
    ImuBiases,
    ImuData,
    LogData,
    Mounting,
    TruthData,
)
from gtsam_dvl.sim import imu as sim_imu
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
from gtsam_dvl.sim.position import PositionTrack, integrate_position

if TYPE_CHECKING:
    from gtsam_dvl.core.earth import LocalFrame
    from gtsam_dvl.sim.scenario import DvlSpec, Scenario


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
    track = integrate_position(motion, frame.lat0, frame.lon0, scenario.origin.height_m, rate, n)
    if progress is not None:
        progress(0.1)
    bias_ss, imu_ss, dvl_ss, event_ss = np.random.SeedSequence(seed).spawn(4)
    imu, errors = _imu(scenario, motion, track, n, bias_ss, imu_ss, white_noise, progress)
    truth = _truth(motion, track, frame, n, int(round(rate / rates.truth_hz)), scenario)
    mount = scenario.mounting
    mounting = Mounting(
        b_R_d0=rpy_deg_to_matrix(mount.dvl_rpy_deg),
        b_p_dvl=np.asarray(mount.dvl_lever_arm_m, dtype=float),
    )
    dvl, constant = _dvl(
        scenario, seed, white_noise, mounting, motion, track, float(imu.t[-1]), dvl_ss, event_ss
    )
    depth = (
        None
        if scenario.depth is None
        else _depth(scenario, motion, track, frame, n, seed, white_noise)
    )
    metadata = _metadata(
        scenario,
        seed,
        white_noise,
        mounting,
        errors.gyro_bias0,
        errors.accel_bias0,
        _bias_series(scenario, errors, rate),
    )
    _sensor_metadata(scenario, metadata)
    drawn_metadata(metadata, given_dvl, constant)
    gnss = None
    origin: GeoOrigin | None = _origin(scenario)
    if scenario.gnss is not None:
        gnss = simulate_gnss(scenario.gnss, motion, track, rate, n, seed, white_noise)
        if not scenario.gnss.origin_in_log:  # the origin must come from the fixes (sim/gnss.py)
            fix_frame = _fix_frame(scenario, first_fix_frame(gnss), metadata)
            truth = reframe_truth(truth, frame, fix_frame)
            origin = None
    if progress is not None:
        progress(1.0)
    return _log_data(
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
    t_meas, t_dvl = _dvl_stamps(rates.dvl_hz, rates.dvl_time_offset_s, t_end)
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


def _log_data(
    scenario: Scenario,
    seed: int,
    gyro_bias0: np.ndarray,
    accel_bias0: np.ndarray,
    metadata: dict[str, Any],
    origin: GeoOrigin | None,
    **data: Any,
) -> LogData:
    """The LogData of a simulation: its sensor data and truth (data) with the typed fields of the scenario."""
    if (
        "dvl" in data
    ):  # without white noise the DVL repeats its velocity bit for bit (DvlData.noise_free)
        data["dvl"].noise_free = not metadata.get("white_noise", True)
    return LogData(
        t0_ns=scenario.t0_ns,
        metadata=metadata,
        source=f"simulated:{scenario.name}:seed={seed}",
        origin=origin,
        true_calibration=DvlCalibration(
            float(scenario.dvl.scale),
            tuple(float(a) for a in scenario.dvl.misalignment_deg),  # type: ignore[arg-type]
            float(scenario.rates.dvl_time_offset_s),
        ),
        true_imu_bias=ImuBiases(tuple(accel_bias0.tolist()), tuple(gyro_bias0.tolist())),  # type: ignore[arg-type]
        segments=scenario.segments_typed(),
        **data,
    )


# the DvlSpec keys whose error is off at 0: left out of the metadata then (an older scenario's stays as it was)
_DVL_OPTIONAL = (
    "stated_noise_m_s",
    "constant_error_sigma_m_s",
    "draw_scale_sigma",
    "draw_misalignment_sigma_deg",
)


def with_drawn_calibration(scenario: Scenario, seed: int) -> Scenario:
    """The scenario with this seed's truth DVL scale and misalignment (sim/dvl.py drawn_calibration; itself when
    its [dvl] table draws none)."""
    dvl = drawn_calibration(scenario.dvl, seed)
    return scenario if dvl is scenario.dvl else dataclasses.replace(scenario, dvl=dvl)


def drawn_metadata(metadata: dict[str, Any], given: DvlSpec, constant: np.ndarray | None) -> None:
    """A drawn calibration and a constant error in the metadata: "sensors" keeps the [dvl] table's scale and
    misalignment (the draw's mean; "truth" has the drawn ones), "truth" gets the run's constant error (m/s in
    dvl_link). Nothing changes for a scenario without them."""
    sensors, truth = metadata["sensors"]["dvl"], metadata["truth"]["dvl"]
    if sensors.get("draw_scale_sigma") or sensors.get("draw_misalignment_sigma_deg"):
        sensors["scale"], sensors["misalignment_deg"] = (
            float(given.scale),
            list(given.misalignment_deg),
        )
    if constant is not None:
        truth["constant_error_m_s"] = constant.tolist()


def _origin(scenario: Scenario) -> GeoOrigin:
    return GeoOrigin(
        float(scenario.origin.lat_deg),
        float(scenario.origin.lon_deg),
        float(scenario.origin.height_m),
    )


def _sensor_metadata(scenario: Scenario, metadata: dict[str, Any]) -> None:
    """The [depth] and [gnss] specifications into metadata["sensors"], when the scenario has them."""
    if scenario.depth is not None:
        metadata["sensors"]["depth"] = _listify_spec(asdict(scenario.depth))
    if scenario.gnss is not None:
        metadata["sensors"]["gnss"] = _listify_spec(asdict(scenario.gnss))


def _fix_frame(
    scenario: Scenario, fix_frame: LocalFrame | None, metadata: dict[str, Any]
) -> LocalFrame:
    """gnss.origin_in_log = false: the first fix's frame becomes the map (metadata without "origin", the truth's
    map origin recorded); an error without any fix."""
    if fix_frame is None:
        raise GtsamDvlError(
            f"{scenario.source}: key 'gnss.origin_in_log': false needs at least one fix, "
            "and the vehicle never surfaces while the receiver records"
        )
    metadata.pop("origin", None)
    metadata["truth"]["map_origin"] = {
        "lat_deg": fix_frame.lat_deg,
        "lon_deg": fix_frame.lon_deg,
        "height_m": fix_frame.height_m,
        "from": "first GNSS fix",
    }
    return fix_frame


def _water_truth(scenario: Scenario) -> dict[str, Any]:
    """metadata["truth"]'s "current" and "seafloor" (sim/current.py), those the scenario has."""
    out: dict[str, Any] = {}
    if scenario.current is not None:
        out["current"] = _listify_spec(asdict(scenario.current))
    if scenario.seafloor is not None:
        out["seafloor"] = asdict(scenario.seafloor)
    return out


def _without(d: dict[str, Any], keys: tuple[str, ...]) -> dict[str, Any]:
    """d without keys (the settings of an error that is off)."""
    return {k: v for k, v in d.items() if k not in keys}


def _listify_spec(d: dict[str, Any]) -> dict[str, Any]:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


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
    return _depth_at(scenario, motion, track, frame, k, depth_rng(seed) if white_noise else None)


def _depth_at(
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


def _dvl_stamps(dvl_hz: float, offset_s: float, t_end: float) -> tuple[np.ndarray, np.ndarray]:
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
    return _truth_at(motion, track, frame, np.arange(0, n, step), scenario)


def _truth_at(
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


def _metadata(
    scenario: Scenario,
    seed: int,
    white: bool,
    mounting: Mounting,
    gyro_bias0: np.ndarray,
    accel_bias0: np.ndarray,
    bias_series: dict[str, Any] | None,
) -> dict[str, Any]:
    from gtsam_dvl import __version__

    def listify(d: dict[str, Any]) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}

    o = scenario.origin
    imu_truth_md: dict[str, Any] = {
        "gyro_bias_rad_s": gyro_bias0.tolist(),
        "accel_bias_m_s2": accel_bias0.tolist(),
    }
    if bias_series is not None:
        imu_truth_md["bias_series"] = bias_series
    return {
        "scenario_name": scenario.name,
        "scenario": copy.deepcopy(scenario.raw),
        "seed": int(seed),
        "white_noise": bool(white),
        "origin": {
            "lat_deg": float(o.lat_deg),
            "lon_deg": float(o.lon_deg),
            "height_m": float(o.height_m),
        },
        "truth": {
            "dvl": {
                "scale": float(scenario.dvl.scale),
                "misalignment_deg": [float(a) for a in scenario.dvl.misalignment_deg],
                "b_R_d0": mounting.b_R_d0.tolist(),
                "b_lever_arm_m": mounting.b_l.tolist(),
                "time_offset_s": float(scenario.rates.dvl_time_offset_s),
            },
            "imu": imu_truth_md,
            "segments": scenario.segment_table(),
            **_water_truth(scenario),
        },
        "sensors": {  # the optional errors only when on (the metadata of a scenario without them stays as it was)
            "imu": _without(
                listify(asdict(scenario.imu)),
                tuple(
                    k
                    for k in (
                        "quantisation_gyro_rad_s",
                        "quantisation_accel_m_s2",
                        "saturation_gyro_rad_s",
                        "saturation_accel_m_s2",
                    )
                    if not np.any(getattr(scenario.imu, k))
                ),
            ),
            "dvl": _without(
                listify(asdict(scenario.dvl)),
                (
                    ("correlated_sigma_m_s", "correlated_tau_s")
                    if scenario.dvl.correlated_sigma_m_s == 0
                    else ()
                )
                + (("bottom_range_m", "water_track_noise_m_s") if scenario.seafloor is None else ())
                + tuple(k for k in _DVL_OPTIONAL if not np.any(getattr(scenario.dvl, k))),
            ),
            "rates": asdict(scenario.rates),
            "mounting": listify(asdict(scenario.mounting)),
        },
        "generator": f"gtsam_dvl {__version__}",
    }
