"""ROS 2 node benchmark: how long after its epoch's processing each Odometry reaches a subscriber, at real time and
at 10x, three processes on this machine's DDS.

    .venv/bin/python bench/bench_node.py [--rates 1 10] [--imu-hz 200] [--dvl-hz 5] [--seed 1]

A log is simulated first (not timed): paper-3d-short cut to 165 s (45 s static, surge, descent) at 200 Hz IMU and
5 Hz DVL, the paper's configuration with the DVL time offset estimated. For each replay rate, `gtsam-dvl play`
publishes it (a process of its own, each publication's steady-clock time recorded), `gtsam-dvl node` estimates
(its per-epoch timings in its stats_file: when the message that released the epoch arrived, when the estimator
was done, when the Odometry was published) and this process subscribes to the Odometry (its arrival times). The
steady clock (CLOCK_MONOTONIC) is one clock for the three processes. Printed per rate, p50 / p99 / max in ms over
the Odometry of the run after the alignment:

- after processing: Odometry received by the subscriber - the estimator done with its epoch (the node's part: the
  message made, published, carried by DDS); the target is 5 ms at p99;
- end to end: Odometry received - the releasing message published by the player (DDS in, the node's callback,
  the estimator's epoch, DDS out);
- processing: the estimator's own time for the epoch (OnlineEstimator.latencies_s);
- baseline, measured in the same run: one message carried by DDS (the releasing message published -> its arrival
  in the node's callback); the ratios of the figures above to it.

The machine's load shows in these figures (three processes share its cores): run it alone.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.decode import MessageDecoder
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

# the node's test harness (its log's segments, files, commands, environment and Listener), shared with its test
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.support.node import (  # noqa: E402
    SEGMENTS,
    Listener,
    cli,
    config_toml,
    params_yaml,
    ros_env,
)

PLAYER = """
import json, sys
from gtsam_dvl.app.node.player import play_log
out = play_log(sys.argv[1], rate=float(sys.argv[2]), topics=["/imu/data_raw", "/dvl/twist"],
               wait_for_subscribers_s=60.0, record=True)
json.dump({"log_ns": out.log_ns, "topics": out.topics, "wall": out.wall, "wall_s": out.wall_s}, open(sys.argv[3], "w"))
"""


def stats(x: np.ndarray) -> str:
    x = np.asarray(x, dtype=float) * 1e3
    return f"{np.percentile(x, 50):6.2f} / {np.percentile(x, 99):6.2f} / {x.max():6.2f} ms"


def run(tmp: Path, mcap: Path, rate: float, env: dict[str, str]) -> dict[str, np.ndarray]:
    from nav_msgs.msg import Odometry

    stats_file, played = tmp / f"stats_{rate:g}.json", tmp / f"played_{rate:g}.json"
    params = tmp / "params.yaml"
    params.write_text(
        params_yaml(
            imu_topic="/imu/data_raw",
            dvl_topic="/dvl/twist",
            pressure_topic="",
            gnss_topic="",
            path_period_s=1.0,
            stats_file=str(stats_file),
            qos_inputs={"reliability": "reliable", "depth": 100000},
        )
    )
    decode = MessageDecoder("/gtsam_dvl/odometry", "nav_msgs/msg/Odometry")
    listener = Listener("bench_subscriber", env)
    received = listener.record(Odometry, "/gtsam_dvl/odometry", 10000, raw=True)
    node = subprocess.Popen(
        cli("node", "-c", tmp / "cfg.toml", "--params", params),
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    player = subprocess.Popen(
        [sys.executable, "-c", PLAYER, str(mcap), str(rate), str(played)], env=env
    )
    listener.spin_until(lambda: player.poll() is not None)
    node.send_signal(2)  # SIGINT: the node finishes and writes its stats
    listener.spin_until(lambda: node.poll() is not None)
    listener.close()
    timings = json.loads(stats_file.read_text())["timings"]
    play = json.loads(played.read_text())
    pub_wall = {
        (t, ns): w for ns, t, w in zip(play["log_ns"], play["topics"], play["wall"], strict=True)
    }
    recv = {int(stamps_ns(decode(b))[0]): w for w, b in received}
    topics = {"imu": "/imu/data_raw", "dvl": "/dvl/twist"}
    rows = []
    for r in timings:
        got, pub = (
            recv.get(r["stamp_ns"]),
            pub_wall.get((topics.get(r["trigger_kind"], ""), r["trigger_ns"])),
        )
        if got is None or pub is None or not np.isfinite(r["published"]):
            continue
        rows.append(
            (got - r["done"], got - pub, r["processing_s"], r["arrived"] - pub, got - r["arrived"])
        )
    a = np.array(rows)
    return {
        "after_processing": a[:, 0],
        "end_to_end": a[:, 1],
        "processing": a[:, 2],
        "dds": a[:, 3],
        "node": a[:, 4],
        "matched": np.array([len(rows), len(timings)]),
        "wall_s": np.array([play["wall_s"]]),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rates", type=float, nargs="+", default=[1.0, 10.0])
    ap.add_argument("--imu-hz", type=float, default=200.0)
    ap.add_argument("--dvl-hz", type=float, default=5.0)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    raw = dict(load_scenario("paper-3d-short").raw)
    raw["segments"] = SEGMENTS
    raw["rates"] = {**raw["rates"], "imu_hz": args.imu_hz, "dvl_hz": args.dvl_hz}
    log = simulate(scenario_from_dict(raw, name="bench-node"), args.seed)
    assert log.origin is not None
    env = ros_env()
    print(
        f"log: {log.imu.t[-1] - log.imu.t[0]:.0f} s, IMU {args.imu_hz:g} Hz, DVL {args.dvl_hz:g} Hz; load "
        f"{os.getloadavg()[0]:.2f}; p50 / p99 / max"
    )
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        mcap = tmp / "bench.mcap"
        write_log(mcap, log)
        (tmp / "cfg.toml").write_text(config_toml(log, "[dvl]\nestimate_time_offset = true\n"))
        for rate in args.rates:
            r = run(tmp, mcap, rate, env)
            n, total = r["matched"]
            base = np.percentile(r["dds"], 99)
            ratio = {k: np.percentile(r[k], 99) / base for k in ("after_processing", "end_to_end")}
            print(
                f"replay {rate:g}x real time ({r['wall_s'][0]:.1f} s wall), {n} of {total} Odometry matched:"
            )
            print(
                f"  after processing  {stats(r['after_processing'])}  (p99 {ratio['after_processing']:.2f}x the "
                "baseline's)"
            )
            print(f"  end to end        {stats(r['end_to_end'])}  (p99 {ratio['end_to_end']:.2f}x)")
            print(f"  processing        {stats(r['processing'])}")
            print(f"  node: releasing message's arrival -> Odometry received  {stats(r['node'])}")
            print(f"  baseline: DDS, one message player -> node's callback  {stats(r['dds'])}")


if __name__ == "__main__":
    main()
