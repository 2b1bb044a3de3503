"""What the commands do, as plain functions returning typed results (the CLI only prints them)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gtsam_dvl.errors import GtsamDvlError
from gtsam_dvl.progress import progress_bar
from gtsam_dvl.types import LogData


@dataclass
class SimulateResult:
    path: Path
    scenario: str
    seed: int
    duration_s: float
    n_imu: int
    n_dvl: int
    distance_m: float
    wall_s: float

    def describe(self) -> str:
        return (f"{self.path}: {self.scenario} seed {self.seed}, {self.duration_s:.0f} s, {self.n_imu} IMU and "
                f"{self.n_dvl} DVL messages, {self.distance_m / 1000:.2f} km travelled ({self.wall_s:.1f} s)")


def distance_travelled(n_p: np.ndarray) -> float:
    """Path length in metres of a sampled trajectory (m)."""
    return float(np.linalg.norm(np.diff(n_p, axis=0), axis=1).sum()) if len(n_p) > 1 else 0.0


def simulate_to_file(scenario: str | Path, output: Path, seed: int = 7, white_noise: bool = True,
                     show_progress: bool = True) -> SimulateResult:
    """Simulate a built-in or TOML scenario and write it as a ROS 2 MCAP log."""
    from gtsam_dvl.io.writer import write_log
    from gtsam_dvl.scenario import load_scenario
    from gtsam_dvl.sim import simulate

    start = time.perf_counter()
    scen = load_scenario(scenario)
    with progress_bar(f"simulating {scen.name}", enabled=show_progress) as progress:
        log = simulate(scen, seed, white_noise=white_noise, progress=progress)
    write_log(output, log)
    truth_p = log.truth.n_p if log.truth is not None else np.zeros((0, 3))
    return SimulateResult(Path(output), scen.name, seed, float(log.imu.t[-1]), len(log.imu), len(log.dvl),
                          distance_travelled(truth_p), time.perf_counter() - start)


def load_log(path: Path | str, **options: object) -> LogData:
    """Read a log (MCAP file or rosbag2 directory) with the project reader."""
    from gtsam_dvl.io.reader import read_log

    if not Path(path).exists():
        raise GtsamDvlError(f"{path}: no such file or directory")
    return read_log(path, **options)  # type: ignore[arg-type]


def plot_log_to_dir(log_path: Path, out_dir: Path) -> list[Path]:
    """Figures 1-3 of a log."""
    from gtsam_dvl.plots.log_plots import plot_log

    return plot_log(load_log(log_path), Path(out_dir))


def describe_log(log_path: Path) -> str:
    """A few lines about a log: what a navigator wants to know before processing it."""
    log = load_log(log_path)
    imu, dvl = log.imu, log.dvl
    lines = [f"{log_path}",
             f"  duration {imu.t[-1] - imu.t[0]:.1f} s, IMU {len(imu)} msgs ({1.0 / np.median(np.diff(imu.t)):.1f} Hz), "
             f"DVL {len(dvl)} msgs ({int(dvl.valid.sum())} valid 3-D)"]
    if dvl.beams is not None:
        lines.append(f"  DVL beams: {dvl.beams.v.shape[1]}, valid beam measurements {int(dvl.beams.valid.sum())}")
    lines.append(f"  lever arm IMU->DVL in base_link: {np.round(log.mounting.b_l, 4).tolist()} m")
    cal = log.true_calibration
    if cal is not None:
        lines.append(f"  truth: scale {cal.scale}, misalignment [roll, pitch, yaw] {list(cal.misalignment_deg)} deg")
    for warning in log.metadata.get("reader_warnings", []):
        lines.append(f"  warning: {warning}")
    return "\n".join(lines)


def run_demo(out_dir: Path, seed: int = 7) -> None:
    """Simulate paper-3d and paper-2d and plot their logs (later steps add the estimators)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    for name in ("paper-3d", "paper-2d"):
        log_path = out_dir / f"{name}.mcap"
        result = simulate_to_file(name, log_path, seed=seed)
        print(result.describe())
        for fig in plot_log_to_dir(log_path, out_dir / name / "figures"):
            print(f"  wrote {fig}")
