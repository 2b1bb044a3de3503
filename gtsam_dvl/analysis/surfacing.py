"""The surfacing error: estimates against the GNSS fixes that did not aid, the accuracy figure of a real log.

Works without truth. For every held-out fix (estimators/inputs/gnss.py: a good fix that was not a position factor,
e.g. the fixes of the final surfacing under [gnss] use = "start") the estimated antenna position at the fix's
time,

    n_p_a = n_p_i + n_R_b,i b_p_a + dt n_v_i      (state i the fix's nearest, dt = t_fix - t_i),

is compared with the fix in map (ENU at the map origin): the horizontal error sqrt(dE^2 + dN^2) and the vertical
error dU in metres, and the horizontal error in % of the distance travelled up to then (the 3-D path length of
the estimated trajectory, state to state, plus dt |n_v_i|). Sigmas: the fix's (sqrt(var_E + var_N)
horizontally, sqrt(var_U) vertically, from the covariance the estimator used) and the estimate's, from the
marginal covariance of (pose, velocity) of state i through the Jacobian of n_p_a. nis is the error's squared
Mahalanobis norm with both covariances (chi^2 with 3 dof when both are right).

The surfacing error is the error at the first held-out fix of the last surface interval: the first fix after
the final ascent, where the dead-reckoning error is largest and has not been corrected. One fix carries the
receiver's noise (2-3 m for a plain GNSS fix), which hides a navigation error of 0.1 % of a 2 km dive; so the
report also gives the mean of the errors over all held-out fixes of that interval (surfacing_mean: the
receiver's white noise averaged down by sqrt(N), its sigma the mean covariance / N; the estimate's sigma is that
at the first fix, and its error changes little over a surface interval of a minute).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import skew
from gtsam_dvl.core.state_covariance import pose_velocity_covariance
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.alignment import map_frame_of
from gtsam_dvl.estimators.inputs.gnss import plan_fixes


@dataclass(frozen=True)
class FixCheck:
    """One held-out fix against the estimate (module doc). Metres, seconds, map ENU axes."""

    t_s: float
    interval: int
    error_enu_m: tuple[float, float, float]
    horizontal_error_m: float
    vertical_error_m: float
    distance_m: float
    horizontal_error_pct: float  # of distance_m
    fix_sigma_h_m: float
    fix_sigma_v_m: float
    estimate_sigma_h_m: float
    estimate_sigma_v_m: float
    nis: float


@dataclass
class SurfacingReport:
    """The held-out fixes of a result and its surfacing error (None when there are no held-out fixes)."""

    use: str
    counters: dict[str, int]
    checks: list[FixCheck] = field(default_factory=list)
    surfacing: FixCheck | None = None
    # mean over the last interval's held-out fixes (module doc)
    surfacing_mean: FixCheck | None = None
    surfacing_fixes: int = 0  # how many fixes surfacing_mean averages
    n_intervals: int = 0

    def as_dict(self) -> dict[str, Any]:
        """For metrics.json."""
        h = np.array([c.horizontal_error_m for c in self.checks])
        return {
            "use": self.use,
            "counters": self.counters,
            "surface_intervals": self.n_intervals,
            "held_out_evaluated": len(self.checks),
            "held_out_horizontal_rms_m": float(np.sqrt(np.mean(h**2))) if len(h) else None,
            "surfacing_error": asdict(self.surfacing) if self.surfacing is not None else None,
            "surfacing_error_mean": asdict(self.surfacing_mean)
            if self.surfacing_mean is not None
            else None,
            "surfacing_fixes": self.surfacing_fixes,
            "fixes": [asdict(c) for c in self.checks],
        }


def antenna_estimate(
    res: NavResult, i: int, b_p_a: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Estimated antenna position (3,) in map at t_i + dt and its covariance (3, 3), map axes (module doc)."""
    R = res.n_R_b[i]
    p = res.n_p[i] + R @ b_p_a + dt * res.n_v[i]
    # [rotation (body), translation (body), n_v]
    J = np.hstack((-R @ skew(b_p_a), R, dt * np.eye(3)))
    P = pose_velocity_covariance(
        res.pose_cov[i],
        res.vel_cov[i],
        None if res.pose_vel_cross is None else res.pose_vel_cross[i],
    )
    return np.asarray(p), np.asarray(J @ P @ J.T)


