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

# Segment shading in greys and hatching, so that it never looks like an estimator's coloured band: Type I (a
# specific-force change at constant attitude) light grey, Type II (turns) hatched, I and II both.
SEGMENT_STYLE: dict[str, dict[str, Any]] = {
    "I": {"facecolor": "0.9", "hatch": None, "label": "Type I segment (specific-force change)"},
    "II": {"facecolor": "white", "hatch": "///", "label": "Type II segment (turns)"},
    "I+II": {"facecolor": "0.9", "hatch": "///", "label": "Type I and II segment"},
}


def shade_segments(
    ax: Any,
    segments: list[Segment],
    label: bool = False,
    t_min: float | None = None,
    t_max: float | None = None,
) -> None:
    """Shade the paper's Type-I / Type-II segments behind a time plot (segment_legend explains the shading)
    and mark every boundary inside [t_min, t_max] with a line; with label, each boundary's time is written
    vertically at the top inside the axes (clear of titles; vertical, so that boundaries 30 s apart do not
    overprint)."""
    for seg in segments:
        style = SEGMENT_STYLE.get(seg.type)
        if style is not None:
            ax.axvspan(
                seg.start_s,
                seg.end_s,
                facecolor=style["facecolor"],
                hatch=style["hatch"],
                edgecolor="0.75",
                lw=0,
                zorder=0,
            )
    bounds = sorted(
        {seg.start_s for seg in segments} | ({segments[-1].end_s} if segments else set())
    )
    shown = [
        b
        for b in bounds
        if not ((t_min is not None and b < t_min) or (t_max is not None and b > t_max))
    ]
    span = (shown[-1] - shown[0]) if len(shown) > 1 else 1.0
    previous, level = -float("inf"), 0
    for b in shown:
        ax.axvline(b, color="0.6", lw=0.6, zorder=1)
        if label:
            # a boundary within 2.5 % of the span of the previous one is written lower, so the two do not touch
            level = (level + 1) % 3 if b - previous < 0.025 * span else 0
            previous = b
            ax.text(
                b,
                0.98 - 0.17 * level,
                f"{b:.0f} ",
                transform=ax.get_xaxis_transform(),
                rotation=90,
                fontsize=7,
                va="top",
                ha="right",
                color="0.3",
                zorder=5,
            )


def segment_legend(ax: Any, segments: list[Segment], **kwargs: Any) -> None:
    """A legend on ax with its own handles plus the segment shading's (only the types present)."""
    from matplotlib.patches import Patch

    handles, labels = ax.get_legend_handles_labels()
    for kind in ("I", "II", "I+II"):
        if any(seg.type == kind for seg in segments):
            st = SEGMENT_STYLE[kind]
            handles.append(
                Patch(
                    facecolor=st["facecolor"], hatch=st["hatch"], edgecolor="0.6", label=st["label"]
                )
            )
            labels.append(st["label"])
    ax.legend(handles, labels, **kwargs)


def save_figure(fig: Figure, path: Path) -> Path:
    """Write a PNG atomically (temporary file then rename) and close the figure."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    os.replace(tmp, path)
    return path
