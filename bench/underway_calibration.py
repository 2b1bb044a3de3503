"""Does estimating the DVL calibration cost accuracy on short underway logs, and are the sigmas honest? (issue 21)

Per scenario (default: straight-transect and steady-turn) and seed, one simulated log goes through
- "defaults": batch, online and EKF with the default configuration (plus the scenario's [estimator] overrides):
  error/sigma of every calibration and bias state and of the final position, and the block NEES
  (app/campaign/montecarlo.py run_errors and campaign_statistics);
- "white": the defaults with the DVL's error taken as white ([dvl] correlated_sigma_m_s = 0; the defaults model a
  correlated error of 2 mm/s over 60 s, estimators/models/correlated.py, which is the scenarios' own), batch, online
  and EKF;
- "presets": batch, online and EKF with the sensor presets of the scenario's units (--imu-model, --dvl-model;
  a DVL preset brings its correlated error, so these model it too);
- "presets_free": the same, batch and online, with every calibration direction estimated ([priors]
  hold_weak_information = 0: the weakly determined ones not held, estimators/models/weak_hold.py);
- "truth": the same estimators with the calibration fixed at the truth (the nominal mounting replaced by the true
  b_R_d, the scale prior at the true scale, both with negligible sigmas);
- "nominal": the calibration fixed at nominal (scale 1, the nominal mounting): what a plain INS/DVL filter assumes.
All variants run on the same log in the same process, so their final horizontal errors (in % of the distance run)
compare run for run. The runs are Dask tasks (app/campaign/cluster.py: a LocalCluster of --workers processes).

    .venv/bin/python bench/underway_calibration.py --runs 50 [--scenarios straight-transect,steady-turn]
        [--imu-model NAME] [--dvl-model NAME] [--workers 2] [--out underway.json]
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np
from campaign_loop import campaign_parser, run_on_dask, seeds

FIXED_SCALE_SIGMA = 1e-7  # "fixed": a prior sigma far below anything the data can resolve (0.1 ppm)
FIXED_MISALIGNMENT_SIGMA_DEG = 1e-5
ALL3 = ("batch", "online", "ekf")
VARIANTS: dict[str, tuple[str, ...]] = {
    "defaults": ALL3,
    "white": ALL3,
    "presets": ALL3,
    "presets_free": ("batch", "online"),
    "truth": ("batch", "online"),
    "nominal": ("batch", "online"),
}
CAMPAIGN_VARIANTS = (
    "defaults",
    "white",
    "presets",
    "presets_free",
)  # those whose error/sigma statistics are recorded


def _with(config: Any, section: str, **values: Any) -> Any:
    return config.model_copy(update={section: getattr(config, section).model_copy(update=values)})


def _selecting(section: dict[str, Any], model: str, filled: dict[str, float]) -> dict[str, Any]:
    """A configuration section (as to_dict() writes it) that selects the preset `model`: the fields the preset
    fills (`filled`) taken out, so that the preset's values apply."""
    return {**{k: v for k, v in section.items() if k not in filled}, "model": model}


