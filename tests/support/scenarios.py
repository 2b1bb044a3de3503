"""Scenario variants for the tests: a built-in scenario (by default paper-3d-short: the paper's sensors, 120 s
static, 60 s legs) with some of its tables changed, simulated with a seed; and dives that start and end at the
surface, for the GNSS tests."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

SHORT = "paper-3d-short"


# the paper's sensors (Table 1) at latitude 30 deg, 100 m below the ellipsoid: the tables a test's own scenario
# starts from (with_tables), the rates, the segments and the rest its own
PAPER_SENSORS: dict[str, Any] = {
    "origin": {"lat_deg": 30.0, "lon_deg": 114.0, "height_m": -100.0},
    "initial": {"roll_deg": 3.0, "yaw_deg": 10.0},
    "imu": {
        "gyro_bias_deg_per_h": 0.01,
        "accel_bias_micro_g": 50.0,
        "gyro_noise_deg_per_h_per_sqrt_hz": 0.1,
        "accel_noise_micro_g_per_sqrt_hz": 10.0,
    },
    "dvl": {"scale": 0.9998, "misalignment_deg": [-0.1, 0.2, -0.5], "noise_m_s": 0.02},
}


def scenario_raw(base: str = SHORT, **tables: Any) -> dict[str, Any]:
    """A copy of the built-in scenario base's TOML dict with the tables changed (with_tables)."""
    return with_tables(load_scenario(base).raw, **tables)


def with_tables(base: dict[str, Any], **tables: Any) -> dict[str, Any]:
    """A copy of a scenario's TOML dict base with each keyword's table updated by its dict (rates={"dvl_hz":
    5.0}); a list (segments=[...]), a value, or a table the base lacks is set as given; None leaves the base's as
    it is."""
    raw = copy.deepcopy(base)
    for key, value in tables.items():
        if value is None:
            continue
        raw[key] = (
            {**raw[key], **value}
            if isinstance(value, dict) and key in raw
            else copy.deepcopy(value)
        )
    return raw


def simulate_variant(
    seed: int, base: str = SHORT, *, name: str = "custom", white_noise: bool = True, **tables: Any
) -> LogData:
    """scenario_raw(base, **tables) simulated with seed (the scenario named name)."""
    return simulate(
        scenario_from_dict(scenario_raw(base, **tables), name=name), seed, white_noise=white_noise
    )


def surface_dive_raw(segments: list[dict[str, Any]], **tables: Any) -> dict[str, Any]:
    """paper-3d-short's sensors on a dive from the surface: the origin at height 0 (the vehicle starts at the
    surface), the given segments, the default estimator configuration (as for a real log), the other tables
    (gnss=..., depth=...) as scenario_raw sets them."""
    raw = scenario_raw(SHORT, origin={"height_m": 0.0}, segments=segments, **tables)
    raw.pop("estimator_config", None)
    return raw


# the water dive's settings, for tests that check its pings against the model
WATER_DIVE: dict[str, Any] = {
    "seafloor_m": 30.0,
    "bottom_range_m": 20.0,  # lock from 10 m down
    "current": {
        "surface_m_s": [0.45, 0.1],
        "reference_m_s": [-0.1, 0.2],
        "reference_depth_m": 15.0,
        "variation_m_s": [0.05, -0.03],
        "variation_period_s": 80.0,
    },
    "lever_m": np.array([0.6, 0.1, -0.3]),
    "misalignment_deg": (0.3, -0.2, 0.5),  # roll, pitch, yaw of R_c
    "scale": 1.002,
}


def water_dive_raw(noise_model: str = "velocity", **dvl: Any) -> dict[str, Any]:
    """A dive from the surface to 18.3 m and back in 110 s (2 Hz DVL, z-down mounting with a lever arm; WATER_DIVE)
    in a sheared, varying current over a seafloor 30 m down: water track to 10 m, bottom lock below, water track
    again. dvl: [dvl] keys set over these."""
    w = WATER_DIVE
    raw = surface_dive_raw(
        [
            {"kind": "level", "duration_s": 10.0, "speed_end_m_s": 1.5},
            {"kind": "descent", "duration_s": 40.0, "peak_vertical_speed_m_s": 1.0},
            {"kind": "turn", "duration_s": 20.0, "heading_change_deg": 90.0, "bank_deg": 10.0},
            {"kind": "ascent", "duration_s": 40.0, "peak_vertical_speed_m_s": 1.0},
        ],
        rates={"dvl_hz": 2.0},
        mounting={"dvl_rpy_deg": [180.0, 0.0, 0.0], "dvl_lever_arm_m": w["lever_m"].tolist()},
    )
    raw["initial"]["speed_m_s"] = 0.5
    raw["dvl"].update(
        face_axis=[0.0, 0.0, 1.0],
        scale=w["scale"],
        misalignment_deg=list(w["misalignment_deg"]),
        bottom_range_m=w["bottom_range_m"],
        noise_model=noise_model,
        **dvl,
    )
    raw["seafloor"] = {"depth_m": w["seafloor_m"]}
    raw["current"] = copy.deepcopy(w["current"])
    return raw
