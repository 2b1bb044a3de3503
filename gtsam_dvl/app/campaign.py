"""Monte Carlo campaigns on Dask distributed: `gtsam-dvl montecarlo SCENARIO --runs N ...`.

The engine is dask.distributed, not a home-made pool: a LocalCluster sized to the machine by default (processes
with one thread each: GTSAM's Python factors hold the GIL), or any running scheduler by address
(`--scheduler tcp://host:8786`, started with `dask scheduler` and `dask worker tcp://host:8786` on the machines,
which need only `pip install gtsam-dvl[distributed]`). A task is one seed (analysis/montecarlo.run_seed): it
ships the scenario's tables, the seed, the estimator names and the configuration as plain data, so a worker
needs no file and no object of the client's, and the result is the same on any machine.

The campaign folder DIR holds campaign.json (what the campaign is: scenario, estimators, configuration; a
rerun with other settings is refused), runs/seed_NNNNNN.json (one file per finished seed, written atomically as
it completes: an interrupted campaign resumes without redoing them), failures.json (seeds whose task failed
twice, with their error: Dask retries a task once), montecarlo.json (the statistics) and report.md with the
figures under figures/.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError

INSTALL_HINT = "Dask is not installed: pip install 'gtsam-dvl[distributed]' (make test and make demo install it)"
# for tests of the engine only: the run of this seed raises (a task that fails on every try)
FAIL_SEED_ENV = "GTSAM_DVL_MONTECARLO_FAIL_SEED"


def _run_task(scenario: dict[str, Any], seed: int, estimators: list[str], config: dict[str, Any] | None,
              name: str) -> dict[str, Any]:
    """The worker's task: one seed (analysis/montecarlo.run_seed)."""
    from gtsam_dvl.analysis.montecarlo import run_seed

    if os.environ.get(FAIL_SEED_ENV) == str(seed):
        raise RuntimeError(f"{FAIL_SEED_ENV}={seed}: this run fails on purpose")
    return run_seed(scenario, seed, estimators, config, name)


def _crb_task(scenario: dict[str, Any], config: dict[str, Any] | None, name: str) -> list[float]:
    from gtsam_dvl.analysis.montecarlo import cramer_rao_sigmas

    return cramer_rao_sigmas(scenario, config, name)


@dataclass
class CampaignResult:
    out_dir: Path
    statistics: dict[str, Any]
    runs_done: int
    runs_new: int
    failures: list[dict[str, Any]] = field(default_factory=list)
    written: list[Path] = field(default_factory=list)