def run_one(
    scenario_name: str,
    seed: int,
    imu_model: str | None,
    dvl_model: str | None,
    mounting_tolerance_deg: float | None = None,
    variants: tuple[str, ...] = tuple(VARIANTS),
) -> dict[str, Any]:
    """Every variant on one simulated log: per variant and estimator the final horizontal error (m, % of the
    distance), its sigma, and for "defaults" the campaign's error/sigma record (run_errors)."""
    from gtsam_dvl.app.campaign.montecarlo import run_errors
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.core.config.presets import DVL_PRESETS, IMU_PRESETS
    from gtsam_dvl.estimators.run import run_trajectory_estimator
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    sc = load_scenario(scenario_name)
    log = simulate(sc, seed)
    cal, truth = log.true_calibration, log.truth
    assert cal is not None and truth is not None
    distance_m = float(np.sum(np.linalg.norm(np.diff(truth.n_p[:, :2], axis=0), axis=1)))
    base = sc.estimator_configuration()
    preset = base
    if imu_model or dvl_model or mounting_tolerance_deg:
        d = base.to_dict()
        if mounting_tolerance_deg:
            d["priors"] = {**d["priors"], "mounting_tolerance_deg": mounting_tolerance_deg}
            d["priors"].pop("misalignment_sigma_deg", None)  # the tolerance sets it
        # a preset fills only the fields the configuration does not set itself, and to_dict() lists every field:
        # take out those the presets fill (else the "presets" variant would be the defaults with another tolerance)
        if imu_model:
            d["imu"] = _selecting(d["imu"], imu_model, IMU_PRESETS[imu_model].config_values())
        if dvl_model:
            d["dvl"] = _selecting(d["dvl"], dvl_model, DVL_PRESETS[dvl_model].config_values())
            d["priors"] = {k: v for k, v in d["priors"].items() if k != "scale_sigma"}
        preset = EstimatorConfig.from_dict(d)
        if dvl_model:
            assert preset.priors.scale_sigma == DVL_PRESETS[dvl_model].scale_accuracy
    true_mounting = dataclasses.replace(log.mounting, b_R_d0=cal.b_R_d(log.mounting.b_R_d0))
    fixed_at = {
        "truth": (dataclasses.replace(log, mounting=true_mounting), cal.scale),
        "nominal": (log, 1.0),
    }
    out: dict[str, Any] = {
        "scenario": scenario_name,
        "seed": seed,
        "distance_m": distance_m,
        "variants": {},
    }
    for variant, estimators in VARIANTS.items():
        if variant not in variants or (variant.startswith("presets") and preset is base):
            continue
        run_log, cfg = log, preset if variant.startswith("presets") else base
        # every calibration direction estimated, however little the run informs it
        if variant == "presets_free":
            cfg = _with(cfg, "priors", hold_weak_information=0.0)
        if variant == "white":
            cfg = _with(base, "dvl", correlated_sigma_m_s=0.0)
        if variant in fixed_at:
            run_log, scale = fixed_at[variant]
            cfg = _with(
                cfg,
                "priors",
                scale_initial=scale,
                scale_sigma=FIXED_SCALE_SIGMA,
                misalignment_sigma_deg=(FIXED_MISALIGNMENT_SIGMA_DEG,) * 3,
            )
        rows: dict[str, Any] = {}
        for name in estimators:
            t0 = time.perf_counter()
            try:
                res = run_trajectory_estimator(run_log, name, cfg, timeline=name != "batch")
            except Exception as exc:  # a run that fails is reported, not a campaign that stops
                rows[name] = {"failed": f"{type(exc).__name__}: {exc}"}
                continue
            n_p_true = np.array([np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)])
            e_h = res.n_p[-1, :2] - n_p_true
            row: dict[str, Any] = {
                "horizontal_error_m": float(np.linalg.norm(e_h)),
                "horizontal_error_pct": float(100.0 * np.linalg.norm(e_h) / distance_m),
                "horizontal_z": (e_h / res.position_sigma_m[-1, :2]).tolist(),
                "wall_s": time.perf_counter() - t0,
            }
            if variant in CAMPAIGN_VARIANTS:
                row["campaign"] = {**run_errors(res, log), "wall_s": row["wall_s"]}
            solver, ekf = res.info.get("solver") or {}, res.info.get("filter") or {}
            # the batch smoother's chi^2/dof after the noise fit, the EKF's NIS/dof
            if solver.get("dof"):
                row["chi2_dof"] = 2.0 * float(solver["final_error"]) / float(solver["dof"])
            if "mean_nis_per_dof" in ekf:
                row["nis_dof"] = float(ekf["mean_nis_per_dof"])
            rows[name] = row
        out["variants"][variant] = rows
    return out


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per scenario: per variant and estimator the RMS final horizontal error (% of distance) and the error/sigma
    std of the horizontal components; for "defaults" the campaign statistics (error/sigma std per state, NEES)."""
    from gtsam_dvl.app.campaign.montecarlo import campaign_statistics

    out: dict[str, Any] = {}
    for scenario in sorted({r["scenario"] for r in runs}):
        mine = [r for r in runs if r["scenario"] == scenario]
        table: dict[str, Any] = {}
        for variant in VARIANTS:
            for name in VARIANTS[variant]:
                rows = [
                    r["variants"][variant][name]
                    for r in mine
                    if variant in r["variants"] and name in r["variants"][variant]
                ]
                ok = [x for x in rows if "failed" not in x]
                if not rows:
                    continue
                pct = np.array([x["horizontal_error_pct"] for x in ok])
                z = np.array([x["horizontal_z"] for x in ok]).reshape(-1)
                table[f"{variant}/{name}"] = {
                    "runs": len(ok),
                    "failed": len(rows) - len(ok),
                    "rms_pct": float(np.sqrt(np.mean(pct**2))) if len(pct) else math.nan,
                    "median_pct": float(np.median(pct)) if len(pct) else math.nan,
                    "horizontal_z_std": float(np.std(z, ddof=1)) if len(z) > 1 else math.nan,
                    **{
                        k: float(np.mean([x[k] for x in ok]))
                        for k in ("chi2_dof", "nis_dof")
                        if ok and all(k in x for x in ok)
                    },
                }
        out[scenario] = {"errors": table}
        for variant in CAMPAIGN_VARIANTS:
            campaign = [
                {
                    "estimators": {
                        n: x["campaign"]
                        for n, x in r["variants"][variant].items()
                        if "campaign" in x
                    }
                }
                for r in mine
                if variant in r["variants"]
            ]
            out[scenario][variant] = campaign_statistics(campaign) if campaign else {}
    return out


def print_summary(summary: dict[str, Any]) -> None:
    for scenario, s in summary.items():
        print(
            f"\n{scenario}: final horizontal error, % of distance (RMS over runs; horizontal error/sigma std)"
        )
        for key, row in s["errors"].items():
            fit = "".join(
                f"  mean {k.replace('_dof', '')}/dof {row[k]:.3f}"
                for k in ("chi2_dof", "nis_dof")
                if k in row
            )
            print(
                f"  {key:18s} {row['rms_pct']:7.3f} %  median {row['median_pct']:6.3f} %  z std "
                f"{row['horizontal_z_std']:5.2f}  ({row['runs']} runs, {row['failed']} failed){fit}"
            )
        for variant, est in (
            ("batch", "truth"),
            ("online", "truth"),
            ("batch", "nominal"),
            ("online", "nominal"),
        ):
            for pre in ("presets", "presets_free"):
                p, f = s["errors"].get(f"{pre}/{variant}"), s["errors"].get(f"{est}/{variant}")
                if p and f:
                    print(
                        f"  {pre}/{variant} over {est}/{variant}: {p['rms_pct'] / f['rms_pct']:.2f}x"
                    )
        for variant in CAMPAIGN_VARIANTS:
            for name, est in s.get(variant, {}).get("estimators", {}).items():
                worst = max(est["states"].items(), key=lambda kv: kv[1]["z_std"])
                nees = est["nees_block"]
                print(
                    f"  {variant}/{name}: largest error/sigma std {worst[1]['z_std']:.2f} ({worst[0]}); block NEES "
                    f"{nees['mean']:.2f} in [{nees['band_95'][0]:.2f}, {nees['band_95'][1]:.2f}]: "
                    f"{'inside' if nees['inside_band'] else 'OUTSIDE'}"
                )


def main() -> None:
    ap = campaign_parser(__doc__, runs=50, out="underway_calibration.json")
    ap.add_argument("--scenarios", default="straight-transect,steady-turn")
    # the scenarios' sensors: the paper's navigation-grade IMU (0.1 deg/h/sqrt(Hz), 0.01 deg/h, 10 micro-g/sqrt(Hz),
    # 50 micro-g: the PHINS preset's class) and a 7 mm/s bottom-track DVL (a Pathfinder's class, 0.4 % scale)
    ap.add_argument(
        "--imu-model", default="ixblue-phins", help="[imu] model of the 'presets' variant"
    )
    ap.add_argument(
        "--dvl-model", default="teledyne-pathfinder", help="[dvl] model of the 'presets' variant"
    )
    ap.add_argument(
        "--mounting-tolerance-deg",
        type=float,
        default=0.5,
        help="[priors] mounting_tolerance_deg of the 'presets' variant",
    )
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--variants", default=",".join(VARIANTS), help="the variants to run (default: all)"
    )
    args = ap.parse_args()
    variants = tuple(args.variants.split(","))
    sensors = (args.imu_model, args.dvl_model, args.mounting_tolerance_deg, variants)
    tasks = [(s, seed, *sensors) for s in args.scenarios.split(",") for seed in seeds(args)]
    runs = run_on_dask(run_one, tasks, args.workers, args.out, summarise, every=10)
    print_summary(summarise(runs))


if __name__ == "__main__":
    main()
