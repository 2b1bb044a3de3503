"""Fleet processing: `gtsam-dvl smooth LOG... --out-dir DIR`, every log smoothed (and evaluated) in parallel on
Dask with one configuration (campaign/cluster.py), one folder per log and a table of all runs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gtsam_dvl.app.campaign.cluster import LOCAL_CLUSTER, DaskEngine, finished, require_dask
from gtsam_dvl.core.errors import GtsamDvlError

if TYPE_CHECKING:
    from gtsam_dvl.io.read_options import ReadOptions


def _smooth_task(
    log_path: str,
    run_dir: str,
    mode: str,
    config_path: str | None,
    read_options: ReadOptions | None,
) -> dict[str, Any]:
    """The worker's task: `smooth` one log into run_dir (result.mcap, summary.json) and, for a result MCAP,
    `evaluate` it (the surfacing error against held-out GNSS fixes, errors against the truth when the log has
    it). Returns one row of the fleet table; a bad log gives its error line instead of raising."""
    from gtsam_dvl.app.commands import evaluate_to_dir, smooth_file

    out = Path(run_dir)
    row: dict[str, Any] = {"log": log_path, "dir": run_dir}
    try:
        result = out / "result.mcap" if mode != "io-dvlc" else None
        outcome = smooth_file(
            Path(log_path),
            result,
            mode=mode,
            summary_path=out / "summary.json",
            config_path=Path(config_path) if config_path else None,
            show_progress=False,
            read_options=read_options,
            timeline=False,
        )
        s = outcome.summary
        row.update(
            status=outcome.status,
            scale=s["scale"],
            misalignment_deg=s["misalignment_deg"],
            time_offset_s=s.get("dvl_time_offset_s"),
            states=s.get("states"),
            wall_s=s.get("timing_s", {}).get("total"),
        )
        if result is not None:
            evaluate_to_dir(result, out / "evaluation")
            metrics = json.loads((out / "evaluation" / "metrics.json").read_text())
            gnss = metrics.get("gnss") or {}
            mean, first = gnss.get("surfacing_error_mean"), gnss.get("surfacing_error")
            n_fixes = int(gnss.get("surfacing_fixes") or 0)
            # the mean over the last surfacing's held-out fixes when there are several, else the first fix's
            row["surfacing_error"] = mean if mean is not None and n_fixes > 1 else first
            row["surfacing_figure"] = (
                f"mean of {n_fixes} fixes"
                if mean is not None and n_fixes > 1
                else "first fix"
                if first is not None
                else None
            )
            row["errors"] = s.get("errors")
    except GtsamDvlError as exc:
        row.update(status="error", error=str(exc))
    except Exception as exc:  # noqa: BLE001 - one log's unexpected failure must not stop the fleet: reported
        row.update(status="error", error=f"{type(exc).__name__}: {exc}")
    return row


def run_names(logs: list[Path]) -> list[str]:
    """One readable folder name per log: the file's name without .mcap / .db3; where names clash, the parent
    folder's name before it (dive1/dive.mcap, dive2/dive.mcap: dive1_dive, dive2_dive); still clashing, a
    number after it (_2, _3, in the order given)."""

    def stem(p: Path) -> str:
        return p.name.removesuffix(".mcap").removesuffix(".db3") or "log"

    paths = [Path(p) for p in logs]
    names = [stem(p) for p in paths]
    names = [
        f"{p.absolute().parent.name}_{n}" if names.count(n) > 1 else n
        for p, n in zip(paths, names, strict=True)
    ]
    out: list[str] = []
    for n in names:
        k, name = 1, n
        while name in out:
            k += 1
            name = f"{n}_{k}"
        out.append(name)
    return out


def smooth_fleet(
    logs: list[Path],
    out_dir: Path,
    mode: str = "batch",
    config_path: Path | None = None,
    read_options: ReadOptions | None = None,
    engine: DaskEngine = LOCAL_CLUSTER,
    show_progress: bool = True,
) -> tuple[list[dict[str, Any]], list[Path]]:
    """`gtsam-dvl smooth LOG... --out-dir DIR`: every log smoothed in parallel with the same configuration, one
    folder per log (DIR/<log name>/), and a table of all runs (DIR/fleet.json, DIR/fleet.md). Tasks ship the
    log's path: a remote cluster's workers must see the same file system. One bad log gets its error line in
    the table; the others finish."""
    from gtsam_dvl.io.atomic import atomic_write_json, atomic_write_text

    if not logs:
        raise GtsamDvlError("no logs given")
    require_dask()  # before anything is written
    names = run_names(logs)
    out_dir = Path(out_dir)
    from gtsam_dvl.app.progress import progress_bar

    by_index: dict[
        int, dict[str, Any]
    ] = {}  # rows in the order the logs were given, whatever the completion order
    with engine.client() as client:
        futures = {
            client.submit(
                _smooth_task,
                str(Path(p).resolve()),
                str((out_dir / n).resolve()),
                mode,
                str(config_path.resolve()) if config_path else None,
                read_options,
                pure=False,
                retries=1,
            ): i
            for i, (p, n) in enumerate(zip(logs, names, strict=True))
        }
        with progress_bar(
            f"smoothing {len(logs)} logs ({mode})", enabled=show_progress
        ) as progress:
            for i, fut, exc in finished(futures, progress):
                by_index[i] = (
                    fut.result()
                    if exc is None
                    else {
                        "log": str(logs[i]),
                        "dir": str(out_dir / names[i]),
                        "status": "error",
                        "error": f"{type(exc).__name__}: {exc}",
                    }
                )
    rows = [by_index[i] for i in sorted(by_index)]
    table = "\n".join(fleet_table(rows)) + "\n"
    written = [
        atomic_write_json(out_dir / "fleet.json", rows),
        atomic_write_text(out_dir / "fleet.md", table),
    ]
    return rows, written


def fleet_table(rows: list[dict[str, Any]]) -> list[str]:
    """The fleet's table in Markdown: per log the health, scale, misalignment, time offset and surfacing error,
    or its error line."""
    lines = [
        "| log | health | scale | misalignment r/p/y (deg) | time offset (ms, + = stamps early) | "
        "surfacing error (last surfacing) |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        name = Path(r["dir"]).name  # the run's folder: unique and readable (run_names)
        if r["status"] == "error":
            lines.append(f"| {name} | error | {r['error']} | | | |")
            continue
        sc, mis = r["scale"], r["misalignment_deg"]
        off, surf = r.get("time_offset_s"), r.get("surfacing_error")
        cells = [
            name,
            r["status"],
            f"{sc['value']:.5f} +- {sc['sigma']:.5f}",
            " ".join(f"{v:+.3f}" for v in mis["value"])
            + " +- "
            + " ".join(f"{v:.3f}" for v in mis["sigma"]),
            f"{off['value'] * 1e3:+.1f} +- {off['sigma'] * 1e3:.1f}" if off else "-",
            (
                f"{surf['horizontal_error_m']:.2f} m ({surf['horizontal_error_pct']:.3f} % of "
                f"{surf['distance_m']:.0f} m), {r.get('surfacing_figure') or 'first fix'}"
            )
            if surf
            else "-",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines
