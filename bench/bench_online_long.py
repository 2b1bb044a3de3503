"""Online estimator on a long, high-rate mission: per-epoch time, real-time factor, memory.

    .venv/bin/python bench/bench_online_long.py [--hours 6] [--imu-hz 200] [--dvl-hz 5] [--config default]
        [--cache-dir bench/.cache] [--baseline-hours 1] [--no-baseline] [--plot out.png] [--profile out.prof]
        [--between deferred|immediate] [--keyframe-spacing S]

The mission is data/scenarios/survey-6h.toml (static alignment, Type-I manoeuvres, a lawnmower with banked
turns) with [rates] imu_hz and dvl_hz replaced (200 Hz IMU, 5 Hz DVL by default); --hours cuts it shorter
(the segments up to that time, the last straight line shortened). The log is simulated once and cached as a
ROS 2 MCAP in --cache-dir (default bench/.cache/, ignored by git through its own .gitignore), then read back
(not timed) and fed message by message to the fixed-lag online estimator: the IMU samples up to each ping as
one batch, then the ping (gtsam_dvl.estimators.online.feed_log's order), with --config "default" (the
default EstimatorConfig: real-DVL priors, the DVL time offset estimated) or "paper" (EstimatorConfig.paper():
the paper's priors, no time offset). States at keyframes [solver] keyframe_spacing_s apart (1 s by default;
--keyframe-spacing 0: a state per ping), the pings between them as factors on the state before them, in the
next state's iSAM2 update (--between deferred, the default) or each in an update of its own (immediate).

Printed:
- time per DVL epoch (every ping, and the states without a ping; OnlineEstimator.latencies_s: preintegration,
  factors, iSAM2 update, marginal covariances, the estimate at the ping): p50 / p99 / max over the mission, over
  its first and its last hour, and last / first; wall time, and the process's CPU time over the same spans
  (latencies_cpu_s: what other processes on a shared machine do not inflate); the same for the epochs that
  make a state;
- the real-time factor: mission duration / wall time of everything from the first message to the result (and
  on CPU time);
- every 10 simulated minutes: the process's resident memory (RSS from /proc/self/statm), the number of live
  EarthImuFactor objects (gc), the variables iSAM2 holds, and the p99 of the epochs of those 10 minutes (wall
  and CPU); the RSS slope over the mission after the first hour (MB/h): flat memory is a slope near 0 (the
  per-state history kept for the result, EpochHistory, grows by a fixed amount per state);
- a baseline measured in the same run: the first --baseline-hours of the same mission at 100 Hz IMU / 1 Hz
  DVL (the rates of survey-6h.toml), and the ratios of the high-rate run's figures to it.
--plot writes a PNG (matplotlib) of RSS and per-epoch time against mission time; --profile writes a cProfile
of the high-rate run (view with python -m pstats). The machine's load shows in the wall times (the load
average is printed): run it alone, or read the CPU times and the ratios to the baseline.
"""

from __future__ import annotations

import argparse
import copy
import gc
import os
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.online import OnlineEstimator, latency_stats
from gtsam_dvl.factors import EarthImuFactor
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict

