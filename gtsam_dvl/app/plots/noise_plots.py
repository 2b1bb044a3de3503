"""The Allan deviation figure of `gtsam-dvl characterise` (app/characterise.py): per IMU axis the measured curve,
with the configured white-noise density and the quantisation floor drawn as sigma(tau) = N / sqrt(tau)."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence

import numpy as np

from gtsam_dvl.app.plots.common import plt
from gtsam_dvl.core.sensor_noise import AllanCurve

AXIS_COLOURS = {"x": "tab:blue", "y": "tab:orange", "z": "tab:green"}
UNITS = {"gyro": ("deg/h", "deg/h/sqrt(Hz)"), "accel": ("micro-g", "micro-g/sqrt(Hz)")}


def allan_png(
    curves: Sequence[AllanCurve],
    configured: Mapping[str, float],
    floors: Mapping[str, Sequence[float | None]],
    title: str,
) -> bytes:
    """The figure as PNG bytes (written with the command's other outputs, all or none): one panel per sensor
    (gyro in deg/h, accelerometer in micro-g), log-log; configured: the configured white density per sensor
    (dashed black line); floors: the quantisation floor's density per axis (dotted: in the axis' colour, grey for
    a floor the axes share; None: the axis is not quantised)."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    for ax, sensor in zip(axes, ("gyro", "accel"), strict=True):
        unit, density_unit = UNITS[sensor]
        mine = [c for c in curves if c.sensor == sensor]
        taus = np.concatenate([c.taus for c in mine]) if mine else np.array([0.01, 1.0])
        span = np.geomspace(max(float(taus.min()), 1e-6), max(float(taus.max()), 1e-5), 50)
        for c in mine:
            pos = c.adev > 0
            label = f"{c.axis}" + (
                f" (white {c.white_density:.3g})" if c.white_density is not None else " (zero)"
            )
            ax.loglog(
                c.taus[pos],
                c.adev[pos],
                "o-",
                ms=2.5,
                lw=1.2,
                color=AXIS_COLOURS[c.axis],
                label=label,
            )
        n_cfg = float(configured[sensor])
        ax.loglog(
            span,
            n_cfg / np.sqrt(span),
            "k--",
            lw=1.0,
            label=f"configured {n_cfg:.3g} {density_unit}",
        )
        # one line per distinct floor (the axes of one sensor usually share their step), in the axis' colour
        drawn: list[tuple[float, list[str]]] = []
        for axis, floor in zip(("x", "y", "z"), floors[sensor], strict=True):
            if floor is None:
                continue
            same = next((d for d in drawn if abs(d[0] - floor) <= 1e-3 * floor), None)
            if same is None:
                drawn.append((floor, [axis]))
            else:
                same[1].append(axis)
        for floor, named in drawn:
            ax.loglog(
                span,
                floor / np.sqrt(span),
                ":",
                lw=1.5,
                color=AXIS_COLOURS[named[0]] if len(named) == 1 else "0.4",
                label=f"{', '.join(named)} quantisation floor {floor:.3g}",
            )
        ax.set_xlabel("averaging time tau, s")
        ax.set_ylabel(f"Allan deviation, {unit}")
        ax.set_title("gyro" if sensor == "gyro" else "accelerometer")
        ax.grid(True, which="both", lw=0.3, color="0.8")
        ax.legend(fontsize=7)
    fig.suptitle(title)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()
