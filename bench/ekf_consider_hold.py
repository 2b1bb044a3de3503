"""The EKF's hold at the nominal calibration against the nominal peer on a realistic log (bench/realistic_logs.py's
"defaults" and "nominal" variants), with the final position's consistency and the ratio's sampling interval.

On realistic-turn (a 400 s steady turn: the scale and misalignment do not pay for their states, so the nominal
check holds them) the EKF filters again with them as consider states (a Schmidt-Kalman filter: their prior's
uncertainty in every gain, their values at nominal), where the batch smoother's hold keeps the solution at the
nominal calibration and adds the prior's uncertainty to the covariance, and the peer fixes them (prior sigmas far
below what the data resolve). Per seed: the final horizontal error (% of the distance run) and its normalised
squared error against the reported horizontal covariance (NIS, 2 dof: 2 on average when the covariance is right)
for the batch smoother, the EKF (held), the EKF estimating the calibration (no nominal check) and the peer. Then per
estimator the RMS error, its ratio to the peer's with a paired bootstrap 90 % interval over the seeds, and the mean
NIS / 2. One process, the seeds one after another.

    .venv/bin/python bench/ekf_consider_hold.py [--scenario realistic-turn] [--seeds 1-20]
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np
from ekf_seeds import seed_list
from realistic_logs import _with, variant_runs

ESTIMATORS = ("batch", "ekf", "ekf estimating", "peer")
BOOTSTRAP = 4000


def final_horizontal(res: Any, log: Any) -> tuple[float, float]:
    """The final horizontal error in % of the distance run, and its NIS against the reported covariance."""
    truth = log.truth
    distance = float(np.sum(np.linalg.norm(np.diff(truth.n_p[:, :2], axis=0), axis=1)))
    e = res.n_p[-1, :2] - np.array(
        [np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)]
    )
    R = res.n_R_b[-1]
    cov = (R @ res.pose_cov[-1, 3:, 3:] @ R.T)[
        :2, :2
    ]  # the pose's translation tangent is in body axes
    return 100.0 * float(np.linalg.norm(e)) / distance, float(e @ np.linalg.solve(cov, e))


def main() -> None:
    from gtsam_dvl.estimators.run import run_trajectory_estimator
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="realistic-turn")
    parser.add_argument("--seeds", default="1-20")
    args = parser.parse_args()
    sc = load_scenario(args.scenario)
    rows: dict[str, list[tuple[float, float]]] = {name: [] for name in ESTIMATORS}
    t0 = time.perf_counter()
    print("| seed | " + " | ".join(f"{n} error (%), NIS" for n in ESTIMATORS) + " |")
    print("| --- |" + " --- |" * len(ESTIMATORS))
    for seed in seed_list(args.seeds):
        log = simulate(sc, seed)
        runs = variant_runs(log, sc.estimator_configuration())
        base = runs["defaults"][1]
        cases = {
            "batch": ("batch", base),
            "ekf": ("ekf", base),
            "ekf estimating": ("ekf", _with(base, "priors", nominal_check=False)),
            "peer": ("ekf", runs["nominal"][1]),
        }
        line = []
        for name, (mode, cfg) in cases.items():
            res = run_trajectory_estimator(log, mode, cfg, timeline=False)
            rows[name].append(final_horizontal(res, log))
            line.append(f"{rows[name][-1][0]:.3f}, {rows[name][-1][1]:.2f}")
        print(f"| {seed} | " + " | ".join(line) + " |", flush=True)
    rng = np.random.default_rng(0)
    peer = np.array([r[0] for r in rows["peer"]])
    draws = rng.integers(0, len(peer), (BOOTSTRAP, len(peer)))
    print("\n| estimator | RMS error (%) | ratio to the peer | 90 % interval | mean NIS / 2 |")
    print("| --- | --- | --- | --- | --- |")
    for name in ESTIMATORS:
        err = np.array([r[0] for r in rows[name]])
        nis = np.array([r[1] for r in rows[name]])
        ratio = np.sqrt(np.mean(err**2) / np.mean(peer**2))
        boot = np.sqrt(np.mean(err[draws] ** 2, axis=1) / np.mean(peer[draws] ** 2, axis=1))
        lo, hi = np.percentile(boot, [5, 95])
        print(
            f"| {name} | {np.sqrt(np.mean(err**2)):.3f} | {ratio:.3f} | {lo:.3f}-{hi:.3f} | "
            f"{np.mean(nis) / 2:.2f} |"
        )
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
