"""Errors of an estimate against the simulated truth, and the summary every estimator reports."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gtsam_dvl.analysis.observability import lever_arm_verdict, time_offset_verdict
from gtsam_dvl.core.config.schema import SCHEMA_VERSION
from gtsam_dvl.core.result import NavResult, WaterCurrentProfile
from gtsam_dvl.core.rotations import matrix_to_rpy_deg, rpy_deg_to_matrix
from gtsam_dvl.core.summary import Summary
from gtsam_dvl.core.types import LogData, TruthData
from gtsam_dvl.core.units import DEG_PER_H, UG


def truth_at(truth: TruthData, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth (n_p m, n_R_b, n_v m/s) interpolated at times t (linear; slerp for attitude)."""
    t = np.clip(t, truth.t[0], truth.t[-1])
    n_p = np.stack([np.interp(t, truth.t, truth.n_p[:, i]) for i in range(3)], axis=1)
    n_v = np.stack([np.interp(t, truth.t, truth.n_v[:, i]) for i in range(3)], axis=1)
    n_R_b = Slerp(truth.t, Rotation.from_quat(truth.n_q_b))(t).as_matrix()
    return n_p, n_R_b, n_v


def path_length(n_p: np.ndarray) -> float:
    """Distance travelled along a sampled path, m."""
    return float(np.linalg.norm(np.diff(n_p, axis=0), axis=1).sum()) if len(n_p) > 1 else 0.0


def attitude_errors_deg(n_R_b_est: np.ndarray, n_R_b_true: np.ndarray) -> np.ndarray:
    """(N, 3) attitude error about map axes (east, north, up) in degrees: log(R_est R_true^T)."""
    return np.degrees(
        Rotation.from_matrix(n_R_b_est @ np.transpose(n_R_b_true, (0, 2, 1))).as_rotvec()
    )


@dataclass
class TrajectoryErrors:
    """Errors of an estimated trajectory against the truth at the estimate's epochs, and the one set of metrics
    summary and evaluate report. Attitude errors about map axes (east, north, up), deg; position m and
    velocity m/s in map axes."""

    t: np.ndarray  # (N,) s
    attitude_deg: np.ndarray  # (N, 3)
    position_m: np.ndarray  # (N, 3)
    velocity_m_s: np.ndarray  # (N, 3)
    distance_m: float  # along the true path

    def metrics(self) -> dict[str, Any]:
        """RMSEs (3-D norms and per axis), the final horizontal position error (m and % of distance), the final
        attitude error."""
        final_h = float(np.linalg.norm(self.position_m[-1, :2]))
        return {
            "final_horizontal_position_m": final_h,
            "final_horizontal_position_pct_distance": 100.0 * final_h / self.distance_m
            if self.distance_m > 0
            else None,
            "position_rmse_m": float(np.sqrt(np.mean(np.sum(self.position_m**2, axis=1)))),
            "position_rmse_axes_m": np.sqrt(np.mean(self.position_m**2, axis=0)).tolist(),
            "velocity_rmse_m_s": float(np.sqrt(np.mean(np.sum(self.velocity_m_s**2, axis=1)))),
            "velocity_rmse_axes_m_s": np.sqrt(np.mean(self.velocity_m_s**2, axis=0)).tolist(),
            "attitude_rmse_deg": np.sqrt(np.mean(self.attitude_deg**2, axis=0)).tolist(),
            "final_attitude_deg": self.attitude_deg[-1].tolist(),
        }


def trajectory_errors(result: NavResult, truth: TruthData) -> TrajectoryErrors:
    """Errors of result's states against the truth interpolated at their times."""
    n_p_true, n_R_b_true, n_v_true = truth_at(truth, result.t)
    return TrajectoryErrors(
        result.t,
        attitude_errors_deg(result.n_R_b, n_R_b_true),
        result.n_p - n_p_true,
        result.n_v - n_v_true,
        path_length(truth.n_p),
    )


def truth_in_user_units(log: LogData) -> dict[str, Any]:
    """The log's true calibration and biases in the units of Timeline (what figures draw as truth lines):
    scale, misalignment (deg, [roll, pitch, yaw]), time_offset (s), lever_arm (m, base_link), gyro_bias (deg/h),
    accel_bias (micro-g); absent ones are left out."""
    out: dict[str, Any] = {}
    if (cal := log.true_calibration) is not None:
        out["scale"] = cal.scale
        out["misalignment"] = np.array(cal.misalignment_deg)
        out["time_offset"] = cal.time_offset_s
    truth_md = log.metadata.get("truth")
    if (
        isinstance(truth_md, dict)
        and (lever := (truth_md.get("dvl") or {}).get("b_lever_arm_m")) is not None
    ):
        out["lever_arm"] = np.asarray(lever, dtype=float)
    if (bias := log.true_imu_bias) is not None:
        out["gyro_bias"] = np.array(bias.gyro_rad_s) / DEG_PER_H
        out["accel_bias"] = np.array(bias.accel_m_s2) / UG
    return out


