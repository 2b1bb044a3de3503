"""The paper's Figures 1-3 for one log: trajectory, DVL outputs, IMU outputs."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from gtsam_dvl.app.plots.common import save_figure, segment_legend, shade_segments
from gtsam_dvl.core.types import LogData


def plot_trajectory(
    log: LogData, path: Path, n_p: np.ndarray | None = None, label: str = "truth"
) -> Path:
    """Figure 1: the trajectory in the map frame (truth, or a given estimate): a plan view with equal axes and
    the 3-D view, whose vertical axis is stretched at most 5 times the horizontal (a planar run stays flat)."""
    if n_p is None:
        if log.truth is None:
            raise ValueError("no trajectory: the log has no truth and no estimate was given")
        n_p = log.truth.n_p
    fig = plt.figure(figsize=(12, 5.5))
    plan = fig.add_subplot(1, 2, 1)
    plan.plot(n_p[:, 0], n_p[:, 1], lw=1.2, label=label)
    plan.scatter(n_p[0, 0], n_p[0, 1], color="green", s=20, label="start", zorder=3)
    plan.scatter(n_p[-1, 0], n_p[-1, 1], color="red", s=20, label="end", zorder=3)
    plan.set_aspect("equal", adjustable="datalim")
    plan.set_xlabel("east (m)")
    plan.set_ylabel("north (m)")
    plan.set_title("plan view (equal axes)")
    plan.grid(alpha=0.3)
    plan.legend(loc="best", fontsize=8)
    ax = fig.add_subplot(1, 2, 2, projection="3d")
    ax.plot(n_p[:, 0], n_p[:, 1], n_p[:, 2], lw=1.2)
    ax.scatter(*n_p[0], color="green", s=20)
    ax.scatter(*n_p[-1], color="red", s=20)
    ranges = np.ptp(n_p, axis=0)
    horizontal = max(float(ranges[0]), float(ranges[1]), 1.0)
    vertical = float(ranges[2])
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_zlabel("up (m)")
    from matplotlib.ticker import MaxNLocator

    ax.zaxis.set_major_locator(MaxNLocator(3))  # a flat box has room for few vertical ticks
    if vertical < 0.02 * horizontal / 5.0:
        # a planar run: a vertical axis of a tenth of the horizontal span at true scale, not its millimetres
        # stretched into a wall
        mid = float(np.mean(n_p[:, 2]))
        ax.set_zlim(mid - 0.05 * horizontal, mid + 0.05 * horizontal)
        ax.set_box_aspect((float(ranges[0]) or 1.0, float(ranges[1]) or 1.0, 0.1 * horizontal))
        ax.set_title("3-D view (true scale; the run is level)")
    else:
        ax.set_box_aspect(
            (float(ranges[0]) or 1.0, float(ranges[1]) or 1.0, min(vertical * 5.0, horizontal))
        )
        stretch = min(vertical * 5.0, horizontal) / vertical
        ax.set_title(
            f"3-D view (vertical stretched x{stretch:.1f})"
            if stretch > 1.01
            else "3-D view (true scale)"
        )
    fig.suptitle(
        f"Trajectory in map ({log.metadata.get('scenario_name', Path(log.source).name)}), {label}"
    )
    return save_figure(fig, path)


def plot_dvl(log: LogData, path: Path) -> Path:
    """Figure 2: DVL velocity output (dvl_link) over time, segments shaded."""
    dvl = log.dvl
    segments = log.segments
    fig, axes = plt.subplots(3, 1, figsize=(9, 6.5), sharex=True)
    for i, (ax, name) in enumerate(zip(axes, "xyz", strict=True)):
        shade_segments(ax, segments, label=(i == 0))
        ax.plot(dvl.t, dvl.d_v[:, i], lw=0.9)
        ax.set_ylabel(f"y_{name} (m/s)")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title("DVL output in dvl_link")
    segment_legend(axes[0], segments, fontsize=7, loc="lower right")
    return save_figure(fig, path)


def plot_imu(log: LogData, path: Path, decimate_to_hz: float = 10.0) -> Path:
    """Figure 3: gyro (deg/s) and accelerometer (m/s^2) outputs over time, segments shaded."""
    imu = log.imu
    dt = float(np.median(np.diff(imu.t))) if len(imu) > 1 else 1.0
    step = max(1, int(round(1.0 / (decimate_to_hz * dt))))
    t = imu.t[::step]
    segments = log.segments
    fig, axes = plt.subplots(3, 2, figsize=(12, 6.5), sharex=True)
    for i, name in enumerate("xyz"):
        for j, (data, unit, title) in enumerate(
            [
                (np.degrees(imu.b_omega[::step, i]), "deg/s", "gyro"),
                (imu.b_f[::step, i], "m/s^2", "accelerometer"),
            ]
        ):
            ax = axes[i, j]
            shade_segments(ax, segments, label=(i == 0))
            ax.plot(t, data, lw=0.8)
            ax.set_ylabel(f"{title} {name} ({unit})")
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    axes[0, 0].set_title("Gyro output in imu_link")
    axes[0, 1].set_title("Specific force in imu_link")
    if segments:
        segment_legend(axes[-1, 1], segments, fontsize=7, loc="lower right")
    return save_figure(fig, path)


def plot_log(log: LogData, out_dir: Path) -> list[Path]:
    """Figures 1-3 for a log into out_dir; Figure 1 only when the log holds truth."""
    out_dir = Path(out_dir)
    paths = []
    if log.truth is not None:
        paths.append(plot_trajectory(log, out_dir / "fig01_trajectory.png"))
    paths.append(plot_dvl(log, out_dir / "fig02_dvl_output.png"))
    paths.append(plot_imu(log, out_dir / "fig03_imu_output.png"))
    return paths
