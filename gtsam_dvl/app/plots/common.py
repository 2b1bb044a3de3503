"""Shared figure helpers: headless backend, segment shading, atomic PNG writes."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: figures are files, never windows
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from gtsam_dvl.core.types import Segment  # noqa: E402

SEGMENT_COLOURS = {"I": "#d8e8f8", "II": "#f8e4d0", "I+II": "#f2f2d0", "-": "#ffffff"}


def shade_segments(ax: Any, segments: list[Segment], label: bool = False) -> None:
    """Shade the paper's Type-I / Type-II segments behind a time plot and mark their boundaries (labels
    thinned so that neighbours closer than 4 % of the span do not overprint)."""
    span = (segments[-1].end_s - segments[0].start_s) if segments else 1.0
    last_label = -float("inf")
    for seg in segments:
        colour = SEGMENT_COLOURS.get(seg.type, "#ffffff")
        if colour != "#ffffff":
            ax.axvspan(seg.start_s, seg.end_s, color=colour, zorder=0, lw=0)
        ax.axvline(seg.start_s, color="0.75", lw=0.6, zorder=1)
        if label and seg.start_s - last_label >= 0.04 * span:
            last_label = seg.start_s
            ax.text(seg.start_s, 1.0, f" {seg.start_s:.0f}", transform=ax.get_xaxis_transform(),
                    fontsize=7, va="bottom", color="0.4")


def save_figure(fig: Figure, path: Path) -> Path:
    """Write a PNG atomically (temporary file then rename) and close the figure."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    os.replace(tmp, path)
    return path