def current_summary(wc: WaterCurrentProfile, log: LogData) -> dict[str, Any]:
    """The water current in the summary (its per-state profile is NavResult.water_current): the verdict, the
    water-track pings used, the current's range with its sigma where determined, per 50 m of depth, and against the
    simulated truth when the log has it (RMS error and error/sigma over the determined states)."""
    t = np.asarray(wc.t_s, dtype=float)
    c = np.stack([wc.east_m_s, wc.north_m_s], axis=1)
    sig = np.stack([wc.east_sigma_m_s, wc.north_sigma_m_s], axis=1)
    det = np.asarray(wc.determined, dtype=bool)
    depth = np.asarray(wc.depth_m, dtype=float)
    water = log.dvl.water_track
    out: dict[str, Any] = {
        "verdict": wc.verdict,
        "states": len(t),
        "determined_share": float(det.mean()) if len(det) else 0.0,
        "water_track_pings": int(np.sum(water)) if water is not None else 0,
    }
    layers = []
    for top in np.arange(0.0, float(depth.max()) + 50.0, 50.0) if len(depth) else []:
        m = (depth >= top) & (depth < top + 50.0) & det
        if m.any():
            mean = c[m].mean(axis=0)
            layers.append(
                {
                    "depth_m": [float(top), float(top + 50.0)],
                    "east_m_s": float(mean[0]),
                    "north_m_s": float(mean[1]),
                    "sigma_m_s": float(sig[m].mean()),
                    "speed_m_s": float(np.hypot(*mean)),
                    "states": int(m.sum()),
                }
            )
    out["by_depth"] = layers
    # the current per depth layer: each boundary crossed, the change across it
    if wc.layer_thickness_m is not None:
        out["layers"] = {
            "thickness_m": wc.layer_thickness_m,
            "boundaries": len(wc.layer_boundaries or []),
            "shear": wc.layer_shear or [],
        }
    truth = log.truth
    if truth is not None and truth.n_c is not None and det.any():
        k = np.clip(np.searchsorted(truth.t, t[det]), 0, len(truth.t) - 1)
        err = c[det] - truth.n_c[k, :2]
        out["errors"] = {
            "rms_m_s": float(np.sqrt(np.mean(err**2))),
            "max_abs_z": float(np.max(np.abs(err / sig[det]))),
        }
    return out


def truth_errors(result: NavResult, log: LogData) -> dict[str, Any] | None:
    """The `errors` block of the summary: None when the log has no truth."""
    if log.truth is None:
        return None
    out: dict[str, Any] = {}
    cal = log.true_calibration
    if cal is not None:
        out["scale_ppm"] = (result.scale - cal.scale) / cal.scale * 1e6
        R_c_true = rpy_deg_to_matrix(cal.misalignment_deg)
        R_c_est = result.b_R_d @ result.b_R_d0.T
        err_rpy = matrix_to_rpy_deg(R_c_est @ R_c_true.T)
        out["misalignment_deg"] = err_rpy.tolist()
        sig = result.misalignment_sigma_deg
        out["misalignment_nsigma"] = (err_rpy / sig).tolist()
        out["scale_nsigma"] = (result.scale - cal.scale) / result.scale_sigma
        if np.isfinite(result.time_offset_sigma_s):  # the DVL time offset was estimated
            out["dvl_time_offset_s"] = result.time_offset_s - cal.time_offset_s
            out["dvl_time_offset_nsigma"] = (
                result.time_offset_s - cal.time_offset_s
            ) / result.time_offset_sigma_s
    # a simulated log's true lever arm (its /tf_static may be wrong)
    truth_md = log.metadata.get("truth")
    true_lever = (
        truth_md.get("dvl", {}).get("b_lever_arm_m") if isinstance(truth_md, dict) else None
    )
    if (
        result.lever_arm_m is not None
        and result.lever_arm_sigma_m is not None
        and true_lever is not None
    ):
        err = result.lever_arm_m - np.asarray(true_lever, dtype=float)  # m, base_link
        out["dvl_lever_arm_m"] = err.tolist()
        out["dvl_lever_arm_nsigma"] = (err / result.lever_arm_sigma_m).tolist()
    if log.true_imu_bias is not None:
        g_err = (result.gyro_bias - np.asarray(log.true_imu_bias.gyro_rad_s)) / DEG_PER_H
        a_err = (result.accel_bias - np.asarray(log.true_imu_bias.accel_m_s2)) / UG
        out["gyro_bias_deg_per_h"] = g_err.tolist()
        out["accel_bias_ug"] = a_err.tolist()
        out["gyro_bias_nsigma"] = (g_err / result.gyro_bias_sigma_deg_per_h).tolist()
        out["accel_bias_nsigma"] = (a_err / result.accel_bias_sigma_ug).tolist()
    out.update(trajectory_errors(result, log.truth).metrics())
    return out


