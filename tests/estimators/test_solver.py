"""The QR Gauss-Newton loop and the Bayes-net marginals against independent dense computations."""

import gtsam
import numpy as np
import pytest

from gtsam_dvl.estimators.graph.solver import bayes_net_marginals, gauss_newton_qr


def _chain_problem(rng: np.random.Generator, n: int = 12, dim: int = 3, scales: float = 1.0):
    """Random linear least squares with a chain of states and two shared 'calibration' keys, badly scaled."""
    gfg = gtsam.GaussianFactorGraph()
    shared = [gtsam.symbol("c", 0), gtsam.symbol("c", 1)]
    states = [gtsam.symbol("x", i) for i in range(n)]
    unit = gtsam.noiseModel.Unit.Create(dim)
    gfg.add(
        gtsam.JacobianFactor(
            states[0], rng.normal(size=(dim, dim)) * 1e3, rng.normal(size=dim), unit
        )
    )
    for i in range(n - 1):
        gfg.add(
            gtsam.JacobianFactor(
                states[i],
                rng.normal(size=(dim, dim)) * 1e6 * scales,
                states[i + 1],
                rng.normal(size=(dim, dim)) * 1e6 * scales,
                rng.normal(size=dim),
                unit,
            )
        )
    for i in range(n):
        keys = [states[i], shared[i % 2]]
        gfg.add(
            gtsam.JacobianFactor(
                keys[0],
                rng.normal(size=(dim, dim)),
                keys[1],
                rng.normal(size=(dim, dim)),
                rng.normal(size=dim),
                unit,
            )
        )
    for c in shared:
        gfg.add(gtsam.JacobianFactor(c, np.eye(dim) * 1e-2, np.zeros(dim), unit))
    ordering = gtsam.Ordering()
    for k in states + shared:
        ordering.push_back(k)
    return gfg, ordering, states, shared


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("scales", "rtol"), [(1e-3, 1e-9), (1.0, 1e-5)])
def test_bayes_net_marginals_match_dense_inverse(seed: int, scales: float, rtol: float) -> None:
    """Well scaled: agreement to 1e-9. Badly scaled (condition number ~5e6): both computations lose digits
    (measured: up to 5e-7 relative), so 1e-5."""
    rng = np.random.default_rng(seed)
    gfg, ordering, states, shared = _chain_problem(rng, scales=scales)
    bn = gfg.eliminateSequential(ordering, gtsam.EliminateQR)
    groups = [(states[3], states[4]), tuple(shared)]
    marg = bayes_net_marginals(bn, groups)
    # independent: dense QR of the whole Jacobian (same key order), cov = R^-1 R^-T; inverting A^T A
    # directly would lose the digits that these badly scaled rows (1e6 vs 1e-2) need
    A, _ = gfg.jacobian(ordering)
    r_inv = np.linalg.inv(np.linalg.qr(A, mode="r"))
    cov = r_inv @ r_inv.T
    dim = 3
    keys = states + shared
    for j, k in enumerate(keys):
        block = cov[j * dim : (j + 1) * dim, j * dim : (j + 1) * dim]
        np.testing.assert_allclose(
            marg.covariances[k], block, rtol=rtol, atol=rtol * np.abs(block).max()
        )
    j3 = slice(3 * dim, 5 * dim)
    np.testing.assert_allclose(
        marg.joints[groups[0]], cov[j3, j3], rtol=rtol, atol=rtol * np.abs(cov[j3, j3]).max()
    )
    js = slice(len(states) * dim, (len(states) + 2) * dim)
    np.testing.assert_allclose(
        marg.joints[groups[1]], cov[js, js], rtol=rtol, atol=rtol * np.abs(cov[js, js]).max()
    )


def test_gauss_newton_qr_solves_nonlinear_problem() -> None:
    """A pose chain with a loop: GN with QR reaches the same optimum as GTSAM's LM with QR."""
    rng = np.random.default_rng(3)
    graph = gtsam.NonlinearFactorGraph()
    noise = gtsam.noiseModel.Isotropic.Sigma(6, 0.1)
    graph.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    truth = [gtsam.Pose3()]
    for i in range(1, 8):
        step = gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3) * 0.3), rng.normal(size=3))
        truth.append(truth[-1].compose(step))
        graph.add(gtsam.BetweenFactorPose3(i - 1, i, step, noise))
    graph.add(
        gtsam.BetweenFactorPose3(
            0, 7, truth[0].between(truth[7]).retract(rng.normal(size=6) * 0.05), noise
        )
    )
    init = gtsam.Values()
    for i, p in enumerate(truth):
        init.insert(i, p.retract(rng.normal(size=6) * 0.2))
    ordering = gtsam.Ordering()
    for i in range(8):
        ordering.push_back(i)
    ours, report = gauss_newton_qr(graph, init, ordering, max_iterations=50)
    params = gtsam.LevenbergMarquardtParams()
    params.setLinearSolverType("MULTIFRONTAL_QR")
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    ref = gtsam.LevenbergMarquardtOptimizer(graph, init, params).optimize()
    assert report.converged
    assert graph.error(ours) <= graph.error(ref) * (1 + 1e-9) + 1e-12
    for i in range(8):
        assert ours.atPose3(i).equals(ref.atPose3(i), 1e-6)
