"""Monte Carlo engine on this machine: wall time of a fixed campaign with 1 and 2 Dask workers (LocalCluster,
one process and thread each), the scaling ratio, and the overhead per task against the estimators' own time
(the wall time the runs report), all measured in the same run.

    .venv/bin/python bench/bench_montecarlo.py [--runs 8] [--scenario paper-3d-short] [--estimators batch,ekf]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

from gtsam_dvl.app.campaign.cluster import DaskEngine
from gtsam_dvl.app.campaign.runner import run_campaign


def campaign(
    scenario: str, runs: int, estimators: list[str], workers: int, folder: Path
) -> tuple[float, float]:
    """(wall time of the campaign, sum of the estimators' own wall times over its runs), seconds."""
    t0 = time.perf_counter()
    run_campaign(
        scenario, runs, estimators, folder, engine=DaskEngine(workers=workers), show_progress=False
    )
    wall = time.perf_counter() - t0
    own = sum(
        sum(e["wall_s"] for e in json.loads(p.read_text())["estimators"].values())
        for p in (folder / "runs").glob("seed_*.json")
    )
    return wall, own


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--scenario", default="paper-3d-short")
    ap.add_argument("--estimators", default="batch,ekf")
    args = ap.parse_args()
    estimators = args.estimators.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        results = {}
        for workers in (1, 2):
            results[workers] = campaign(
                args.scenario, args.runs, estimators, workers, Path(tmp) / f"w{workers}"
            )
    print(f"campaign: {args.runs} runs of {args.scenario}, estimators {args.estimators}")
    print("workers | wall (s) | estimators' own time (s) | overhead per task (s) | overhead share")
    for workers, (wall, own) in results.items():
        # the campaign's wall time times its workers, minus the estimators' own time: simulation, cluster start,
        # scheduling, the Cramer-Rao task and the report, spread over the tasks
        overhead = (wall * workers - own) / args.runs
        share = overhead * args.runs / (wall * workers)
        print(f"{workers:7d} | {wall:8.1f} | {own:24.1f} | {overhead:21.2f} | {share:.0%}")
    w1, w2 = results[1][0], results[2][0]
    print(f"scaling 1 -> 2 workers: {w1 / w2:.2f}x faster (ideal 2.00x)")


if __name__ == "__main__":
    main()
