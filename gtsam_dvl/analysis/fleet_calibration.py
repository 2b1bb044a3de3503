"""Each dive of a calibration against the joint calibration: did a dive's DVL calibration move?

For every dive, its estimate alone (smoothed with the priors: x_d, covariance S_d) is compared with the joint
calibration of all dives (x_J, S_J), which holds that dive. When every dive sees the same calibration, the joint
estimate is the efficient combination of the dives, and cov(x_d - x_J) = S_d - S_J (the covariance of an
efficient estimator with any other unbiased one is its own; the priors are in both once). Per state (the scale;
the misalignment, three components)

    chi^2 = r^T (S_d - S_J)^-1 r,   r = x_d - x_J   (the misalignment: Log(b_R_d,J^T b_R_d,d), right tangent)

is chi^2 with the state's dimension as degrees of freedom; it is also given as the number of sigmas of one normal
variable with the same tail probability (n_sigma: for the scale, |r| / sqrt(sigma_d^2 - sigma_J^2)). A state
"moved beyond 3 sigma" when n_sigma > 3 (probability 0.27 % for a dive that did not move, per state); a dive moved
when one of its states did. The whole block's chi^2 is given too. Directions the dive did not inform (S_d - S_J
with a tiny eigenvalue against S_d: the dive added nothing there, e.g. a straight transect's yaw misalignment)
are left out (a pseudo-inverse), with the degrees of freedom they would have had.

Pure computation (analysis layer); the table and figure are app/campaign/calibrate.py's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm

from gtsam_dvl.core.rotations import so3_log
from gtsam_dvl.core.states import BY_NAME, Estimate

NSIGMA = 3.0  # a state moved when its chi^2 is beyond this many sigmas (tail probability of one normal variable)
INFORMED = 1e-6  # an eigenvalue of (S_d - S_J) below this fraction of S_d's: a direction the dive did not inform


@dataclass
class StateMove:
    """One state of a dive against the joint: chi^2 over its informed directions, their number, the equivalent
    number of sigmas of one normal variable, and the residual in the display unit (misalignment: degrees about
    body axes, scale: ppm)."""

    name: str
    chi2: float
    dof: int
    n_sigma: float
    residual_display: np.ndarray

    @property
    def moved(self) -> bool:
        return self.n_sigma > NSIGMA


@dataclass
class DiveVsJoint:
    """One dive alone against the joint calibration (module doc)."""

    name: str
    residual: np.ndarray  # x_d - x_J in the block's tangent, SI, `states` order
    chi2: float  # over the whole block
    dof: int
    states: dict[str, StateMove] = field(default_factory=dict)

    @property
    def moved(self) -> bool:
        return any(m.moved for m in self.states.values())

    def moved_states(self) -> list[str]:
        return [n for n, m in self.states.items() if m.moved]

    @property
    def n_sigma(self) -> float:
        """The block's chi^2 as sigmas of one normal variable."""
        return _n_sigma(self.chi2, self.dof)


def _n_sigma(chi2: float, dof: int) -> float:
    if dof == 0:
        return 0.0
    return float(norm.isf(0.5 * chi2_dist.sf(chi2, dof)))


def _chi2(r: np.ndarray, D: np.ndarray, Sd: np.ndarray) -> tuple[float, int]:
    """r^T D^+ r over the directions D informs (relative to Sd's scale), and their number."""
    s = np.sqrt(np.diag(Sd))
    w, U = np.linalg.eigh(0.5 * (D + D.T) / np.outer(s, s))
    keep = w > INFORMED
    proj = U[:, keep].T @ (r / s)
    return float(np.sum(proj**2 / w[keep])), int(keep.sum())


def block_residual(
    states: Sequence[str], alone: dict[str, Estimate], joint: dict[str, Estimate]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """r = x_d - x_J over the states (the misalignment's in b_R_d,J's right tangent), S_d and S_J from the
    per-state marginals (block-diagonal)."""
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
        out[col : col + b.shape[0], col : col + b.shape[0]] = b
        col += b.shape[0]
    return out


def dive_vs_joint(
    name: str,
    states: Sequence[str],
    alone: dict[str, Estimate],
    joint: dict[str, Estimate],
    alone_cov: np.ndarray | None = None,
    joint_cov: np.ndarray | None = None,
) -> DiveVsJoint:
    """The comparison of one dive with the joint calibration (module doc). alone_cov / joint_cov: the joint
    covariances over the block (else the per-state marginals, block-diagonal)."""
    r, Sd, Sj = block_residual(states, alone, joint)
    Sd = Sd if alone_cov is None else np.asarray(alone_cov, dtype=float)
    Sj = Sj if joint_cov is None else np.asarray(joint_cov, dtype=float)
    chi2, dof = _chi2(r, Sd - Sj, Sd)
    out = DiveVsJoint(name, r, chi2, dof)
    col = 0
    for n in states:
        st = BY_NAME[n]
        sl = slice(col, col + st.dim)
        col += st.dim
        c, k = _chi2(r[sl], (Sd - Sj)[sl, sl], Sd[sl, sl])
        display = st.to_display * (
            np.asarray(joint[n].value) @ r[sl] if st.kind == "rot3" else r[sl]
        )
        out.states[n] = StateMove(n, c, k, _n_sigma(c, k), np.asarray(display, dtype=float))
    return out
