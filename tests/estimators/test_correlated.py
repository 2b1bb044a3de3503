"""estimators/models/correlated.py: the DVL's correlated (Gauss-Markov) velocity error as a state of each epoch.

The link and prior factors against the process's own discretisation (an independent formula); the EKF's propagation
keeps the stationary covariance; and on a simulated log whose DVL carries a strong correlated error (6 mm/s, 30 s,
over 5 mm/s of white noise) the batch smoother's estimate of E follows the error the simulator drew."""

from __future__ import annotations

from functools import cache

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import E
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch, solve_graph
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.models import correlated
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.dvl import correlated_error
from gtsam_dvl.sim.scenario import Scenario, load_scenario, scenario_from_dict

SIGMA, TAU = 0.006, 30.0  # m/s, s


def _with_gm(c: EstimatorConfig) -> EstimatorConfig:
    return c.model_copy(
        update={
            "dvl": c.dvl.model_copy(update={"correlated_sigma_m_s": SIGMA, "correlated_tau_s": TAU})
        }
    )


def _config() -> EstimatorConfig:
    return _with_gm(EstimatorConfig())


def test_link_and_prior_are_the_discrete_process() -> None:
    """error = 0.5 |E_j - phi E_i|^2 / q with phi = exp(-dt / tau), q = sigma^2 (1 - phi^2); the prior's
    0.5 |E_0|^2 / sigma^2."""
    cfg, dt = _config(), 2.5
    e_i, e_j = np.array([0.004, -0.002, 0.001]), np.array([0.003, 0.001, -0.002])
    values = gtsam.Values()
    values.insert(E(3), e_i)
    values.insert(E(4), e_j)
    phi = np.exp(-dt / TAU)
    q = SIGMA**2 * (1 - phi**2)
    assert correlated.link_factor(cfg, 3, 4, dt).error(values) == pytest.approx(
        0.5 * np.sum((e_j - phi * e_i) ** 2) / q, rel=1e-12
    )
    assert correlated.prior_factor(cfg, 3).error(values) == pytest.approx(
        0.5 * np.sum(e_i**2) / SIGMA**2, rel=1e-12
    )


def test_ekf_propagation_keeps_the_stationary_covariance() -> None:
    """From the stationary sigma^2 I the block stays sigma^2 I over any step; a cross-covariance with another state
    decays by phi, the estimate too."""
    cfg = _config()
    P = np.eye(5) * 0.3
    P[2:, 2:] = np.eye(3) * SIGMA**2
    P[0, 2] = P[2, 0] = 1e-4
    d_e = np.array([0.002, 0.0, -0.001])
    out, d_e2 = correlated.ekf_propagate(cfg, P, d_e, slice(2, 5), 7.0)
    phi = np.exp(-7.0 / TAU)
    np.testing.assert_allclose(out[2:, 2:], np.eye(3) * SIGMA**2, rtol=1e-12)
    assert out[0, 2] == pytest.approx(phi * 1e-4, rel=1e-12) and out[2, 0] == out[0, 2]
    assert out[0, 0] == P[0, 0]
    np.testing.assert_allclose(d_e2, phi * d_e)


@cache
def _scenario() -> Scenario:
    raw = dict(load_scenario("steady-turn").raw)
    raw["dvl"] = {
        **raw["dvl"],
        "correlated_sigma_m_s": SIGMA,
        "correlated_tau_s": TAU,
        "noise_m_s": 0.005,
    }
    raw["segments"] = [{**raw["segments"][0], "duration_s": 200.0}]
    return scenario_from_dict(raw)


@cache
def _log(seed: int) -> LogData:
    return simulate(_scenario(), seed)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_batch_follows_the_simulated_correlated_error(seed: int) -> None:
    """E(i) at the pings' states against the Gauss-Markov error the simulator added (drawn again from the same
    seed): correlated with it on every dvl_link axis (measured on seeds 1-3: 0.60-0.91), and its fluctuation about
    the mean recovered (RMS error 0.41-0.83 of the error's own RMS; 1 without the model). The mean over the run is
    not: along-track it trades with the scale, across with the yaw misalignment."""
    sc, log = _scenario(), _log(seed)
    truth = correlated_error(sc.dvl, sc.rates.dvl_hz, seed)
    assert truth is not None
    d_e_true = truth.take(len(log.dvl.t))
    builder = LogGraph(log, _with_gm(sc.estimator_configuration()))
    graph, values = builder.build_bulk()
    _, values, report, _ = solve_graph(builder, graph, values, builder.elimination_ordering())
    assert report.converged
    at = [(i, ep.dvl_index) for i, ep in enumerate(builder.epochs) if ep.dvl_index >= 0]
    est = np.array([values.atVector(E(i)) for i, _ in at])
    tru = d_e_true[[j for _, j in at]]
    for k in range(3):
        assert np.corrcoef(est[:, k], tru[:, k])[0, 1] > 0.5, f"axis {k}"
    fluct_err = (est - est.mean(axis=0)) - (tru - tru.mean(axis=0))
    ratio = np.sqrt(np.mean(fluct_err**2, axis=0) / np.mean((tru - tru.mean(axis=0)) ** 2, axis=0))
    assert np.all(ratio < 0.9), ratio


def test_result_reports_the_model() -> None:
    """info["dvl_correlated_error"]: the level and time constant used and the estimate's RMS; absent when the
    error is white."""
    sc, log = _scenario(), _log(1)
    base = sc.estimator_configuration()
    white = smooth_batch(
        log,
        base.model_copy(update={"dvl": base.dvl.model_copy(update={"correlated_sigma_m_s": 0.0})}),
    )
    with_gm = smooth_batch(log, _with_gm(base))
    info = with_gm.info["dvl_correlated_error"]
    assert info["sigma_m_s"] == SIGMA and info["tau_s"] == TAU
    assert all(0.0 < r < 3 * SIGMA for r in info["estimate_rms_m_s"])
    assert "dvl_correlated_error" not in white.info


def test_filtering_timeline_ends_at_the_smoother_marginals() -> None:
    """The filtering timeline carries E_i with the epoch's state: at the last epoch its calibration and bias sigmas
    equal the smoother's marginals (timeline.py), to 1e-4: the smoother's come from the last Gauss-Newton
    iteration's Bayes net, linearised one (tiny) step before the timeline's point."""
    sc, log = _scenario(), _log(2)
    res = smooth_batch(log, _with_gm(sc.estimator_configuration()), timeline=True)
    tl = res.timeline
    assert tl is not None
    np.testing.assert_allclose(tl.scale_sigma[-1], res.scale_sigma, rtol=1e-4)
    np.testing.assert_allclose(tl.misalignment_sigma_deg[-1], res.misalignment_sigma_deg, rtol=1e-4)
    np.testing.assert_allclose(tl.accel_bias_sigma_ug[-1], res.accel_bias_sigma_ug, rtol=1e-4)
    np.testing.assert_allclose(tl.attitude_sigma_deg[-1], res.attitude_sigma_deg[-1], rtol=1e-4)
    assert tl.time_offset_sigma_s is not None
    np.testing.assert_allclose(tl.time_offset_sigma_s[-1], res.time_offset_sigma_s, rtol=1e-4)
