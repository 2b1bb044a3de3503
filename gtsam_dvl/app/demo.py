"""`gtsam-dvl demo`: the paper's two runs through every estimator, with the paper's figures and reports; then a
field-style dive (data/scenarios/field-survey.toml) smoothed as a user would smooth a vehicle's log."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.app.commands import evaluate_to_dir, run_estimator, run_trajectory_estimator
from gtsam_dvl.app.progress import progress_bar
from gtsam_dvl.core.types import LogData

if TYPE_CHECKING:
    from rich.table import Table

    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.core.result import NavResult


def _iodvlc_timeline(res: Any) -> Any:
    """IO-DVLC's scale and misalignment timelines as a Timeline (no biases, no attitude) for the figures."""
    from gtsam_dvl.core.result import Timeline

    n = len(res.t)
    nan3 = np.full((n, 3), np.nan)
    return Timeline(
        res.t,
        res.scale,
        res.scale_sigma,
        res.misalignment_deg,
        res.misalignment_sigma_deg,
        nan3,
        nan3,
        nan3,
        nan3,
        nan3,
    )


def _run_estimators(
    log: LogData, name: str, config: EstimatorConfig, run_dir: Path
) -> tuple[dict[str, NavResult], Any, list[dict[str, Any]]]:
    """The run's log through the trajectory estimators (batch, online, EKF), each one's result MCAP, summary and
    timeline written under run_dir/<mode>/, then through IO-DVLC (its summary under run_dir/io-dvlc/). Returns
    the trajectory estimators' results by mode, IO-DVLC's result and every summary."""
    from gtsam_dvl.analysis.metrics import summary
    from gtsam_dvl.estimators.iodvlc import iodvlc_summary
    from gtsam_dvl.io.atomic import atomic_write_bytes, atomic_write_json
    from gtsam_dvl.io.result_writer import timeline_npz_bytes, write_result_log

    results: dict[str, NavResult] = {}
    summaries: list[dict[str, Any]] = []
    modes = ["batch", "online", "ekf"]
    for mode in modes:
        t0 = time.perf_counter()
        with progress_bar(f"{name}: {mode}") as progress:
            res = run_trajectory_estimator(log, mode, config, progress=progress)
        res.timing_s.setdefault("total", time.perf_counter() - t0)
        summ = summary(res, log)
        out = run_dir / mode
        write_result_log(out / "result.mcap", res, log, summ)
        atomic_write_json(out / "summary.json", summ)
        if res.timeline is not None:
            atomic_write_bytes(out / "timeline.npz", timeline_npz_bytes(res.timeline))
        results[mode] = res
        summaries.append(summ)
    io_res = run_estimator(log, "io-dvlc", config)
    io_summ = iodvlc_summary(io_res, log)
    atomic_write_json(run_dir / "io-dvlc" / "summary.json", io_summ)
    summaries.append(io_summ)
    return results, io_res, summaries


def _calibration_figures(
    log: LogData,
    results: dict[str, NavResult],
    io_res: Any,
    truths: dict[str, Any],
    figs: Path,
    two_d: bool,
) -> list[Path]:
    """The paper's figures of the calibration and biases over time: IO-DVLC's scale and misalignment (the 3-D
    run), then the trajectory estimators', numbered as the paper numbers them."""
    from gtsam_dvl.app.plots.timeline_plots import plot_estimates

    segments = log.segments
    written: list[Path] = []
    io_tl = _iodvlc_timeline(io_res)
    if not two_d:
        for state, figure in (("scale", "fig04"), ("misalignment", "fig05")):
            written.append(
                plot_estimates(
                    [("IO-DVLC", io_tl)],
                    figs / f"{figure}_iodvlc_{state}.png",
                    state,
                    truths[state],
                    segments,
                    t_min=590.0,
                )
            )
    tls = [(m, r.timeline) for m, r in results.items() if r.timeline is not None]
    numbers = {
        "scale": (13, 6),
        "misalignment": (14, 7),
        "gyro_bias": (None, 8),
        "accel_bias": (None, 9),
    }
    for q, (n2d, n3d) in numbers.items():
        num = n2d if two_d else n3d
        if num is not None:
            written.append(
                plot_estimates(
                    tls,
                    figs / f"fig{num:02d}_{q}.png",
                    q,
                    truths[q],
                    segments,
                    t_min=0.0 if "bias" in q else 590.0,
                )
            )
    return written


