"""The water current over time and depth (NavResult.water_current, estimators/models/current.py), with its
3-sigma band and, for a simulated log, the truth."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from gtsam_dvl.app.plots.common import save_figure
from gtsam_dvl.core.result import WaterCurrentProfile


def plot_current(
    profile: WaterCurrentProfile,
    path: Path,
    truth_t: np.ndarray | None = None,
    truth_n_c: np.ndarray | None = None,
    label: str = "estimate",
) -> Path:
    """Three panels: east and north current (m/s) over time with +-3 sigma, the water-track states shaded where
    known, and the current against depth (determined states only, speed and direction as east/north)."""
    t = np.asarray(profile.t_s, dtype=float)
    c = np.stack([profile.east_m_s, profile.north_m_s], axis=1)
    sig = np.stack([profile.east_sigma_m_s, profile.north_sigma_m_s], axis=1)
    depth = np.asarray(profile.depth_m, dtype=float)
    det = np.asarray(profile.determined, dtype=bool)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), gridspec_kw={"width_ratios": [2, 2, 1.2]})
    for a, (ax, name) in enumerate(zip(axes[:2], ("east", "north"), strict=True)):
        ax.plot(t, c[:, a], lw=1.1, color="C0", label=label)
        ax.fill_between(
            t,
            c[:, a] - 3 * sig[:, a],
            c[:, a] + 3 * sig[:, a],
            color="C0",
            alpha=0.15,
            lw=0,
            label="+-3 sigma",
        )
        if truth_t is not None and truth_n_c is not None:
            ax.plot(truth_t, truth_n_c[:, a], lw=1.0, color="k", ls="--", label="truth")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"current {name} (m/s, map)")
        # (an undetermined stretch's band would flatten the rest)
        band = 3 * np.minimum(sig[:, a], 0.3)
        ax.set_ylim(np.nanmin(c[:, a] - band) - 0.05, np.nanmax(c[:, a] + band) + 0.05)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    ax = axes[2]
    ax.plot(c[det, 0], depth[det], ".", ms=2, color="C1", label="east")
    ax.plot(c[det, 1], depth[det], ".", ms=2, color="C2", label="north")
    if truth_t is not None and truth_n_c is not None:
        k = np.clip(np.searchsorted(truth_t, t), 0, len(truth_t) - 1)
        ax.plot(truth_n_c[k[det], 0], depth[det], lw=0.8, color="C1", alpha=0.5, ls="--")
        ax.plot(truth_n_c[k[det], 1], depth[det], lw=0.8, color="C2", alpha=0.5, ls="--")
    ax.invert_yaxis()
    ax.set_xlabel("current (m/s)")
    ax.set_ylabel("depth (m)")
    ax.set_title("where determined", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"Water current: {profile.verdict}", fontsize=9)
    fig.tight_layout()
    return save_figure(fig, path)
