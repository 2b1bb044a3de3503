"""The DVL's constant velocity error as a consider term of the calibration's covariance ([dvl]
constant_error_sigma_m_s; issue 31).

A bottom-track DVL's error has a part that stays the same for a whole run: what the speed of sound at the
transducer, the beams' geometry and the bottom's slope leave (the offset term of a datasheet's long-term accuracy:
+-0.1 cm/s beside the +-0.2 % or +-0.1 % of speed on Teledyne's Workhorse Navigator and Nortek's DVL1000 sheets,
met over a flat bottom; on real logs the residuals averaged over 30-60 s stay at a few mm/s, issue 31). Such an
error b (dvl_link, m/s) and the calibration are one and the same to the data whenever the vehicle moves mostly
along one body direction: at a body velocity u seen as w = d_R_b u in dvl_link,

    k d_R_b(theta) u + b  =  (k + dk) d_R_b u  +  k [w]_x dtheta            (b_R_d perturbed on the right)

so dk = b . w / |w|^2 and dtheta the part of b across w over |w|: 2 mm/s at 1.9 m/s is 1,050 ppm of scale and
0.06 deg of pitch or yaw, as much as a log of turns determines them (realistic-turns: scale sigma 1,030 ppm, yaw
0.06 deg, and error/sigma std 1.6 and 1.5 over 50 runs without this term). No estimator can tell b from the
calibration along those directions, and none estimates b (a state per run would be degenerate with them): the
calibration's covariance is given b's share instead, Schmidt's consider covariance S Sigma_b S^T, where S is the
calibration's least-squares response to a constant b over the log's velocities,

    S = (sum_i A_i^T A_i / sigma_w^2 + P0^-1)^-1 sum_i A_i^T / sigma_w^2,    A_i = [w_i,  k [w_i]_x]   (3 x 4)

(sigma_w the ping's white sigma, P0 the calibration's prior: a direction no velocity excites, the roll on a
straight track, keeps its prior and takes none of b). Where the result holds the calibration at the nominal
(weak_hold.py: the nominal check, the weak directions), the held directions take none of it either: the nominal
is not moved by b. Written by hand: a 4 x 4 regression on the result's states, no library call does it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import skew
from gtsam_dvl.core.states import Estimate

# [scale, b_R_d right tangent] in calib_joint_cov and shared_joint_cov (states.py)
CALIBRATION = slice(6, 10)


def response(
    b_v: np.ndarray, k: float, b_R_d: np.ndarray, sigma_w: float, P0: np.ndarray
) -> np.ndarray:
    """S (4, 3): the [scale, b_R_d right tangent (rad)] that a constant velocity error (dvl_link, m/s) moves the
    calibration by, from the body velocities b_v (N, 3) m/s (module doc); P0 (4, 4) the calibration's prior."""
    w = np.asarray(b_v, dtype=float) @ np.asarray(b_R_d, dtype=float)  # (d_R_b u)^T = u^T b_R_d
    A = np.concatenate([w[:, :, None], k * skew(w).reshape(-1, 3, 3)], axis=2)  # (N, 3, 4)
    info = np.einsum("nji,njk->ik", A, A) / sigma_w**2 + np.linalg.inv(P0)
    return np.linalg.solve(info, A.sum(axis=0).T / sigma_w**2)


def _held_directions(result: NavResult, P0: np.ndarray) -> np.ndarray:
    """(4, m) the held directions in the prior-whitened calibration ([scale, rad] / L, L L^T = P0), orthonormal;
    all four when the calibration is held at the nominal."""
    hold = result.info.get("calibration_hold") or {}
    nominal = hold.get("nominal") or {}
    held = hold.get("held") or []
    if nominal.get("pays") is False or hold.get("reason") == "nominal_check":
        return np.eye(4)
    L = np.linalg.cholesky(P0)
    cols = []
    for h in held:
        if isinstance(h, dict) and isinstance(h.get("direction"), dict):
            d = h["direction"]
            v = np.array(
                [
                    d["scale"],
                    *np.radians(
                        [d["misalignment roll"], d["misalignment pitch"], d["misalignment yaw"]]
                    ),
                ]
            )
            cols.append(np.linalg.solve(L, v))
    if not cols:
        return np.zeros((4, 0))
    q, _ = np.linalg.qr(np.stack(cols, axis=1))
    return q


def consider_constant_error(
    result: NavResult, config: EstimatorConfig, file_prior: bool = False
) -> None:
    """Add the constant DVL error's share (module doc) to the result's scale and misalignment covariance (their
    Estimates, calib_joint_cov and shared_joint_cov), outside the held directions; recorded in
    info["dvl_constant_error"]. Nothing when [dvl] constant_error_sigma_m_s is 0, the result has no states, or
    file_prior: a vehicle calibration file is the prior, whose covariance (the earlier dives' posteriors, each with
    its own constant error's share) stands for it and which the data only tighten."""
    sigma_b = float(config.dvl.constant_error_sigma_m_s)
    if sigma_b <= 0.0 or file_prior or not len(result.t) or "scale" not in result.calibration:
        return
    pr = config.priors
    P0 = np.diag([pr.scale_sigma**2, *np.radians(pr.misalignment_sigma_deg) ** 2])
    b_v = np.einsum("nji,nj->ni", result.n_R_b, result.n_v)  # n_R_b^T n_v
    sigma_w = (config.dvl.noise_m_s or config.dvl.default_noise_m_s) * config.dvl.noise_multiplier
    S = response(b_v, result.scale, result.b_R_d, sigma_w, P0)
    added = sigma_b**2 * S @ S.T
    Q = _held_directions(result, P0)
    if Q.shape[1]:  # none of it along a held direction (whitened by the prior)
        L = np.linalg.cholesky(P0)
        proj = np.eye(4) - Q @ Q.T
        Li = np.linalg.inv(L)
        added = L @ proj @ (Li @ added @ Li.T) @ proj @ L.T
    added = 0.5 * (added + added.T)
    cal = result.calibration
    cal["scale"] = Estimate(cal["scale"].value, cal["scale"].cov + added[:1, :1])
    cal["misalignment"] = Estimate(
        cal["misalignment"].value, cal["misalignment"].cov + added[1:, 1:]
    )
    for name in ("calib_joint_cov", "shared_joint_cov"):
        joint = getattr(result, name)
        if joint is not None and np.shape(joint)[0] >= CALIBRATION.stop:
            joint = np.array(joint, dtype=float)
            joint[CALIBRATION, CALIBRATION] += added
            setattr(result, name, joint)
    report: dict[str, Any] = {
        "sigma_m_s": sigma_b,
        "scale_sigma_added": float(np.sqrt(added[0, 0])),
        "misalignment_sigma_added_deg": np.degrees(np.sqrt(np.diag(added)[1:])).tolist(),
        "held_directions": int(Q.shape[1]),
    }
    result.info["dvl_constant_error"] = report
