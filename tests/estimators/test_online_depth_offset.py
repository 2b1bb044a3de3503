"""Depth and the DVL-IMU time offset dt_d in the online (iSAM2) estimator and the EKF, against the batch smoother and
the simulated truth (estimators/online/estimator.py, estimators/ekf/filter.py: module docs).

Runs: paper-3d-short (data/scenarios/paper-3d-short.toml, about 840 s: 120 s static, the paper's manoeuvres with
60 s legs), seed 7. Measured (printed by the tests):
- dt_d = 0.6 s: batch 0.582 +- 0.0270 s; online 0.583 +- 0.0271 s (sigma ratio to the batch 1.005); EKF 0.580 +-
  0.0267 s (ratio 0.99); all within 0.8 sigma of the truth and within 0.1 batch sigma of each other.
- dt_d = 1.5 s, online: with the IMU windows re-centred on the current estimate 1.495 +- 0.028 s (-0.2 sigma),
  kept at the prior 0 1.453 s (-1.7 sigma) and the scale 2.6 sigma low: the re-centring matters.
- depth (1 Hz, 5 cm, lever arm (0.4, -0.2, 0.3) m): the vertical error's rms 1.4 cm online and in the EKF (0.3 m
  without depth), every state within 3 sigma, final sigma 1.2 cm (1.8 m without).
Together about 16 s of CPU.
"""

from __future__ import annotations

import copy
from functools import cache

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, T_OFFSET, V, X
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import so3_exp
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf.filter import run_ekf
from gtsam_dvl.estimators.ekf.measurements import depth_measurement_model, offset_measurement_model
from gtsam_dvl.estimators.ekf.strapdown import FilterState, NavState
from gtsam_dvl.estimators.online import OnlineEstimator, feed_log
from gtsam_dvl.estimators.online.dvl_factors import (
    considered_calibration_factor as _considered_calibration_factor,
)
from tests.support.numerical import numerical_jacobian, numerical_jacobians
from tests.support.scenarios import simulate_variant

SEED = 7


@cache
def offset_log(dt: float) -> LogData:
    """paper-3d-short whose DVL stamps are dt seconds early (tests/estimators/test_time_offset.py)."""
    return simulate_variant(SEED, rates={"dvl_time_offset_s": dt})


@cache
def depth_log() -> LogData:
    return simulate_variant(
        SEED,
        name="paper-3d-short-depth",
        depth={"rate_hz": 1.0, "noise_m": 0.05, "lever_arm_m": [0.4, -0.2, 0.3]},
    )


def offset_config() -> EstimatorConfig:
    cfg = EstimatorConfig.paper()
    return cfg.model_copy(update={"dvl": cfg.dvl.model_copy(update={"estimate_time_offset": True})})


@cache
def offset_run(estimator: str, dt: float, recentre: bool = True) -> NavResult:
    log, cfg = offset_log(dt), offset_config()
    if estimator == "batch":
        return smooth_batch(log, cfg)
    if estimator == "ekf":
        return run_ekf(log, cfg)
    est = OnlineEstimator.for_log(log, cfg)
    est.recentre_offset_window = recentre
    feed_log(est, log)
    return est.result(log.t0_ns)


@cache
def depth_run(estimator: str, use: bool) -> NavResult:
    cfg = EstimatorConfig.paper()
    cfg.depth.use = use
    log = depth_log()
    if estimator == "batch":
        return smooth_batch(log, cfg)
    if estimator == "ekf":
        return run_ekf(log, cfg)
    est = OnlineEstimator.for_log(log, cfg)
    feed_log(est, log)
    return est.result(log.t0_ns)


def scale_nsigma(r: NavResult, log: LogData) -> float:
    assert log.true_calibration is not None
    return (r.scale - log.true_calibration.scale) / r.scale_sigma


def vertical(r: NavResult, log: LogData) -> tuple[np.ndarray, np.ndarray]:
    """Vertical position error (m, up) and its sigma (m) at every state (pose covariance rotated into map)."""
    assert log.truth is not None
    R = r.n_R_b
    cov = np.einsum("kij,kjl,kml->kim", R, r.pose_cov[:, 3:, 3:], R)
    return r.n_p[:, 2] - np.interp(r.t, log.truth.t, log.truth.n_p[:, 2]), np.sqrt(cov[:, 2, 2])


# ----- the time offset -----------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["online", "ekf"])
def test_offset_recovered_with_the_batch_sigma(estimator: str) -> None:
    dt, log = 0.6, offset_log(0.6)
    r, rb = offset_run(estimator, dt), offset_run("batch", dt)
    n = (r.time_offset_s - dt) / r.time_offset_sigma_s
    ratio = r.time_offset_sigma_s / rb.time_offset_sigma_s
    print(
        f"\n{estimator}: dt_d {r.time_offset_s:.4f} +- {r.time_offset_sigma_s * 1e3:.1f} ms ({n:+.2f} sigma), "
        f"sigma / batch's {ratio:.3f}; batch {rb.time_offset_s:.4f} +- {rb.time_offset_sigma_s * 1e3:.1f} ms; "
        f"scale {scale_nsigma(r, log):+.2f} sigma (batch {scale_nsigma(rb, log):+.2f})"
    )
    assert abs(n) < 3.0
    assert 0.9 < ratio < 1.1
    assert abs(scale_nsigma(r, log)) < 3.0
    # the batch smoother's estimate and this one: the same data, so far closer than a sigma
    assert abs(r.time_offset_s - rb.time_offset_s) < 0.5 * rb.time_offset_sigma_s


