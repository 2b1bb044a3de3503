"""The estimators against a plain INS/DVL filter on realistic logs (issue 31, must-haves 6 and 7).

Per scenario (default: realistic-straight, realistic-turn, realistic-turns; their DVL error is 5 mm/s white plus a
slow error of a few mm/s, the messages state 20 mm/s, the stamps are 1.0 s early and the truth calibration is drawn
per seed from the default prior) and seed, one simulated log goes, in the same process, through
- "defaults": batch, online and EKF with the default configuration plus the scenario's [estimator] overrides
  (the initial attitude): every calibration state estimated, the time offset from its 0 +- 0.5 s prior;
- "nominal": the peer, what an engineer writes in a week: the error-state EKF with the scale fixed at 1 and the
  misalignment at the nominal mounting (prior sigmas far below what the data resolve), the DVL stamps taken as
  recorded (no time offset estimated: dt_d = 0), the DVL's stated noise (no noise fit, no correlated-error state);
  the IMU's noise floor from its quantisation stays (a competent peer: the harder bar);
- "truth": batch, online and EKF with the calibration fixed at the truth (the nominal mounting replaced by the true
  b_R_d, the scale prior at the true scale, the time offset prior at the true 1.0 s, all with negligible sigmas).
Printed per scenario x estimator x variant: the final horizontal error's RMS over the runs in % of the distance
run, its ratio to the nominal peer's, the error/sigma std of the calibration states each variant estimates (scale,
misalignment roll/pitch/yaw, time offset), the fraction of runs whose time offset ends within 3 sigma of the truth,
and the count of health verdicts "failed" (analysis/health.py). The runs are Dask tasks (app/campaign/cluster.py: a
LocalCluster of --workers processes).

    .venv/bin/python bench/realistic_logs.py --runs 50 [--scenarios realistic-straight,realistic-turn,realistic-turns]
        [--workers 2] [--out realistic_logs.json]
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np
from campaign_loop import campaign_parser, run_on_dask, seeds

SCENARIOS = ("realistic-straight", "realistic-turn", "realistic-turns")
FIXED_SCALE_SIGMA = 1e-7  # "fixed": a prior sigma far below anything the data can resolve (0.1 ppm)
FIXED_MISALIGNMENT_SIGMA_DEG = 1e-5
FIXED_TIME_OFFSET_SIGMA_S = 1e-5
ALL3 = ("batch", "online", "ekf")
VARIANTS: dict[str, tuple[str, ...]] = {"defaults": ALL3, "nominal": ("ekf",), "truth": ALL3}
CALIBRATION = ("scale", "roll", "pitch", "yaw", "time_offset")  # the error/sigma columns
# the calibration states a variant estimates (the others are fixed: their error/sigma says nothing)
ESTIMATED: dict[str, tuple[str, ...]] = {"defaults": CALIBRATION, "nominal": (), "truth": ()}
OFFSET_NSIGMA = 3.0


def _with(config: Any, section: str, **values: Any) -> Any:
    return config.model_copy(update={section: getattr(config, section).model_copy(update=values)})


def variant_runs(log: Any, base: Any) -> dict[str, tuple[Any, Any]]:
    """(log, configuration) of each variant: the truth variant's log has the true b_R_d as its nominal mounting."""
    cal = log.true_calibration
    fixed = {
        "scale_sigma": FIXED_SCALE_SIGMA,
        "misalignment_sigma_deg": (FIXED_MISALIGNMENT_SIGMA_DEG,) * 3,
    }
    nominal = _with(base, "priors", scale_initial=1.0, **fixed)
    nominal = _with(
        nominal,
        "dvl",
        estimate_time_offset=False,
        time_offset_prior_s=0.0,
        correlated_sigma_m_s=0.0,
    )
    nominal = _with(nominal, "noise", fit_dvl=False)
    truth = _with(base, "priors", scale_initial=cal.scale, **fixed)
    truth = _with(
        truth,
        "dvl",
        time_offset_prior_s=cal.time_offset_s,
        time_offset_sigma_s=FIXED_TIME_OFFSET_SIGMA_S,
    )
    true_mounting = dataclasses.replace(log.mounting, b_R_d0=cal.b_R_d(log.mounting.b_R_d0))
    return {
        "defaults": (log, base),
        "nominal": (log, nominal),
        "truth": (dataclasses.replace(log, mounting=true_mounting), truth),
    }


def calibration_z(res: Any, log: Any) -> dict[str, float]:
    """(estimate - truth) / sigma of the scale, the misalignment's roll, pitch, yaw (ZYX angles of R_c, as
    app/campaign/montecarlo.py run_errors) and the time offset (NaN where not estimated)."""
    cal = log.true_calibration
    err = [
        res.scale - cal.scale,
        *(res.misalignment_deg - np.array(cal.misalignment_deg)),
        res.time_offset_s - cal.time_offset_s,
    ]
    sig = [res.scale_sigma, *res.misalignment_sigma_deg, res.time_offset_sigma_s]
    return {
        k: float(e / s) if np.isfinite(s) and s > 0 else math.nan
        for k, e, s in zip(CALIBRATION, err, sig, strict=True)
    }


