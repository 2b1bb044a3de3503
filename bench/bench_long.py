"""Long missions in the batch smoother: wall time per stage, peak RSS and real-time factor of the
survey-24h scenario (200 Hz IMU, 5 Hz DVL, the paper's IMU grade, survey-6h's calibration manoeuvres at the
start) cut to 1, 3, 6, 12 and 24 h, and the cost against mission length, measured in one run.

    .venv/bin/python bench/bench_long.py [--hours 1 3 6 12 24] [--cache DIR] [--keyframe-spacing S]
                                         [--config default|paper] [--per-ping-hours 6]

Each length is its own simulation of survey-24h.toml with fewer lawnmower lines (the same start, the same
ascent and stop at the end; 1 h = 3 lines, 3 h = 13, 6 h = 28 as survey-6h, 12 h = 58, 24 h = 118), simulated
once with seed 7 and cached as an MCAP in the cache folder (default ~/.cache/gtsam_dvl/bench_long), reused
when present. Every simulation and every smoother run is a fresh subprocess, so that each peak RSS
(resource.getrusage(RUSAGE_SELF).ru_maxrss) is its own. Stages: read (read_log), epochs (the states and their
pings), preintegration, factors (the IMU factors, then the initial guess and the graph), solve (linearise,
eliminate, both passes when the time offset is estimated) and marginals. The smoother runs with the
configuration's defaults; --keyframe-spacing sets [solver] keyframe_spacing_s when the configuration has it,
and --per-ping-hours runs those lengths a second time with a state per ping (keyframe_spacing_s = 0) and
prints both solutions' calibration sigmas side by side.

The logs are simulated in 600 s chunks straight into the MCAP (gtsam_dvl.sim.stream.ChunkedSimulation written by
gtsam_dvl.io.writer.write_log_stream: the file write_log writes of simulate()'s log, byte for byte, in a memory
that does not grow with the mission): a length is skipped, and said so, only if even that would need more than
--sim-memory-gb.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "data" / "scenarios" / "survey-24h.toml"
SEED = 7
# peak RSS of the chunked simulation (write_log_stream of ChunkedSimulation, 600 s chunks at 200 Hz): this script
# prints it for each length (docs/results.md, "Speed"); it does not grow with the mission
SIM_GB_PER_H = 0.0
SIM_GB_FIXED = 0.3


def peak_rss_gib() -> float:
    """Peak resident set size of this process so far (ru_maxrss is in KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20


def scenario_hours(hours: float) -> dict[str, Any]:
    """survey-24h's TOML dict with as many lawnmower lines as fit ``hours``: the first four segments (the
    static alignment and the calibration manoeuvres, 750 s), pairs of a 600 s line and a 120 s turn, the last
    570 s line and the 120 s of surge, ascent and stop."""
    raw = tomllib.loads(SCENARIO.read_text())
    segs = raw["segments"]
    pairs = int(round((hours * 3600.0 - 750.0 - 570.0 - 120.0) / 720.0))
    if pairs < 0 or 4 + 2 * pairs > len(segs) - 4:
        raise SystemExit(f"--hours {hours:g}: between 0.4 and 24 h")
    raw["segments"] = segs[:4] + segs[4 : 4 + 2 * pairs] + segs[-4:]
    raw["name"] = f"survey-24h-cut-{hours:g}h"
    return raw


def cached_log(cache: Path, hours: float) -> Path:
    return cache / f"survey-24h-{hours:g}h-seed{SEED}.mcap"


# ----- child processes ----------------------------------------------------------------------------------
def child_simulate(hours: float, out: Path) -> dict[str, Any]:
    from gtsam_dvl.io.writer import write_log_stream
    from gtsam_dvl.sim.scenario import scenario_from_dict
    from gtsam_dvl.sim.stream import ChunkedSimulation

    sc = scenario_from_dict(scenario_hours(hours), f"survey-24h-cut-{hours:g}h", str(SCENARIO))
    # simulation and writing interleave, chunk by chunk
    res = write_log_stream(out, ChunkedSimulation(sc, SEED))
    return {
        "simulate_s": res["seconds"] - res["write_seconds"],
        "write_s": res["write_seconds"],
        "peak_rss_gib": peak_rss_gib(),
        "imu": res["imu"],
        "pings": res["dvl"],
        "mb": out.stat().st_size / 1e6,
    }


def child_smooth(path: Path, config: str, spacing: float | None) -> dict[str, Any]:
    """One batch run with the stages timed by wrapping LogGraph's and FactorMaker's own steps."""
    import gtsam

    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.estimators.batch.solve import extract_result, solve_graph
    from gtsam_dvl.estimators.graph import log_graph as graph_mod
    from gtsam_dvl.io.reader import read_log

    stages: dict[str, float] = {}
    rss: dict[str, float] = {}

    def timed(owner: Any, name: str, stage: str) -> None:
        fn = getattr(owner, name)

        def wrapper(*a: Any, **k: Any) -> Any:
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                stages[stage] = stages.get(stage, 0.0) + time.perf_counter() - t

        setattr(owner, name, wrapper)

    timed(graph_mod.LogGraph, "_select_epochs", "epochs")
    timed(graph_mod.LogGraph, "_preintegrate", "preintegration")
    timed(graph_mod.FactorMaker, "new_imu_factor", "factors")

    cfg = EstimatorConfig.named(config)
    if spacing is not None:
        if not hasattr(cfg.solver, "keyframe_spacing_s"):
            raise SystemExit(
                "--keyframe-spacing: this version's [solver] has no keyframe_spacing_s"
            )
        cfg.solver.keyframe_spacing_s = spacing
    cfg = cfg.validate()
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    log = read_log(path)
    stages["read"] = time.perf_counter() - t0
    rss["read"] = peak_rss_gib()
    t0 = time.perf_counter()
    builder = graph_mod.LogGraph(log, cfg)
    t_graph = time.perf_counter() - t0
    stages["epochs, other"] = (
        t_graph
        - stages.get("epochs", 0.0)
        - stages.get("preintegration", 0.0)
        - stages.get("factors", 0.0)
    )
    rss["preintegration"] = peak_rss_gib()
    t0 = time.perf_counter()
    # as smooth_batch: the DVL factors in bulk where the configuration allows (estimators/graph/bulk.py)
    graph, values = builder.build_bulk()
    ordering = builder.elimination_ordering()
    stages["factors"] = stages.get("factors", 0.0) + time.perf_counter() - t0
    rss["factors"] = peak_rss_gib()
    t0 = time.perf_counter()
    graph, values, report, passes = solve_graph(builder, graph, values, ordering)  # as smooth_batch
    lin = sum(p["linearize"] for p in passes)
    elim = sum(p["eliminate"] for p in passes)
    iterations = int(sum(p["iterations"] for p in passes))
    stages["solve"] = time.perf_counter() - t0
    rss["solve"] = peak_rss_gib()
    t0 = time.perf_counter()
    result = extract_result(
        builder, graph, values, ordering, bayes_net=report.bayes_net if report.converged else None
    )
    stages["marginals"] = time.perf_counter() - t0
    total = time.perf_counter() - t_all
    duration = float(log.imu.t[-1] - log.imu.t[0])
    del gtsam
    return {
        "stages_s": stages,
        "linearize_s": lin,
        "eliminate_s": elim,
        "iterations": iterations,
        "total_s": total,
        "rss_gib": rss,
        "peak_rss_gib": peak_rss_gib(),
        "duration_s": duration,
        "imu": len(log.imu),
        "pings": len(log.dvl),
        "states": len(builder.epochs),
        "pings_used": int(sum(e.dvl_index >= 0 for e in builder.epochs)),
        "scale": result.scale,
        "scale_sigma": result.scale_sigma,
        "misalignment_deg": list(map(float, result.misalignment_deg)),
        "misalignment_sigma_deg": list(map(float, result.misalignment_sigma_deg)),
    }


def run_child(args: list[str]) -> dict[str, Any]:
    proc = subprocess.run(
        [sys.executable, __file__, *args],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    if proc.returncode != 0:
        raise SystemExit(f"child {' '.join(args)} failed:\n{proc.stderr.strip()[-2000:]}")
    out: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return out


# ----- the report ---------------------------------------------------------------------------------------
STAGES = ["read", "epochs", "preintegration", "factors", "solve", "marginals"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--hours", type=float, nargs="+", default=[1, 3, 6, 12, 24], help="mission lengths (h)"
    )
    ap.add_argument(
        "--cache",
        type=Path,
        default=Path.home() / ".cache" / "gtsam_dvl" / "bench_long",
        help="folder of the simulated logs (reused when present)",
    )
    ap.add_argument(
        "--config", default="default", help="named estimator configuration (default, paper)"
    )
    ap.add_argument(
        "--keyframe-spacing",
        type=float,
        default=None,
        help="[solver] keyframe_spacing_s (s) instead of the configuration's default",
    )
    ap.add_argument(
        "--per-ping-hours",
        type=float,
        nargs="*",
        default=[6],
        help="lengths also run with a state per ping (keyframe_spacing_s = 0), if the solver has it",
    )
    ap.add_argument(
        "--sim-memory-gb", type=float, default=8.0, help="skip simulations expected to need more"
    )
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        kind, *rest = args.child
        if kind == "simulate":
            res = child_simulate(float(rest[0]), Path(rest[1]))
        else:
            res = child_smooth(
                Path(rest[0]), rest[1], None if rest[2] == "none" else float(rest[2])
            )
        print(json.dumps(res))
        return

    args.cache.mkdir(parents=True, exist_ok=True)
    spacing = "none" if args.keyframe_spacing is None else str(args.keyframe_spacing)
    rows: list[tuple[float, dict[str, Any]]] = []
    for hours in args.hours:
        path = cached_log(args.cache, hours)
        if not path.exists():
            need = SIM_GB_FIXED + SIM_GB_PER_H * hours
            if need > args.sim_memory_gb:
                print(
                    f"{hours:g} h: skipped, its simulation would need about {need:.1f} GB (> --sim-memory-gb "
                    f"{args.sim_memory_gb:g})"
                )
                continue
            tmp = path.with_suffix(".partial.mcap")
            sim = run_child(["--child", "simulate", str(hours), str(tmp)])
            tmp.replace(path)
            print(
                f"{hours:g} h: simulated {sim['imu']:,} IMU samples, {sim['pings']:,} pings in "
                f"{sim['simulate_s']:.1f} s, written in {sim['write_s']:.1f} s ({sim['mb']:.0f} MB, peak RSS "
                f"{sim['peak_rss_gib']:.2f} GiB) to {path}"
            )
        res = run_child(["--child", "smooth", str(path), args.config, spacing])
        rows.append((hours, res))
        print(
            f"{hours:g} h: {res['total_s']:.1f} s, peak RSS {res['peak_rss_gib']:.2f} GiB",
            flush=True,
        )
    if not rows:
        return

    print(
        f"\nbatch smoother, configuration '{args.config}', keyframe spacing "
        f"{'default' if args.keyframe_spacing is None else args.keyframe_spacing}; seconds per stage"
    )
    head = f"{'hours':>6}{'IMU':>11}{'pings':>9}{'states':>9}" + "".join(
        f"{s[:9]:>10}" for s in STAGES
    )
    print(head + f"{'(lin)':>8}{'(elim)':>8}{'total':>9}{'RSS GiB':>9}{'RT factor':>10}")
    for hours, r in rows:
        st = r["stages_s"]
        cells = "".join(f"{st.get(s, 0.0):>10.2f}" for s in STAGES)
        print(
            f"{hours:>6g}{r['imu']:>11,}{r['pings']:>9,}{r['states']:>9,}{cells}{r['linearize_s']:>8.2f}"
            f"{r['eliminate_s']:>8.2f}{r['total_s']:>9.1f}{r['peak_rss_gib']:>9.2f}"
            f"{r['duration_s'] / r['total_s']:>10.0f}"
        )
    print(
        "peak RSS after each stage (GiB): "
        + "; ".join(
            f"{h:g} h: " + ", ".join(f"{k} {v:.2f}" for k, v in r["rss_gib"].items())
            for h, r in rows
        )
    )
    if len(rows) >= 2:
        h0, r0 = rows[0]
        print(
            "cost per hour of mission relative to the shortest run (1.00 = linear): "
            + ", ".join(
                f"{h:g} h: time {r['total_s'] / h / (r0['total_s'] / h0):.2f}, RSS "
                f"{r['peak_rss_gib'] / h / (r0['peak_rss_gib'] / h0):.2f}"
                for h, r in rows[1:]
            )
        )
    for hours in args.per_ping_hours or []:
        match = [r for h, r in rows if h == hours]
        if not match:
            continue
        try:
            pp = run_child(
                ["--child", "smooth", str(cached_log(args.cache, hours)), args.config, "0"]
            )
        except SystemExit as e:
            print(f"state per ping at {hours:g} h: not run ({str(e).splitlines()[-1]})")
            continue
        kf = match[0]
        print(
            f"\n{hours:g} h, state per ping against the default: {pp['states']:,} vs {kf['states']:,} states, "
            f"{pp['total_s']:.1f} s vs {kf['total_s']:.1f} s ({pp['total_s'] / kf['total_s']:.1f}x), "
            f"peak RSS {pp['peak_rss_gib']:.2f} vs {kf['peak_rss_gib']:.2f} GiB"
        )
        print(
            f"  scale sigma {pp['scale_sigma']:.3e} vs {kf['scale_sigma']:.3e} "
            f"(ratio {kf['scale_sigma'] / pp['scale_sigma']:.3f}); misalignment sigma (deg) "
            + ", ".join(
                f"{a:.4f} vs {b:.4f}"
                for a, b in zip(
                    pp["misalignment_sigma_deg"], kf["misalignment_sigma_deg"], strict=True
                )
            )
            + f"; scale difference {(kf['scale'] - pp['scale']) / pp['scale_sigma']:+.2f} sigma"
        )


if __name__ == "__main__":
    main()
