"""Scenario variants for the tests: a built-in scenario (by default paper-3d-short: the paper's sensors, 120 s
static, 60 s legs) with some of its tables changed, simulated with a seed; and dives that start and end at the
surface, for the GNSS tests."""

from __future__ import annotations

import copy
from typing import Any

from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

SHORT = "paper-3d-short"


def scenario_raw(base: str = SHORT, **tables: Any) -> dict[str, Any]:
    """A copy of the built-in scenario base's TOML dict with each keyword's table updated by its dict
    (rates={"dvl_hz": 5.0}); a list (segments=[...]), a value, or a table the base lacks is set as given; None
    leaves the base's as it is."""
    raw = copy.deepcopy(load_scenario(base).raw)
    for key, value in tables.items():
        if value is None:
            continue
        raw[key] = {**raw[key], **value} if isinstance(value, dict) and key in raw else copy.deepcopy(value)
    return raw


def simulate_variant(seed: int, base: str = SHORT, *, name: str = "custom", white_noise: bool = True,
                     **tables: Any) -> LogData:
    """scenario_raw(base, **tables) simulated with seed (the scenario named name)."""
    return simulate(scenario_from_dict(scenario_raw(base, **tables), name=name), seed, white_noise=white_noise)


def surface_dive_raw(segments: list[dict[str, Any]], **tables: Any) -> dict[str, Any]:
    """paper-3d-short's sensors on a dive from the surface: the origin at height 0 (the vehicle starts at the
    surface), the given segments, the default estimator configuration (as for a real log), the other tables
    (gnss=..., depth=...) as scenario_raw sets them."""
    raw = scenario_raw(SHORT, origin={"height_m": 0.0}, segments=segments, **tables)
    raw.pop("estimator_config", None)
    return raw