@pytest.mark.slow
def test_offset_not_estimated_is_reported_as_such() -> None:
    r = depth_run("online", False)
    e = depth_run("ekf", False)
    for res in (r, e):
        assert res.time_offset_s == 0.0 and np.isnan(res.time_offset_sigma_s)


@pytest.mark.slow
def test_recentred_windows_matter_at_1_5_s() -> None:
    """At dt_d = 1.5 s the IMU window kept at the prior (the tangent at the stamp) biases the offset and the scale;
    centred on the current estimate, as the batch smoother's second pass does, it does not."""
    dt, log = 1.5, offset_log(1.5)
    r, r0 = offset_run("online", dt, True), offset_run("online", dt, False)
    n, n0 = ((x.time_offset_s - dt) / x.time_offset_sigma_s for x in (r, r0))
    s, s0 = scale_nsigma(r, log), scale_nsigma(r0, log)
    print(
        f"\nre-centred: {r.time_offset_s:.4f} s ({n:+.2f} sigma), scale {s:+.2f} sigma; at the prior: "
        f"{r0.time_offset_s:.4f} s ({n0:+.2f} sigma), scale {s0:+.2f} sigma"
    )
    assert abs(n) < 3.0 and abs(s) < 3.0
    assert abs(n) < abs(n0) - 0.5 and abs(s) < abs(s0) - 0.5


def test_offset_with_beams_is_refused() -> None:
    cfg = offset_config()
    cfg = cfg.model_copy(update={"dvl": cfg.dvl.model_copy(update={"use_beams": True})})
    with pytest.raises(GtsamDvlError, match="use_beams"):
        OnlineEstimator.for_log(offset_log(0.6), cfg)
    with pytest.raises(GtsamDvlError, match="use_beams"):
        run_ekf(offset_log(0.6), cfg)


# ----- depth ---------------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("estimator", ["online", "ekf"])
def test_depth_bounds_the_vertical_position(estimator: str) -> None:
    log = depth_log()
    r, r0, rb = depth_run(estimator, True), depth_run(estimator, False), depth_run("batch", True)
    (e, s), (e0, s0) = vertical(r, log), vertical(r0, log)
    rms, rms0 = float(np.sqrt(np.mean(e**2))), float(np.sqrt(np.mean(e0**2)))
    c = r.info["counters"]
    print(
        f"\n{estimator}: vertical error rms {rms * 100:.2f} cm (without depth {rms0 * 100:.1f} cm), final "
        f"{e[-1]:+.3f} +- {s[-1]:.3f} m (without {e0[-1]:+.3f} +- {s0[-1]:.3f} m), max |e| / sigma "
        f"{np.max(np.abs(e) / s):.2f}, rms(e / sigma) {np.sqrt(np.mean((e / s) ** 2)):.2f}; counters "
        f"{ {k: v for k, v in c.items() if k.startswith('depth')} }"
    )
    assert "depth_ignored" not in c and "depth_used" not in r0.info["counters"]
    bc = rb.info["counters"]
    assert c["depth_used"] == bc["depth_used"] and c["depth_too_far"] == bc["depth_too_far"]
    assert c.get("depth_gated", 0) == 0
    # within 3 sigma: the final state, 99 % of them, none beyond 4; consistent: rms of the normalised error ~ 1
    assert abs(e[-1]) < 3 * s[-1]
    assert np.mean(np.abs(e) < 3 * s) > 0.99 and np.all(np.abs(e) < 4 * s)
    assert 0.6 < np.sqrt(np.mean((e / s) ** 2)) < 1.4
    # and far better than without depth
    assert rms < 0.25 * rms0 and s[-1] < 0.05 < 0.5 < s0[-1]


def test_online_depth_waits_for_its_state_and_rejects_disorder() -> None:
    """A sample is placed only once its nearest state is known: pushed before any state exists it waits; a sample
    older than the previous one is bad input."""
    log = depth_log()
    est = OnlineEstimator.for_log(log, EstimatorConfig.paper())
    est.push_depth(5.0, 100.0, 0.0025)
    assert len(est._depth) == 1 and est.counters["depth_used"] == 0
    with pytest.raises(GtsamDvlError, match="older than the previous one"):
        est.push_depth(4.0, 100.0)
    est.push_depth(6.0, float("nan"))
    assert est.counters["depth_invalid"] == 1 and len(est._depth) == 1


