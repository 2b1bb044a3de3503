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
    imu_hz = 1.0 / np.median(np.diff(imu.t))
    lines = [f"{log_path}",
             f"  duration {imu.t[-1] - imu.t[0]:.1f} s, IMU {len(imu)} msgs ({imu_hz:.1f} Hz), "
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


@dataclass
class SmoothOutcome:
    summary: dict
    written: list[Path]

    def describe(self) -> str:
        s = self.summary
        mis, mis_sig = s["misalignment_deg"]["value"], s["misalignment_deg"]["sigma"]
        lines = [
            f"{s['estimator']}: {s['states']} states over {s['duration_s']:.0f} s, "
            f"{s['timing_s'].get('total', float('nan')):.2f} s wall",
            f"  scale        {s['scale']['value']:.6f} +- {s['scale']['sigma']:.6f}",
            "  misalignment roll/pitch/yaw "
            + ", ".join(f"{v:+.3f} +- {e:.3f}" for v, e in zip(mis, mis_sig, strict=True)) + " deg",
            "  gyro bias    " + ", ".join(f"{v:+.4f}" for v in s["gyro_bias_deg_per_h"]["value"]) + " deg/h",
            "  accel bias   " + ", ".join(f"{v:+.1f}" for v in s["accel_bias_ug"]["value"]) + " micro-g",
        ]
        err = s.get("errors")
        if err:
            lines.append(f"  vs truth: scale {err.get('scale_ppm', float('nan')):+.0f} ppm, misalignment "
                         + ", ".join(f"{v:+.3f}" for v in err.get("misalignment_deg", [])) + " deg, final horizontal "
                         f"position {err['final_horizontal_position_m']:.2f} m "
                         f"({err['final_horizontal_position_pct_distance']:.3f} % of distance)")
        lines += [f"  wrote {p}" for p in self.written]
        return "\n".join(lines)


def smooth_file(log_path: Path, output: Path | None = None, mode: str = "batch", summary_path: Path | None = None,
                tum_path: Path | None = None, config_path: Path | None = None, show_progress: bool = True,
                salvage: bool = False) -> SmoothOutcome:
    """Run one estimator on a log and write its results (MCAP, summary JSON, TUM)."""
    from gtsam_dvl.atomic import atomic_write_json, write_tum
    from gtsam_dvl.batch import smooth_batch
    from gtsam_dvl.config import EstimatorConfig
    from gtsam_dvl.evaluation import summary
    from gtsam_dvl.rotations import matrix_to_quat_xyzw

    config = EstimatorConfig.from_toml(config_path) if config_path else EstimatorConfig()
    t_read = time.perf_counter()
    log = load_log(log_path, salvage=salvage)
    read_s = time.perf_counter() - t_read
    if mode != "batch":
        raise GtsamDvlError(f"unknown mode '{mode}' (available: batch)")
    with progress_bar(f"{mode} smoothing {Path(log_path).name}", enabled=show_progress) as progress:
        result = smooth_batch(log, config, progress=progress)
    result.timing_s["read"] = read_s
    summ = summary(result, log)
    written: list[Path] = []
    if output is not None:
        from gtsam_dvl.io.results import write_result_log

        written.append(write_result_log(output, result, log, summ))
    if summary_path is not None:
        written.append(atomic_write_json(summary_path, summ))
    if tum_path is not None:
        written.append(write_tum(tum_path, log.t0_ns * 1e-9 + result.t, result.n_p, matrix_to_quat_xyzw(result.n_R_b)))
    return SmoothOutcome(summ, written)


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
