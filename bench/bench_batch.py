"""Batch smoother wall time on paper-3d: read, build (preintegration + factors), solve, marginals, and the
real-time factor, as smooth_batch runs them (the DVL and IMU factors in bulk, estimators/graph/bulk.py and bulk_imu.py),
against the same stages with every factor a Python CustomFactor evaluated one by one (the per-factor graph, the
baseline) in the same run; then GTSAM's own Levenberg-Marquardt (QR) on the per-factor graph.

    .venv/bin/python bench/bench_batch.py [--log run.mcap] [--no-baseline]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path
from typing import Any

import gtsam

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.solve import extract_result, solve_graph
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario


def run(log: LogData, cfg: EstimatorConfig, bulk: bool) -> dict[str, Any]:
    """smooth_batch's stages (the paper configuration: one pass), with the DVL and IMU factors in bulk or one by
    one."""
    out: dict[str, Any] = {}
    t0 = time.perf_counter()
    builder = LogGraph(log, cfg)
    out["preintegrate"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph, init = builder.build_bulk() if bulk else builder.build()
    ordering = builder.elimination_ordering()
    out["build graph"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph, values, report, _ = solve_graph(builder, graph, init, ordering)  # as smooth_batch
    out["solve"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = extract_result(builder, graph, values, ordering, bayes_net=report.bayes_net)
    out["marginals"] = time.perf_counter() - t0
    out["total"] = sum(out[k] for k in ("preintegrate", "build graph", "solve", "marginals"))
    out.update(
        result=result,
        report=report,
        graph=graph,
        init=init,
        values=values,
        states=len(builder.epochs),
    )
    return out


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
    duration = float(log.imu.t[-1] - log.imu.t[0])
    runs = {name: run(log, cfg, bulk) for name, bulk in (("bulk", True), ("per-factor", False))}
    fast, slow = runs["bulk"], runs["per-factor"]
    print(
        f"log: {path.name}, {duration:.0f} s, {len(log.imu)} IMU, {fast['states']} states; "
        f"read {t_read:.3f} s (counted in both totals)"
    )
    print(f"{'stage':<28}{'bulk (product)':>20}{'per-factor (baseline)':>24}{'ratio':>8}")
    for stage in ("preintegrate", "build graph", "solve", "marginals"):
        print(
            f"{stage:<28}{fast[stage]:>20.3f}{slow[stage]:>24.3f}{slow[stage] / fast[stage]:>8.2f}"
        )
    tot_f, tot_s = t_read + fast["total"], t_read + slow["total"]
    print(f"{'total (read to marginals)':<28}{tot_f:>20.3f}{tot_s:>24.3f}{tot_s / tot_f:>8.2f}")
    for name, r in runs.items():
        rep = r["report"]
        print(
            f"  {name}: {rep.iterations} GN iterations, linearize {rep.timing_s['linearize']:.3f} s, eliminate "
            f"{rep.timing_s['eliminate']:.3f} s, final error {rep.final_error:.6f}"
        )
    print(f"real-time factor: {duration / tot_f:.0f}x   (target: total under 1.5 s)")
    rf, rs = fast["result"], slow["result"]
    print(
        f"scale {rf.scale:.6f} +- {rf.scale_sigma:.6f} (per-factor {rs.scale:.6f} +- {rs.scale_sigma:.6f}; "
        f"difference {abs(rf.scale - rs.scale) / rs.scale_sigma:.1e} sigma)"
    )
    graph, init, values = slow["graph"], slow["init"], slow["values"]
    t_solve = slow["solve"]

    if not args.no_baseline:
        params = gtsam.LevenbergMarquardtParams()
        params.setLinearSolverType("MULTIFRONTAL_QR")
        params.setOrderingType("COLAMD")
        params.setMaxIterations(50)
        t0 = time.perf_counter()
        lm_values = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
        t_lm = time.perf_counter() - t0
        print(
            f"baseline GTSAM LevenbergMarquardtOptimizer (QR) on the same graph: {t_lm:.2f} s "
            f"(ours {t_solve:.2f} s: {t_lm / t_solve:.1f}x faster); final error ours {graph.error(values):.3f}, "
            f"LM {graph.error(lm_values):.3f}"
        )


if __name__ == "__main__":
    main()