def open_client(scheduler: str | None, workers: int | None) -> Any:
    """A dask.distributed Client: to the scheduler at `scheduler`, else on a LocalCluster of `workers` processes
    (default: the machine's cores) with one thread each."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise GtsamDvlError(INSTALL_HINT) from None
    if scheduler:
        try:
            return Client(scheduler, timeout="20s")
        except OSError as exc:
            raise GtsamDvlError(f"cannot reach the Dask scheduler at {scheduler} ({exc})") from None
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                           silence_logs=logging.ERROR)
    return Client(cluster)


def _campaign_record(scenario_name: str, scenario: dict[str, Any], estimators: list[str],
                     config: dict[str, Any] | None) -> dict[str, Any]:
    return {"scenario_name": scenario_name, "scenario": scenario, "estimators": list(estimators), "config": config}


def run_campaign(scenario: str | Path, runs: int, estimators: list[str], out_dir: Path, seed_start: int = 1,
                 scheduler: str | None = None, workers: int | None = None, config_path: Path | None = None,
                 show_progress: bool = True) -> CampaignResult:
    """Run (or resume) a campaign of seeds seed_start .. seed_start + runs - 1 (module doc)."""
    from gtsam_dvl.analysis.montecarlo import ESTIMATORS, campaign_statistics
    from gtsam_dvl.app.progress import progress_bar
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.io.atomic import atomic_write_json
    from gtsam_dvl.sim.scenario import load_scenario

    unknown = [e for e in estimators if e not in ESTIMATORS + ("online-full",)]
    if unknown or not estimators:
        raise GtsamDvlError(f"unknown estimator(s) {', '.join(unknown) or '(none given)'} "
                            f"(known: {', '.join(ESTIMATORS)}, online-full)")
    if runs < 1:
        raise GtsamDvlError(f"--runs must be at least 1, got {runs}")
    sc = load_scenario(scenario)
    config = EstimatorConfig.load(config_path).to_dict() if config_path else None
    record = json.loads(json.dumps(_campaign_record(sc.name, sc.raw, estimators, config), default=str))
    out_dir = Path(out_dir)
    runs_dir = out_dir / "runs"
    meta_path = out_dir / "campaign.json"
    if meta_path.exists():
        old = json.loads(meta_path.read_text())
        if old != record:
            raise GtsamDvlError(f"{out_dir}: holds a campaign with other settings (scenario, estimators or "
                                "configuration); choose another folder")
    else:
        atomic_write_json(meta_path, record)
    seeds = list(range(seed_start, seed_start + runs))
    done = {s for s in seeds if (runs_dir / f"seed_{s:06d}.json").exists()}
    todo = [s for s in seeds if s not in done]
    failures: list[dict[str, Any]] = []
    crb = None
    crb_path = out_dir / "cramer_rao.json"
    if todo or not crb_path.exists():
        from dask.distributed import as_completed

        client = open_client(scheduler, workers)
        try:
            futures = {client.submit(_run_task, record["scenario"], s, list(estimators), config, sc.name,
                                     key=f"gtsam-dvl-seed-{sc.name}-{s}", pure=False, retries=1): s for s in todo}
            crb_future = (client.submit(_crb_task, record["scenario"], config, sc.name, pure=False)
                          if not crb_path.exists() else None)
            with progress_bar(f"montecarlo {sc.name}: {len(todo)} runs", enabled=show_progress) as progress:
                for k, fut in enumerate(as_completed(list(futures)), start=1):
                    seed = futures[fut]
                    if fut.status == "error":
                        exc = fut.exception()
                        failures.append({"seed": seed, "error": f"{type(exc).__name__}: {exc}"})
                    else:
                        atomic_write_json(runs_dir / f"seed_{seed:06d}.json", fut.result())
                    progress(k / max(len(futures), 1))
            if crb_future is not None:
                try:
                    atomic_write_json(crb_path, crb_future.result())
                except Exception as exc:  # noqa: BLE001 - the bound is optional: say why it is missing
                    failures.append({"seed": None, "error": f"Cramer-Rao bound: {type(exc).__name__}: {exc}"})
        finally:
            cluster = getattr(client, "cluster", None)
            client.close()
            if cluster is not None:
                cluster.close()
    if crb_path.exists():
        crb = json.loads(crb_path.read_text())
    results = [json.loads((runs_dir / f"seed_{s:06d}.json").read_text()) for s in seeds
               if (runs_dir / f"seed_{s:06d}.json").exists()]
    atomic_write_json(out_dir / "failures.json", failures)
    if not results:
        raise GtsamDvlError(f"{out_dir}: every run failed; see failures.json (first: {failures[0]['error']})"
                            if failures else f"{out_dir}: no runs")
    stats = campaign_statistics(results, crb)
    stats.update(scenario=sc.name, seeds=[r["seed"] for r in results], failures=failures)
    written = [atomic_write_json(out_dir / "montecarlo.json", stats)]
    written += write_report(out_dir, stats)
    return CampaignResult(out_dir, stats, len(results), len(todo) - len(failures), failures, written)


def write_report(out_dir: Path, stats: dict[str, Any]) -> list[Path]:
    """report.md and the figures of a campaign's statistics."""
    from gtsam_dvl.analysis.montecarlo import BLOCK_DOF
    from gtsam_dvl.io.atomic import atomic_write_text

    figs = plot_campaign(out_dir / "figures", stats)
    n = stats["runs"]
    lines = [f"# Monte Carlo campaign: {stats['scenario']}, {n} runs", "",
             "Error/sigma of each state over the runs (0 +- 1 when the sigmas are honest), the fraction within 3 "
             "sigma (99.7 % expected), the RMSE against the mean reported sigma and against the Cramer-Rao bound "
             "(noise-free batch information at the truth), and the NEES of the "
             f"{BLOCK_DOF}-dof calibration and bias block with its 95 % band for {n} runs.", ""]
    for name, est in stats["estimators"].items():
        nb = est["nees_block"]
        lines += [f"## {name}", "",
                  f"Mean wall time per run {est['wall_s_mean']:.2f} s. Block NEES mean {nb['mean']:.2f} "
                  f"(band {nb['band_95'][0]:.2f}-{nb['band_95'][1]:.2f}): "
                  f"{'inside' if nb['inside_band'] else '**outside**'}.", "",
                  "| state | unit | mean z | std z | within 3 sigma | RMSE | mean sigma | RMSE/sigma | RMSE/CRB |",
                  "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for state, r in est["states"].items():
            crb = f"{r['rmse_over_crb']:.2f}" if "rmse_over_crb" in r else "-"
            lines.append(f"| {state} | {r['unit']} | {r['z_mean']:+.2f} | {r['z_std']:.2f} | "
                         f"{100 * r['within_3_sigma']:.0f} % | {r['rmse']:.4g} | {r['mean_sigma']:.4g} | "
                         f"{r['rmse_over_sigma']:.2f} | {crb} |")
        if "nees_time" in est:
            nt = est["nees_time"]
            lines += ["", f"NEES over time (diagonal, every 60 s): {100 * nt['fraction_inside']:.0f} % of the samples "
                          f"inside the 95 % band {nt['band_95'][0]:.2f}-{nt['band_95'][1]:.2f}."]
        lines.append("")
    if stats.get("failures"):
        lines += ["## Failed runs", ""] + [f"- seed {f['seed']}: {f['error']}" for f in stats["failures"]] + [""]
    lines += ["## Figures", ""] + [f"![{p.stem}](figures/{p.name})" for p in figs] + [""]
    return [atomic_write_text(out_dir / "report.md", "\n".join(lines)), *figs]


def plot_campaign(fig_dir: Path, stats: dict[str, Any]) -> list[Path]:
    """Per estimator a grid of error/sigma histograms with the N(0, 1) density (from the runs' files), and the
    filters' NEES over time with the 95 % band."""
    import matplotlib.pyplot as plt

    from gtsam_dvl.app.plots.common import save_figure

    out: list[Path] = []
    runs_dir = fig_dir.parent / "runs"
    seeds = set(stats.get("seeds", []))
    runs = [r for r in (json.loads(p.read_text()) for p in sorted(runs_dir.glob("seed_*.json"))) if r["seed"] in seeds]
    for name, est in stats["estimators"].items():
        states = list(est["states"])
        rows = [r["estimators"][name] for r in runs if name in r["estimators"]]
        z = np.array([np.array(x["error"]) / np.array(x["sigma"]) for x in rows])
        if "time_offset" in states:
            z = np.column_stack([z, [x["time_offset"]["error"] / x["time_offset"]["sigma"] for x in rows]])
        cols = 4
        nrows = int(np.ceil(len(states) / cols))
        fig, axes = plt.subplots(nrows, cols, figsize=(12, 2.4 * nrows + 0.6), squeeze=False)
        grid = np.linspace(-4, 4, 200)
        for j, state in enumerate(states):
            ax = axes[j // cols, j % cols]
            ax.hist(np.clip(z[:, j], -4, 4), bins=np.linspace(-4, 4, 17), density=True, color="0.7",
                    edgecolor="0.4", label="runs")
            ax.plot(grid, np.exp(-0.5 * grid**2) / np.sqrt(2 * np.pi), color="C3", lw=1.2, label="N(0, 1)")
            ax.set_title(f"{state}: std {est['states'][state]['z_std']:.2f}", fontsize=8)
            ax.set_xlabel("error / sigma (-)", fontsize=7)
            ax.set_ylabel("density (-)", fontsize=7)
            ax.tick_params(labelsize=7)
        for j in range(len(states), nrows * cols):
            axes[j // cols, j % cols].axis("off")
        axes[0, 0].legend(fontsize=7)
        fig.suptitle(f"{name}: error/sigma over {len(rows)} runs (clipped to +-4)")
        out.append(save_figure(fig, fig_dir / f"z_histograms_{name}.png"))
        if "nees_time" in est:
            nt = est["nees_time"]
            fig, ax = plt.subplots(figsize=(9, 3.5))
            ax.plot(nt["t"], nt["mean"], color="C0", label=f"{name}: mean NEES over the runs")
            ax.axhspan(*nt["band_95"], color="0.85", label="95 % band")
            ax.axhline(10, color="0.4", ls="--", lw=0.8, label="dof (10)")
            ax.set_yscale("log")
            ax.set_xlabel("time (s)")
            ax.set_ylabel("NEES (-)")
            ax.legend(fontsize=8)
            ax.set_title(f"{name}: NEES of scale, misalignment and biases over time (diagonal)")
            out.append(save_figure(fig, fig_dir / f"nees_time_{name}.png"))
    return out


# ----- fleet processing: many logs, one configuration --------------------------------------------------------------
def _smooth_task(log_path: str, run_dir: str, mode: str, config_path: str | None,
                 read_options: dict[str, Any]) -> dict[str, Any]:
    """The worker's task: `smooth` one log into run_dir (result.mcap, summary.json) and, for a result MCAP,
    `evaluate` it (the surfacing error against held-out GNSS fixes, errors against the truth when the log has
    it). Returns one row of the fleet table; a bad log gives its error line instead of raising."""
    from gtsam_dvl.app.commands import evaluate_to_dir, smooth_file

    out = Path(run_dir)
    row: dict[str, Any] = {"log": log_path, "dir": run_dir}
    try:
        result = out / "result.mcap" if mode != "io-dvlc" else None
        outcome = smooth_file(Path(log_path), result, mode=mode, summary_path=out / "summary.json",
                              config_path=Path(config_path) if config_path else None, show_progress=False,
                              read_options=read_options, timeline=False)
        s = outcome.summary
        row.update(status=outcome.status, scale=s["scale"], misalignment_deg=s["misalignment_deg"],
                   time_offset_s=s.get("dvl_time_offset_s"), states=s.get("states"),
                   wall_s=s.get("timing_s", {}).get("total"))
        if result is not None:
            evaluate_to_dir(result, out / "evaluation", read_options={})
            metrics = json.loads((out / "evaluation" / "metrics.json").read_text())
            gnss = metrics.get("gnss") or {}
            row["surfacing_error"] = gnss.get("surfacing_error_mean") or gnss.get("surfacing_error")
            row["errors"] = s.get("errors")
    except GtsamDvlError as exc:
        row.update(status="error", error=str(exc))
    except Exception as exc:  # noqa: BLE001 - one log's unexpected failure must not stop the fleet: reported
        row.update(status="error", error=f"{type(exc).__name__}: {exc}")
    return row


def smooth_fleet(logs: list[Path], out_dir: Path, mode: str = "batch", config_path: Path | None = None,
                 read_options: dict[str, Any] | None = None, scheduler: str | None = None,
                 workers: int | None = None, show_progress: bool = True) -> tuple[list[dict[str, Any]], list[Path]]:
    """`gtsam-dvl smooth LOG... --out-dir DIR`: every log smoothed in parallel with the same configuration, one
    folder per log (DIR/<log name>/), and a table of all runs (DIR/fleet.json, DIR/fleet.md). Tasks ship the
    log's path: a remote cluster's workers must see the same file system. One bad log gets its error line in
    the table; the others finish."""
    from gtsam_dvl.io.atomic import atomic_write_json, atomic_write_text

    if not logs:
        raise GtsamDvlError("no logs given")
    names = [Path(p).name.removesuffix(".mcap").removesuffix(".db3") or "log" for p in logs]
    if len(set(names)) != len(names):  # two logs of one name in different folders: number them
        names = [f"{i:03d}_{n}" for i, n in enumerate(names)]
    out_dir = Path(out_dir)
    from dask.distributed import as_completed

    from gtsam_dvl.app.progress import progress_bar

    client = open_client(scheduler, workers)
    by_index: dict[int, dict[str, Any]] = {}  # rows in the order the logs were given, whatever the completion order
    try:
        futures = {client.submit(_smooth_task, str(Path(p).resolve()), str((out_dir / n).resolve()), mode,
                                 str(config_path.resolve()) if config_path else None, dict(read_options or {}),
                                 pure=False, retries=1): i for i, (p, n) in enumerate(zip(logs, names, strict=True))}
        with progress_bar(f"smoothing {len(logs)} logs ({mode})", enabled=show_progress) as progress:
            for k, fut in enumerate(as_completed(list(futures)), start=1):
                i = futures[fut]
                if fut.status == "error":
                    exc = fut.exception()
                    by_index[i] = {"log": str(logs[i]), "dir": str(out_dir / names[i]), "status": "error",
                                   "error": f"{type(exc).__name__}: {exc}"}
                else:
                    by_index[i] = fut.result()
                progress(k / len(futures))
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None:
            cluster.close()
    rows = [by_index[i] for i in sorted(by_index)]
    table = "\n".join(fleet_table(rows)) + "\n"
    written = [atomic_write_json(out_dir / "fleet.json", rows), atomic_write_text(out_dir / "fleet.md", table)]
    return rows, written


def fleet_table(rows: list[dict[str, Any]]) -> list[str]:
    """The fleet's table in Markdown: per log the health, scale, misalignment, time offset and surfacing error,
    or its error line."""
    lines = ["| log | health | scale | misalignment r/p/y (deg) | time offset (ms) | surfacing error |",
             "| --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        name = Path(r["log"]).name
        if r["status"] == "error":
            lines.append(f"| {name} | error | {r['error']} | | | |")
            continue
        sc, mis = r["scale"], r["misalignment_deg"]
        off, surf = r.get("time_offset_s"), r.get("surfacing_error")
        cells = [name, r["status"], f"{sc['value']:.5f} +- {sc['sigma']:.5f}",
                 " ".join(f"{v:+.3f}" for v in mis["value"]) + " +- " + " ".join(f"{v:.3f}" for v in mis["sigma"]),
                 f"{off['value'] * 1e3:+.1f} +- {off['sigma'] * 1e3:.1f}" if off else "-",
                 (f"{surf['horizontal_error_m']:.2f} m ({surf['horizontal_error_pct']:.3f} % of "
                  f"{surf['distance_m']:.0f} m)") if surf else "-"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines
