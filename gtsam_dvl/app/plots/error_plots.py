"""Attitude and position errors against the truth with the estimator's 3-sigma (the paper's Figures 10,
11, 15 and 16), several estimators overlaid."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from gtsam_dvl.app.plots.common import save_figure, shade_segments
from gtsam_dvl.core.types import Segment


def plot_errors(runs: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], path: Path, what: str,
                segments: list[Segment] | None = None) -> Path:
    """runs: (label, t, error (N,3), sigma (N,3)); what: "attitude" (deg, about east/north/up), "velocity"
    (m/s) or "position" (m, east/north/up)."""
    names = ["about east (roll-like)", "about north (pitch-like)", "about up (heading)"] if what == "attitude" \
        else ["east", "north", "up"]
    unit = {"attitude": "deg", "velocity": "m/s", "position": "m"}[what]
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, ax in enumerate(axes):
        if segments:
            shade_segments(ax, segments, label=(j == 0))
        for k, (label, t, err, sig) in enumerate(runs):
            c = colours[k % len(colours)]
            ax.plot(t, err[:, j], color=c, lw=1.0, label=f"{label} error")
            ax.plot(t, 3 * sig[:, j], color=c, lw=0.8, ls="--", label=f"{label} +-3 sigma")
            ax.plot(t, -3 * sig[:, j], color=c, lw=0.8, ls="--")
        ax.set_ylabel(f"{names[j]} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper left", ncol=2)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(f"{what.capitalize()} error against the truth, with the estimator's 3 sigma")
    return save_figure(fig, path)
