"""Each dive of a calibration against the joint calibration: did a dive's DVL calibration move?

For every dive, its estimate alone (smoothed with the priors: x_d, covariance S_d) is compared with the joint
calibration of all dives (x_J, S_J), which holds that dive. When every dive sees the same calibration, the joint
estimate is the efficient combination of the dives, and cov(x_d - x_J) = S_d - S_J (the covariance of an
efficient estimator with any other unbiased one is its own). So over the shared block

    chi^2_d = r^T (S_d - S_J)^-1 r,   r = x_d - x_J   (the misalignment: Log(b_R_d,J^T b_R_d,d), right tangent)

is chi^2 with n degrees of freedom (n the block's dimension); per tangent component z_i = r_i / sqrt(S_d,ii -
S_J,ii). A dive "moved beyond 3 sigma" when chi^2_d exceeds the chi^2 quantile of the two-sided 3-sigma
probability (0.9973: 14.2 for n = 4), the block test, so that a direction the dive did not determine (S_d,ii
close to its prior) cannot raise it alone; the components beyond 3 in |z| are named. Directions the dive did not
inform (S_d - S_J with a tiny or negative eigenvalue) are left out of the test (a pseudo-inverse).

Pure computation (analysis layer); the table and figure are app/campaign/calibrate.py's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_dist

from gtsam_dvl.core.rotations import so3_log
from gtsam_dvl.core.states import BY_NAME, Estimate

MOVED_PROBABILITY = 0.9973  # two-sided 3 sigma of a normal variable
NSIGMA = 3.0


@dataclass
class DiveVsJoint:
    """One dive alone against the joint calibration (module doc)."""

    name: str
    residual: np.ndarray  # x_d - x_J in the block's tangent, SI, `states` order
    chi2: float
    dof: int  # the directions the dive informed
    threshold: float  # chi^2 quantile at MOVED_PROBABILITY for dof
    z: np.ndarray  # per component r_i / sqrt(S_d,ii - S_J,ii) (nan where the dive added nothing)
    components: list[str] = field(default_factory=list)

    @property
    def moved(self) -> bool:
        return self.dof > 0 and self.chi2 > self.threshold

    def beyond(self) -> list[str]:
        """The components beyond NSIGMA in |z|."""
        return [c for c, z in zip(self.components, self.z, strict=True) if np.isfinite(z) and abs(z) > NSIGMA]


def block_residual(states: Sequence[str], alone: dict[str, Estimate], joint: dict[str, Estimate]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r = x_d - x_J over the states (the misalignment's in b_R_d,J's right tangent), S_d (block-diagonal from the
    per-state marginals when no joint block is given) and S_J's diagonal blocks (likewise)."""
    parts, Sd, Sj = [], [], []
    for n in states:
        a, j = alone[n], joint[n]
        if BY_NAME[n].kind == "rot3":
            parts.append(so3_log(np.asarray(j.value).T @ np.asarray(a.value)))
        else:
            parts.append(np.asarray(a.value, dtype=float) - np.asarray(j.value, dtype=float))
        Sd.append(np.asarray(a.cov, dtype=float))
        Sj.append(np.asarray(j.cov, dtype=float))
    return np.concatenate(parts), _block_diag(Sd), _block_diag(Sj)


def _block_diag(blocks: list[np.ndarray]) -> np.ndarray:
    n = sum(b.shape[0] for b in blocks)
    out = np.zeros((n, n))
    col = 0
    for b in blocks:
        out[col:col + b.shape[0], col:col + b.shape[0]] = b
        col += b.shape[0]
    return out


def dive_vs_joint(name: str, states: Sequence[str], alone: dict[str, Estimate], joint: dict[str, Estimate],
                  alone_cov: np.ndarray | None = None, joint_cov: np.ndarray | None = None) -> DiveVsJoint:
    """The comparison of one dive with the joint calibration (module doc). alone_cov / joint_cov: the joint
    covariances over the block (else the per-state marginals, block-diagonal)."""
    r, Sd, Sj = block_residual(states, alone, joint)
    Sd = Sd if alone_cov is None else np.asarray(alone_cov, dtype=float)
    Sj = Sj if joint_cov is None else np.asarray(joint_cov, dtype=float)
    D = 0.5 * ((Sd - Sj) + (Sd - Sj).T)
    # scale each component by the dive's own sigma, so that the eigenvalue threshold is relative
    s = np.sqrt(np.diag(Sd))
    Dn = D / np.outer(s, s)
    w, U = np.linalg.eigh(Dn)
    keep = w > 1e-6
    rn = r / s
    proj = U[:, keep].T @ rn
    chi2 = float(np.sum(proj**2 / w[keep]))
    dof = int(keep.sum())
    diag = np.diag(D)
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where(diag > 1e-6 * s**2, r / np.sqrt(np.where(diag > 0, diag, 1.0)), np.nan)
    threshold = float(chi2_dist.ppf(MOVED_PROBABILITY, dof)) if dof else float("inf")
    components = [c for n in states for c in BY_NAME[n].component_names()]
    return DiveVsJoint(name, r, chi2, dof, threshold, z, components)