def _error_figures(
    log: LogData, results: dict[str, NavResult], figs: Path, two_d: bool
) -> list[Path]:
    """The paper's figures of the trajectory estimators' attitude and position errors against the truth."""
    from gtsam_dvl.analysis.metrics import attitude_errors_deg, truth_at
    from gtsam_dvl.app.plots.error_plots import plot_errors

    segments = log.segments
    written: list[Path] = []
    runs_att, runs_pos = [], []
    assert log.truth is not None  # simulated
    for m, r in results.items():
        p_true, R_true, _ = truth_at(log.truth, r.t)
        runs_att.append((m, r.t, attitude_errors_deg(r.n_R_b, R_true), r.attitude_sigma_deg))
        runs_pos.append((m, r.t, r.n_p - p_true, r.position_sigma_m))
    written.append(
        plot_errors(
            runs_att,
            figs / f"fig{15 if two_d else 10:02d}_attitude_error.png",
            "attitude",
            segments,
        )
    )
    written.append(
        plot_errors(
            runs_pos,
            figs / f"fig{16 if two_d else 11:02d}_position_error.png",
            "position",
            segments,
        )
    )
    return written


def demo_run(name: str, run_dir: Path, seed: int, console: Any) -> dict[str, Any]:
    """One simulated run through every estimator, with figures named after the paper's and a report."""
    from gtsam_dvl.analysis.metrics import truth_in_user_units
    from gtsam_dvl.app.plots.log_plots import plot_log
    from gtsam_dvl.app.plots.timeline_plots import plot_normalised_sigmas, priors_for_plots
    from gtsam_dvl.app.report import paper_findings, write_run_report
    from gtsam_dvl.io.writer import write_log
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    scen = load_scenario(name)
    config = scen.estimator_configuration()  # the paper's runs: the paper's priors
    log = simulate(scen, seed)
    log_path = run_dir / f"{name}.mcap"
    write_log(log_path, log)
    log.source = str(log_path)
    figs = run_dir / "figures"
    written = plot_log(log, figs)
    segments = log.segments
    results, io_res, summaries = _run_estimators(log, name, config, run_dir)
    truths = {"scale": None, "misalignment": None, **truth_in_user_units(log)}
    two_d = not any(s.kind in ("descent", "ascent") for s in log.segments)  # the paper's 2-D run
    written += _calibration_figures(log, results, io_res, truths, figs, two_d)
    written += _error_figures(log, results, figs, two_d)
    priors = priors_for_plots(config.to_dict())
    ref = "ekf" if "ekf" in results else next(iter(results))
    if (ref_timeline := results[ref].timeline) is not None:
        written.append(
            plot_normalised_sigmas(
                ref_timeline,
                figs / "fig12_normalised_sigmas.png",
                priors,
                segments,
                title=f"Normalised sigmas, {name}, {ref}",
            )
        )
    findings = {
        m: paper_findings(r.timeline, priors, log.segments)
        for m, r in results.items()
        if r.timeline is not None
    }
    verdict = (
        evaluate_to_dir(
            run_dir / "batch" / "result.mcap", run_dir / "batch" / "evaluation", truth_path=log_path
        )[0]
        if "batch" in results
        else []
    )
    report = write_run_report(
        run_dir / "report.md", name, summaries, findings, verdict, sorted(written)
    )
    return {"run": name, "summaries": summaries, "findings": findings, "report": report}


FIELD_SCENARIO = "field-survey"


def field_run(run_dir: Path, seed: int, console: Any) -> dict[str, Any]:
    """The field-style dive as a user would process a vehicle's log: simulate it to MCAP (the origin only in the
    GNSS fixes), `smooth` it with the default configuration (a real DVL's priors, time offset estimated, attitude
    aligned in motion), `evaluate` it (the surfacing error against the held-out final fixes, and, simulated, the
    errors against the truth). Returns the summary, the evaluation metrics and the printed lines."""
    from gtsam_dvl.app.commands import simulate_to_file, smooth_file
    from gtsam_dvl.app.report import gnss_lines

    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = run_dir / f"{FIELD_SCENARIO}.mcap"
    simulate_to_file(FIELD_SCENARIO, log_path, seed=seed, show_progress=False)
    t0 = time.perf_counter()
    outcome = smooth_file(
        log_path, run_dir / "result.mcap", summary_path=run_dir / "summary.json", show_progress=True
    )
    wall = time.perf_counter() - t0
    lines, _ = evaluate_to_dir(run_dir / "result.mcap", run_dir / "evaluation")
    import json

    metrics = json.loads((run_dir / "evaluation" / "metrics.json").read_text())
    return {
        "run": FIELD_SCENARIO,
        "summary": outcome.summary,
        "metrics": metrics,
        "lines": lines,
        "gnss_lines": gnss_lines(metrics.get("gnss")),
        "wall_s": wall,
    }


