"""Attitude and position errors against the truth with the estimator's 3-sigma (the paper's Figures 10,
11, 15 and 16), several estimators overlaid."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from gtsam_dvl.app.plots.common import save_figure, segment_legend, shade_segments
from gtsam_dvl.core.types import Segment


def plot_errors(
    runs: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
    path: Path,
    what: str,
    segments: list[Segment] | None = None,
) -> Path:
    """runs: (label, t, error (N,3), sigma (N,3)); what: "attitude" (deg, about east/north/up), "velocity"
    (m/s) or "position" (m, east/north/up)."""
    names = (
        ["about east (roll-like)", "about north (pitch-like)", "about up (heading)"]
        if what == "attitude"
        else ["east", "north", "up"]
    )
    unit = {"attitude": "deg", "velocity": "m/s", "position": "m"}[what]
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    t_conv = converged_from(runs) if what == "attitude" else None
    for j, ax in enumerate(axes):
        if segments:
            shade_segments(ax, segments, label=(j == 0))
        top = 0.0
        for k, (label, t, err, sig) in enumerate(runs):
            c = colours[k % len(colours)]
            ax.plot(t, err[:, j], color=c, lw=1.0, label=f"{label} error")
            ax.plot(t, 3 * sig[:, j], color=c, lw=0.8, ls="--", label=f"{label} +-3 sigma")
            ax.plot(t, -3 * sig[:, j], color=c, lw=0.8, ls="--")
            if t_conv is not None:
                sel = t >= t_conv
                if sel.any():
                    top = max(
                        top,
                        float(np.nanmax(np.abs(err[sel, j]))),
                        float(np.nanmax(3 * sig[sel, j])),
                    )
        if t_conv is not None and top > 0:
            # the converged errors visible; the first minutes go off scale
            ax.set_ylim(-1.25 * top, 1.25 * top)
        ax.set_ylabel(f"{names[j]} ({unit})")
        ax.grid(alpha=0.3)
    if segments:
        segment_legend(axes[0], segments, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    else:
        axes[0].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[-1].set_xlabel("time (s)")
    zoom = (
        f"\n(y zoomed on the errors from {t_conv:.0f} s on; the alignment transient before it is off scale)"
        if t_conv is not None
        else ""
    )
    fig.suptitle(
        f"{what.capitalize()} error against the truth, with the estimator's 3 sigma{zoom}",
        fontsize=11,
    )
    return save_figure(fig, path)


def converged_from(runs: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]) -> float:
    """The time from which the attitude errors are drawn to scale: when every run's 3-sigma of every axis has
    fallen below a quarter of its initial value (heading by gyrocompassing takes minutes), else a tenth of the
    run."""
    t_from = 0.0
    for _, t, _, sig in runs:
        if not len(t):
            continue
        start = np.maximum(sig[0], 1e-12)
        done = np.all(sig <= 0.25 * start, axis=1)
        t_from = max(
            t_from, float(t[np.argmax(done)]) if done.any() else float(t[0] + 0.1 * (t[-1] - t[0]))
        )
    return t_from
