"""The new estimate against a vehicle's calibration file: has the vehicle's calibration moved since?

A run that took its prior from a calibration file (`smooth --calibration FILE`) records that prior in
result.info["calibration_prior"] (core/states.py calibration_info: the states that took it, the file's values and
joint covariance, inflated for the days since its date). Here the posterior of those states is compared with it.

The test. The prior is x ~ N(mu0, P0) (the file, inflated); the dive's data add information I, and the posterior
has mean mu1 and covariance P1 = (P0^-1 + I)^-1. If the vehicle's calibration is still the file's (within P0), the
shift d = mu1 - mu0 (the misalignment's as Log(R0^T R1), b_R_d's right tangent, as the file's covariance) is
Gaussian with covariance P0 - P1 (the Kalman update's K S K^T: the information this dive added), so

    chi^2 = d^T (P0 - P1)^+ d    with dof = the number of directions the dive informed

follows chi^2(dof). It is the innovation test of the dive's own estimate x_d against the file,
(x_d - mu0)^T (P0 + I^-1)^-1 (x_d - mu0), written with what the result holds. Testing d against P0 alone would be
too lenient: d's covariance P0 - P1 is smaller than P0, the more so the less the dive adds, and a dive that sees
little would never see a change. The directions the dive hardly informed (in P0's metric, the variance it removed
below INFORMED_FRACTION: a straight transect's yaw) carry no evidence either way; they are left out of the
pseudo-inverse and of dof. The dive is flagged when chi^2 exceeds the quantile of chi^2(dof) at the tail
probability of +- [calibration] moved_sigmas in one dimension (3: 0.27 % of consistent dives flagged).

Per state and tangent component, in words: z = d_i / sqrt((P0 - P1)_ii); beyond moved_sigmas "DVL scale moved
4.1 sigma since 2026-11-02 (+10000 ppm): remounted, or another sound-speed setting?"; a component the dive hardly
informed (under LITTLE_FRACTION of its variance removed) is "from the calibration", and not said to have moved
(its shift follows the others' through the file's correlations: the scale's drags a correlated yaw). The health
(analysis/health.py) takes the findings: "degraded" when the joint test rejects the file (the result leans on a
prior its data contradict: the estimates are pulled towards the file's), with a "warn" line per state that moved;
a "warn" alone for a state beyond moved_sigmas that the joint test does not reject (it has more directions to
spread its tail over); a note when it is consistent.

Pure computation on NavResult (analysis layer).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from scipy.special import (  # chi^2(k) tails (scipy.stats costs a second to import)
    gammaincc,
    gammainccinv,
)

from gtsam_dvl.core.calibration import config_hash
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import so3_log
from gtsam_dvl.core.states import BY_NAME, block_states, joint_states

# A direction the dive informed: it removed at least this fraction of the prior's variance there (P0 - P1 in P0's
# metric). Below it the shift there is numerical noise over a tiny variance, not evidence.
INFORMED_FRACTION = 0.02
# A component the dive added less than this fraction of its prior's variance to is named as "from the calibration"
# in the verdict (a straight transect's yaw).
LITTLE_FRACTION = 0.1

# what a move of each state suggests, for the verdict's words
CAUSES = {
    "scale": "remounted, or another sound-speed setting?",
    "misalignment": "the DVL remounted or knocked?",
    "time_offset": "another clock source, driver or DVL firmware?",
    "lever_arm": "the DVL moved on the vehicle, or /tf_static changed?",
}


@dataclass
class ComponentShift:
    """One tangent component of a state: the shift since the file (SI and display unit), its sigma (of what the
    dive could move it, sqrt((P0 - P1)_ii)), z and the fraction of the prior's variance the dive removed."""

    state: str  # "scale", "misalignment", ...
    name: str  # "scale", "misalignment_yaw", ...
    text: str  # "DVL scale factor", "DVL misalignment about body z (yaw)"
    shift: float
    shift_display: float
    unit: str
    sigma: float
    z: float
    informed: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "shift": self.shift_display,
            "unit": self.unit,
            "nsigma": self.z,
            "information_added": self.informed,
        }


@dataclass
class CalibrationCheck:
    """The verdict (module doc): the joint chi^2, its dof and threshold, whether the calibration moved, each
    component's shift and the findings (severity, text) for the health."""

    vehicle: str
    date: str
    chi2: float
    dof: int
    threshold: float
    p_value: float
    moved: bool
    components: list[ComponentShift] = field(default_factory=list)
    findings: list[tuple[str, str]] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {
            "vehicle": self.vehicle,
            "date": self.date,
            "chi2": self.chi2,
            "dof": self.dof,
            "threshold": self.threshold,
            "p_value": self.p_value,
            "moved": self.moved,
            "components": [c.as_dict() for c in self.components],
            "verdict": self.findings[0][1] if self.findings else "",
        }


