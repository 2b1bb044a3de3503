"""The water around a simulated vehicle: the current (optional [current] table) and the seafloor (optional
[seafloor] table) that decides the DVL's bottom lock.

Current (core/current.py CurrentSpec: the profile and its formula): sheared in depth, with a slow depth-uniform
variation, in the map frame. The truth (TruthData.n_c) gives it at base_link's depth, and the DVL's water-track
pings see it at the same depth (sim/dvl.py).

Seafloor: flat, depth_m below the surface. The DVL is in bottom lock while its altitude (seafloor depth minus
the DVL's depth) is at most its bottom-track range ([dvl] bottom_range_m); beyond, it reports water track. A
scenario without [seafloor] keeps the DVL's older model: a seafloor [dvl] altitude_m below the start, and
beams lost one by one where their slant range exceeds [dvl] max_range_m, never water track.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from gtsam_dvl.core.current import CurrentSpec
from gtsam_dvl.sim.schema import Reader

__all__ = ["CurrentSpec", "SeafloorSpec", "current_spec", "seafloor_spec"]


@dataclass(frozen=True)
class SeafloorSpec:
    """The [seafloor] table: a flat seafloor depth_m below the water surface (module doc)."""

    depth_m: float


def _pair(r: Reader, key: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list) or len(value) != 2:
        raise r.fail(key, f"expected [east, north] in m/s, got {value!r}")
    e, n = (r.number(key, v) for v in value)
    return (e, n)


def current_spec(r: Reader) -> CurrentSpec:
    """The [current] table, checked."""
    d = r.raw["current"]
    if not isinstance(d, dict):
        raise r.fail("current", "expected a table")
    defaults = {k: v.default for k, v in CurrentSpec.__dataclass_fields__.items()}
    r.check_keys("current", list(defaults), d)
    values: dict[str, Any] = {}
    for key, default in defaults.items():
        if key not in d:
            values[key] = default
        elif isinstance(default, tuple):
            values[key] = _pair(r, f"current.{key}", d[key])
        else:
            values[key] = r.number(f"current.{key}", d[key])
    spec = CurrentSpec(**values)
    for key in ("reference_depth_m", "variation_period_s"):
        r.require(getattr(spec, key) > 0, f"current.{key}", "must be positive")
    return spec


def seafloor_spec(r: Reader) -> SeafloorSpec:
    """The [seafloor] table, checked."""
    spec = SeafloorSpec(**r.table("seafloor", {"depth_m": None}))
    r.require(spec.depth_m > 0, "seafloor.depth_m", "must be positive (metres below the surface)")
    return spec
