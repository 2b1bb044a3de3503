"""The EKF's time offset over seeds of a scenario, with the default configuration, as a user runs it.

Each seed is simulated, written as MCAP and read back (a scenario with gnss.origin_in_log = false, as field-survey,
then has its map origin in the first fix, as a reader finds it), filtered by the EKF (estimators/ekf/filter.py
run_ekf, the scenario's configuration) and judged by analysis/health.py. Printed per seed: the time offset's
estimate and sigma, its error in sigmas against the truth, the health verdict, where the warm-up centred the
offset's prior (or "kept" and the configured centre), whether the divergence watch fired, and the wall time; then
how many seeds end within 3 sigma and how many "failed". One process, the seeds one after another.

    .venv/bin/python bench/ekf_seeds.py [--scenario field-survey] [--seeds 1-20] [--out ekf_seeds.json]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

NSIGMA = 3.0


def seed_list(spec: str) -> list[int]:
    """ "1-20" or "3,5,7" (or both, comma-separated) as a list of seeds."""
    out: list[int] = []
    for part in spec.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def run_seed(scenario_name: str, seed: int, folder: Path) -> dict[str, Any]:
    """One seed through MCAP and the EKF (module doc)."""
    from gtsam_dvl.analysis.health import assess_health
    from gtsam_dvl.estimators.ekf.filter import run_ekf
    from gtsam_dvl.io.reader import read_log
    from gtsam_dvl.io.writer import write_log
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    path = folder / f"{scenario_name}-{seed}.mcap"
    write_log(path, simulate(load_scenario(scenario_name), seed))
    log = read_log(path)
    assert log.true_calibration is not None
    t0 = time.perf_counter()
    result = run_ekf(log)
    wall = time.perf_counter() - t0
    health = assess_health(result, log)
    truth = log.true_calibration.time_offset_s
    prior = result.info.get("time_offset_prior") or {}
    return {
        "seed": seed,
        "truth_s": truth,
        "offset_s": float(result.time_offset_s),
        "sigma_s": float(result.time_offset_sigma_s),
        "nsigma": float((result.time_offset_s - truth) / result.time_offset_sigma_s),
        "health": health.status,
        "prior_centre_s": prior.get("centre_s"),
        "prior_why": prior.get("why"),
        "diverged_at_s": result.info["filter"].get("diverged_at_s"),
        "time_offset_bounded": int(result.info["counters"].get("time_offset_bounded", 0)),
        "warnings": list(health.warnings),
        "wall_s": wall,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="field-survey")
    parser.add_argument("--seeds", default="1-20")
    parser.add_argument("--out", type=Path, default=None, help="every seed's row as JSON")
    args = parser.parse_args()
    rows = []
    print(f"EKF on {args.scenario}, default configuration, seeds {args.seeds}")
    print(
        "| seed | offset (s) | sigma (s) | nsigma | health | prior centre (s) | diverged | wall (s) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seed_list(args.seeds):
            r = run_seed(args.scenario, seed, Path(tmp))
            rows.append(r)
            centre = "kept" if r["prior_centre_s"] is None else f"{r['prior_centre_s']:+.3f}"
            diverged = "-" if r["diverged_at_s"] is None else f"{r['diverged_at_s']:.0f} s"
            print(
                f"| {r['seed']} | {r['offset_s']:+.3f} | {r['sigma_s']:.3f} | {r['nsigma']:+.2f} | {r['health']} | "
                f"{centre} | {diverged} | {r['wall_s']:.1f} |",
                flush=True,
            )
    within = sum(abs(r["nsigma"]) < NSIGMA for r in rows)
    failed = sum(r["health"] == "failed" for r in rows)
    print(
        f"{within} of {len(rows)} within {NSIGMA:g} sigma of the truth, {failed} failed "
        f"({time.perf_counter() - t0:.0f} s)"
    )
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
