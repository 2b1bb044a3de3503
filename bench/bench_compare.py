"""The four estimators side by side on the same simulated logs and seeds: final calibration errors and
sigmas, attitude and position RMSE over the whole trajectory, wall time; and by how much the batch
smoother's trajectory RMSE beats the EKF's (it uses the future).

    .venv/bin/python bench/bench_compare.py [--scenario paper-3d] [--seeds 1 2 3] [--no-online]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.app.commands import run_estimator
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.estimators.iodvlc import iodvlc_summary
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenario", default="paper-3d")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--no-online", action="store_true")
    args = ap.parse_args()
    modes = ["io-dvlc", "ekf", "batch"] if args.no_online else ["io-dvlc", "ekf", "online", "batch"]
    rows: dict[str, list[dict]] = {m: [] for m in modes}
    for seed in args.seeds:
        log = simulate(load_scenario(args.scenario), seed)
        for mode in modes:
            t0 = time.perf_counter()
            res = run_estimator(log, mode, EstimatorConfig.paper(), timeline=False)
            wall = time.perf_counter() - t0
            s = iodvlc_summary(res, log) if mode == "io-dvlc" else summary(res, log)
            s["wall"] = wall
            rows[mode].append(s)
        print(f"seed {seed} done", flush=True)

    def mean(mode: str, f) -> np.ndarray:
        return np.mean([f(s) for s in rows[mode]], axis=0)

    print(f"\n{args.scenario}, seeds {args.seeds}: means over seeds (errors are |error|)")
    hdr = (
        f"{'estimator':<10}{'|scale| ppm':>12}{'sig ppm':>9}{'|mis| r/p/y deg':>22}{'sig r/p/y deg':>22}"
        f"{'att RMSE e/n/u deg':>26}{'pos RMSE m':>11}{'wall s':>8}"
    )
    print(hdr)
    for mode in modes:
        sc = mean(mode, lambda s: abs(s["errors"]["scale_ppm"]))
        sg = mean(mode, lambda s: s["scale"]["sigma"] * 1e6)
        mis = mean(mode, lambda s: np.abs(s["errors"]["misalignment_deg"]))
        ms = mean(mode, lambda s: np.array(s["misalignment_deg"]["sigma"]))
        wall = mean(mode, lambda s: s["wall"])
        if mode == "io-dvlc":
            att, pos = "-", "-"
        else:
            att = " ".join(
                f"{v:.4f}" for v in mean(mode, lambda s: np.array(s["errors"]["attitude_rmse_deg"]))
            )
            pos = f"{mean(mode, lambda s: s['errors']['position_rmse_m']):.2f}"
        print(
            f"{mode:<10}{sc:>12.0f}{sg:>9.0f}{' '.join(f'{v:.3f}' for v in mis):>22}"
            f"{' '.join(f'{v:.3f}' for v in ms):>22}{att:>26}{pos:>11}{wall:>8.2f}"
        )
    b = mean("batch", lambda s: s["errors"]["position_rmse_m"])
    e = mean("ekf", lambda s: s["errors"]["position_rmse_m"])
    ba = mean("batch", lambda s: np.array(s["errors"]["attitude_rmse_deg"]))
    ea = mean("ekf", lambda s: np.array(s["errors"]["attitude_rmse_deg"]))
    print(
        f"\nbatch vs EKF: position RMSE {b:.2f} m vs {e:.2f} m ({100 * (1 - b / e):.0f} % lower); attitude RMSE "
        f"e/n/u {np.round(ba, 4)} vs {np.round(ea, 4)} deg ({np.round(ea / ba, 1)}x lower)"
    )


if __name__ == "__main__":
    main()
