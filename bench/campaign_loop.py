"""What the Monte Carlo benchmarks (realistic_logs.py, underway_calibration.py, water_track.py, correlated_fit.py)
share: their common command-line options, and the loop that runs their seeds on a local Dask cluster and writes
the runs so far as they finish (partial results survive an interrupted campaign).

Imported by the benchmark scripts as a sibling module (`python bench/<script>.py` puts bench/ on sys.path); not a
benchmark itself.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

Summarise = Callable[[list[dict[str, Any]]], Any]


def campaign_parser(doc: str | None, runs: int, out: str) -> argparse.ArgumentParser:
    """An argument parser with the options every campaign benchmark takes: --runs (seeds per scenario, default
    runs), --seed-start (the first seed) and --out (the JSON of the runs and their summary, default out)."""
    ap = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--runs", type=int, default=runs)
    ap.add_argument("--seed-start", type=int, default=1)
    ap.add_argument("--out", type=Path, default=Path(out))
    return ap


def seeds(args: argparse.Namespace) -> range:
    """The seeds --seed-start and --runs name."""
    return range(args.seed_start, args.seed_start + args.runs)


def write_runs(out: Path, runs: list[dict[str, Any]], summarise: Summarise) -> None:
    """The runs so far and their summary as JSON at out, replaced whole (never half written)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(json.dumps({"runs": runs, "summary": summarise(runs)}, indent=1))
    tmp.replace(out)


def run_on_dask(
    fn: Callable[..., dict[str, Any]],
    tasks: Sequence[tuple[Any, ...]],
    workers: int,
    out: Path,
    summarise: Summarise,
    every: int,
    **kwargs: Any,
) -> list[dict[str, Any]]:
    """fn(*task, **kwargs) for each task on a local Dask cluster of `workers` processes, in the order they finish;
    the progress on one line, and the runs so far written to out (write_runs) every `every` runs and at the end."""
    from dask.distributed import as_completed

    from gtsam_dvl.app.campaign.cluster import dask_client

    t0 = time.perf_counter()
    runs: list[dict[str, Any]] = []
    with dask_client(None, workers) as client:
        futures = [client.submit(fn, *task, **kwargs, pure=False) for task in tasks]
        for k, fut in enumerate(as_completed(futures), 1):
            runs.append(fut.result())
            print(f"\r{k}/{len(tasks)} runs, {time.perf_counter() - t0:.0f} s", end="", flush=True)
            if k % every == 0 or k == len(tasks):
                write_runs(out, runs, summarise)
    print(f"\n{len(tasks)} runs on {workers} workers in {time.perf_counter() - t0:.0f} s; {out}")
    return runs
