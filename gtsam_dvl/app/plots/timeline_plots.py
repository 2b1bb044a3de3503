"""Calibration and bias estimates with sigmas over time (the paper's Figures 4-9) and normalised sigmas
(Figure 12), one or several estimators overlaid; the prior sigmas and accuracy targets that normalise them
(priors_for_plots, targets_for_plots)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from gtsam_dvl.app.plots.common import save_figure, segment_legend, shade_segments
from gtsam_dvl.core.result import Timeline
from gtsam_dvl.core.types import Segment

AXES3 = ("x", "y", "z")
MIS_AXES = ("roll (about x)", "pitch (about y)", "yaw (about z)")

# plot_estimates' quantities: the Timeline's value and sigma fields, the axes' titles, the figure's unit
ESTIMATE_SPEC: dict[str, tuple[str, str, list[str], str]] = {
    "scale": ("scale", "scale_sigma", ["DVL scale factor k"], "dimensionless"),
    "misalignment": ("misalignment_deg", "misalignment_sigma_deg", list(MIS_AXES), "deg"),
    "gyro_bias": (
        "gyro_bias_deg_per_h",
        "gyro_bias_sigma_deg_per_h",
        [f"gyro bias {a}" for a in AXES3],
        "deg/h",
    ),
    "accel_bias": (
        "accel_bias_ug",
        "accel_bias_sigma_ug",
        [f"accel bias {a}" for a in AXES3],
        "micro-g",
    ),
    "time_offset": ("time_offset_s", "time_offset_sigma_s", ["DVL time offset dt_d"], "ms"),
    "lever_arm": ("lever_arm_m", "lever_arm_sigma_m", [f"lever arm {a}" for a in AXES3], "m"),
}


def _band(
    ax: Any, t: np.ndarray, value: np.ndarray, sigma: np.ndarray, label: str, colour: str
) -> None:
    ax.plot(t, value, color=colour, lw=1.1, label=label)
    ax.fill_between(t, value - 3 * sigma, value + 3 * sigma, color=colour, alpha=0.15, lw=0)


def _final_estimate(
    ax: Any, t_sel: np.ndarray, value: np.ndarray, sigma: np.ndarray, label: str, colour: str
) -> None:
    """A smoother's timeline on one axis: the filtering band about the final estimate, and the final estimate."""
    # a smoother's timeline: its sigmas are filtering sigmas (the data up to t), its value the final
    # estimate only; the filtering band is drawn about the final estimate (dashed: not an estimate at
    # t), and the final estimate with its smoothed sigma is a marker at the end
    ax.plot(t_sel, value, color=colour, lw=0.9, ls="--")
    ax.fill_between(
        t_sel,
        value - 3 * sigma,
        value + 3 * sigma,
        color=colour,
        alpha=0.15,
        lw=0,
        label=f"{label}: filtering +-3 sigma (data up to t) about the final estimate",
    )
    ax.errorbar(
        [t_sel[-1]],
        [value[-1]],
        yerr=[3 * sigma[-1]],
        fmt="D",
        color=colour,
        ms=5,
        capsize=4,
        label=f"{label}: final estimate +-3 sigma",
        zorder=4,
    )


def _estimate_row(
    ax: Any,
    timelines: list[tuple[str, Timeline]],
    row: int,
    value_name: str,
    sigma_name: str,
    to_unit: float,
    t_min: float,
    colours: list[str],
) -> tuple[float, float]:
    """One component of the quantity, every timeline on its axis from t_min. Returns the y range of the
    converged part (the second half: the band at the end, not the prior's width)."""
    lo, hi = np.inf, -np.inf
    for k, (label, tl) in enumerate(timelines):
        sel = tl.t >= t_min
        value = to_unit * np.asarray(getattr(tl, value_name)).reshape(len(tl.t), -1)[sel, row]
        sigma = to_unit * np.asarray(getattr(tl, sigma_name)).reshape(len(tl.t), -1)[sel, row]
        colour = colours[k % len(colours)]
        if len(value) and np.ptp(value) == 0.0:
            _final_estimate(ax, tl.t[sel], value, sigma, label, colour)
        else:
            _band(ax, tl.t[sel], value, sigma, f"{label} (+-3 sigma)", colour)
        tail = value[len(value) // 2 :], sigma[len(sigma) // 2 :]
        # zoom on the converged part: the band at the end, not the prior's width
        lo = min(lo, float(np.min(tail[0] - 4 * tail[1])))
        hi = max(hi, float(np.max(tail[0] + 4 * tail[1])))
    return lo, hi


def plot_estimates(
    timelines: list[tuple[str, Timeline]],
    path: Path,
    quantity: str,
    truth: np.ndarray | float | None = None,
    segments: list[Segment] | None = None,
    t_min: float = 0.0,
) -> Path:
    """One figure per quantity: "scale", "misalignment", "gyro_bias", "accel_bias", and when the timelines hold
    them "time_offset" (shown in ms; the truth given in s, as the Timeline holds it) and "lever_arm" (m);
    estimate +- 3 sigma."""
    value_name, sigma_name, titles, unit = ESTIMATE_SPEC[quantity]
    to_unit = 1e3 if quantity == "time_offset" else 1.0  # the Timeline's unit to the figure's
    n = len(titles)
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.6 * n + 0.6), sharex=True, squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    t_max = max(float(tl.t[-1]) for _, tl in timelines) if timelines else None
    for row, title in enumerate(titles):
        ax = axes[row, 0]
        if segments:
            shade_segments(ax, segments, label=(row == 0), t_min=t_min, t_max=t_max)
        lo, hi = _estimate_row(ax, timelines, row, value_name, sigma_name, to_unit, t_min, colours)
        if truth is not None:
            tv = to_unit * float(np.atleast_1d(truth)[row])
            ax.axhline(tv, color="k", ls="--", lw=0.9, label="truth")
            lo, hi = min(lo, tv), max(hi, tv)
        if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
            pad = 0.15 * (hi - lo)
            ax.set_ylim(lo - pad, hi + pad)
        ax.set_ylabel(f"{title}\n({unit})")
        ax.grid(alpha=0.3)
    if t_min > 0:
        axes[-1, 0].set_xlim(left=t_min)
    if segments:
        segment_legend(
            axes[0, 0], segments, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0)
        )
    else:
        axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    smoothed = all(
        len(tl.t) and np.ptp(np.asarray(getattr(tl, value_name))) == 0.0 for _, tl in timelines
    )
    what = (
        "final estimate and filtering 3-sigma band"
        if timelines and smoothed
        else "estimate and 3-sigma band"
    )
    fig.suptitle(
        f"{quantity.replace('_', ' ')} {what} over time\n(y zoomed on the converged part)",
        fontsize=11,
    )
    return save_figure(fig, path)


def _sigma_groups(
    axes: Any, timeline: Timeline, priors: dict[str, np.ndarray | float]
) -> list[tuple[Any, str, Any, Any, list[str]]]:
    """plot_normalised_sigmas' four panels: (axis, title, sigmas over time, prior sigmas, curve labels) of the
    attitude, the DVL scale and misalignment, the gyro bias and the accelerometer bias."""
    return [
        (
            axes[0, 0],
            "attitude (east, north, up)",
            timeline.attitude_sigma_deg,
            timeline.attitude_sigma_deg[0],
            ["east", "north", "up"],
        ),
        (
            axes[0, 1],
            "DVL scale and misalignment",
            np.column_stack([timeline.scale_sigma, timeline.misalignment_sigma_deg]),
            np.concatenate([[priors["scale"]], np.atleast_1d(priors["misalignment_deg"])]),
            ["scale", *MIS_AXES],
        ),
        (
            axes[1, 0],
            "gyro bias",
            timeline.gyro_bias_sigma_deg_per_h,
            priors["gyro_bias_deg_per_h"],
            list(AXES3),
        ),
        (
            axes[1, 1],
            "accelerometer bias",
            timeline.accel_bias_sigma_ug,
            priors["accel_bias_ug"],
            list(AXES3),
        ),
    ]