DEEP_SCENARIO = "deep-descent"


def deep_run(run_dir: Path, seed: int) -> dict[str, Any]:
    """The deep descent (data/scenarios/deep-descent.toml: 300 m without bottom lock in a sheared current) simulated
    to MCAP and smoothed twice with the default configuration: water-track pings used (the current a state), and
    refused (-c with [current] water_track = "refuse"); evaluated (water_current.png). Returns both summaries."""
    from gtsam_dvl.app.commands import simulate_to_file, smooth_file
    from gtsam_dvl.io.atomic import atomic_write_text

    run_dir.mkdir(parents=True, exist_ok=True)
    log_path = run_dir / f"{DEEP_SCENARIO}.mcap"
    simulate_to_file(DEEP_SCENARIO, log_path, seed=seed, show_progress=False)
    used = smooth_file(
        log_path, run_dir / "result.mcap", summary_path=run_dir / "summary.json", show_progress=True
    )
    evaluate_to_dir(run_dir / "result.mcap", run_dir / "evaluation")
    refuse_cfg = atomic_write_text(
        run_dir / "refuse-water-track.toml", '[current]\nwater_track = "refuse"\n'
    )
    refused = smooth_file(
        log_path,
        run_dir / "result-refused.mcap",
        summary_path=run_dir / "summary-refused.json",
        config_path=refuse_cfg,
        show_progress=True,
    )
    return {"run": DEEP_SCENARIO, "used": used.summary, "refused": refused.summary}


def _deep_table(run: dict[str, Any]) -> list[str]:
    """The deep descent's numbers as markdown lines: water track used against refused."""
    out = []
    for key, words in (("used", "water track used"), ("refused", "water track refused")):
        s = run[key]
        e = s.get("errors", {})
        out.append(
            f"- {words}: final horizontal error {e.get('final_horizontal_position_m', float('nan')):.2f} m "
            f"(sigma {s['final_horizontal_position_sigma_m']:.2f} m), scale error "
            f"{e.get('scale_nsigma', float('nan')):+.2f} sigma, roll (thrust-axis) misalignment sigma "
            f"{s['misalignment_deg']['sigma'][0]:.3f} deg, health {s['health']['status']}"
        )
    wc = run["used"].get("water_current")
    if wc:
        err = wc.get("errors", {})
        out.append(
            f"- water current: {wc['verdict']}; RMS error {err.get('rms_m_s', float('nan')):.3f} m/s over "
            f"{100 * wc['determined_share']:.0f} % of the states ({wc['water_track_pings']} water-track pings)"
        )
    return out


def _field_table(run: dict[str, Any]) -> list[str]:
    """The field run's numbers as markdown lines (the demo prints and indexes them)."""
    s, e = run["summary"], run["summary"].get("errors", {})
    t_off = s.get("dvl_time_offset_s", {})
    truth_off = e.get("dvl_time_offset_s")
    out = [
        f"- scale {s['scale']['value']:.5f} +- {s['scale']['sigma']:.5f} "
        f"(error {e.get('scale_nsigma', float('nan')):+.2f} sigma)",
        "- misalignment r/p/y "
        + " ".join(f"{v:+.3f}" for v in s["misalignment_deg"]["value"])
        + " +- "
        + " ".join(f"{v:.3f}" for v in s["misalignment_deg"]["sigma"])
        + " deg (errors "
        + " ".join(f"{v:+.2f}" for v in e.get("misalignment_nsigma", []))
        + " sigma)",
    ]
    if t_off:
        out.append(
            f"- DVL time offset {t_off['value']:.3f} +- {t_off['sigma']:.3f} s "
            f"(error {truth_off if truth_off is None else f'{truth_off * 1e3:+.1f} ms'}, "
            f"{e.get('dvl_time_offset_nsigma', float('nan')):+.2f} sigma)"
        )
    if "final_horizontal_position_m" in e:
        out.append(
            f"- final horizontal error against the truth {e['final_horizontal_position_m']:.2f} m "
            f"({e['final_horizontal_position_pct_distance']:.3f} % of distance travelled)"
        )
    out += [f"- {line}" for line in run["gnss_lines"] if "surfacing error" in line]
    out.append(
        f"- health {s['health']['status']}, {s['states']} states, smoothed in {run['wall_s']:.1f} s"
    )
    return out


def _section(console: Any, name: str, headline: str, intro: str, table: list[str]) -> list[str]:
    """A further run's lines printed (headline, then its table's lines) and its section of the index report."""
    console.print(f"{name}: {headline}")
    for line in table:
        console.print("  " + line[2:])
    return [f"## {name}", "", intro, "", *table, ""]


