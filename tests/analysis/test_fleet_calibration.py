"""Each dive against the joint calibration (analysis/fleet_calibration.py): on linear Gaussian dives built here,
the per-state chi^2 with S_d - S_J is chi^2 distributed when no dive moved, and a dive whose scale moved is named."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.analysis.fleet_calibration import dive_vs_joint
from gtsam_dvl.core.rotations import so3_exp
from gtsam_dvl.core.states import Estimate

STATES = ["scale", "misalignment"]


def _estimates(x: np.ndarray, cov: np.ndarray) -> dict[str, Estimate]:
    """[scale, misalignment tangent] as Estimates (the misalignment as b_R_d = Exp(x[1:]), right tangent)."""
    return {
        "scale": Estimate(np.array([x[0]]), cov[:1, :1]),
        "misalignment": Estimate(so3_exp(x[1:]), cov[1:, 1:]),
    }


def _fleet(
    rng: np.random.Generator, infos: list[np.ndarray], shift: np.ndarray | None = None
) -> tuple[list[tuple[np.ndarray, np.ndarray]], tuple[np.ndarray, np.ndarray]]:
    """Dives with informations infos about a true x (scale 1, misalignment 1e-3 rad), a shared prior; the last dive
    measures x + shift. Returns each dive alone (x_d, S_d) and the joint (x_J, S_J), information-weighted."""
    x_true = np.array([1.0, 1e-3, -2e-3, 5e-3])
    P = np.diag([1e-2, 1e-2, 1e-2, 1e-2]) ** 2
    Pi = np.linalg.inv(P)
    x0 = x_true + rng.multivariate_normal(np.zeros(4), P)
    ys = [x_true + rng.multivariate_normal(np.zeros(4), np.linalg.inv(info)) for info in infos]
    if shift is not None:
        ys[-1] = ys[-1] + shift
    alone = []
    for info, y in zip(infos, ys, strict=True):
        S = np.linalg.inv(Pi + info)
        alone.append((S @ (Pi @ x0 + info @ y), S))
    SJ = np.linalg.inv(Pi + sum(infos))
    return alone, (SJ @ (Pi @ x0 + sum(i @ y for i, y in zip(infos, ys, strict=True))), SJ)


def _infos(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    out = []
    for _ in range(n):
        # scale ~1e-3, angles ~2e-4 rad
        A = rng.normal(size=(6, 4)) * np.array([1e3, 1e3, 5e3, 5e3])
        out.append(A.T @ A)
    return out


def test_chi2_of_dives_that_did_not_move_is_chi2_distributed() -> None:
    rng = np.random.default_rng(3)
    infos = _infos(rng, 4)
    chi2 = {"scale": [], "misalignment": []}
    moved = 0
    for _ in range(150):
        alone, (xJ, SJ) = _fleet(rng, infos)
        joint = _estimates(xJ, SJ)
        for k, (x, S) in enumerate(alone):
            c = dive_vs_joint(f"d{k}", STATES, _estimates(x, S), joint, S, SJ)
            chi2["scale"].append(c.states["scale"].chi2)
            chi2["misalignment"].append(c.states["misalignment"].chi2)
            assert c.states["scale"].dof == 1 and c.states["misalignment"].dof == 3
            moved += c.moved
    assert abs(np.mean(chi2["scale"]) - 1.0) < 0.2
    assert abs(np.mean(chi2["misalignment"]) - 3.0) < 0.4
    assert moved / 600 < 0.03  # 2 x 0.27 % expected


def test_a_dive_whose_scale_moved_is_named() -> None:
    rng = np.random.default_rng(5)
    infos = _infos(rng, 4)
    shift = 8 * np.sqrt(np.linalg.inv(infos[-1])[0, 0])  # 8 sigma of the last dive's scale
    alone, (xJ, SJ) = _fleet(rng, infos, shift=np.array([shift, 0.0, 0.0, 0.0]))
    joint = _estimates(xJ, SJ)
    comps = [
        dive_vs_joint(f"d{k}", STATES, _estimates(x, S), joint, S, SJ)
        for k, (x, S) in enumerate(alone)
    ]
    assert comps[-1].moved_states() == ["scale"]
    assert comps[-1].states["scale"].n_sigma > 4
    # in the display unit (ppm): most of the shift (the joint moved by a part of it)
    assert 0.4 * shift * 1e6 < comps[-1].states["scale"].residual_display[0] < shift * 1e6
    assert not comps[-1].states["misalignment"].moved  # not shifted
    # the others' scales sit on the other side of the joint, nearer it
    assert all(c.states["scale"].residual_display[0] < 0 for c in comps[:-1])
    assert max(c.states["scale"].n_sigma for c in comps[:-1]) < comps[-1].states["scale"].n_sigma
