"""Attach the Foxglove live view to the online estimator in your own loop.

On a vehicle the IMU and DVL drivers hand you messages; here a simulated run stands in for them. Each message is
pushed into `OnlineEstimator` (push_imu_batch / push_dvl, estimators/online/), mirrored raw to the view
(publish_imu / publish_dvl), and whenever a push completes a DVL epoch the estimate is published
(publish_epoch): tf map -> base_link, odometry with covariance, the path, scale, misalignment, time offset and
biases with their sigmas, the counters. `gtsam-dvl live LOG` does the same for a recorded log (app/live/replay.py
replay_log).

    pip install 'gtsam-dvl[live]'
    python examples/live_view.py --speed 10          # then in Foxglove: Open connection > Foxglove WebSocket >
                                                     # ws://localhost:8765; Layouts > Import from file >
                                                     # the file `gtsam-dvl live --layout FILE` writes

Options: --scenario (a built-in name or TOML file), --seed, --duration-s (cut the run), --speed (times real
time; 0: as fast as possible), --port (0: any free port), --wait (start once Foxglove subscribes).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from gtsam_dvl.app.live import LiveView
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.estimators.online import OnlineEstimator
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--scenario", default="paper-3d-short", help="built-in scenario name or TOML file"
    )
    ap.add_argument("--seed", type=int, default=3, help="random seed of the simulation")
    ap.add_argument(
        "--duration-s",
        type=float,
        default=math.inf,
        help="replay only the first seconds of the run",
    )
    ap.add_argument(
        "--speed", type=float, default=1.0, help="times real time (0: as fast as possible)"
    )
    ap.add_argument("--port", type=int, default=8765, help="WebSocket port (0: any free port)")
    ap.add_argument("--wait", action="store_true", help="start once a client subscribes")
    args = ap.parse_args(argv)

    log = simulate(load_scenario(args.scenario), args.seed)  # your drivers instead
    imu, dvl = log.imu, log.dvl
    # map origin and mounting of the log; on a vehicle: from its config
    estimator = OnlineEstimator.for_log(log)
    with LiveView(port=args.port, t0_ns=log.t0_ns, mounting=log.mounting) as view:
        print(f"live view on {view.url}", flush=True)
        if args.wait:
            view.wait_for_subscribers(timeout_s=600)
        wall0, start = time.monotonic(), 0
        for j in range(len(dvl)):
            t = float(dvl.t[j])
            if t > args.duration_s:
                break
            if args.speed > 0:  # pace the replay: the drivers would deliver at this rate
                time.sleep(max(0.0, wall0 + t / args.speed - time.monotonic()))
            end = int(np.searchsorted(imu.t, t, side="right"))  # the IMU samples up to the ping
            epochs = estimator.push_imu_batch(
                imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end]
            )
            view.publish_imu(imu.t[start:end], imu.b_omega[start:end], imu.b_f[start:end])
            start = end
            epochs += estimator.push_dvl(t, dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
            view.publish_dvl(t, dvl.d_v[j], dvl.d_cov[j], bool(dvl.valid[j]))
            estimate = estimator.estimate()
            # a DVL epoch was completed: publish what the estimator knows now
            if epochs and estimate is not None:
                view.publish_epoch(
                    estimate, counters=estimator.counters, latency_s=estimator.latencies_s[-1]
                )
        final = estimator.finish()
        if final is None:
            print("no DVL epoch was processed", file=sys.stderr)
            return 1
        view.publish_epoch(final, counters=estimator.counters, final=True)
        print(
            f"{estimator.epochs} epochs; final scale {final.scale:.5f} +- {final.scale_sigma:.5f}, "
            f"counters {estimator.counters}"
        )
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except GtsamDvlError as exc:  # bad input or foxglove-sdk missing: one line, no traceback
        sys.exit(f"live_view: error: {exc}")
    except KeyboardInterrupt:
        sys.exit(0)
