"""Are the batch smoother's sigmas honest? Runs paper-3d (or another scenario) over many seeds and prints,
per state, the mean and standard deviation of error / sigma (z-scores); a consistent estimator gives mean
~0 and std ~1 (with N seeds the std itself is uncertain by about 1/sqrt(2N)).

    .venv/bin/python bench/bench_consistency.py [--scenario paper-3d] [--seeds 16]
"""

from __future__ import annotations

import argparse

import numpy as np

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

NAMES = [
    "scale",
    "mis roll",
    "mis pitch",
    "mis yaw",
    "gyro x",
    "gyro y",
    "gyro z",
    "acc x",
    "acc y",
    "acc z",
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenario", default="paper-3d")
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--first-seed", type=int, default=20)
    args = ap.parse_args()
    scenario = load_scenario(args.scenario)
    rows, pos = [], []
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        log = simulate(scenario, seed)
        s = summary(smooth_batch(log), log)
        e = s["errors"]
        rows.append(
            [
                e["scale_nsigma"],
                *e["misalignment_nsigma"],
                *e["gyro_bias_nsigma"],
                *e["accel_bias_nsigma"],
            ]
        )
        pos.append(e["final_horizontal_position_m"] / s["final_horizontal_position_sigma_m"])
        print(f"seed {seed}: z = {np.round(rows[-1], 2).tolist()}", flush=True)
    z = np.array(rows)
    print(f"\n{args.scenario}, {args.seeds} seeds: error / sigma per state")
    print(f"{'state':<10}{'mean':>8}{'std':>8}{'max |z|':>9}")
    for j, name in enumerate(NAMES):
        print(
            f"{name:<10}{z[:, j].mean():>8.2f}{z[:, j].std(ddof=1):>8.2f}{np.abs(z[:, j]).max():>9.2f}"
        )
    print(f"final horizontal position error / horizontal sigma: mean {np.mean(pos):.2f}")


if __name__ == "__main__":
    main()
