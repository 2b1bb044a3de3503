"""Does the batch smoother's fit of the DVL's correlated error ([noise] fit_correlated) find the simulated level,
and what does it do to the sigmas? On the underway scenarios (simulated with 2 mm/s over 60 s of Gauss-Markov
DVL error besides 7 mm/s white), per seed, the batch smoother with the scenario's configuration and
- "configured": the defaults' level (2 mm/s over 60 s, the simulated one), fit off;
- "fit": the same with fit_correlated on;
- "low" / "fit-low": a level of 0.5 mm/s over 60 s, fit off / on;
- "high" / "fit-high": 10 mm/s over 60 s, fit off / on.
Per variant: the level and time constant used (mean, std), how often the last fit was significant, and the std over
runs of the final horizontal error/sigma (east and north pooled) and of the scale's error/sigma.

    .venv/bin/python bench/correlated_fit.py --runs 10 [--scenarios straight-transect,steady-turn] [--out FILE]
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from campaign_loop import campaign_parser, seeds, write_runs

VARIANTS: dict[str, tuple[float, bool]] = {
    "configured": (0.002, False),
    "fit": (0.002, True),
    "low": (0.0005, False),
    "fit-low": (0.0005, True),
    "high": (0.01, False),
    "fit-high": (0.01, True),
}


def run_one(scenario_name: str, seed: int) -> dict[str, Any]:
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.estimators.run import run_trajectory_estimator
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    sc = load_scenario(scenario_name)
    log = simulate(sc, seed)
    cal, truth = log.true_calibration, log.truth
    assert cal is not None and truth is not None
    base = sc.estimator_configuration().to_dict()
    out: dict[str, Any] = {"scenario": scenario_name, "seed": seed, "variants": {}}
    for name, (level, fit) in VARIANTS.items():
        d = {
            **base,
            "dvl": {**base["dvl"], "correlated_sigma_m_s": level, "correlated_tau_s": 60.0},
            "noise": {**base["noise"], "fit_correlated": fit},
        }
        t0 = time.perf_counter()
        res = run_trajectory_estimator(log, "batch", EstimatorConfig.from_dict(d), timeline=False)
        n_p_true = np.array([np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)])
        e_h = res.n_p[-1, :2] - n_p_true
        used = res.info.get("dvl_correlated_error", {})
        entry = res.info["noise"].get("dvl_correlated", {})
        out["variants"][name] = {
            "sigma_m_s": used.get("sigma_m_s"),
            "tau_s": used.get("tau_s"),
            "significant": entry.get("significant"),
            "passes": entry.get("passes"),
            "last_fit": entry.get("fit"),
            "horizontal_z": (e_h / res.position_sigma_m[-1, :2]).tolist(),
            "horizontal_sigma_m": float(np.hypot(*res.position_sigma_m[-1, :2])),
            "horizontal_error_m": float(np.linalg.norm(e_h)),
            "scale_z": float((res.scale - cal.scale) / res.scale_sigma),
            "wall_s": time.perf_counter() - t0,
        }
    return out


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for scenario in sorted({r["scenario"] for r in runs}):
        mine = [r for r in runs if r["scenario"] == scenario]
        table = {}
        for name in VARIANTS:
            rows = [r["variants"][name] for r in mine]
            s = np.array([x["sigma_m_s"] for x in rows]) * 1e3
            t = np.array([x["tau_s"] for x in rows])
            z = np.array([x["horizontal_z"] for x in rows]).reshape(-1)
            table[name] = {
                "runs": len(rows),
                "sigma_mm_s": [float(s.mean()), float(s.std(ddof=1))],
                "tau_s": [float(t.mean()), float(t.std(ddof=1))],
                "significant": sum(bool(x["significant"]) for x in rows),
                "horizontal_z_std": float(np.std(z, ddof=1)),
                "scale_z_std": float(np.std([x["scale_z"] for x in rows], ddof=1)),
                "horizontal_sigma_m": float(np.mean([x["horizontal_sigma_m"] for x in rows])),
                "horizontal_rms_m": float(
                    np.sqrt(np.mean([x["horizontal_error_m"] ** 2 for x in rows]))
                ),
            }
        out[scenario] = table
    return out


def main() -> None:
    ap = campaign_parser(__doc__, runs=10, out="correlated_fit.json")
    ap.add_argument("--scenarios", default="straight-transect,steady-turn")
    args = ap.parse_args()
    runs = []
    t0 = time.perf_counter()
    for scenario in args.scenarios.split(","):
        for seed in seeds(args):
            runs.append(run_one(scenario, seed))
            print(f"\r{len(runs)} runs, {time.perf_counter() - t0:.0f} s", end="", flush=True)
            write_runs(args.out, runs, summarise)
    print()
    for scenario, table in summarise(runs).items():
        print(
            f"{scenario}: level used mm/s (mean, std), tau s, fits significant, final horizontal and scale "
            "error/sigma std, horizontal sigma and RMS error m"
        )
        for name, row in table.items():
            print(
                f"  {name:10s} {row['sigma_mm_s'][0]:5.2f} {row['sigma_mm_s'][1]:5.2f}  {row['tau_s'][0]:6.1f} "
                f"{row['tau_s'][1]:6.1f}  {row['significant']:2d}/{row['runs']}  z_h {row['horizontal_z_std']:5.2f}"
                f"  z_k {row['scale_z_std']:5.2f}  sigma_h {row['horizontal_sigma_m']:6.2f} rms_h "
                f"{row['horizontal_rms_m']:6.2f}"
            )


if __name__ == "__main__":
    main()