class Findings(Protocol):
    """What takes the verdict: analysis/health.py's Health (its figures and flag)."""

    figures: dict[str, Any]

    def flag(self, severity: str, text: str) -> None: ...


def judge_calibration(result: NavResult, health: Findings) -> None:
    """The verdict into the health: its figures under "calibration_check" and its findings flagged; nothing for a
    run without a calibration prior."""
    check = check_calibration(result)
    if check is not None:
        health.figures["calibration_check"] = check.as_dict()
        for severity, text in check.findings:
            health.flag(severity, text)


def tail_probability(nsigma: float) -> float:
    """P(|z| > nsigma) for a standard normal z: the false-alarm rate of +- nsigma in one dimension."""
    return math.erfc(nsigma / math.sqrt(2.0))


def check_calibration(
    result: NavResult, config: EstimatorConfig | None = None
) -> CalibrationCheck | None:
    """The verdict on a run that took its prior from a calibration file (module doc); None for a run that did
    not. config: the run's (default: the one the result records)."""
    prior = result.info.get("calibration_prior")
    if not isinstance(prior, dict) or not prior.get("states"):
        return None
    config = config or result.estimator_config or EstimatorConfig()
    names = [n for n in prior["states"] if n in result.calibration]
    if not names:
        return None
    P0 = _block(np.asarray(prior["cov"], dtype=float), list(prior["states"]), names)
    P1 = _posterior(result, config, names)
    d = np.concatenate(
        [
            _shift(
                n,
                np.asarray(prior["values"][n], dtype=float),
                np.asarray(result.calibration[n].value, dtype=float),
            )
            for n in names
        ]
    )
    chi2, dof = _chi2(d, P0, P1)
    nsigma = config.calibration.moved_sigmas
    alpha = tail_probability(nsigma)
    # chi^2(dof)'s upper alpha point
    threshold = 2.0 * float(gammainccinv(0.5 * dof, alpha)) if dof else math.inf
    p_value = float(gammaincc(0.5 * dof, 0.5 * chi2)) if dof else 1.0  # P(chi^2(dof) > chi2)
    check = CalibrationCheck(
        str(prior.get("vehicle", "")),
        str(prior.get("date", "")),
        chi2,
        dof,
        threshold,
        p_value,
        bool(dof and chi2 > threshold),
        _components(names, d, P0, P1),
    )
    check.findings = _findings(check, nsigma)
    theirs, ours = prior.get("config_hash"), config_hash(getattr(result, "config", None) or {})
    # another model: a cause of a move
    if theirs and getattr(result, "config", None) and theirs != ours:
        check.findings.append(
            (
                "note",
                f"the calibration was made with another configuration (hash {theirs}; this "
                f"run's {ours}): a different noise or error model moves estimates too",
            )
        )
    return check


def _block(cov: np.ndarray, order: list[str], names: list[str]) -> np.ndarray:
    """The joint covariance of `names` out of one over `order` (each state's tangent columns)."""
    cols = _columns(order)
    idx = np.concatenate([cols[n] for n in names])
    return cov[np.ix_(idx, idx)]


def _posterior(result: NavResult, config: EstimatorConfig, names: list[str]) -> np.ndarray:
    """The posterior joint covariance of `names`: from shared_joint_cov (its states as analysis/geometry.py finds
    them) when it holds them all, else each state's marginal with the calibration block's (scale, misalignment)
    joint over those it holds (the online estimator's), without the correlations no block gives."""
    if result.shared_joint_cov is not None:
        cov = np.asarray(result.shared_joint_cov, dtype=float)
        for states in (joint_states(config), joint_states(config, ekf=True)):
            order = [s.name for s in states]
            if sum(s.dim for s in states) == cov.shape[0] and all(n in order for n in names):
                return _block(cov, order, names)
    dims = [BY_NAME[n].dim for n in names]
    out = np.zeros((sum(dims), sum(dims)))
    col = 0
    for n, dim in zip(names, dims, strict=True):
        out[col : col + dim, col : col + dim] = np.asarray(result.calibration[n].cov, dtype=float)
        col += dim
    if result.calib_joint_cov is not None:
        order = [s.name for s in block_states()]
        shared = [n for n in names if n in order]
        idx = np.concatenate([_columns(names)[n] for n in shared])
        out[np.ix_(idx, idx)] = _block(
            np.asarray(result.calib_joint_cov, dtype=float), order, shared
        )
    return out


