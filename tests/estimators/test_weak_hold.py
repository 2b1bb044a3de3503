"""Weakly determined calibration directions held at the prior (estimators/models/weak_hold.py): the eigen-directions
against a diagonal case worked by hand, and on a straight transect with the sensor presets (the yaw misalignment
and the scale barely informed) the held estimate's weak components at the prior's mean, its covariance along them
the prior's (the consider covariance), the informed directions as the free run has them, the position within its
sigmas."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.estimators.models import weak_hold


def test_weak_directions_diagonal() -> None:
    """P0 = diag(4, 1, 1, 9), P1 = diag(2, 0.9, 0.1, 9): lambda = P0 / P1 - 1 = (1, 0.111, 9, 0)."""
    lam, V, weak = weak_hold.weak_directions(
        np.diag([4.0, 1.0, 1.0, 9.0]), np.diag([2.0, 0.9, 0.1, 9.0]), 0.25
    )
    got = {int(np.argmax(np.abs(V[:, k]))): lam[k] for k in range(4)}
    assert got == pytest.approx({0: 1.0, 1: 1 / 9, 2: 9.0, 3: 0.0}, abs=1e-12)
    assert sorted(int(np.argmax(np.abs(V[:, k]))) for k in np.flatnonzero(weak)) == [1, 3]


def _presets(base: EstimatorConfig) -> EstimatorConfig:
    """The scenario's configuration with the PHINS and Pathfinder presets and a 0.5 deg mounting tolerance (as
    bench/underway_calibration.py's "presets" variant)."""
    from gtsam_dvl.core.config.presets import DVL_PRESETS, IMU_PRESETS

    d = base.to_dict()
    d["priors"] = {
        k: v for k, v in d["priors"].items() if k not in ("misalignment_sigma_deg", "scale_sigma")
    }
    d["priors"]["mounting_tolerance_deg"] = 0.5
    d["imu"] = {
        **{
            k: v
            for k, v in d["imu"].items()
            if k not in IMU_PRESETS["ixblue-phins"].config_values()
        },
        "model": "ixblue-phins",
    }
    d["dvl"] = {
        **{
            k: v
            for k, v in d["dvl"].items()
            if k not in DVL_PRESETS["teledyne-pathfinder"].config_values()
        },
        "model": "teledyne-pathfinder",
    }
    # the weak directions alone (the nominal check: test_nominal_check.py)
    d["priors"]["nominal_check"] = False
    # the posteriors of the data alone: the constant DVL error's share (test_constant_error.py) is added after the
    # hold, outside the held directions, and would blur the free run's directions compared below
    d["dvl"]["constant_error_sigma_m_s"] = 0.0
    return EstimatorConfig.from_dict(d)


@pytest.mark.slow
def test_straight_transect_holds_yaw_and_scale() -> None:
    from gtsam_dvl.core.states import columns, shared_keys
    from gtsam_dvl.estimators.batch.smoother import smooth_batch
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario

    sc = load_scenario("straight-transect")
    log = simulate(sc, 2)
    cfg = _presets(sc.estimator_configuration())
    free_cfg = cfg.model_copy(
        update={"priors": cfg.priors.model_copy(update={"hold_weak_information": 0.0})}
    )
    free, held = smooth_batch(log, free_cfg), smooth_batch(log, cfg)
    assert "calibration_hold" not in free.info
    info = held.info["calibration_hold"]
    assert sorted(h["mostly"] for h in info["held"]) == ["misalignment yaw", "scale"]
    assert info["consistent"] and info["chi2_increase"] < info["chi2_limit_99"]

    k0, R0, P0 = weak_hold.calibration_prior(cfg, log.mounting)
    Li = np.linalg.inv(np.linalg.cholesky(P0))
    n = len(held.t) - 1
    cols = columns(shared_keys(cfg, n, block=True), cfg)
    idx = np.r_[
        cols["scale"].start, np.arange(cols["misalignment"].start, cols["misalignment"].stop)
    ]

    def whitened(res: NavResult) -> tuple[np.ndarray, np.ndarray]:
        d = np.r_[res.scale - k0, gtsam.Rot3.Logmap(gtsam.Rot3(R0).between(gtsam.Rot3(res.b_R_d)))]
        assert res.calib_joint_cov is not None
        return Li @ d, Li @ res.calib_joint_cov[np.ix_(idx, idx)] @ Li.T

    plan = weak_hold.plan(cfg, log.mounting, free.calib_joint_cov, n)  # type: ignore[arg-type]
    assert plan is not None
    V, weak = plan["V"], plan["weak"]
    u_free, M_free = whitened(free)
    u_held, M_held = whitened(held)
    for k in np.flatnonzero(weak):  # pinned at the prior's mean, with the prior's variance
        assert abs(V[:, k] @ u_held) < 1e-3, V[:, k] @ u_held
        assert V[:, k] @ M_held @ V[:, k] == pytest.approx(1.0, abs=0.02)
        # (the free run's: the data's little information)
        assert V[:, k] @ M_free @ V[:, k] < 1.0 / (1.0 + 0.05)
    for k in np.flatnonzero(~weak):  # the informed directions: the free run's variance, within 10 %
        assert V[:, k] @ M_held @ V[:, k] == pytest.approx(V[:, k] @ M_free @ V[:, k], rel=0.1)
    truth = log.truth
    assert truth is not None
    for res in (held, free):  # the final position within 3 sigma of the truth
        e = res.n_p[-1, :2] - [np.interp(res.t[-1], truth.t, truth.n_p[:, k]) for k in range(2)]
        assert np.all(np.abs(e) < 3 * res.position_sigma_m[-1, :2]), (
            e,
            res.position_sigma_m[-1, :2],
        )
    # (the prior carried in)
    assert np.all(held.position_sigma_m[-1, :2] >= 0.98 * free.position_sigma_m[-1, :2])


