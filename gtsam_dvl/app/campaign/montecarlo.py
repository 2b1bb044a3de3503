"""Monte Carlo consistency: one simulated run per seed through the chosen estimators, and the statistics of a
campaign (is each estimator's sigma honest, and how close does it come to the Cramer-Rao bound?).

A run (run_seed) is a pure function of plain data: the scenario as a dict (the TOML's tables), the seed, the
estimator names and the configuration as a dict. It simulates, runs each estimator and returns, per estimator,
the errors against the truth and the reported sigmas of every calibration and bias state (user units: ppm, deg,
s, micro-g, deg/h, m), the NEES of the calibration and bias block (10 dof, from the estimator's joint covariance)
and, for the filters, the NEES over time from their timelines (diagonal: the sum of squared normalised errors,
the timeline keeps marginal sigmas only). Seeds decide everything, so a run is reproducible on any machine, which
is what lets a campaign run on a Dask cluster (campaign/runner.py) without shipping objects between processes.

Statistics (campaign_statistics), per estimator and state over N runs: the mean and standard deviation of
error/sigma (0 and 1 when the sigmas are honest), the fraction of runs within 3 sigma (99.7 %), the RMSE against
the mean reported sigma and against the Cramer-Rao bound (the noise-free batch information at the truth: the
planner's covariance, analysis/planning.py, given by the caller), and the mean NEES of the block with its 95 %
chi-square band for N runs of 10 dof: mean NEES ~ chi2(10 N) / N.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.stats import chi2

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import so3_log
from gtsam_dvl.core.states import BY_NAME
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.run import run_trajectory_estimator

# the states of a campaign, in the order of their vectors, with units: the registry's (core/states.py) components
# in their display units, then the final position
STATES: list[tuple[str, str]] = [
    (name, BY_NAME[state].display_unit)
    for state in ("scale", "misalignment", "accel_bias", "gyro_bias")
    for name in BY_NAME[state].component_names()
] + [("final_position_east", "m"), ("final_position_north", "m"), ("final_position_up", "m")]
TIME_OFFSET_STATE = (
    BY_NAME["time_offset"].name,
    BY_NAME["time_offset"].unit,
)  # in s (the registry shows ms)
ESTIMATORS = ("batch", "online", "ekf")
# [accel bias, gyro bias, scale, misalignment]: the joint covariance every estimator reports
BLOCK_DOF = 10
NEES_EVERY_S = 60.0  # the filters' NEES over time, sampled this often


def run_seed(
    scenario: Mapping[str, Any],
    seed: int,
    estimators: list[str] | tuple[str, ...],
    config: Mapping[str, Any] | None = None,
    scenario_name: str = "scenario",
    calibration: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """One Monte Carlo run (module doc). scenario: a scenario dict (the TOML's tables); config: an
    EstimatorConfig as a dict (None: the configuration the scenario names); calibration: a vehicle's calibration
    file's data (app/calibration_files.py calibration_data), every estimator's prior, inflated for the days to the
    simulated log's date. Returns plain data (JSON-able)."""
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import scenario_from_dict

    sc = scenario_from_dict(
        dict(scenario), name=scenario_name, source=f"{scenario_name} (seed {seed})"
    )
    log = simulate(sc, int(seed))
    cfg = EstimatorConfig.from_dict(config) if config else sc.estimator_configuration()
    prior = None
    if calibration is not None:
        from gtsam_dvl.app.calibration_files import inflated_for
        from gtsam_dvl.io.calibration_file import calibration_from_dict

        prior, _ = inflated_for(
            calibration_from_dict(dict(calibration), "the campaign's calibration"), log, cfg
        )
    out: dict[str, Any] = {"seed": int(seed), "estimators": {}}
    for name in estimators:
        t0 = time.perf_counter()
        res = run_trajectory_estimator(log, name, cfg, timeline=False, calibration=prior)
        wall = time.perf_counter() - t0
        out["estimators"][name] = {**run_errors(res, log), "wall_s": wall}
    return out


def run_errors(res: NavResult, log: LogData) -> dict[str, Any]:
    """Errors (estimate - truth) and sigmas of STATES (and the time offset when estimated), user units; the NEES
    of the calibration and bias block; the filters' NEES over time."""
    cal, bias, truth = log.true_calibration, log.true_imu_bias, log.truth
    if cal is None or bias is None or truth is None:
        raise ValueError(
            "a Monte Carlo run needs a simulated log (true calibration, biases and trajectory)"
        )
    acc_true, gyro_true = np.array(bias.accel_m_s2), np.array(bias.gyro_rad_s)
    n_p_true = np.array([np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(3)])
    err = np.concatenate(
        [
            [(res.scale - cal.scale) * 1e6],
            res.misalignment_deg - np.array(cal.misalignment_deg),
            res.accel_bias_ug - acc_true / UG,
            res.gyro_bias_deg_per_h - gyro_true / DEG_PER_H,
            res.n_p[-1] - n_p_true,
        ]
    )
    sig = np.concatenate(
        [
            [res.scale_sigma * 1e6],
            res.misalignment_sigma_deg,
            res.accel_bias_sigma_ug,
            res.gyro_bias_sigma_deg_per_h,
            res.position_sigma_m[-1],
        ]
    )
    out: dict[str, Any] = {
        "error": err.tolist(),
        "sigma": sig.tolist(),
        "nees_block": block_nees(res, log),
    }
    if np.isfinite(res.time_offset_sigma_s):
        out["time_offset"] = {
            "error": float(res.time_offset_s - cal.time_offset_s),
            "sigma": float(res.time_offset_sigma_s),
        }
    if res.timeline is not None and res.estimator != "batch":
        out["nees_time"] = timeline_nees(res, log)
    return out


def block_nees(res: NavResult, log: LogData) -> float | None:
    """e^T P^-1 e of [accel bias, gyro bias, scale, b_R_d] (SI; the misalignment as the right-tangent rotation
    from the truth to the estimate), P the estimator's joint covariance (NavResult.calib_joint_cov)."""
    cal, bias = log.true_calibration, log.true_imu_bias
    if res.calib_joint_cov is None or cal is None or bias is None:
        return None
    b_R_d_true = cal.b_R_d(log.mounting.b_R_d0)
    e = np.concatenate(
        [
            res.accel_bias - np.array(bias.accel_m_s2),
            res.gyro_bias - np.array(bias.gyro_rad_s),
            [res.scale - cal.scale],
            so3_log(b_R_d_true.T @ res.b_R_d),
        ]
    )
    P = np.asarray(res.calib_joint_cov, dtype=float)
    return float(e @ np.linalg.solve(P, e))


def timeline_nees(res: NavResult, log: LogData) -> dict[str, list[float]]:
    """A filter's NEES over time (every NEES_EVERY_S): the sum over scale, misalignment and biases of the squared
    normalised errors of its timeline (diagonal: the timeline keeps marginal sigmas only)."""
    tl, cal, bias = res.timeline, log.true_calibration, log.true_imu_bias
    assert tl is not None and cal is not None and bias is not None
    z = np.column_stack(
        [
            (tl.scale - cal.scale) / tl.scale_sigma,
            (tl.misalignment_deg - np.array(cal.misalignment_deg)) / tl.misalignment_sigma_deg,
            (tl.accel_bias_ug - np.array(bias.accel_m_s2) / UG) / tl.accel_bias_sigma_ug,
            (tl.gyro_bias_deg_per_h - np.array(bias.gyro_rad_s) / DEG_PER_H)
            / tl.gyro_bias_sigma_deg_per_h,
        ]
    )
    grid = np.arange(tl.t[0], tl.t[-1] + 1e-9, NEES_EVERY_S)
    idx = np.clip(np.searchsorted(tl.t, grid), 0, len(tl.t) - 1)
    return {"t": tl.t[idx].tolist(), "nees": np.sum(z[idx] ** 2, axis=1).tolist()}


def cramer_rao_sigmas(
    scenario: Mapping[str, Any],
    config: Mapping[str, Any] | None = None,
    scenario_name: str = "scenario",
) -> list[float]:
    """The Cramer-Rao bound of STATES: the sigmas of the noise-free batch solution at the truth (the mission
    planner's covariance), user units."""
    from gtsam_dvl.analysis.planning import plan_mission
    from gtsam_dvl.sim.scenario import scenario_from_dict

    sc = scenario_from_dict(dict(scenario), name=scenario_name)
    cfg = EstimatorConfig.from_dict(config) if config else None
    r = plan_mission(sc, cfg).result
    return np.concatenate(
        [
            [r.scale_sigma * 1e6],
            r.misalignment_sigma_deg,
            r.accel_bias_sigma_ug,
            r.gyro_bias_sigma_deg_per_h,
            r.position_sigma_m[-1],
        ]
    ).tolist()


def nees_band(n_runs: int, dof: int = BLOCK_DOF, level: float = 0.95) -> tuple[float, float]:
    """The two-sided band of the mean NEES over n_runs runs of dof each: chi2(dof n) / n."""
    a = (1.0 - level) / 2.0
    return float(chi2.ppf(a, dof * n_runs) / n_runs), float(
        chi2.ppf(1.0 - a, dof * n_runs) / n_runs
    )


def campaign_statistics(
    runs: list[dict[str, Any]], crb: list[float] | None = None
) -> dict[str, Any]:
    """Per estimator and state: mean and std of error/sigma, fraction within 3 sigma, RMSE, mean sigma,
    RMSE / mean sigma, RMSE / Cramer-Rao bound; the block NEES mean with its 95 % band and the runs outside it;
    the filters' mean NEES over time. runs: the outputs of run_seed."""
    out: dict[str, Any] = {"runs": len(runs), "estimators": {}}
    names = sorted(
        {e for r in runs for e in r["estimators"]}, key=lambda e: (ESTIMATORS + (e,)).index(e)
    )
    for name in names:
        rows = [r["estimators"][name] for r in runs if name in r["estimators"]]
        err, sig = np.array([x["error"] for x in rows]), np.array([x["sigma"] for x in rows])
        states = [s for s, _ in STATES]
        units = [u for _, u in STATES]
        if all("time_offset" in x for x in rows):
            err = np.column_stack([err, [x["time_offset"]["error"] for x in rows]])
            sig = np.column_stack([sig, [x["time_offset"]["sigma"] for x in rows]])
            states.append(TIME_OFFSET_STATE[0])
            units.append(TIME_OFFSET_STATE[1])
        z = err / sig
        rmse = np.sqrt(np.mean(err**2, axis=0))
        per_state = {}
        for j, (state, unit) in enumerate(zip(states, units, strict=True)):
            row = {
                "unit": unit,
                "z_mean": float(np.mean(z[:, j])),
                "z_std": float(np.std(z[:, j], ddof=1)) if len(z) > 1 else float("nan"),
                "within_3_sigma": float(np.mean(np.abs(z[:, j]) <= 3.0)),
                "rmse": float(rmse[j]),
                "mean_sigma": float(np.mean(sig[:, j])),
                "rmse_over_sigma": float(rmse[j] / np.mean(sig[:, j])),
            }
            if crb is not None and j < len(crb):
                row["crb"] = float(crb[j])
                row["rmse_over_crb"] = float(rmse[j] / crb[j]) if crb[j] > 0 else float("nan")
            per_state[state] = row
        nees = np.array(
            [x["nees_block"] for x in rows if x.get("nees_block") is not None], dtype=float
        )
        lo, hi = nees_band(len(nees)) if len(nees) else (float("nan"), float("nan"))
        est: dict[str, Any] = {
            "states": per_state,
            "wall_s_mean": float(np.mean([x["wall_s"] for x in rows])),
            "nees_block": {
                "mean": float(np.mean(nees)) if len(nees) else float("nan"),
                "dof": BLOCK_DOF,
                "band_95": [lo, hi],
                "inside_band": bool(lo <= np.mean(nees) <= hi) if len(nees) else False,
            },
        }
        times = [x["nees_time"] for x in rows if "nees_time" in x]
        if times:
            n = min(len(x["t"]) for x in times)
            mean_t = np.mean([x["nees"][:n] for x in times], axis=0)
            band = nees_band(len(times))
            est["nees_time"] = {
                "t": times[0]["t"][:n],
                "mean": mean_t.tolist(),
                "band_95": list(band),
                "fraction_inside": float(np.mean((mean_t >= band[0]) & (mean_t <= band[1]))),
            }
        out["estimators"][name] = est
    return out
