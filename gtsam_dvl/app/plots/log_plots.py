"""The paper's Figures 1-3 for one log: trajectory, DVL outputs, IMU outputs."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from gtsam_dvl.app.plots.common import save_figure, shade_segments
from gtsam_dvl.core.types import LogData


def plot_trajectory(log: LogData, path: Path, n_p: np.ndarray | None = None, label: str = "truth") -> Path:
    """Figure 1: the 3-D trajectory in the map frame (truth, or a given estimate)."""
    if n_p is None:
        if log.truth is None:
            raise ValueError("no trajectory: the log has no truth and no estimate was given")
        n_p = log.truth.n_p
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    ax.plot(n_p[:, 0], n_p[:, 1], n_p[:, 2], lw=1.2, label=label)
    ax.scatter(*n_p[0], color="green", s=20, label="start")
    ax.scatter(*n_p[-1], color="red", s=20, label="end")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_zlabel("up (m)")
    ax.set_title(f"Trajectory in map ({log.metadata.get('scenario_name', Path(log.source).name)})")
    ax.legend(loc="upper left", fontsize=8)
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
    axes[0].set_title("DVL output in dvl_link (shaded: Type-I blue, Type-II orange)")
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
        for j, (data, unit, title) in enumerate([
            (np.degrees(imu.b_omega[::step, i]), "deg/s", "gyro"),
            (imu.b_f[::step, i], "m/s^2", "accelerometer"),
        ]):
            ax = axes[i, j]
            shade_segments(ax, segments)
            ax.plot(t, data, lw=0.8)
            ax.set_ylabel(f"{title} {name} ({unit})")
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    axes[0, 0].set_title("Gyro output in imu_link")
    axes[0, 1].set_title("Specific force in imu_link")
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
