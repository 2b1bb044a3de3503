"""The water current of a simulated log (the [current] table of a scenario), in the map frame (ENU at the
origin), horizontal, m/s: a sheared profile in depth plus a slow, depth-uniform variation (a tide moves the whole
water column, so its part of the current does not shear):

    n_c(d, t) = c_s + (c_r - c_s) * clip(d / d_r, 0, 1) + c_v * sin(2 pi t / T_v)

d the depth below the water surface (m, positive down; the surface is at ellipsoidal height 0, as for the
pressure sensor), c_s = surface_m_s at and above the surface, c_r = reference_m_s at and below
reference_depth_m = d_r (linear in depth between them: a vector interpolation, so the current turns as well
as weakens when the two differ in direction), c_v = variation_m_s, T_v = variation_period_s (default the M2
tide's 12.42 h). Vectors are [east, north]; the vertical component is 0.

The simulator (sim/current.py, sim/dvl.py) and the reader (the truth of a simulated log read back) share it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.core.earth import LocalFrame

M2_PERIOD_S = 44714.0  # the principal lunar semidiurnal tide, 12.42 h


@dataclass(frozen=True)
class CurrentSpec:
    """The [current] table (module doc): [east, north] vectors in m/s, depths in m, period in s."""

    surface_m_s: tuple[float, float] = (0.0, 0.0)
    reference_m_s: tuple[float, float] = (0.0, 0.0)
    reference_depth_m: float = 100.0
    variation_m_s: tuple[float, float] = (0.0, 0.0)
    variation_period_s: float = M2_PERIOD_S

    def at(self, depth_m: np.ndarray, t: np.ndarray) -> np.ndarray:
        """n_c (K, 3) m/s in map at depths depth_m (K,) m (positive down) and times t (K,) s."""
        d = np.asarray(depth_m, dtype=float)
        w = np.clip(d / self.reference_depth_m, 0.0, 1.0)[:, None]
        c_s, c_r = np.asarray(self.surface_m_s), np.asarray(self.reference_m_s)
        tide = np.sin(2.0 * np.pi * np.asarray(t, dtype=float) / self.variation_period_s)[:, None]
        horizontal = c_s + (c_r - c_s) * w + np.asarray(self.variation_m_s) * tide
        return np.concatenate([horizontal, np.zeros((len(d), 1))], axis=1)


def truth_current(metadata: dict[str, Any], t: np.ndarray, n_p: np.ndarray) -> np.ndarray | None:
    """TruthData.n_c (K, 3) of a simulated log read back from its file: the current the metadata's truth records
    ("current", the [current] table) at the truth's times t (K,) and positions n_p (K, 3) in the truth's map
    (metadata truth "map_origin" when the origin came from the first GNSS fix, else the scenario's origin);
    None when the log records no current."""
    truth = metadata.get("truth") or {}
    if not isinstance(truth, dict) or not truth.get("current"):
        return None
    values: dict[str, Any] = {
        k: tuple(v) if isinstance(v, list) else v for k, v in truth["current"].items()
    }
    spec = CurrentSpec(**values)
    o = (metadata.get("scenario") or {}).get("origin") or metadata.get("origin")
    if not o:
        return None
    frame = LocalFrame(float(o["lat_deg"]), float(o["lon_deg"]), float(o.get("height_m", 0.0)))
    m = truth.get("map_origin")
    truth_frame = (
        frame
        if not m
        else LocalFrame(float(m["lat_deg"]), float(m["lon_deg"]), float(m["height_m"]))
    )
    _, _, h = truth_frame.map_to_geodetic(n_p)
    n_c = spec.at(-np.asarray(h), t)
    return n_c if not m else n_c @ (truth_frame.e_R_n.T @ frame.e_R_n).T
