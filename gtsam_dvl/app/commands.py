"""What the commands do, as plain functions returning typed results (the CLI only prints them)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.analysis.metrics import path_length
from gtsam_dvl.app.outputs import check_outputs
from gtsam_dvl.app.progress import progress_bar
from gtsam_dvl.app.summary_lines import health_lines, summary_lines
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import StoredResult
from gtsam_dvl.core.summary import AnySummary, HealthSummary, IoDvlcSummary, parse_summary
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.run import (  # noqa: F401 - re-exported for the demo, tests, bench
    MODES,
    get_estimator,
    run_estimator,
    run_trajectory_estimator,
)

if TYPE_CHECKING:
    from gtsam_dvl.analysis.evaluate import Evaluation
    from gtsam_dvl.core.calibration import VehicleCalibration
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.core.result import NavResult
    from gtsam_dvl.io.atomic import OutputSet
    from gtsam_dvl.io.read_options import ReadOptions


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
        return (
            f"{self.path}: {self.scenario} seed {self.seed}, {self.duration_s:.0f} s, {self.n_imu} IMU and "
            f"{self.n_dvl} DVL messages, {self.distance_m / 1000:.2f} km travelled ({self.wall_s:.1f} s)"
        )


# IMU samples above which simulate_to_file simulates in chunks (sim/stream.py: the same file, in a memory that does
# not grow with the mission)
STREAM_ABOVE_SAMPLES = 720_000


def simulate_to_file(
    scenario: str | Path,
    output: Path,
    seed: int = 7,
    white_noise: bool = True,
    show_progress: bool = True,
) -> SimulateResult:
    """Simulate a built-in or TOML scenario and write it as a ROS 2 MCAP log (long ones chunk by chunk)."""
    from gtsam_dvl.io.writer import write_log
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    start = time.perf_counter()
    scen = load_scenario(scenario)
    if scen.duration_s * scen.rates.imu_hz > STREAM_ABOVE_SAMPLES:
        from gtsam_dvl.io.writer import write_log_stream
        from gtsam_dvl.sim.stream import ChunkedSimulation

        sim = ChunkedSimulation(scen, seed, white_noise=white_noise)
        with progress_bar(f"simulating {scen.name}", enabled=show_progress) as progress:
            res = write_log_stream(output, sim, progress=progress)
        return SimulateResult(
            Path(output),
            scen.name,
            seed,
            sim.duration_s,
            res["imu"],
            res["dvl"],
            sim.distance_m,
            time.perf_counter() - start,
        )
    with progress_bar(f"simulating {scen.name}", enabled=show_progress) as progress:
        log = simulate(scen, seed, white_noise=white_noise, progress=progress)
    write_log(output, log)
    truth_p = log.truth.n_p if log.truth is not None else np.zeros((0, 3))
    return SimulateResult(
        Path(output),
        scen.name,
        seed,
        float(log.imu.t[-1]),
        len(log.imu),
        len(log.dvl),
        path_length(truth_p),
        time.perf_counter() - start,
    )


def load_log(
    path: Path | str,
    options: ReadOptions | None = None,
    *,
    progress: Callable[[float], None] | None = None,
) -> LogData:
    """Read a log (MCAP file or rosbag2 directory) with the project reader (options None: the defaults)."""
    from gtsam_dvl.io.reader import read_log

    if not Path(path).exists():
        raise GtsamDvlError(f"{path}: no such file or directory")
    return read_log(path, options, progress=progress)


def plot_log_to_dir(
    log_path: Path, out_dir: Path, read_options: ReadOptions | None = None
) -> list[Path]:
    """Figures 1-3 of a log."""
    from gtsam_dvl.app.plots.log_plots import plot_log

    return plot_log(load_log(log_path, read_options), Path(out_dir))


NOTHING_WRITTEN = "  wrote nothing (give -o RESULT.mcap, --summary FILE.json or --tum FILE.txt to keep the results)"


@dataclass
class SmoothOutcome:
    """A run of `smooth`: its summary as written (the JSON dict of core/summary.py's model) and the files written."""

    summary: dict
    written: list[Path]

    @property
    def typed(self) -> AnySummary:
        """The summary as its model (core/summary.py parse_summary: one of an older version migrated)."""
        return parse_summary(self.summary, "the run's summary")

    @property
    def status(self) -> str:
        """The run's health status: "ok", "warn", "degraded" or "failed" (analysis/health.py)."""
        health = self.typed.health
        return health.status if health is not None else "ok"

    def describe(self) -> str:
        """The console lines (app/summary_lines.py), then the files written."""
        written = [f"  wrote {p}" for p in self.written] or [NOTHING_WRITTEN]
        return "\n".join(summary_lines(self.typed) + written)


def _check_smooth_request(
    log_path: Path,
    output: Path | None,
    mode: str,
    summary_path: Path | None,
    tum_path: Path | None,
    config_path: Path | None,
    timeline: bool,
    timeline_path: Path | None,
    calibration_path: Path | None,
    calibration_out: Path | None,
) -> Path | None:
    """smooth_file's checks before any work: the mode known, the outputs it can write, every output path
    writable and none an input (check_outputs). Returns the default timeline file next to -o (None: none)."""
    get_estimator(mode)  # an unknown mode: a one-line error before the log is read
    if mode == "io-dvlc" and (
        output is not None or tum_path is not None or timeline_path is not None
    ):
        raise GtsamDvlError(
            "--mode io-dvlc estimates the calibration only (no trajectory): it writes --summary, "
            "not -o, --tum or --timeline-npz; run another mode for a result MCAP"
        )
    default_timeline = (
        Path(output).with_suffix(".timeline.npz")
        if output is not None and timeline and timeline_path is None and mode != "io-dvlc"
        else None
    )
    if mode == "io-dvlc" and (calibration_path is not None or calibration_out is not None):
        raise GtsamDvlError(
            "--mode io-dvlc takes no --calibration and writes no --calibration-out (it estimates "
            "from the Type-I segments alone); run another mode"
        )
    check_outputs(
        {"the input log": Path(log_path), "the configuration": config_path},
        {
            "-o": output,
            "--summary": summary_path,
            "--tum": tum_path if mode != "io-dvlc" else None,
            "--timeline-npz": timeline_path,
            "the timeline file next to -o": default_timeline,
            "--calibration-out": calibration_out,
        },
    )
    return default_timeline


def smooth_file(
    log_path: Path,
    output: Path | None = None,
    mode: str = "batch",
    summary_path: Path | None = None,
    tum_path: Path | None = None,
    config_path: Path | None = None,
    show_progress: bool = True,
    read_options: ReadOptions | None = None,
    timeline: bool = True,
    timeline_path: Path | None = None,
    calibration_path: Path | None = None,
    calibration_out: Path | None = None,
    vehicle: str | None = None,
) -> SmoothOutcome:
    """Run one estimator on a log and write its results (MCAP, summary JSON, TUM, timeline arrays).
    The timeline arrays go to timeline_path, or next to the output MCAP as <output>.timeline.npz.

    Safe outputs: before any work, an output that is an input (or another output) or cannot be written is a
    one-line GtsamDvlError. The outputs are written as a set (io/atomic.py OutputSet): all of them, or none if
    any fails or the run is interrupted. The summary carries the run's health (analysis/health.py).

    calibration_path: a vehicle's calibration file as the prior (app/calibration_files.py, inflated for its age);
    calibration_out: the run's calibration written as one (one of the outputs; it may be calibration_path: the
    file is read first and replaced whole); vehicle: its name (vehicle_name)."""
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.core.result import NavResult
    from gtsam_dvl.io.atomic import OutputSet

    default_timeline = _check_smooth_request(
        log_path,
        output,
        mode,
        summary_path,
        tum_path,
        config_path,
        timeline,
        timeline_path,
        calibration_path,
        calibration_out,
    )
    if config_path:  # a configuration that cannot be read: refused before the log is read
        EstimatorConfig.load(config_path)
    t_read = time.perf_counter()
    with progress_bar(f"reading {Path(log_path).name}", enabled=show_progress) as read_progress:
        # (a day: docs/results.md, Speed)
        log = load_log(log_path, read_options, progress=read_progress)
    read_s = time.perf_counter() - t_read
    config = _configuration(config_path, log)
    result, prior = _run_with_prior(
        log, Path(log_path).name, mode, config, calibration_path, vehicle, timeline, show_progress
    )
    outputs = OutputSet()
    with outputs:
        if not isinstance(result, NavResult):  # io-dvlc: calibration only
            summ = _write_iodvlc_outputs(outputs, result, log, summary_path)
        else:
            result.timing_s["read"] = read_s
            summ = _write_nav_outputs(
                outputs,
                result,
                log,
                log_path,
                config,
                prior,
                read_options=read_options,
                output=output,
                summary_path=summary_path,
                tum_path=tum_path,
                timeline_path=timeline_path,
                default_timeline=default_timeline,
                calibration_out=calibration_out,
                vehicle=vehicle,
            )
    return SmoothOutcome(summ, outputs.committed)


def _configuration(config_path: Path | None, log: LogData) -> EstimatorConfig:
    """The run's configuration: -c's, with the log's scenario's [estimator] table (e.g. its initial attitude) below
    it; without -c, the one the log's scenario names (the paper's runs: "paper"), else the defaults."""
    from gtsam_dvl.core.config import EstimatorConfig, estimator_overrides

    if config_path:
        return EstimatorConfig.load(config_path, under=estimator_overrides(log.metadata))
    return EstimatorConfig.for_log(log.metadata)


def _run_with_prior(
    log: LogData,
    name: str,
    mode: str,
    config: EstimatorConfig,
    calibration_path: Path | None,
    vehicle: str | None,
    timeline: bool,
    show_progress: bool,
) -> tuple[Any, VehicleCalibration | None]:
    """The estimator's run on the log, with the vehicle's calibration file as the prior when one is given
    (app/calibration_files.py: inflated for its age, the inflation recorded in a NavResult). Returns the result
    (NavResult, or IoDvlcResult for io-dvlc) and the prior (None: none)."""
    from gtsam_dvl.app.calibration_files import calibration_prior, record_prior
    from gtsam_dvl.core.result import NavResult

    prior = inflation = None
    if calibration_path is not None:
        prior, inflation = calibration_prior(calibration_path, log, config, vehicle)
    with progress_bar(f"{mode} on {name}", enabled=show_progress) as progress:
        result = run_estimator(
            log, mode, config, progress=progress, timeline=timeline, calibration=prior
        )
    if inflation is not None and isinstance(result, NavResult):
        record_prior(result, inflation)
    return result, prior


def _write_iodvlc_outputs(
    outputs: OutputSet, result: Any, log: LogData, summary_path: Path | None
) -> dict[str, Any]:
    """io-dvlc's outputs (calibration only): its summary with the log's health (failed without a scale)."""
    from gtsam_dvl.analysis.health import assess_log_health
    from gtsam_dvl.estimators.iodvlc import IoDvlcResult, iodvlc_summary

    assert isinstance(result, IoDvlcResult), type(result)

    summ = iodvlc_summary(result, log)
    health = assess_log_health(log)
    if not np.isfinite(summ["scale"]["value"]):
        health.flag(
            "failed",
            "IO-DVLC computed no scale: the log has no Type-I segment (an acceleration at "
            "constant attitude) it could use; run another estimator, or log such a segment",
        )
    summ = IoDvlcSummary.model_validate(
        {**summ, "health": health.as_dict(), "losses": log.metadata.get("reader_losses", {})}
    ).to_json_dict()
    if summary_path is not None:
        outputs.write_json(summary_path, summ)
    return summ


def _write_nav_outputs(
    outputs: OutputSet,
    result: NavResult,
    log: LogData,
    log_path: Path,
    config: EstimatorConfig,
    prior: VehicleCalibration | None,
    *,
    read_options: ReadOptions | None,
    output: Path | None,
    summary_path: Path | None,
    tum_path: Path | None,
    timeline_path: Path | None,
    default_timeline: Path | None,
    calibration_out: Path | None,
    vehicle: str | None,
) -> dict[str, Any]:
    """A trajectory estimator's outputs into the output set: the result MCAP, the timeline arrays (next to it
    unless timeline_path), the summary, the TUM trajectory, the run's calibration file. Returns the summary."""
    from gtsam_dvl.analysis.metrics import summary
    from gtsam_dvl.app.calibration_files import calibration_of_run, vehicle_name
    from gtsam_dvl.core.rotations import matrix_to_quat_xyzw
    from gtsam_dvl.io.atomic import tum_text
    from gtsam_dvl.io.calibration_file import calibration_text
    from gtsam_dvl.io.result_writer import timeline_npz_bytes, write_result_log

    summ = summary(result, log)
    if output is not None:
        with outputs.staged(output) as tmp:
            write_result_log(tmp, result, log, summ, read_options=read_options, result_path=output)
        if result.timeline is not None and timeline_path is None:
            timeline_path = default_timeline
    if timeline_path is not None and result.timeline is not None:
        outputs.write_bytes(timeline_path, timeline_npz_bytes(result.timeline))
    if summary_path is not None:
        outputs.write_json(summary_path, summ)
    if tum_path is not None:
        outputs.write_text(
            tum_path,
            tum_text(log.t0_ns * 1e-9 + result.t, result.n_p, matrix_to_quat_xyzw(result.n_R_b)),
        )
    if calibration_out is not None:
        cal = calibration_of_run(
            result, log_path, config, vehicle_name(log_path, vehicle, prior), prior
        )
        outputs.write_text(calibration_out, calibration_text(cal))
    return summ


def plan_to_dir(
    scenario: str | Path, out_dir: Path, config_path: Path | None = None, show_progress: bool = True
) -> tuple[str, list[Path]]:
    """`gtsam-dvl plan`: covariance analysis of a scenario; writes plan.json, plan.md, timeline.npz and
    figures, returns the answer text and the files written."""
    from gtsam_dvl.analysis.planning import plan_mission
    from gtsam_dvl.app.plots.timeline_plots import (
        plot_normalised_sigmas,
        priors_for_plots,
        targets_for_plots,
    )
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.io.atomic import atomic_write_bytes, atomic_write_json, atomic_write_text
    from gtsam_dvl.io.result_writer import timeline_npz_bytes
    from gtsam_dvl.sim.scenario import load_scenario

    scen = load_scenario(scenario)
    config = (
        EstimatorConfig.load(config_path, under=scen.estimator)
        if config_path
        else scen.estimator_configuration()
    )
    with progress_bar(f"planning {scen.name}", enabled=show_progress) as progress:
        plan = plan_mission(scen, config, progress=progress)
    out_dir = Path(out_dir)
    answer = plan.answer()
    data = {
        "scenario": scen.name,
        "answer": answer.splitlines()[0],
        "wall_s": plan.wall_s,
        "states": [
            {
                "key": s.key,
                "description": s.description,
                "unit": s.unit,
                "prior_sigma": s.prior_sigma,
                "final_sigma": s.posterior_sigma,
                "ratio": s.ratio,
                "verdict": s.verdict,
                "determined_at_s": plan.determined_at_s.get(s.key),
                "credited_segments": s.credited_segments,
                "segment_shares": plan.shares.get(s.key, []),
                "hours_to_halve": s.hours_to_halve,
            }
            for s in plan.report.all_states()
        ],
        "directions": [
            {"ratio": d.ratio, "verdict": d.verdict, "weights": d.weights}
            for d in plan.report.directions
        ],
        "segments": [s.as_dict() for s in plan.segments],
        "config": config.to_dict(),
    }
    written = [
        atomic_write_json(out_dir / "plan.json", data),
        atomic_write_text(
            out_dir / "plan.md",
            f"# Mission plan: {scen.name}\n\n"
            + answer.replace("\n  ", "\n- ")
            + "\n\n![normalised sigmas](normalised_sigmas.png)\n",
        ),
        atomic_write_bytes(out_dir / "timeline.npz", timeline_npz_bytes(plan.timeline)),
        plot_normalised_sigmas(
            plan.timeline,
            out_dir / "normalised_sigmas.png",
            priors_for_plots(config.to_dict()),
            plan.segments,
            title=f"Predicted normalised sigmas, {scen.name} (plan, no noise; dashed: the targets)",
            targets=targets_for_plots(config.to_dict()),
        ),
    ]
    return answer, written


def find_source_log(stored: StoredResult) -> tuple[Path | None, str]:
    """The source log a StoredResult names: at its path relative to the result file's folder (the two moved
    together), else at its absolute path. Returns (path, "") or (None, the line saying why there is none)."""
    recorded = stored.source_log or stored.source_log_relative
    if not recorded:
        return (
            None,
            "the result names no source log: errors against the truth not computed; give --truth LOG",
        )
    candidates = []
    if stored.source_log_relative:
        candidates.append(Path(stored.path).resolve().parent / stored.source_log_relative)
    if stored.source_log:
        candidates.append(Path(stored.source_log))
    for candidate in candidates:
        if candidate.exists():
            return candidate, ""
    return (
        None,
        f"source log {recorded} not found: errors against the truth not computed; give --truth LOG",
    )


def evaluate_to_dir(
    result_path: Path,
    out_dir: Path,
    truth_path: Path | None = None,
    read_options: ReadOptions | None = None,
    force: bool = False,
) -> tuple[list[str], list[Path]]:
    """`gtsam-dvl evaluate`: errors over time against the truth (when a log with truth is given, or the
    result's source log has one), observability verdict with the segments credited, figures and
    metrics.json (with the run's health and what reading the truth log lost). Returns the verdict lines, then the
    health and loss lines, and the files written.

    Without truth_path the source log is looked for where the result records it (find_source_log) and read with
    the options smooth used; the read_options given here (their model_fields_set) override them. When it is not
    found, a line says so and the errors against the truth are left out. A log that is not the result's source
    (analysis/evaluate.py source_mismatch: its content hash, stamps, origin) is refused with one line unless
    force, and then a line says so."""
    from gtsam_dvl.analysis.evaluate import evaluate_result
    from gtsam_dvl.io.atomic import atomic_write_json, atomic_write_text
    from gtsam_dvl.io.result_reader import read_result

    out_dir = Path(out_dir)
    check_outputs(
        {"the result": Path(result_path), "the truth log": truth_path},
        {"-o": out_dir / "metrics.json"},
    )
    stored = read_result(result_path)
    res = stored.result
    from gtsam_dvl.io.read_options import ReadOptions

    options = read_options or ReadOptions()
    missing = ""
    if truth_path is not None:
        log_path: Path | None = Path(truth_path)
    else:
        log_path, missing = find_source_log(stored)
        recorded = ReadOptions.from_record(stored.read_options, f"{result_path}: read_options")
        options = options.over(recorded)
    log = load_log(log_path, options) if log_path is not None else None
    forced = _check_truth_source(stored, log, log_path, result_path, force)
    ev = evaluate_result(stored, log)
    ev.metrics["truth_log_not_source"] = forced or None
    # the health of the run (from the summary smooth wrote) and what reading the truth log here lost
    health = stored.summary.health
    truth_losses = log.metadata.get("reader_losses", {}) if log is not None else {}
    ev.metrics["health"] = health.model_dump() if health is not None else None
    ev.metrics["truth_log_losses"] = truth_losses
    ev.metrics["truth_log"] = str(log_path) if log_path is not None else None
    ev.metrics["truth_log_read_options"] = options.record() if log_path is not None else None
    written = [atomic_write_json(out_dir / "metrics.json", ev.metrics)]
    label = res.estimator
    written += _error_figures(ev, label, out_dir)
    if (wc := res.water_current) is not None and len(wc.t_s):
        from gtsam_dvl.app.plots.current_plots import plot_current

        truth = log.truth if log is not None else None
        written.append(
            plot_current(
                wc,
                out_dir / "water_current.png",
                None if truth is None else truth.t,
                None if truth is None else truth.n_c,
                label,
            )
        )
    if res.timeline is not None:
        written += _timeline_figures(res, log, ev, label, out_dir)
    lines = ([forced] if forced else []) + ev.lines()
    written.append(atomic_write_text(out_dir / "observability.txt", "\n".join(lines) + "\n"))
    lines = _evaluation_lines(lines, ev.metrics, health, log_path, truth_losses, missing)
    return lines, written


def _check_truth_source(
    stored: StoredResult, log: LogData | None, log_path: Path | None, result_path: Path, force: bool
) -> str:
    """A truth log that is not the result's source (analysis/evaluate.py source_mismatch) refused with one line,
    unless force. Returns the line saying it was judged anyway ("": the log is the source, or none)."""
    forced = ""
    if log is not None and log_path is not None:
        from gtsam_dvl.analysis.evaluate import source_mismatch
        from gtsam_dvl.io.result_writer import file_sha256

        if why := source_mismatch(stored, log, file_sha256(log_path)):
            if not force:
                raise GtsamDvlError(
                    f"{log_path} is not the source of {result_path}: {why}; give the log it was "
                    "smoothed from, or --force to judge it against this one"
                )
            forced = f"--force: judged against {log_path}, which is not the result's source: {why}"
    return forced


def _error_figures(ev: Evaluation, label: str, out_dir: Path) -> list[Path]:
    """The attitude, position and velocity errors against the truth over time (none without a truth)."""
    from gtsam_dvl.app.plots.error_plots import plot_errors

    written: list[Path] = []
    if ev.attitude_error_deg is not None and ev.position_error_m is not None:
        written.append(
            plot_errors(
                [(label, ev.t, ev.attitude_error_deg, ev.attitude_sigma_deg)],
                out_dir / "attitude_error.png",
                "attitude",
                ev.segments,
            )
        )
        written.append(
            plot_errors(
                [(label, ev.t, ev.position_error_m, ev.position_sigma_m)],
                out_dir / "position_error.png",
                "position",
                ev.segments,
            )
        )
        if ev.velocity_error_m_s is not None:
            written.append(
                plot_errors(
                    [(label, ev.t, ev.velocity_error_m_s, ev.velocity_sigma_m_s)],
                    out_dir / "velocity_error.png",
                    "velocity",
                    ev.segments,
                )
            )
    return written


def _timeline_figures(
    res: NavResult, log: LogData | None, ev: Evaluation, label: str, out_dir: Path
) -> list[Path]:
    """The calibration's and biases' estimates over time with their sigmas (against the truth when the log has
    it), and the normalised sigmas."""
    from gtsam_dvl.analysis.metrics import truth_in_user_units
    from gtsam_dvl.app.plots.timeline_plots import (
        plot_estimates,
        plot_normalised_sigmas,
        priors_for_plots,
    )

    assert res.timeline is not None  # the caller's condition
    written: list[Path] = []
    truths: dict[str, Any] = truth_in_user_units(log) if log is not None else {}
    estimated = [
        q
        for q, sigma in (
            ("time_offset", res.timeline.time_offset_sigma_s),
            ("lever_arm", res.timeline.lever_arm_sigma_m),
        )
        if sigma is not None
    ]
    for q in ("scale", "misalignment", "gyro_bias", "accel_bias", *estimated):
        written.append(
            plot_estimates(
                [(label, res.timeline)],
                out_dir / f"{q}.png",
                q,
                truths.get(q),
                ev.segments,
                t_min=0.0,
            )
        )
    written.append(
        plot_normalised_sigmas(
            res.timeline,
            out_dir / "normalised_sigmas.png",
            priors_for_plots(res.config),
            ev.segments,
            title=f"Normalised sigmas, {label}",
        )
    )
    return written


def _evaluation_lines(
    lines: list[str],
    metrics: dict[str, Any],
    health: HealthSummary | None,
    log_path: Path | None,
    truth_losses: dict[str, Any],
    missing: str,
) -> list[str]:
    """evaluate_to_dir's printed lines: the verdict lines, then the surfacing error, the run's health, what
    reading the truth log lost and why there is no truth."""
    from gtsam_dvl.app.report import gnss_lines

    lines = lines + gnss_lines(metrics.get("gnss"))  # the surfacing error (analysis/surfacing.py)
    if health is not None:
        lines = lines + [
            f"result {line.strip()}" if i == 0 else line
            for i, line in enumerate(health_lines(health, indent=""))
        ]
    else:
        lines = lines + [
            "result health: not recorded (a result written before health checks existed)"
        ]
    from gtsam_dvl.analysis.health import loss_lines

    lines += [f"  reading {log_path}: {line}" for line in loss_lines(truth_losses)]
    if missing:
        lines.append(missing)
    return lines