def _estimates_table(run: dict[str, Any]) -> Table:
    """A paper run's table of final estimates against the truth, one row per estimator (rich Table)."""
    from rich.table import Table

    table = Table(title=f"{run['run']}: final estimates against the truth")
    for col in (
        "estimator",
        "scale err/sigma (ppm)",
        "misalignment err r/p/y (deg)",
        "sigma r/p/y (deg)",
        "final horiz. pos.",
        "attitude RMSE (deg)",
        "wall (s)",
    ):
        table.add_column(col, justify="right")
    for s in run["summaries"]:
        e = s.get("errors", {})
        pos = (
            f"{e['final_horizontal_position_m']:.2f} m ({e['final_horizontal_position_pct_distance']:.3f}%)"
            if "final_horizontal_position_m" in e
            else "-"
        )
        att = (
            " ".join(f"{v:.4f}" for v in e["attitude_rmse_deg"])
            if "attitude_rmse_deg" in e
            else "-"
        )
        wall = s.get("timing_s", {}).get("total")
        table.add_row(
            s["estimator"],
            f"{e.get('scale_ppm', float('nan')):+.0f}/{s['scale']['sigma'] * 1e6:.0f}",
            " ".join(f"{v:+.3f}" for v in e.get("misalignment_deg", [])),
            " ".join(f"{v:.3f}" for v in s["misalignment_deg"]["sigma"]),
            pos,
            att,
            f"{wall:.1f}" if wall is not None else "-",
        )
    return table


def _run_section(console: Any, run: dict[str, Any], out_dir: Path) -> list[str]:
    """A paper run's section of the index report (its calibration table, the paper's findings per estimator),
    the findings' counts printed."""
    from gtsam_dvl.app.report import calibration_table

    index = [
        f"## {run['run']}",
        "",
        f"[full report with figures]({Path(run['report']).relative_to(out_dir)})",
        "",
        *calibration_table(run["summaries"]),
        "",
    ]
    for est, items in run["findings"].items():
        held = sum(f.held for f in items)
        console.print(f"  {run['run']} {est}: {held}/{len(items)} of the paper's findings hold")
        index.append(
            f"- {est}: " + "; ".join(f"{'yes' if f.held else 'NO'}: {f.text}" for f in items)
        )
    index.append("")
    return index


def run_demo(out_dir: Path, seed: int = 7) -> list[dict[str, Any]]:
    """Simulate paper-3d and paper-2d, run every estimator (batch, online, EKF, IO-DVLC), evaluate, write the
    paper's figures and a report per run plus an index report; print the comparison table."""
    from rich.console import Console

    from gtsam_dvl.io.atomic import atomic_write_text

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    console = Console(width=150) if not sys.stdout.isatty() else Console()
    t_start = time.perf_counter()
    runs = [demo_run(name, out_dir / name, seed, console) for name in ("paper-3d", "paper-2d")]
    index = [
        "# gtsam_dvl demo: the paper's runs",
        "",
        f"Seed {seed}. Every number is measured on these simulated logs; see each run's report for the "
        "figures.",
        "",
    ]
    for run in runs:
        console.print(_estimates_table(run))
        index += _run_section(console, run, out_dir)
    index += _section(
        console,
        FIELD_SCENARIO,
        "a survey dive smoothed with the default configuration "
        "(`gtsam-dvl smooth` then `gtsam-dvl evaluate`)",
        "A survey dive as a vehicle records it (data/scenarios/field-survey.toml): underway GNSS start, "
        "5 Hz z-down DVL whose stamps are 0.3 s early, a lever arm, 200 Hz IMU, pressure, the origin "
        "only in the fixes; smoothed with the default configuration.",
        _field_table(field_run(out_dir / FIELD_SCENARIO, seed, console)),
    )
    index += _section(
        console,
        DEEP_SCENARIO,
        "a 300 m descent without bottom lock in a sheared current, smoothed "
        "with water track used and refused",
        "GNSS at the surface, a 300 m descent in water track through a 0.45 to 0.2 m/s sheared "
        "current, bottom lock, the paper's square, the ascent in water track "
        "(data/scenarios/deep-descent.toml); smoothed with the default configuration, water-track "
        "pings used and refused.",
        _deep_table(deep_run(out_dir / DEEP_SCENARIO, seed)),
    )
    atomic_write_text(out_dir / "report.md", "\n".join(index) + "\n")
    console.print(f"Reports: {out_dir / 'report.md'} ({time.perf_counter() - t_start:.0f} s)")
    return runs
