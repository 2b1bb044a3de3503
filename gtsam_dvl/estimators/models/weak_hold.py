"""Weakly determined DVL calibration directions held at their prior ([priors] hold_weak_information, batch).

A run that excites the calibration little (a straight transect: the yaw misalignment; a steady turn: the scale,
which trades with the horizontal accelerometer bias) still moves the estimate: in a direction whose data carry the
information lambda (in units of its prior's), the estimate's shift from the prior's mean has the standard deviation
sqrt(lambda / (1 + lambda)) prior sigmas, while the sigma hardly shrinks (1 / sqrt(1 + lambda)). When the truth is
near the prior's mean (a DVL mounted as drawn, a scale the factory set), that shift is pure error: the
calibration wanders, and a filter that assumes the nominal calibration ends closer. Holding such directions at the
prior's mean is what an engineer does by hand ("do not calibrate what the run cannot see"). This module does it
for the DVL's scale and misalignment, with sigmas that stay honest:

- In the prior-whitened calibration u = L0^-1 (theta - theta0) (P0 = L0 L0^T the prior's covariance of
  theta = [scale, misalignment in b_R_d's right tangent at the prior's mean]), the posterior covariance
  M = L0^-1 P1 L0^-T has eigen-directions v_k with M v_k = v_k / (1 + lambda_k): lambda_k is the data's
  information along v_k. Those with lambda_k < hold_weak_information are weak.
- The held estimate solves the graph with the weak directions' whitened components pinned at 0 (a factor of
  sigma 1e-4 prior sigmas): the navigation and the other calibration directions follow.
- Its covariance is the "consider" covariance of the held estimate (the weak directions' prior uncertainty carried
  into every state, their data not used): the marginals of the graph whose calibration prior has the precision
  1 - lambda_k along each weak v_k (and 1 elsewhere, whitened), linearised at the held estimate. Along v_k the
  posterior then has precision (1 - lambda_k) + lambda_k = 1: the prior's, and every other state's covariance
  gains the weak direction's full prior uncertainty through its sensitivity to it (the Schur complement).

The chi^2 increase of the held solution over the free one is reported: a large one (beyond the chi^2 of the weak
directions' dimension) says the data disagree with the prior along a direction they inform little, and the result
says so. Not applied with a vehicle calibration file as prior (its covariance is already the previous dives'
posterior), nor by the online estimator or the EKF, which cannot know while running which directions the rest of
the log will inform.
"""

from __future__ import annotations

import math
from typing import Any

import gtsam
import numpy as np
from scipy.stats import chi2

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, key_dim
from gtsam_dvl.core.states import BY_NAME, block_states, columns, shared_keys
from gtsam_dvl.core.summary import (
    DIRECTION_NAMES,
    CalibrationHold,
    HeldDirection,
    HoldReason,
    NominalCheck,
    hold_why,
)
from gtsam_dvl.core.types import Mounting

HOLD_SIGMA = 1e-4  # the pinned directions' sigma, in prior sigmas (a constraint, to within 1e-4 of a prior sigma)


def calibration_prior(
    config: EstimatorConfig, mounting: Mounting
) -> tuple[float, np.ndarray, np.ndarray]:
    """(k0, b_R_d0, P0): the scale's and misalignment's prior means and their joint covariance (4, 4) over
    [scale, misalignment right tangent] (the registry's priors, core/states.py)."""
    ks, mis = (
        BY_NAME["scale"].prior(config, mounting),
        BY_NAME["misalignment"].prior(config, mounting),
    )
    P0 = np.zeros((4, 4))
    P0[:1, :1], P0[1:, 1:] = ks.cov, mis.cov
    return float(np.asarray(ks.value).reshape(-1)[0]), np.asarray(mis.value, dtype=float), P0


