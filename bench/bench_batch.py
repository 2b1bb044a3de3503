"""Batch smoother wall time on paper-3d: read, build (preintegration + factors), solve, marginals, and the
real-time factor; GTSAM's own Levenberg-Marquardt (QR) on the same graph as the baseline, in the same run.

    .venv/bin/python bench/bench_batch.py [--log run.mcap] [--no-baseline]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import gtsam

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.estimators.batch import extract_result
from gtsam_dvl.estimators.graph import LogGraph
from gtsam_dvl.estimators.solver import gauss_newton_qr
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--log", type=Path, help="an existing log (default: simulate paper-3d, seed 7)")
    ap.add_argument("--no-baseline", action="store_true", help="skip GTSAM's LM optimiser (slow)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.log
        if path is None:
            path = Path(tmp) / "paper-3d.mcap"
            write_log(path, simulate(load_scenario("paper-3d"), 7))
        t0 = time.perf_counter()
        log = read_log(path)
        t_read = time.perf_counter() - t0

    cfg = EstimatorConfig.paper()
    t0 = time.perf_counter()
    builder = LogGraph(log, cfg)
    t_pre = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph, init = builder.build()
    ordering = builder.elimination_ordering()
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    values, report = gauss_newton_qr(graph, init, ordering, before_iteration=builder.refresh_gravity)
    t_solve = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = extract_result(builder, graph, values, ordering, bayes_net=report.bayes_net)
    t_marg = time.perf_counter() - t0
    total = t_read + t_pre + t_build + t_solve + t_marg
    duration = float(log.imu.t[-1] - log.imu.t[0])
    print(f"log: {path.name}, {duration:.0f} s, {len(log.imu)} IMU, {len(builder.epochs)} states")
    print(f"{'stage':<28}{'seconds':>10}")
    for name, sec in [("read", t_read), ("preintegrate", t_pre), ("build graph", t_build),
                      (f"solve ({report.iterations} GN iterations)", t_solve), ("marginals", t_marg),
                      ("total", total)]:
        print(f"{name:<28}{sec:>10.3f}")
    print(f"real-time factor: {duration / total:.0f}x   (target: total under 3 s)")
    lin, elim = report.timing_s["linearize"], report.timing_s["eliminate"]
    print(f"  of the solve: linearize {lin:.3f} s, eliminate {elim:.3f} s")
    print(f"scale {result.scale:.6f} +- {result.scale_sigma:.6f}")

    if not args.no_baseline:
        params = gtsam.LevenbergMarquardtParams()
        params.setLinearSolverType("MULTIFRONTAL_QR")
        params.setOrderingType("COLAMD")
        params.setMaxIterations(50)
        t0 = time.perf_counter()
        lm_values = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
        t_lm = time.perf_counter() - t0
        print(f"baseline GTSAM LevenbergMarquardtOptimizer (QR) on the same graph: {t_lm:.2f} s "
              f"(ours {t_solve:.2f} s: {t_lm / t_solve:.1f}x faster); final error ours {graph.error(values):.3f}, "
              f"LM {graph.error(lm_values):.3f}")


if __name__ == "__main__":
    main()