def distance_travelled(res: NavResult) -> np.ndarray:
    """(N,) 3-D path length of the estimated trajectory from the first state to each state, m."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(res.n_p, axis=0), axis=1))])


def surfacing_report(
    res: NavResult, log: LogData, config: EstimatorConfig | None = None
) -> SurfacingReport | None:
    """The held-out fixes of log (its GNSS data, read as the result's was) against result res; None when the log
    has no GNSS data. config: the result's configuration (default: res.config)."""
    if log.gnss is None or not len(log.gnss):
        return None
    if config is None:
        # (a configuration that does not read: from_dict raises why)
        config = res.estimator_config or EstimatorConfig.from_dict(res.config)
    frame = map_frame_of(log, config)
    plan = plan_fixes(log, config, frame, res.t)
    if plan is None:
        return None
    report = SurfacingReport(config.gnss.use, plan.counters(), n_intervals=plan.n_intervals)
    dist = distance_travelled(res)
    # the fixes behind report.checks, in their order
    held = np.flatnonzero(plan.mask("held_out")).tolist()
    for k in held:
        i, dt = int(plan.state[k]), float(plan.dt[k])
        p, P = antenna_estimate(res, i, plan.b_p_antenna, dt)
        e = p - plan.n_p[k]
        C = plan.cov[k]
        d = float(dist[i] + dt * np.linalg.norm(res.n_v[i]))
        h = float(np.hypot(e[0], e[1]))
        report.checks.append(
            FixCheck(
                t_s=float(plan.t[k]),
                interval=int(plan.interval[k]),
                error_enu_m=(float(e[0]), float(e[1]), float(e[2])),
                horizontal_error_m=h,
                vertical_error_m=float(e[2]),
                distance_m=d,
                horizontal_error_pct=100.0 * h / d if d > 0 else float("nan"),
                fix_sigma_h_m=float(np.sqrt(C[0, 0] + C[1, 1])),
                fix_sigma_v_m=float(np.sqrt(C[2, 2])),
                estimate_sigma_h_m=float(np.sqrt(P[0, 0] + P[1, 1])),
                estimate_sigma_v_m=float(np.sqrt(P[2, 2])),
                nis=float(e @ np.linalg.solve(P + C, e)),
            )
        )
    last = plan.n_intervals - 1
    report.surfacing = next((c for c in report.checks if c.interval == last), None)
    in_last = [(k, c) for k, c in zip(held, report.checks, strict=True) if c.interval == last]
    if report.surfacing is not None and in_last:
        first = report.surfacing
        e = np.mean([c.error_enu_m for _, c in in_last], axis=0)
        C = np.mean([plan.cov[k] for k, _ in in_last], axis=0) / len(in_last)
        _, P = antenna_estimate(
            res, int(plan.state[in_last[0][0]]), plan.b_p_antenna, float(plan.dt[in_last[0][0]])
        )
        h = float(np.hypot(e[0], e[1]))
        report.surfacing_fixes = len(in_last)
        report.surfacing_mean = FixCheck(
            t_s=first.t_s,
            interval=last,
            error_enu_m=(float(e[0]), float(e[1]), float(e[2])),
            horizontal_error_m=h,
            vertical_error_m=float(e[2]),
            distance_m=first.distance_m,
            horizontal_error_pct=100.0 * h / first.distance_m
            if first.distance_m > 0
            else float("nan"),
            fix_sigma_h_m=float(np.sqrt(C[0, 0] + C[1, 1])),
            fix_sigma_v_m=float(np.sqrt(C[2, 2])),
            estimate_sigma_h_m=first.estimate_sigma_h_m,
            estimate_sigma_v_m=first.estimate_sigma_v_m,
            nis=float(e @ np.linalg.solve(P + C, e)),
        )
    return report