def weak_directions(
    P0: np.ndarray, P1: np.ndarray, below: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lambda (n,), V (n, n) columns v_k, weak (n,) bool) of the posterior P1 against the prior P0 (module doc)."""
    L0 = np.linalg.cholesky(P0)
    Li = np.linalg.inv(L0)
    M = Li @ P1 @ Li.T
    mu, V = np.linalg.eigh(0.5 * (M + M.T))
    lam = 1.0 / np.clip(mu, 1e-300, None) - 1.0
    return lam, V, lam < below


def _tangent(values: gtsam.Values, k0: float, b_R_d0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """theta - theta0 (4,) and its Jacobian (4, 4) w.r.t. [scale, misalignment right perturbation]."""
    R = values.atRot3(C_MISALIGN)
    phi = gtsam.Rot3.Logmap(gtsam.Rot3(b_R_d0).between(R))
    J = np.eye(4)
    J[1:, 1:] = gtsam.Rot3.LogmapDerivative(phi)  # d Log(R0^T R Exp(d)) / d d at d = 0
    return np.r_[values.atVector(K_SCALE)[0] - k0, phi], J


def _linear_factor(A: np.ndarray, k0: float, b_R_d0: np.ndarray) -> gtsam.CustomFactor:
    """A factor on [K_SCALE, C_MISALIGN] of whitened residual A (theta - theta0) (A: (m, 4))."""

    def error(
        _: gtsam.CustomFactor, values: gtsam.Values, H: list[np.ndarray] | None
    ) -> np.ndarray:
        d, J = _tangent(values, k0, b_R_d0)
        if H is not None:
            AJ = A @ J
            H[0], H[1] = AJ[:, :1].copy(), AJ[:, 1:].copy()
        return A @ d

    return gtsam.CustomFactor(
        gtsam.noiseModel.Unit.Create(A.shape[0]), [K_SCALE, C_MISALIGN], error
    )


def prior_slots(graph: gtsam.NonlinearFactorGraph) -> list[int]:
    """The slots of the scale's and the misalignment's own prior factors (a factor on that key alone)."""
    out = []
    for j in range(graph.size()):
        f = graph.at(j)
        if f is not None and list(f.keys()) in ([K_SCALE], [C_MISALIGN]):
            out.append(j)
    return out


def _directions(
    config: EstimatorConfig, mounting: Mounting, keys: list[int], cov: np.ndarray
) -> dict[str, Any] | None:
    """The plan of a joint covariance cov over the stacked tangents of keys (the prior, the whitened eigen-
    directions and which are weak, the threshold, the scale's and misalignment's columns idx in cov): None when
    holding does not apply (off, or the scale or misalignment not among keys)."""
    below = config.priors.hold_weak_information
    cols = columns(keys, config)
    if below <= 0 or "scale" not in cols or "misalignment" not in cols:
        return None
    idx = np.r_[
        np.arange(cols["scale"].start, cols["scale"].stop),
        np.arange(cols["misalignment"].start, cols["misalignment"].stop),
    ]
    k0, b_R_d0, P0 = calibration_prior(config, mounting)
    lam, V, weak = weak_directions(P0, cov[np.ix_(idx, idx)], below)
    return {
        "k0": k0,
        "b_R_d0": b_R_d0,
        "P0": P0,
        "lambda": lam,
        "V": V,
        "weak": weak,
        "below": below,
        "idx": idx,
    }


def plan(
    config: EstimatorConfig,
    mounting: Mounting,
    calib_joint_cov: np.ndarray,
    n_last: int,
) -> dict[str, Any] | None:
    """The weak directions of a batch result (its calibration block's joint covariance at the last state n_last):
    None when holding does not apply."""
    return _directions(config, mounting, shared_keys(config, n_last, block=True), calib_joint_cov)


def hold_factor(p: dict[str, Any]) -> gtsam.CustomFactor:
    """The weak directions' whitened components pinned at 0 (module doc)."""
    Li = np.linalg.inv(np.linalg.cholesky(p["P0"]))
    return _linear_factor(p["V"][:, p["weak"]].T @ Li / HOLD_SIGMA, p["k0"], p["b_R_d0"])


def consider_prior(p: dict[str, Any]) -> gtsam.CustomFactor:
    """The calibration prior with the precision 1 - lambda_k along each weak direction (whitened; module doc):
    replaces the scale's and misalignment's own priors for the held estimate's marginals."""
    Li = np.linalg.inv(np.linalg.cholesky(p["P0"]))
    V, lam, weak = p["V"], p["lambda"], p["weak"]
    prec = np.eye(4) - V[:, weak] @ np.diag(np.clip(lam[weak], 0.0, 1.0 - 1e-9)) @ V[:, weak].T
    U = np.linalg.cholesky(prec).T  # U^T U = prec
    return _linear_factor(U @ Li, p["k0"], p["b_R_d0"])


def _direction(p: dict[str, Any], k: int) -> HeldDirection:
    """Eigen-direction k of the plan p: one prior sigma along v_k in the calibration's units (scale; misalignment
    deg), the data's information along it and its largest component in prior sigmas."""
    v = np.linalg.cholesky(p["P0"]) @ p["V"][:, k]  # [scale, rad]
    return HeldDirection(
        mostly=DIRECTION_NAMES[int(np.argmax(np.abs(p["V"][:, k])))],
        information=float(p["lambda"][k]),
        direction={
            n: float(x)
            for n, x in zip(DIRECTION_NAMES, np.r_[v[0], np.degrees(v[1:])], strict=True)
        },
    )


def report(
    p: dict[str, Any],
    chi2_increase: float,
    why: str | None = None,
    released: bool = False,
) -> dict[str, Any]:
    """NavResult.info["calibration_hold"] in its one shape (core/summary.py CalibrationHold): each weak direction
    of the plan p held (released: listed as released, nothing held), every direction's information (in prior
    units), the threshold, p["nominal"] (the nominal calibration's check, when made) and, when chi2_increase is
    finite, what pinning cost against its 99 % limit. The reason: "nominal_check" when the check did not pay and
    every direction is held, "weak_directions" when some are held, else "none"; why: the words, by default
    core/summary.py hold_why's."""
    weak = np.asarray(p["weak"], dtype=bool)
    directions = [_direction(p, int(k)) for k in np.flatnonzero(weak)]
    held = [] if released else directions
    nominal = NominalCheck.model_validate(p["nominal"]) if "nominal" in p else None
    reason: HoldReason = "none"
    if held:
        everything = nominal is not None and not nominal.pays and bool(weak.all())
        reason = "nominal_check" if everything else "weak_directions"
    limit = float(chi2.ppf(0.99, len(directions))) if directions else 0.0
    solved = bool(np.isfinite(chi2_increase))
    increase = float(chi2_increase) if solved else None
    limit_99 = limit if solved else None
    return CalibrationHold(
        reason=reason,
        why=why or hold_why(reason, held, float(p["below"]), nominal, increase, limit_99),
        held=held,
        released=directions if released else [],
        threshold=float(p["below"]),
        information=[float(x) for x in p["lambda"]],
        nominal=nominal,
        chi2_increase=increase,
        chi2_limit_99=limit_99,
        consistent=bool(chi2_increase <= limit) if solved else None,
    ).model_dump()


def filter_nominal_hold(
    config: EstimatorConfig, mounting: Mounting, calib_joint_cov: np.ndarray, check: dict[str, Any]
) -> dict[str, Any]:
    """info["calibration_hold"] of the EKF's nominal calibration check (nominal_check; estimators/ekf/filter.py) in
    the one shape: the eigen-directions of the filtered calibration's covariance against its prior (calib_joint_cov,
    the free filter's [accel bias, gyro bias, scale, misalignment] block, core/states.py block_states), each with
    the data's information along it; all of them held when the check did not pay (the log filtered again with the
    scale and misalignment as consider states), none when it paid (the EKF holds no weak direction)."""
    gain, limit, level = check["chi2_gain"], check["chi2_limit"], check["level"]
    if check["pays"]:
        why = (
            f"nothing held: the filtered calibration's chi^2 gain over the nominal is {gain:.1f}, more than "
            f"{limit:.1f} ({level:.0%} of chi^2 with 4 dof): estimating the DVL scale and misalignment pays for its "
            "four states (the EKF holds no weak direction)"
        )
    else:
        why = (
            f"held at the nominal calibration: the filtered calibration's chi^2 gain over the nominal is {gain:.1f}, "
            f"not more than {limit:.1f} ({level:.0%} of chi^2 with 4 dof); filtered again with the scale and "
            "misalignment as consider states (their prior's sigma)"
        )
    cols, start = {}, 0
    for state in block_states():
        cols[state.name], start = np.arange(start, start + state.dim), start + state.dim
    idx = np.r_[cols["scale"], cols["misalignment"]]
    _, _, P0 = calibration_prior(config, mounting)
    below = config.priors.hold_weak_information
    P = np.asarray(calib_joint_cov, dtype=float)[np.ix_(idx, idx)]
    if np.all(np.isfinite(P)):
        lam, V, _ = weak_directions(P0, P, below)
    else:  # a filter whose covariance is not finite: the prior's axes, their information unknown
        lam, V = np.full(4, np.nan), np.eye(4)
    held = not check["pays"]
    p = {
        "P0": P0,
        "lambda": lam,
        "V": V,
        "weak": np.full(4, held),
        "below": below,
        "nominal": check,
    }
    return report(p, math.nan, why=why)


# Estimating the DVL scale and misalignment pays for its four states when it lowers the chi^2 by more than this
# quantile of chi^2(4) against the nominal (scale 1, the mounting's misalignment: the prior's mean); else the
# calibration is held at the nominal with its prior's sigma (the batch smoother by a pinned solve, a filter's
# reported estimate by hold_joint).
NOMINAL_LEVEL = 0.95


def nominal_check(d: np.ndarray, P: np.ndarray) -> dict[str, Any]:
    """The chi^2 gain of the estimated calibration over the nominal, d' P^-1 d (d the estimate's tangent from the
    prior's mean, P its marginal covariance: the likelihood ratio to first order), against NOMINAL_LEVEL's quantile
    of chi^2 with len(d) degrees of freedom."""
    gain = float(d @ np.linalg.solve(P, d))
    limit = float(chi2.ppf(NOMINAL_LEVEL, len(d)))
    return {
        "chi2_gain": gain,
        "chi2_limit": limit,
        "level": NOMINAL_LEVEL,
        "pays": bool(gain > limit),
    }


def hold_joint(
    config: EstimatorConfig,
    mounting: Mounting,
    values: gtsam.Values,
    keys: list[int],
    cov: np.ndarray,
) -> tuple[gtsam.Values, np.ndarray, dict[str, Any]] | None:
    """The weak directions held in one joint estimate (a filter's newest state with the shared states: values
    over keys, cov their stacked tangents' joint covariance), to first order: the calibration moved to its held
    value theta_h, every other component by its regression on the calibration (K = P_x,theta P_theta^-1), and the
    covariance with the calibration's marginal replaced by the held one (the prior's along the weak directions:
    the consider covariance, module doc). None when nothing is held (off, or no weak direction)."""
    p = _directions(config, mounting, keys, cov) if np.all(np.isfinite(cov)) else None
    if p is None:
        return None
    idx = p["idx"]
    P_tt = cov[np.ix_(idx, idx)]
    d, _ = _tangent(values, p["k0"], p["b_R_d0"])
    if config.priors.nominal_check:
        p["nominal"] = nominal_check(d, P_tt)
        if not p["nominal"]["pays"]:  # the nominal calibration's check: every direction held
            p["weak"] = np.ones_like(p["weak"])
    if not p["weak"].any():
        return None
    lam, V, weak = p["lambda"], p["V"], p["weak"]
    L0 = np.linalg.cholesky(p["P0"])
    u = np.linalg.solve(L0, d)
    # to the prior's mean along the weak directions
    d_theta = L0 @ (-V[:, weak] @ (V[:, weak].T @ u))
    K = np.linalg.solve(P_tt, cov[idx, :]).T  # (n, 4)
    c = np.where(weak, 1.0, 1.0 / (1.0 + lam))  # the held calibration's whitened variances
    C = L0 @ V @ np.diag(c) @ V.T @ L0.T
    cov_h = cov - K @ P_tt @ K.T + K @ C @ K.T
    dx = K @ d_theta
    delta = gtsam.VectorValues()
    col = 0
    for k in keys:
        n = key_dim(k)
        delta.insert(k, dx[col : col + n])
        col += n
    return values.retract(delta), 0.5 * (cov_h + cov_h.T), p