HOUR = 3600.0
SAMPLE_S = 600.0  # memory sampled every 10 simulated minutes
ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "data" / "scenarios" / "survey-6h.toml"
PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_mb() -> float:
    """Resident set size of this process, MB (/proc/self/statm)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * PAGE / 1e6


def scenario_dict(hours: float, imu_hz: float, dvl_hz: float) -> dict[str, Any]:
    """survey-6h.toml with the rates replaced, cut to `hours` (whole segments, the last straight shortened)."""
    raw = tomllib.loads(SCENARIO.read_text())
    raw = copy.deepcopy(raw)
    raw["rates"]["imu_hz"], raw["rates"]["dvl_hz"] = float(imu_hz), float(dvl_hz)
    end = hours * HOUR
    kept, t = [], 0.0
    for seg in raw["segments"]:
        d = float(seg["duration_s"])
        if t + d <= end + 1e-9:
            kept.append(seg)
            t += d
        elif seg["kind"] == "straight" and end - t > 1.0:
            kept.append({**seg, "duration_s": end - t})
            t = end
            break
        else:
            break
    raw["segments"] = kept
    raw["name"] = f"survey-{hours:g}h-{imu_hz:g}hz-{dvl_hz:g}hz"
    return raw


def cached_log(
    hours: float, imu_hz: float, dvl_hz: float, seed: int, cache: Path
) -> tuple[LogData, float]:
    """The mission's log, simulated and written once, read back from the cache (returns it and the seconds
    the simulation took, 0 when cached)."""
    cache.mkdir(parents=True, exist_ok=True)
    ignore = cache / ".gitignore"
    if not ignore.exists():
        ignore.write_text("*\n")
    path = cache / f"survey-{hours:g}h-imu{imu_hz:g}-dvl{dvl_hz:g}-seed{seed}.mcap"
    sim_s = 0.0
    if not path.exists():
        raw = scenario_dict(hours, imu_hz, dvl_hz)
        t0 = time.perf_counter()
        log = simulate(scenario_from_dict(raw, raw["name"]), seed)
        write_log(path, log)
        sim_s = time.perf_counter() - t0
        del log
        gc.collect()
    return read_log(path), sim_s


@dataclass
class Run:
    label: str
    hours: float
    # DVL epochs processed: states (keyframes, states without a ping) and pings between them
    epochs: int = 0
    states: int = 0
    wall_s: float = 0.0
    # this process's CPU time over the same span (less affected by a loaded machine)
    cpu_s: float = 0.0
    rtf: float = 0.0
    lat_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cpu_lat_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # CPU time per epoch
    t_epoch: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # per epoch: a state was made
    is_state: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    samples: list[dict[str, float]] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    def stats(
        self,
        t_from: float = -np.inf,
        t_to: float = np.inf,
        states_only: bool = False,
        cpu: bool = False,
    ) -> dict[str, float]:
        sel = (self.t_epoch >= t_from) & (self.t_epoch < t_to)
        if states_only:
            sel &= self.is_state
        return latency_stats((self.cpu_lat_s if cpu else self.lat_s)[sel])


def live_imu_factors() -> int:
    return sum(isinstance(o, EarthImuFactor) for o in gc.get_objects())


def run(
    label: str,
    log: LogData,
    config: EstimatorConfig,
    until_h: float | None = None,
    sample_memory: bool = True,
    defer: bool = True,
) -> Run:
    """Feed the log (up to until_h hours) to a fixed-lag OnlineEstimator, sampling memory every SAMPLE_S;
    defer: OnlineEstimator.defer_between_pings."""
    imu, dvl = log.imu, log.dvl
    t_first = float(imu.t[0])
    n = len(dvl) if until_h is None else int(np.searchsorted(dvl.t, t_first + until_h * HOUR))
    n_imu = len(imu) if until_h is None else int(np.searchsorted(imu.t, t_first + until_h * HOUR))
    ends = np.searchsorted(imu.t, dvl.t[:n], side="right")
    out = Run(label, float(imu.t[n_imu - 1] - t_first) / HOUR)
    gc.collect()
    t0, c0 = time.perf_counter(), time.process_time()
    est = OnlineEstimator.for_log(log, config)
    est.defer_between_pings = defer
    next_sample, start, k_lat = t_first, 0, 0
    for j in range(n):
        end = int(ends[j])
        if end > start:
            est.push_imu_batch(imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end])
            start = end
        est.push_dvl(dvl.t[j], dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
        if sample_memory and dvl.t[j] >= next_sample:
            paused, c_paused = time.perf_counter(), time.process_time()
            sm = est.smoother
            lat = np.asarray(est.latencies_s[k_lat:])
            lat_cpu = np.asarray(est.latencies_cpu_s[k_lat:])
            k_lat = len(est.latencies_s)
            out.samples.append(
                {
                    "t_h": (dvl.t[j] - t_first) / HOUR,
                    "rss_mb": rss_mb(),
                    "imu_factors": live_imu_factors(),
                    "variables": sm.isam.getLinearizationPoint().size() if sm is not None else 0,
                    "p99_ms": latency_stats(lat)["p99"] if lat.size else float("nan"),
                    "p99_cpu_ms": latency_stats(lat_cpu)["p99"] if lat.size else float("nan"),
                }
            )
            next_sample += SAMPLE_S
            t0 += time.perf_counter() - paused  # sampling is not the estimator's time
            c0 += time.process_time() - c_paused
    if start < n_imu:
        est.push_imu_batch(imu.t[start:n_imu], imu.b_omega[start:n_imu], imu.b_f[start:n_imu])
    est.finish()
    result = est.result(log.t0_ns)
    out.wall_s = time.perf_counter() - t0
    out.cpu_s = time.process_time() - c0
    out.rtf = out.hours * HOUR / out.wall_s
    out.lat_s = np.asarray(est.latencies_s)
    out.cpu_lat_s = np.asarray(est.latencies_cpu_s)
    t_lat = np.asarray(est.latency_t)
    out.t_epoch = (t_lat - t_first) / HOUR
    out.is_state = np.isin(t_lat, result.t)
    out.epochs = len(out.lat_s)
    out.states = len(result.t)
    out.info = {
        "rebases": result.info["isam2"]["rebases"],
        "variables": result.info["isam2"]["variables"],
        "factors": result.info["isam2"]["factors"],
        "scale": result.scale,
        "scale_sigma": result.scale_sigma,
        "history_bytes": sum(b.nbytes for blk in est._history._blocks for b in blk.values()),
    }
    if log.true_calibration is not None:
        out.info["scale_err_sigma"] = (
            result.scale - log.true_calibration.scale
        ) / result.scale_sigma
    return out


def slope_mb_per_h(samples: list[dict[str, float]]) -> float:
    t = np.array([s["t_h"] for s in samples])
    r = np.array([s["rss_mb"] for s in samples])
    sel = t >= 1.0
    if sel.sum() < 3:
        sel = t >= t[len(t) // 2] if len(t) >= 3 else np.ones(len(t), bool)
    if sel.sum() < 2:
        return float("nan")
    return float(np.polyfit(t[sel], r[sel], 1)[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--hours", type=float, default=6.0, help="mission length (cut from survey-6h), h"
    )
    ap.add_argument("--imu-hz", type=float, default=200.0)
    ap.add_argument("--dvl-hz", type=float, default=5.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--config",
        choices=["default", "paper"],
        default="default",
        help="default EstimatorConfig (time offset estimated) or EstimatorConfig.paper()",
    )
    ap.add_argument("--cache-dir", type=Path, default=ROOT / "bench" / ".cache")
    ap.add_argument(
        "--baseline-hours",
        type=float,
        default=1.0,
        help="baseline: this long at 100 Hz IMU / 1 Hz DVL",
    )
    ap.add_argument("--no-baseline", action="store_true")
    ap.add_argument("--plot", type=Path, help="PNG of RSS and per-epoch time against mission time")
    ap.add_argument("--profile", type=Path, help="cProfile of the high-rate run to this file")
    ap.add_argument(
        "--between",
        choices=["deferred", "immediate"],
        default="deferred",
        help="pings between keyframes: their factors in the next state's iSAM2 update (default) or each "
        "in an update of its own (OnlineEstimator.defer_between_pings)",
    )
    ap.add_argument(
        "--keyframe-spacing",
        type=float,
        default=None,
        help="[solver] keyframe_spacing_s, s (default: the config's; 0: a state per ping)",
    )
    args = ap.parse_args()
    config = EstimatorConfig() if args.config == "default" else EstimatorConfig.paper()
    if args.keyframe_spacing is not None:
        config.solver.keyframe_spacing_s = args.keyframe_spacing
    defer = args.between == "deferred"

    log, sim_s = cached_log(args.hours, args.imu_hz, args.dvl_hz, args.seed, args.cache_dir)
    print(
        f"mission: survey-6h cut to {args.hours:g} h, IMU {args.imu_hz:g} Hz ({len(log.imu):,} samples), DVL "
        f"{args.dvl_hz:g} Hz ({len(log.dvl):,} pings), config {args.config!r}"
        + (f"; simulated and cached in {sim_s:.0f} s" if sim_s else "; from the cache")
    )
    label = f"{args.imu_hz:g} Hz / {args.dvl_hz:g} Hz"
    if args.profile is not None:
        import cProfile

        prof = cProfile.Profile()
        prof.enable()
        main_run = run(label, log, config, sample_memory=False, defer=defer)
        prof.disable()
        prof.dump_stats(args.profile)
        print(f"profile written to {args.profile} (profiled run: wall times inflated)")
    else:
        main_run = run(label, log, config, defer=defer)
    del log
    gc.collect()

    base = None
    if not args.no_baseline:
        blog, _ = cached_log(max(args.baseline_hours, 0.5), 100.0, 1.0, args.seed, args.cache_dir)
        base = run(
            f"100 Hz / 1 Hz, first {args.baseline_hours:g} h",
            blog,
            config,
            until_h=args.baseline_hours,
            sample_memory=False,
            defer=defer,
        )
        del blog

    H = main_run.hours
    first, last = main_run.stats(0.0, 1.0), main_run.stats(H - 1.0)
    rows = [
        (
            f"{label}, all {H:.2f} h",
            main_run.stats(),
            main_run.rtf,
            main_run.epochs,
            main_run.wall_s,
        ),
        (f"{label}, first hour", first, None, None, None),
        (f"{label}, last hour", last, None, None, None),
    ]
    if base is not None:
        rows.append((base.label, base.stats(), base.rtf, base.epochs, base.wall_s))
    print(
        f"\nwall time per DVL epoch, ms (fixed lag, window {config.online.window_s:g} s; keyframes "
        f"{config.solver.keyframe_spacing_s:g} s apart, the pings between them {args.between}; "
        f"load average {os.getloadavg()[0]:.2f} at the end)"
    )
    head = (
        f"{'run':34s} {'p50':>6s} {'p99':>6s} {'max':>7s} {'epochs':>7s} {'wall s':>7s} {'RTF':>6s}"
    )
    print(head)
    print("-" * len(head))
    for name, s, rtf, n, wall in rows:
        extra = f" {n:7d} {wall:7.1f} {rtf:6.0f}" if rtf is not None else ""
        print(f"{name:34s} {s['p50']:6.2f} {s['p99']:6.2f} {s['max']:7.1f}{extra}")
    print(
        "CPU time per DVL epoch, ms (the process's, over the same spans: less affected by other processes)"
    )
    cpu_rows = [
        (f"{label}, all", main_run.stats(cpu=True)),
        (f"{label}, first hour", main_run.stats(0.0, 1.0, cpu=True)),
        (f"{label}, last hour", main_run.stats(H - 1.0, cpu=True)),
    ]
    if base is not None:
        cpu_rows.append((base.label, base.stats(cpu=True)))
    for name, s in cpu_rows:
        print(f"{name:34s} {s['p50']:6.2f} {s['p99']:6.2f} {s['max']:7.1f}")
    print(
        f"real-time factor on CPU time (less affected by other processes): {H * HOUR / main_run.cpu_s:.0f} "
        f"({main_run.cpu_s:.1f} s CPU, {main_run.wall_s:.1f} s wall)"
    )
    print(
        f"last hour / first hour: p50 {last['p50'] / first['p50']:.2f}, p99 {last['p99'] / first['p99']:.2f}"
    )
    ks = main_run.stats(states_only=True)
    print(
        f"{label}: {main_run.states} states for {main_run.epochs} epochs; the epochs that make a state: p50 "
        f"{ks['p50']:.2f}, p99 {ks['p99']:.2f}, max {ks['max']:.1f} ms"
    )
    if base is not None:
        b = base.stats()
        print(
            f"{label} / baseline: p50 {main_run.stats()['p50'] / b['p50']:.2f}, p99 "
            f"{main_run.stats()['p99'] / b['p99']:.2f}, RTF {main_run.rtf / base.rtf:.2f} (epochs per hour "
            f"{main_run.epochs / H / (base.epochs / base.hours):.1f}x)"
        )
    info = main_run.info
    print(
        f"iSAM2: {info['rebases']} rebases, {info['variables']} variables and {info['factors']} factors held at "
        f"the end; history kept for the result {info['history_bytes'] / 1e6:.1f} MB "
        f"({info['history_bytes'] / max(main_run.states, 1):.0f} B per state)"
    )
    if "scale_err_sigma" in info:
        print(
            f"final scale {info['scale']:.6f} +- {info['scale_sigma']:.2e} ({info['scale_err_sigma']:+.2f} sigma "
            "from the truth)"
        )

    if main_run.samples:
        print("\nmemory every 10 simulated minutes")
        print(
            f"{'t h':>6s} {'RSS MB':>8s} {'live IMU factors':>16s} {'iSAM2 vars':>10s} {'p99 ms (10 min)':>15s} "
            f"{'CPU p99 ms':>10s}"
        )
        for s in main_run.samples:
            print(
                f"{s['t_h']:6.2f} {s['rss_mb']:8.1f} {s['imu_factors']:16d} {s['variables']:10d} {s['p99_ms']:15.2f} "
                f"{s['p99_cpu_ms']:10.2f}"
            )
        hist_mb_h = info["history_bytes"] / 1e6 / H
        print(
            f"RSS slope after the first hour: {slope_mb_per_h(main_run.samples):+.1f} MB/h, of which the history "
            f"kept for the result {hist_mb_h:.1f} MB/h"
        )

    ok = (main_run.stats()["p99"] < 10.0, main_run.rtf > 100.0)
    print(
        f"\ntargets: p99 < 10 ms {'met' if ok[0] else 'MISSED'}; real-time factor > 100 "
        f"{'met' if ok[1] else 'MISSED'}"
    )
    if args.plot is not None and main_run.samples:
        plot(main_run, args.plot)
        print(f"plot written to {args.plot}")


def plot(r: Run, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    t = [s["t_h"] for s in r.samples]
    rss = [s["rss_mb"] for s in r.samples]
    a1.plot(
        t,
        rss,
        "o-",
        label=f"RSS (slope after the first hour {slope_mb_per_h(r.samples):+.1f} MB/h)",
    )
    a1.set_ylim(0.0, 1.25 * max(rss))  # from zero: flat reads as flat
    a1.set_ylabel("RSS (MB)")
    a1.legend(loc="lower right")
    a1.set_title(f"online estimator, {r.label}: memory and wall time per DVL epoch")
    a1.grid(True)
    a2.plot(r.t_epoch, r.lat_s * 1e3, ",", alpha=0.4, label="per epoch")
    a2.plot(t, [s["p99_ms"] for s in r.samples], "r-", label="p99 per 10 min (wall)")
    a2.plot(t, [s["p99_cpu_ms"] for s in r.samples], "g-", label="p99 per 10 min (CPU)")
    a2.axhline(10.0, color="k", ls="--", lw=0.8, label="target p99 10 ms")
    a2.set_yscale("log")
    a2.set_ylabel("wall time per epoch (ms)")
    a2.set_xlabel("mission time (h)")
    a2.legend()
    a2.grid(True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    main()