# ----- Jacobians -----------------------------------------------------------------------------------------------
def _filter_state(rng: np.random.Generator, offset: bool) -> FilterState:
    n = 20 if offset else 19
    return FilterState(
        NavState(so3_exp(rng.normal(size=3)), rng.normal(size=3) * 2, rng.normal(size=3) * 300),
        rng.normal(size=3) * 1e-4,
        rng.normal(size=3) * 1e-3,
        0.98,
        so3_exp(rng.normal(size=3) * 0.1),
        np.eye(n),
        0.4 if offset else 0.0,
    )


def _inject(fs: FilterState, dx: np.ndarray) -> FilterState:
    """The EKF's error injection (FilterState.inject, as filter.update applies it) on a copy: true = estimate (+)
    error."""
    out = copy.copy(fs)
    out.inject(dx)
    return out


def _numerical(f, fs: FilterState, n: int) -> np.ndarray:  # type: ignore[no-untyped-def]
    return numerical_jacobian(lambda dx: f(_inject(fs, dx)), [np.zeros(n)], 0)


def test_ekf_offset_and_depth_jacobians_match_finite_differences() -> None:
    rng = np.random.default_rng(3)
    fs = _filter_state(rng, True)
    b_l, n_g = np.array([0.5, -0.2, 0.3]), np.array([0.0, 0.0, -9.79])
    rate = (
        rng.normal(size=3) * 0.1 + [0.0, 0.0, 9.79],
        rng.normal(size=3) * 0.05,
        so3_exp(rng.normal(size=3) * 0.01),
    )
    _, H = offset_measurement_model(fs, b_l, rate, n_g)
    H_num = _numerical(lambda s: offset_measurement_model(s, b_l, rate, n_g)[0], fs, 20)
    np.testing.assert_allclose(H, H_num, atol=1e-6)
    radius, b_p = 6.38e6, np.array([0.4, -0.2, 0.3])
    for dt in (0.0, 0.3):
        _, Hd = depth_measurement_model(fs, b_p, radius, dt)
        Hd_num = _numerical(lambda s, dt=dt: depth_measurement_model(s, b_p, radius, dt)[0], fs, 20)
        np.testing.assert_allclose(Hd, Hd_num, atol=1e-6)


def test_considered_offset_factor_jacobians() -> None:
    """The online estimator's DVL factor for a slow ping with the time offset: the offset model's error, its
    Jacobians for pose, velocity and offset (numerical derivatives), none for scale and misalignment."""
    rng = np.random.default_rng(5)
    rate = (
        rng.normal(size=3) * 0.1 + [0.0, 0.0, 9.79],
        rng.normal(size=3) * 0.05,
        so3_exp(rng.normal(size=3) * 0.01),
    )
    n_g = np.array([0.0, 0.0, -9.79])
    f = _considered_calibration_factor(
        gtsam.noiseModel.Isotropic.Sigma(3, 0.02),
        2,
        np.zeros(3),
        np.array([0.5, -0.2, 0.3]),
        d_y=np.array([0.05, 0.01, -0.02]),
        offset=(rate, n_g),
        config=EstimatorConfig(dvl=DvlConfig(estimate_time_offset=True, correlated_sigma_m_s=0.0)),
    )  # (E: test_dvl.py)
    values = gtsam.Values()
    values.insert(X(2), gtsam.Pose3(gtsam.Rot3(so3_exp(rng.normal(size=3))), rng.normal(size=3)))
    values.insert(V(2), rng.normal(size=3) * 0.05)
    values.insert(K_SCALE, np.array([0.98]))
    values.insert(C_MISALIGN, gtsam.Rot3(so3_exp(rng.normal(size=3) * 0.1)))
    values.insert(T_OFFSET, np.array([0.6]))
    lin = f.linearize(values)
    A, _ = lin.jacobian()
    sigma = 0.02  # whitened Jacobian = H / sigma
    keys = [X(2), V(2), K_SCALE, C_MISALIGN, T_OFFSET]
    assert list(f.keys()) == keys
    H = A * sigma
    dims = dict(zip(keys, (6, 3, 1, 3, 1), strict=True))

    def error(
        pose: gtsam.Pose3, n_v: np.ndarray, scale: np.ndarray, b_R_d: gtsam.Rot3, offset: np.ndarray
    ) -> np.ndarray:
        moved = gtsam.Values()
        for key, value in zip(keys, (pose, n_v, scale, b_R_d, offset), strict=True):
            moved.insert(key, value)
        return f.unwhitenedError(moved)

    numerical = numerical_jacobians(
        error,
        [
            values.atPose3(X(2)),
            values.atVector(V(2)),
            values.atVector(K_SCALE),
            values.atRot3(C_MISALIGN),
            values.atVector(T_OFFSET),
        ],
    )
    col = 0
    for (key, d), num in zip(dims.items(), numerical, strict=True):
        block = H[:, col : col + d]
        if key in (K_SCALE, C_MISALIGN):
            assert np.all(block == 0.0)
        else:
            np.testing.assert_allclose(block, num, atol=1e-6)
        col += d