def _group_targets(
    targets: dict[str, np.ndarray | float] | None,
) -> list[np.ndarray | None]:
    """The accuracy targets per panel of _sigma_groups (None: none; the attitude has none)."""
    target_of: list[np.ndarray | None] = [None, None, None, None]
    if targets is not None:
        target_of[1:] = [
            np.concatenate([[targets["scale"]], np.broadcast_to(targets["misalignment_deg"], 3)]),
            np.broadcast_to(targets["gyro_bias_deg_per_h"], 3),
            np.broadcast_to(targets["accel_bias_ug"], 3),
        ]
    return target_of


def _target_lines(ax: Any, target_ratio: np.ndarray, curves: list[Any]) -> None:
    """The targets as dashed lines at target / prior: one grey line when the panel's curves share one, else one
    of each curve's colour."""
    if np.allclose(target_ratio, target_ratio[0]):  # one target for the group
        ax.axhline(target_ratio[0], color="0.2", ls="--", lw=0.9, label="target")
    else:
        for j, curve in enumerate(curves):
            ax.axhline(
                target_ratio[j],
                color=curve.get_color(),
                ls="--",
                lw=0.9,
                label="targets (dashed)" if j == len(curves) - 1 else None,
            )


def plot_normalised_sigmas(
    timeline: Timeline,
    path: Path,
    priors: dict[str, np.ndarray | float],
    segments: list[Segment] | None = None,
    title: str = "",
    targets: dict[str, np.ndarray | float] | None = None,
) -> Path:
    """Figure 12: sigma(t) / sigma(prior) of attitude, biases, scale and misalignment, log scale. targets (the
    units and keys of priors): the accuracy each state is judged against, drawn as a dashed line of its curve's
    colour at target / prior (below it: "determined")."""
    fig, axes = plt.subplots(2, 2, figsize=(12, 7), sharex=True)
    groups = _sigma_groups(axes, timeline, priors)
    target_of = _group_targets(targets)
    for k, (ax, name, sig, p0, labels) in enumerate(groups):
        if segments:
            shade_segments(ax, segments, label=(k < 2))
        ratio = np.asarray(sig) / np.asarray(p0, dtype=float)
        target = target_of[k]
        target_ratio = (
            np.asarray(target, dtype=float)
            / np.broadcast_to(np.asarray(p0, dtype=float), len(labels))
            if target is not None
            else None
        )
        curves = [
            ax.semilogy(timeline.t, ratio[:, j], lw=1.2, label=lab)[0]
            for j, lab in enumerate(labels)
        ]
        if target_ratio is not None:
            _target_lines(ax, target_ratio, curves)
        ax.set_title(name, fontsize=10)
        ax.set_ylabel("sigma / initial sigma (ratio)")
        ax.grid(alpha=0.3, which="both")
        if segments and k == 0:
            segment_legend(ax, segments, fontsize=7, loc="lower left")
        else:
            ax.legend(fontsize=8, loc="lower left")
    for ax in axes[1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(title or "Normalised standard deviations (the paper's Figure 12)")
    return save_figure(fig, path)


def priors_for_plots(config_dict: dict[str, Any]) -> dict[str, Any]:
    """Prior sigmas in the units of Timeline, for normalised-sigma figures."""
    from gtsam_dvl.core.config import EstimatorConfig

    cfg = EstimatorConfig.from_dict(config_dict) if config_dict else EstimatorConfig()
    return {
        "scale": cfg.priors.scale_sigma,
        "misalignment_deg": np.array(cfg.priors.misalignment_sigma_deg),
        "gyro_bias_deg_per_h": np.full(3, cfg.imu.gyro_bias_sigma_deg_per_h),
        "accel_bias_ug": np.full(3, cfg.imu.accel_bias_sigma_ug),
    }


def targets_for_plots(config_dict: dict[str, Any]) -> dict[str, Any]:
    """The [observability] accuracy targets in the units and keys of priors_for_plots (the scale as a fraction)."""
    from gtsam_dvl.core.config import EstimatorConfig

    obs = (
        EstimatorConfig.from_dict(config_dict) if config_dict else EstimatorConfig()
    ).observability
    return {
        "scale": obs.scale_ppm * 1e-6,
        "misalignment_deg": obs.misalignment_deg,
        "gyro_bias_deg_per_h": obs.gyro_bias_deg_per_h,
        "accel_bias_ug": obs.accel_bias_ug,
    }
