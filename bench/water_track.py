"""Water track and the water current on deep-descent: what using water-track pings gives, and are the sigmas honest?

Per seed, one simulated deep-descent log (a 300 m descent without bottom lock in a sheared current, the paper's
square on bottom track, the ascent, GNSS at the surface before the dive; data/scenarios/deep-descent.toml) goes
through the batch smoother, the online estimator and the EKF with water-track pings used ([current] water_track
"use", the current a state: estimators/models/current.py) and through the batch smoother with them refused. Recorded per
run and estimator: the final horizontal error and its sigma (map axes), every calibration and bias state's
error and sigma (app/campaign/montecarlo.py run_errors), the thrust-axis (roll) misalignment sigma, and the
current's error/sigma where it is determined (its sigma below half its prior's), sampled every 20 states.

    .venv/bin/python bench/water_track.py --runs 30 [--workers 2] [--estimators batch,online,ekf]
        [--layers 10] [--out data/water-track/water_track.json]

--layers H adds each estimator with the current per depth layer of H m ([current] layer_thickness_m: "layers/..."
rows), compared with the random walk in depth on the same logs.

The summary prints, per estimator: the RMS final horizontal error used vs refused (batch), the error/sigma std of
every calibration state and of the current, the mean roll-misalignment sigma used vs refused, and the
estimators' agreement (the differences of their final calibration in the sigmas of the difference).
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from campaign_loop import campaign_parser, run_on_dask, seeds

STATE_NAMES = [
    "scale_ppm",
    "mis_roll_deg",
    "mis_pitch_deg",
    "mis_yaw_deg",
    "acc_x",
    "acc_y",
    "acc_z",
    "gyr_x",
    "gyr_y",
    "gyr_z",
]  # run_errors' first ten entries


def _with(config: Any, section: str, **values: Any) -> Any:
    return config.model_copy(update={section: getattr(config, section).model_copy(update=values)})


def run_one(
    seed: int, estimators: tuple[str, ...], scenario: str = "deep-descent", layers_m: float = 0.0
) -> dict[str, Any]:
    from gtsam_dvl.app.campaign.montecarlo import run_errors
    from gtsam_dvl.estimators.run import run_trajectory_estimator
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    sc = load_scenario(scenario)
    log = simulate(sc, seed)
    truth = log.truth
    assert truth is not None and truth.n_c is not None
    base = sc.estimator_configuration()
    out: dict[str, Any] = {"seed": seed, "runs": {}}
    plan = [("use", name) for name in estimators] + [("refuse", "batch")]
    plan += [("layers", name) for name in estimators] if layers_m > 0 else []
    for variant, name in plan:
        cfg = _with(
            base,
            "current",
            water_track="use" if variant == "layers" else variant,
            layer_thickness_m=layers_m if variant == "layers" else 0.0,
        )
        t0 = time.perf_counter()
        try:
            res = run_trajectory_estimator(log, name, cfg, timeline=name != "batch")
        except Exception as exc:  # a failed run is reported, the campaign goes on
            out["runs"][f"{variant}/{name}"] = {"failed": f"{type(exc).__name__}: {exc}"}
            continue
        n_p_true = np.array([np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)])
        e_h = res.n_p[-1, :2] - n_p_true
        n_R_b = res.n_R_b[-1]
        cov_map = n_R_b @ res.pose_cov[-1, 3:6, 3:6] @ n_R_b.T
        row: dict[str, Any] = {
            "horizontal_error_m": float(np.linalg.norm(e_h)),
            "horizontal_z": (e_h / np.sqrt(np.diag(cov_map)[:2])).tolist(),
            "horizontal_sigma_m": float(np.sqrt(np.trace(cov_map[:2, :2]))),
            "wall_s": time.perf_counter() - t0,
            **run_errors(res, log),
            "calibration": {
                "scale": float(res.scale),
                "mis_deg": res.misalignment_deg.tolist(),
                "scale_sigma": float(res.scale_sigma),
                "mis_sigma_deg": res.misalignment_sigma_deg.tolist(),
            },
        }
        if res.water_current is not None:
            wc = res.water_current.as_dict()
            t = np.asarray(wc["t_s"], dtype=float)
            k = np.clip(np.searchsorted(truth.t, t), 0, len(truth.t) - 1)
            est = np.stack([wc["east_m_s"], wc["north_m_s"]], axis=1)
            sig = np.stack([wc["east_sigma_m_s"], wc["north_sigma_m_s"]], axis=1)
            det = np.asarray(wc["determined"], dtype=bool)
            z = (est - truth.n_c[k, :2]) / sig
            pick = np.flatnonzero(det)[
                ::20
            ]  # every 20th determined state: nearly independent samples
            row["current_z"] = z[pick].reshape(-1).tolist()
            row["current_rms_err_m_s"] = float(
                np.sqrt(np.mean((est[det] - truth.n_c[k[det], :2]) ** 2))
            )
            row["current_determined_share"] = float(det.mean())
        out["runs"][f"{variant}/{name}"] = row
    return out


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    keys = sorted({k for r in runs for k in r["runs"]})
    out: dict[str, Any] = {"runs": len(runs), "by": {}}
    for key in keys:
        rows = [r["runs"][key] for r in runs if key in r["runs"] and "failed" not in r["runs"][key]]
        if not rows:
            continue
        err = np.array([x["error"][:10] for x in rows])
        sig = np.array([x["sigma"][:10] for x in rows])
        z = err / sig
        hz = np.array([x["horizontal_z"] for x in rows]).reshape(-1)
        s: dict[str, Any] = {
            "runs": len(rows),
            "rms_horizontal_error_m": float(
                np.sqrt(np.mean([x["horizontal_error_m"] ** 2 for x in rows]))
            ),
            "mean_horizontal_sigma_m": float(np.mean([x["horizontal_sigma_m"] for x in rows])),
            "horizontal_z_std": float(np.std(hz, ddof=1)) if len(hz) > 1 else math.nan,
            "state_z_std": {
                n: float(np.std(z[:, i], ddof=1)) if len(z) > 1 else math.nan
                for i, n in enumerate(STATE_NAMES)
            },
            "state_within_3_sigma": {
                n: float(np.mean(np.abs(z[:, i]) < 3)) for i, n in enumerate(STATE_NAMES)
            },
            "roll_sigma_deg_mean": float(np.mean(sig[:, 1])),
            "wall_s_mean": float(np.mean([x["wall_s"] for x in rows])),
        }
        cz = np.concatenate([np.asarray(x.get("current_z", []), dtype=float) for x in rows])
        if len(cz):
            s["current_z_std"] = float(np.std(cz, ddof=1))
            s["current_within_3_sigma"] = float(np.mean(np.abs(cz) < 3))
            s["current_rms_err_m_s"] = float(
                np.sqrt(np.mean([x["current_rms_err_m_s"] ** 2 for x in rows]))
            )
        out["by"][key] = s
    use, ref = out["by"].get("use/batch"), out["by"].get("refuse/batch")
    if use and ref:
        out["refused_over_used_rms"] = ref["rms_horizontal_error_m"] / use["rms_horizontal_error_m"]
        out["roll_sigma_used_over_refused"] = (
            use["roll_sigma_deg_mean"] / ref["roll_sigma_deg_mean"]
        )
    for name in (
        "batch",
        "online",
        "ekf",
    ):  # the current per depth layer against the random walk in depth
        use, lay = out["by"].get(f"use/{name}"), out["by"].get(f"layers/{name}")
        if use and lay:
            out[f"{name}_random_walk_over_layers_rms"] = (
                use["rms_horizontal_error_m"] / lay["rms_horizontal_error_m"]
            )
    # the estimators' agreement: final scale and misalignment, differences in the sigma of the difference (the
    # larger sigma: the smoother's and a filter's estimates are correlated, so that is a bound)
    agree: dict[str, Any] = {}
    for other in ("use/online", "use/ekf", "layers/online", "layers/ekf"):
        d = []
        for r in runs:
            a, b = r["runs"].get(f"{other.split('/')[0]}/batch"), r["runs"].get(other)
            if not a or not b or "failed" in a or "failed" in b:
                continue
            ca, cb = a["calibration"], b["calibration"]
            d.append(
                [(ca["scale"] - cb["scale"]) / max(ca["scale_sigma"], cb["scale_sigma"])]
                + [
                    (x - y) / max(sx, sy)
                    for x, y, sx, sy in zip(
                        ca["mis_deg"],
                        cb["mis_deg"],
                        ca["mis_sigma_deg"],
                        cb["mis_sigma_deg"],
                        strict=True,
                    )
                ]
            )
        if d:
            arr = np.abs(np.array(d))
            agree[other] = {
                "max_abs": float(arr.max()),
                "share_within_1": float(np.mean(arr < 1.0)),
            }
    out["agreement_with_batch"] = agree
    return out


def print_summary(s: dict[str, Any]) -> None:
    print(f"\n{s['runs']} runs of deep-descent")
    for key, row in s["by"].items():
        worst = max(row["state_z_std"].items(), key=lambda kv: kv[1])
        cur = (
            (
                f"; current error/sigma std {row['current_z_std']:.2f} ({100 * row['current_within_3_sigma']:.0f} % "
                f"within 3 sigma), RMS {row['current_rms_err_m_s']:.3f} m/s"
            )
            if "current_z_std" in row
            else ""
        )
        print(
            f"  {key:13s} final horizontal RMS {row['rms_horizontal_error_m']:6.2f} m (mean sigma "
            f"{row['mean_horizontal_sigma_m']:5.2f}, z std {row['horizontal_z_std']:.2f}); largest state error/sigma "
            f"std {worst[1]:.2f} ({worst[0]}); roll sigma {row['roll_sigma_deg_mean']:.3f} deg; "
            f"{row['wall_s_mean']:.1f} s{cur}"
        )
    if "refused_over_used_rms" in s:
        print(
            f"  batch: refused / used final horizontal RMS {s['refused_over_used_rms']:.2f}x; roll-misalignment "
            f"sigma used / refused {s['roll_sigma_used_over_refused']:.2f}"
        )
    for name in ("batch", "online", "ekf"):
        if f"{name}_random_walk_over_layers_rms" in s:
            print(
                f"  {name}: final horizontal RMS, random walk in depth / per layer "
                f"{s[f'{name}_random_walk_over_layers_rms']:.2f}x"
            )
    for other, a in s.get("agreement_with_batch", {}).items():
        print(
            f"  {other} vs batch, final calibration: max |difference| {a['max_abs']:.2f} sigma, "
            f"{100 * a['share_within_1']:.0f} % within 1 sigma"
        )


def main() -> None:
    ap = campaign_parser(__doc__, runs=30, out="water_track.json")
    ap.add_argument("--estimators", default="batch,online,ekf")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--layers",
        type=float,
        default=0.0,
        help="> 0: also run each estimator with the current per depth layer of this thickness (m)",
    )
    args = ap.parse_args()
    estimators = tuple(args.estimators.split(","))
    tasks = [(seed, estimators) for seed in seeds(args)]
    runs = run_on_dask(
        run_one, tasks, args.workers, args.out, summarise, every=5, layers_m=args.layers
    )
    print_summary(summarise(runs))


if __name__ == "__main__":
    main()