def noise_lines(noise: Any) -> list[str]:
    """The noise levels an estimator took from the data, one line each (result.info["noise"],
    estimators/models/noise_levels.py NoiseReport): the IMU densities raised to their quantisation floor or to the
    static
    segment's measured density, the DVL fit, the depth and GNSS fits, the DVL's correlated error's."""
    if not isinstance(noise, dict):
        return []
    imu = [v for v in (noise.get("imu") or {}).values() if isinstance(v, dict)]
    parts = (
        imu
        + [v["static"] for v in imu if isinstance(v.get("static"), dict)]
        + [noise.get("dvl") or {}]
    )
    parts += [
        noise.get("depth") or {},
        noise.get("gnss") or {},
    ]  # the batch smoother's depth and GNSS fits
    parts += [
        noise.get("dvl_correlated") or {}
    ]  # the DVL's correlated error: fitted (batch) or held
    return [str(p["why"]) for p in parts if isinstance(p, dict) and p.get("why")]


def summary(result: NavResult, log: LogData) -> dict[str, Any]:
    """The summary JSON (docs/command-line.md) as the dict written: build_summary's model, to_json_dict."""
    return build_summary(result, log).to_json_dict()


def build_summary(result: NavResult, log: LogData) -> Summary:
    """The summary (core/summary.py Summary), in user units (degrees, deg/h, micro-g, ppm), with the run's
    health (analysis/health.py), its geometry (analysis/geometry.py) and what the reader lost
    (LogData.metadata["reader_losses"]). A part that does not fit the model is a pydantic ValidationError: a
    programming error, not the user's."""
    truth_dist = path_length(log.truth.n_p) if log.truth is not None else path_length(result.n_p)
    out: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "estimator": result.estimator,
        "log": log.source,
        "scale": {"value": result.scale, "sigma": result.scale_sigma},
        "misalignment_deg": {
            "value": result.misalignment_deg.tolist(),
            "sigma": result.misalignment_sigma_deg.tolist(),
            "convention": "R_c = Rz(yaw) Ry(pitch) Rx(roll) in body FLU axes, b_R_d = R_c b_R_d0",
        },
        "gyro_bias_deg_per_h": {
            "value": result.gyro_bias_deg_per_h.tolist(),
            "sigma": result.gyro_bias_sigma_deg_per_h.tolist(),
        },
        "accel_bias_ug": {
            "value": result.accel_bias_ug.tolist(),
            "sigma": result.accel_bias_sigma_ug.tolist(),
        },
        "distance_travelled_m": truth_dist,
        "final_horizontal_position_sigma_m": float(np.hypot(*result.position_sigma_m[-1, :2])),
        "duration_s": float(result.t[-1] - result.t[0]),
        "states": len(result.t),
        "timing_s": result.timing_s,
        "real_time_factor": float((result.t[-1] - result.t[0]) / result.timing_s["total"])
        if result.timing_s.get("total")
        else None,
        "info": result.info,
    }
    out["noise_levels"] = noise_lines(result.info.get("noise"))
    if isinstance(recentred := result.info.get("time_offset_prior"), dict) and recentred.get("why"):
        # the EKF's warm-up: where its offset prior was centred
        out["noise_levels"].append(str(recentred["why"]))
    if np.isfinite(result.time_offset_sigma_s):
        out["dvl_time_offset_s"] = time_offset_verdict(result)
    if result.lever_arm_m is not None and result.lever_arm_cov is not None:
        out["dvl_lever_arm_m"] = lever_arm_verdict(result, log)
    # (estimators/models/weak_hold.py report: one shape, core/summary.py CalibrationHold)
    if isinstance(hold := result.info.get("calibration_hold"), dict):
        out["calibration_hold"] = hold
    if (wc := result.water_current) is not None:
        out["water_current"] = current_summary(wc, log)
    errors = truth_errors(result, log)
    if errors is not None:
        out["errors"] = errors
    # health reads the config, which metrics does not need
    from gtsam_dvl.analysis.health import (
        assess_health,
    )

    out["health"] = assess_health(result, log).as_dict()
    # the motion and the weak calibration directions (analysis/geometry.py; their sentences are health warnings
    # or notes)
    out["geometry"] = out["health"]["figures"].get("geometry")
    # against a calibration file (analysis/calibration_check.py)
    if "calibration_check" in out["health"]["figures"]:
        out["calibration_check"] = out["health"]["figures"]["calibration_check"]
    out["losses"] = log.metadata.get("reader_losses", {})
    return Summary.model_validate(out)
