"""`calibrate` on 4 simulated paper-3d dives: accuracy against one dive, the truth and the one-graph solve, and the
wall time on Dask with 1 and 2 workers.

    .venv/bin/python bench/calibrate_workers.py [--scenario paper-3d] [--dives 4] [--repeats 2]

Simulates the dives (seeds 1..N, the same truth calibration) as MCAP logs, then
1. in this process: each dive prepared once (smoothed alone), the joint calibration (estimators/batch/multi_dive.py,
   the per-dive reduction) and, on the same prepared dives, the one-graph solve (every dive's linearised factors
   in ONE graph, solved at once): joint sigma / (mean one-dive sigma) against 1/sqrt(N), the distance between
   the two solutions in joint sigmas, and the joint calibration's error against the truth in sigmas;
2. on a Dask LocalCluster of 1 and one of 2 workers (both up, warmed: imports done before timing; the runs
   alternated), the whole calibrate from the log files (read, smooth alone, joint iterations), the best of
   --repeats runs each; prints both times
   and their ratio, and how long the preparation takes against a joint iteration (what keeping each dive's state
   on its worker saves per iteration: a dive rebuilt from its log would cost its preparation again);
3. pieces: a dive (seed 3) with its IMU samples of 30 s in a turn removed (paper-3d: 1070-1100 s), smoothed
   (estimators/batch/pieces.py: two pieces sharing the calibration) against the truth, and the same dive without the
   gap.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from gtsam_dvl.app.campaign.calibrate import calibrate_logs
from gtsam_dvl.app.campaign.cluster import dask_client
from gtsam_dvl.app.commands import simulate_to_file
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_log
from gtsam_dvl.estimators.batch import multi_dive as md
from gtsam_dvl.io.reader import read_log


def _warm() -> None:
    import gtsam_dvl.app.campaign.calibrate  # noqa: F401 - the workers' imports, before timing


def accuracy(paths: list[Path]) -> None:
    logs = [read_log(p) for p in paths]
    t0 = time.perf_counter()
    dives = [md.prepare_dive(log, name=p.name) for log, p in zip(logs, paths, strict=True)]
    t1 = time.perf_counter()
    one = md.solve_one_graph(dives)
    t2 = time.perf_counter()
    joint = md.calibrate_in_process(dives)
    t3 = time.perf_counter()
    n = len(dives)
    print(
        f"in this process: {n} dives prepared in {t1 - t0:.1f} s, one-graph solve {t2 - t1:.1f} s "
        f"({one.iterations} iterations), calibrate's joint iterations {t3 - t2:.1f} s ({joint.iterations})"
    )
    sig = np.sqrt(np.diag(joint.cov))
    alone = np.array(
        [np.concatenate([d.alone.calibration[s].sigma for s in joint.states]) for d in dives]
    )
    cols = [c for s in joint.states for c in md.BY_NAME[s].component_names()]
    ratio = sig / alone.mean(axis=0)
    print(
        f"sigma joint / mean sigma of one dive (1/sqrt({n}) = {1 / np.sqrt(n):.3f}; within 15 %: "
        f"{np.all(np.abs(ratio * np.sqrt(n) - 1) <= 0.15)}):"
    )
    for c, r, s in zip(cols, ratio, sig, strict=True):
        print(f"  {c:20s} {r:.3f}  ({(r * np.sqrt(n) - 1) * 100:+.1f} %), joint sigma {s:.3g}")
    sl = md.state_slices(joint.states)
    d_one = (
        np.concatenate(
            [
                joint.values["scale"] - one.values["scale"],
                so3_log(one.values["misalignment"].T @ joint.values["misalignment"]),
            ]
        )
        / sig[:4]
    )
    print(
        f"calibrate - one graph, in joint sigmas: {np.array2string(d_one, precision=2)} (max |.| "
        f"{np.max(np.abs(d_one)):.2g}); sigma ratio calibrate / one graph "
        f"{np.array2string(sig / np.sqrt(np.diag(one.cov)), precision=6)}"
    )
    truth = logs[0].true_calibration
    if truth is not None:
        b_R_d = rpy_deg_to_matrix(truth.misalignment_deg) @ np.asarray(logs[0].mounting.b_R_d0)
        err = (
            np.concatenate(
                [
                    joint.values["scale"] - truth.scale,
                    so3_log(b_R_d.T @ joint.values["misalignment"]),
                ]
            )
            / sig[sl["scale"].start : 4]
        )
        print(
            f"joint calibration - truth, in joint sigmas: {np.array2string(err, precision=2)} (within 3: "
            f"{np.all(np.abs(err) <= 3)})"
        )


def pieces(scenario: str) -> None:
    import dataclasses

    from gtsam_dvl.estimators.batch.pieces import _take
    from gtsam_dvl.estimators.batch.smoother import smooth_batch
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    # in the second (short: first) turn
    gap = (1070.0, 1100.0) if scenario == "paper-3d" else (285.0, 315.0)
    whole = simulate(load_scenario(scenario), seed=3)
    keep = (whole.imu.t <= gap[0]) | (whole.imu.t > gap[1])
    log = dataclasses.replace(whole, imu=_take(whole.imu, keep))
    t0 = time.perf_counter()
    r = smooth_batch(log)
    dt = time.perf_counter() - t0
    ref = smooth_batch(whole)
    truth = log.true_calibration
    assert truth is not None and log.truth is not None
    b_R_d = rpy_deg_to_matrix(truth.misalignment_deg) @ np.asarray(log.mounting.b_R_d0)
    mis = r.calibration["misalignment"]
    z = np.concatenate(
        [[(r.scale - truth.scale) / r.scale_sigma], so3_log(b_R_d.T @ mis.value) / mis.sigma]
    )
    j = np.searchsorted(log.truth.t, r.t[-1])
    err = float(np.linalg.norm(r.n_p[-1, :2] - log.truth.n_p[j, :2]))
    alone = [p["alone"]["scale"]["sigma"][0] * 1e6 for p in r.info["pieces"]]
    print(
        f"pieces: {scenario} seed 3 with a {gap[1] - gap[0]:.0f} s IMU gap at {gap[0]:.0f} s: "
        f"{len(r.info['pieces'])} pieces in {dt:.1f} s; scale, misalignment r/p/y - truth in sigmas "
        f"{np.array2string(z, precision=2)} (within 3: {np.all(np.abs(z) < 3)}); scale sigma "
        f"{r.scale_sigma * 1e6:.0f} ppm (pieces alone {', '.join(f'{a:.0f}' for a in alone)}; the log without "
        f"the gap {ref.scale_sigma * 1e6:.0f}); final horizontal position error {err:.1f} m"
    )


def _burn(n: int = 20_000_000) -> float:
    t0 = time.perf_counter()
    s = 0
    for i in range(n):
        s += i
    return time.perf_counter() - t0


def machine_parallelism() -> float:
    """What 2 processes get on this machine now: twice one pure-Python loop's time over the wall time of two at
    once (2.0 on two idle cores; less while other processes hold a core): the ceiling of the 2-worker speed-up."""
    import multiprocessing

    one = _burn()
    with multiprocessing.get_context("spawn").Pool(2) as pool:
        pool.map(_burn, [1000, 1000])  # the processes started before timing
        t0 = time.perf_counter()
        pool.map(_burn, [20_000_000, 20_000_000])
        two = time.perf_counter() - t0
    return 2 * one / two


def _run(paths: list[Path], client: object) -> tuple[float, dict[str, float]]:
    t0 = time.perf_counter()
    out = calibrate_logs(paths, show_progress=False, client=client)
    timing = dict(out.timing_s)
    timing["iterations"] = float(out.solution.iterations) if out.solution else 0.0
    return time.perf_counter() - t0, timing


def timed(paths: list[Path], repeats: int) -> dict[int, tuple[float, dict[str, float]]]:
    """The best of `repeats` runs on 1 and on 2 workers, the two clusters up at once and the runs alternated (the
    machine's other load falls on both alike)."""
    best: dict[int, tuple[float, dict[str, float]]] = {1: (np.inf, {}), 2: (np.inf, {})}
    with dask_client(None, 1) as one, dask_client(None, 2) as two:
        for client in (one, two):
            client.run(_warm)
        for _ in range(repeats):
            for w, client in ((1, one), (2, two)):
                dt, timing = _run(paths, client)
                if dt < best[w][0]:
                    best[w] = (dt, timing)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--scenario", default="paper-3d")
    ap.add_argument("--dives", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for seed in range(1, args.dives + 1):
            p = Path(tmp) / f"{args.scenario}-seed{seed}.mcap"
            simulate_to_file(args.scenario, p, seed=seed, show_progress=False)
            paths.append(p)
        print(f"{args.dives} dives of {args.scenario} (seeds 1-{args.dives})")
        accuracy(paths)
        ceiling = machine_parallelism()
        best = timed(paths, args.repeats)
        ceiling = min(ceiling, machine_parallelism())
        (t1, timing1), (t2, timing2) = best[1], best[2]
        for w, t, timing in ((1, t1, timing1), (2, t2, timing2)):
            per_it = timing["joint"] / max(timing["iterations"], 1.0)
            print(
                f"Dask, {w} worker{'s' if w > 1 else ''}: {t:.2f} s (read and smooth alone {timing['prepare']:.2f} "
                f"s, joint {timing['joint']:.2f} s = {timing['iterations']:.0f} iterations, {per_it:.2f} s each)"
            )
        print(
            f"speed-up 2 workers / 1 worker: {t1 / t2:.2f}x (best of {args.repeats} runs each, alternated; "
            f"load average {os.getloadavg()[0]:.1f} at the end); two pure-Python processes got {ceiling:.2f}x "
            "(the machine's ceiling now, the lower of before and after)"
        )
    pieces(args.scenario)


if __name__ == "__main__":
    main()