def test_hold_joint_properties() -> None:
    """A filter's joint [X, V, bias, scale, misalignment] held (weak_hold.hold_joint): the weak directions'
    whitened components at the prior's mean and their whitened variance 1 (the prior's), the informed ones' and
    the conditional covariance of everything else given the calibration unchanged (the hold replaces the
    calibration's marginal only)."""
    from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, B, V, X
    from gtsam_dvl.core.states import columns
    from gtsam_dvl.core.types import Mounting

    # the weak directions alone
    cfg = EstimatorConfig.from_dict({"priors": {"nominal_check": False}})
    mounting = Mounting()
    keys = [X(0), V(0), B(0), K_SCALE, C_MISALIGN]
    k0, R0, P0 = weak_hold.calibration_prior(cfg, mounting)
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose3(gtsam.Rot3.Ypr(0.3, 0.01, -0.02), np.array([10.0, -4.0, -2.0])))
    values.insert(V(0), np.array([1.5, 0.2, 0.0]))
    values.insert(B(0), gtsam.imuBias.ConstantBias(np.full(3, 1e-4), np.full(3, 1e-6)))
    values.insert(K_SCALE, np.array([k0 + 0.004]))
    values.insert(
        C_MISALIGN, gtsam.Rot3(R0).compose(gtsam.Rot3.Expmap(np.radians([0.1, -0.3, 0.5])))
    )
    rng = np.random.default_rng(7)
    n = 6 + 3 + 6 + 1 + 3
    A = rng.normal(size=(n, n)) * np.r_[np.full(15, 0.1), np.sqrt(np.diag(P0))][:, None]
    # the calibration barely informed
    cov = A @ A.T + np.diag(np.r_[np.full(15, 1e-4), 0.9 * np.diag(P0)])
    held = weak_hold.hold_joint(cfg, mounting, values, keys, cov)
    assert held is not None
    values_h, cov_h, plan = held
    idx = np.r_[
        columns(keys, cfg)["scale"].start,
        np.arange(
            columns(keys, cfg)["misalignment"].start, columns(keys, cfg)["misalignment"].stop
        ),
    ]
    Li = np.linalg.inv(np.linalg.cholesky(P0))
    d = np.r_[
        values_h.atVector(K_SCALE)[0] - k0,
        gtsam.Rot3.Logmap(gtsam.Rot3(R0).between(values_h.atRot3(C_MISALIGN))),
    ]
    u, M = Li @ d, Li @ cov_h[np.ix_(idx, idx)] @ Li.T
    M_before = Li @ cov[np.ix_(idx, idx)] @ Li.T
    Vk, weak = plan["V"], plan["weak"]
    assert weak.any()
    for k in range(4):
        if weak[k]:
            assert abs(Vk[:, k] @ u) < 1e-6 and Vk[:, k] @ M @ Vk[:, k] == pytest.approx(
                1.0, rel=1e-9
            )
        else:
            assert Vk[:, k] @ M @ Vk[:, k] == pytest.approx(
                Vk[:, k] @ M_before @ Vk[:, k], rel=1e-9
            )
    rest = np.setdiff1d(np.arange(n), idx)

    def conditional(P: np.ndarray) -> np.ndarray:
        return P[np.ix_(rest, rest)] - P[np.ix_(rest, idx)] @ np.linalg.solve(
            P[np.ix_(idx, idx)], P[np.ix_(idx, rest)]
        )

    np.testing.assert_allclose(conditional(cov_h), conditional(cov), rtol=1e-7, atol=1e-15)