def _columns(order: list[str]) -> dict[str, np.ndarray]:
    """Each state's columns in a covariance over `order`."""
    start, cols = 0, {}
    for n in order:
        cols[n] = np.arange(start, start + BY_NAME[n].dim)
        start += BY_NAME[n].dim
    return cols


def _shift(name: str, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """after - before in the state's tangent (the rotation's Log(R0^T R1), b_R_d's right perturbation)."""
    if BY_NAME[name].kind == "rot3":
        return np.asarray(so3_log(before.T @ after), dtype=float).reshape(3)
    return (after - before).reshape(BY_NAME[name].dim)


def _chi2(d: np.ndarray, P0: np.ndarray, P1: np.ndarray) -> tuple[float, int]:
    """d^T (P0 - P1)^+ d over the directions the dive informed (module doc), and their number."""
    L = np.linalg.cholesky(P0)
    Li = np.linalg.inv(L)
    # P0 - P1 in P0's metric: eigenvalues = fraction of the variance removed
    W = Li @ (P0 - P1) @ Li.T
    lam, U = np.linalg.eigh(0.5 * (W + W.T))
    keep = lam > INFORMED_FRACTION
    y = U[:, keep].T @ (Li @ d)
    return float(np.sum(y**2 / lam[keep])), int(keep.sum())


def _components(
    names: list[str], d: np.ndarray, P0: np.ndarray, P1: np.ndarray
) -> list[ComponentShift]:
    out = []
    col = 0
    for n in names:
        s = BY_NAME[n]
        for name, text in zip(s.component_names(), s.component_texts(), strict=True):
            removed = max(float(P0[col, col] - P1[col, col]), 0.0)
            sigma = math.sqrt(removed)
            informed = removed / float(P0[col, col])
            z = float(d[col] / sigma) if informed > INFORMED_FRACTION else 0.0
            out.append(
                ComponentShift(
                    n,
                    name,
                    text,
                    float(d[col]),
                    float(d[col] * s.to_display),
                    s.display_unit,
                    sigma,
                    z,
                    informed,
                )
            )
            col += 1
    return out


def _amount(c: ComponentShift) -> str:
    return f"{c.shift_display:+,.0f} ppm" if c.unit == "ppm" else f"{c.shift_display:+.3g} {c.unit}"


def _findings(check: CalibrationCheck, nsigma: float) -> list[tuple[str, str]]:
    """The verdict as sentences (module doc): when the joint test rejects the file, "degraded" with a "warn" per
    component that moved (or one for the block when none alone did); a component beyond nsigma that the joint test
    does not reject, a "warn" that says so; else one note."""
    since = f"since {check.date[:10]}" if check.date else "since the calibration"
    whose = f"{check.vehicle}'s calibration" if check.vehicle else "the calibration file"
    # a component the dive hardly informed only follows the others through the file's correlations: not named
    moved = [c for c in check.components if abs(c.z) > nsigma and c.informed >= LITTLE_FRACTION]
    joint = f"chi^2 {check.chi2:.1f} over {check.dof} informed directions, threshold {check.threshold:.1f}"
    out: list[tuple[str, str]] = []
    for c in moved:
        out.append(
            (
                "warn",
                f"{c.text} moved {abs(c.z):.1f} sigma {since} ({_amount(c)}): {CAUSES.get(c.state, '')}"
                + ("" if check.moved else f" (the joint test does not reject the file: {joint})"),
            )
        )
    if check.moved and not moved:
        out.append(
            (
                "warn",
                f"the calibration moved {since} ({joint}), no single state beyond {nsigma:g} sigma",
            )
        )
    if check.moved:
        out.insert(
            0,
            (
                "degraded",
                f"{whose} no longer fits this dive (chi^2 {check.chi2:.1f}, {check.dof} dof, "
                f"p = {check.p_value:.2g}): this result leans on it; if the change is real, "
                "smooth again without --calibration (and write the new one with "
                "--calibration-out)",
            ),
        )
    if out:
        return out
    held = [c.text for c in check.components if c.informed < LITTLE_FRACTION]
    note = (
        f"consistent with {whose} of {check.date[:10] or 'unknown date'} (chi^2 {check.chi2:.1f}, "
        f"{check.dof} dof, p = {check.p_value:.2g})"
    )
    if held:
        note += (
            f"; from the calibration (this dive removed under {LITTLE_FRACTION:.0%} of its variance): "
            + ", ".join(held)
        )
    return [("note", note)]