def evaluate(
    res: Any, run_log: Any, log: Any, distance_m: float, estimated: tuple[str, ...]
) -> dict[str, Any]:
    """One estimator's row: final horizontal error, error/sigma of the estimated calibration states, time offset,
    health verdict."""
    from gtsam_dvl.analysis.health import assess_health

    truth = log.truth
    n_p_true = np.array([np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)])
    e_h = res.n_p[-1, :2] - n_p_true
    z = {k: v if k in estimated else math.nan for k, v in calibration_z(res, log).items()}
    health = assess_health(res, run_log)
    return {
        "horizontal_error_pct": float(100.0 * np.linalg.norm(e_h) / distance_m),
        "z": z,
        "time_offset_s": float(res.time_offset_s),
        "time_offset_sigma_s": float(res.time_offset_sigma_s),
        "offset_within": bool(abs(z["time_offset"]) <= OFFSET_NSIGMA)
        if math.isfinite(z["time_offset"])
        else None,
        "scale": float(res.scale),
        "misalignment_deg": [float(a) for a in res.misalignment_deg],
        "health": health.status,
        "warnings": list(health.warnings)[:3],
    }


def run_one(scenario_name: str, seed: int) -> dict[str, Any]:
    """Every variant on one simulated log (module doc)."""
    from gtsam_dvl.estimators.run import run_trajectory_estimator
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    sc = load_scenario(scenario_name)
    log = simulate(sc, seed)
    assert log.truth is not None and log.true_calibration is not None
    distance_m = float(np.sum(np.linalg.norm(np.diff(log.truth.n_p[:, :2], axis=0), axis=1)))
    cal = log.true_calibration
    out: dict[str, Any] = {
        "scenario": scenario_name,
        "seed": seed,
        "distance_m": distance_m,
        "true_calibration": {
            "scale": cal.scale,
            "misalignment_deg": list(cal.misalignment_deg),
            "time_offset_s": cal.time_offset_s,
        },
        "variants": {},
    }
    for variant, (run_log, cfg) in variant_runs(log, sc.estimator_configuration()).items():
        rows: dict[str, Any] = {}
        for name in VARIANTS[variant]:
            t0 = time.perf_counter()
            try:
                res = run_trajectory_estimator(run_log, name, cfg, timeline=False)
                rows[name] = evaluate(res, run_log, log, distance_m, ESTIMATED[variant])
            except Exception as exc:  # a run that fails is reported, not a campaign that stops
                rows[name] = {"error": f"{type(exc).__name__}: {exc}"}
            rows[name]["wall_s"] = time.perf_counter() - t0
        out["variants"][variant] = rows
    return out


def _stats(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [x for x in rows if "error" not in x]
    pct = np.array([x["horizontal_error_pct"] for x in ok])
    z_std = {}
    for k in CALIBRATION:
        z = np.array([x["z"][k] for x in ok if math.isfinite(x["z"][k])])
        # about 0: the truth is the mean
        z_std[k] = float(np.sqrt(np.mean(z**2))) if len(z) else math.nan
    within = [x["offset_within"] for x in ok if x["offset_within"] is not None]
    return {
        "runs": len(ok),
        "errors": len(rows) - len(ok),
        "rms_pct": float(np.sqrt(np.mean(pct**2))) if len(pct) else math.nan,
        "z_std": z_std,
        "offset_within_fraction": float(np.mean(within)) if within else math.nan,
        "health_failed": sum(x["health"] == "failed" for x in ok),
        "wall_s": float(np.mean([x["wall_s"] for x in rows])) if rows else math.nan,
    }


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per scenario and "variant/estimator": the statistics of _stats and the RMS's ratio to the nominal peer's."""
    out: dict[str, Any] = {}
    for scenario in sorted({r["scenario"] for r in runs}):
        mine = [r for r in runs if r["scenario"] == scenario]
        table = {
            f"{v}/{n}": _stats([r["variants"][v][n] for r in mine])
            for v in VARIANTS
            for n in VARIANTS[v]
        }
        peer = table["nominal/ekf"]["rms_pct"]
        for row in table.values():
            row["ratio_to_peer"] = row["rms_pct"] / peer if peer > 0 else math.nan
        out[scenario] = table
    return out


def print_summary(summary: dict[str, Any], n_runs: int) -> None:
    z_head = " ".join(f"{k[:6]:>6s}" for k in CALIBRATION)
    for scenario, table in summary.items():
        print(
            f"\n{scenario} ({n_runs} runs): final horizontal error RMS (% of distance), ratio to the nominal peer, "
            "calibration error/sigma std (RMS of z), time offset within 3 sigma, health 'failed'"
        )
        print(
            f"  {'variant/estimator':18s} {'RMS %':>7s} {'ratio':>6s}  {z_head}  {'off3s':>5s} {'failed':>6s}"
            f" {'errors':>6s} {'wall s':>6s}"
        )
        for key, s in table.items():
            z = " ".join(
                f"{s['z_std'][k]:6.2f}" if math.isfinite(s["z_std"][k]) else f"{'-':>6s}"
                for k in CALIBRATION
            )
            within = (
                f"{s['offset_within_fraction']:5.2f}"
                if math.isfinite(s["offset_within_fraction"])
                else "    -"
            )
            print(
                f"  {key:18s} {s['rms_pct']:7.3f} {s['ratio_to_peer']:6.2f}  {z}  {within} {s['health_failed']:6d}"
                f" {s['errors']:6d} {s['wall_s']:6.1f}"
            )


def main() -> None:
    ap = campaign_parser(__doc__, runs=50, out="realistic_logs.json")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    tasks = [(s, seed) for s in args.scenarios.split(",") for seed in seeds(args)]
    runs = run_on_dask(run_one, tasks, args.workers, args.out, summarise, every=10)
    print_summary(summarise(runs), args.runs)


if __name__ == "__main__":
    main()
