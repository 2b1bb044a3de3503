"""The 19-state error-state EKF (gtsam_dvl/estimators/ekf.py): its transition and measurement Jacobians against
numerical derivatives, the strapdown's Earth model, and the paper's Figures 6-7 behaviour on paper-3d,
against the truth and against the batch smoother. Each test prints the numbers it measured.
"""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame, gravity_gradient
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_exp, so3_log
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import FilterState, measurement_model, run_ekf
from gtsam_dvl.estimators.ekf.strapdown import (
    BA,
    BG,
    MIS,
    N_ERR,
    PHI,
    POS,
    SCALE,
    VEL,
    NavState,
    propagate_interval,
)
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario
from tests.support.logs import cut_log
from tests.support.numerical import numerical_jacobian

SEEDS = [1, 2, 3]


@functools.cache
def _log(seed: int, white_noise: bool = True) -> LogData:
    return simulate(load_scenario("paper-3d"), seed, white_noise=white_noise)


@functools.cache
def _ekf(seed: int) -> tuple[NavResult, float]:
    start = time.perf_counter()
    result = run_ekf(_log(seed))
    return result, time.perf_counter() - start


# ----- Jacobians ------------------------------------------------------------------------------------


def _interval(rng: np.random.Generator, n: int = 100) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A turning, accelerating 1 s interval: rates up to 0.2 rad/s, specific force about 1 g."""
    t = np.linspace(0.0, 1.0, n)
    b_omega = 0.1 * np.stack([np.sin(3 * t), np.cos(2 * t), 1.0 + 0 * t], axis=1) + rng.normal(
        0, 0.01, (n, 3)
    )
    b_f = np.array([0.3, -0.2, 9.8]) + 0.5 * np.stack([np.cos(t), t, t**2], axis=1)
    return b_omega, b_f, np.full(n, 1.0 / n)


@pytest.mark.parametrize("near_identity", [False, True])
def test_transition_matrix_matches_numerical_derivative(near_identity: bool) -> None:
    """Phi of propagate_interval against central differences of the nonlinear propagation, for each
    column of the navigation and bias errors (scale and misalignment are constant)."""
    rng = np.random.default_rng(3)
    frame = LocalFrame(30.0, 114.0, -100.0)
    R0 = so3_exp(np.full(3, 1e-7)) if near_identity else rpy_deg_to_matrix([3.0, -2.0, 100.0])
    x0 = NavState(R0, np.array([1.5, -0.7, 0.2]), np.array([300.0, -200.0, -30.0]))
    b_omega, b_f, dt = _interval(rng)
    w_ie = frame.n_omega_ie
    G = gravity_gradient(frame, x0.n_p)
    g0 = frame.n_gravity(x0.n_p)
    nominal = propagate_interval(x0, b_omega, b_f, dt, w_ie, g0, G)

    def end_error(dx: np.ndarray) -> np.ndarray:
        start = NavState(so3_exp(dx[PHI]) @ x0.n_R_b, x0.n_v + dx[VEL], x0.n_p + dx[POS])
        # the filter evaluates gravity once per interval: to first order it moves with the position
        end = propagate_interval(
            start, b_omega - dx[BG], b_f - dx[BA], dt, w_ie, g0 + G @ dx[POS], G
        ).state
        out = np.zeros(N_ERR)
        out[PHI] = so3_log(end.n_R_b @ nominal.state.n_R_b.T)
        out[VEL] = end.n_v - nominal.state.n_v
        out[POS] = end.n_p - nominal.state.n_p
        out[BG], out[BA], out[SCALE], out[MIS] = dx[BG], dx[BA], dx[SCALE], dx[MIS]
        return out

    steps = np.array([1e-6] * 3 + [1e-4] * 3 + [1e-2] * 3 + [1e-6] * 3 + [1e-4] * 3 + [1e-3] * 4)
    numerical = numerical_jacobian(end_error, [np.zeros(N_ERR)], 0, delta=steps)
    err = np.abs(nominal.Phi - numerical)
    scale = np.abs(numerical).max(axis=1, keepdims=True)
    print(f"\nmax |Phi - numerical| / row scale = {np.max(err / scale):.2e}")
    # first order in the Earth rate (7e-5 rad/s) and the gravity gradient over a one-second interval
    assert np.all(err <= 1e-4 * scale + 1e-9)


def test_static_vehicle_stays_put_far_from_the_origin() -> None:
    """Exact IMU of a static vehicle 20 km from the map origin (gyro = Earth rate, accelerometer = minus
    normal gravity there): ten minutes of strapdown keep velocity, position and attitude."""
    frame = LocalFrame(30.0, 114.0, -100.0)
    n_p = np.array([20_000.0, 5_000.0, -50.0])
    n_R_b = rpy_deg_to_matrix([3.0, 0.0, 10.0])
    b_omega = np.tile(n_R_b.T @ frame.n_omega_ie, (100, 1))
    b_f = np.tile(-n_R_b.T @ frame.n_gravity(n_p), (100, 1))
    state = NavState(n_R_b, np.zeros(3), n_p.copy())
    G = gravity_gradient(frame, n_p)
    for _ in range(600):
        state = propagate_interval(
            state, b_omega, b_f, np.full(100, 0.01), frame.n_omega_ie, frame.n_gravity(state.n_p), G
        ).state
    drift = (
        np.linalg.norm(state.n_v),
        np.linalg.norm(state.n_p - n_p),
        np.linalg.norm(so3_log(state.n_R_b @ n_R_b.T)),
    )
    print(
        f"\nafter 600 s: |v| {drift[0]:.2e} m/s, |dp| {drift[1]:.2e} m, attitude {drift[2]:.2e} rad"
    )
    assert drift[0] < 1e-8 and drift[1] < 1e-6 and drift[2] < 1e-12


@pytest.mark.parametrize("near_identity", [False, True])
def test_measurement_jacobian_matches_numerical_derivative(near_identity: bool) -> None:
    """H of the DVL model (with a lever arm and a DVL mounted z-down) against central differences."""
    rng = np.random.default_rng(5)
    frame = LocalFrame(30.0, 114.0, 0.0)
    tiny = so3_exp(np.full(3, 1e-7))
    n_R_b = tiny if near_identity else rpy_deg_to_matrix([5.0, -3.0, 40.0])
    b_R_d = (tiny if near_identity else rpy_deg_to_matrix([0.3, -0.2, 0.5])) @ rpy_deg_to_matrix(
        [180.0, 0, 0]
    )
    fs = FilterState(
        NavState(n_R_b, np.array([1.8, 0.4, -0.3]), np.zeros(3)),
        rng.normal(0, 1e-6, 3),
        np.zeros(3),
        0.97,
        b_R_d,
        np.eye(N_ERR),
    )
    b_omega_m, b_l = np.array([0.05, -0.02, 0.1]), np.array([1.2, -0.3, -0.5])
    y0, H, _ = measurement_model(fs, b_omega_m, b_l, frame.n_omega_ie)

    def h(dx: np.ndarray) -> np.ndarray:
        moved = FilterState(
            NavState(so3_exp(dx[PHI]) @ n_R_b, fs.nav.n_v + dx[VEL], fs.nav.n_p + dx[POS]),
            fs.gyro_bias + dx[BG],
            fs.accel_bias + dx[BA],
            fs.scale + dx[SCALE],
            b_R_d @ so3_exp(dx[MIS]),
            fs.P,
        )
        return measurement_model(moved, b_omega_m, b_l, frame.n_omega_ie)[0]

    numerical = numerical_jacobian(h, [np.zeros(N_ERR)], 0)
    print(
        f"\nmax |H - numerical| = {np.max(np.abs(H - numerical)):.2e} (|y| = {np.linalg.norm(y0):.2f} m/s)"
    )
    np.testing.assert_allclose(H, numerical, atol=1e-8)


# ----- paper-3d -------------------------------------------------------------------------------------


def _print_summary(tag: str, s: dict) -> None:
    e = s["errors"]
    print(
        f"\n{tag}: scale err {e['scale_ppm']:+.0f} ppm (sigma {s['scale']['sigma'] * 1e6:.0f} ppm); "
        f"misalignment err {np.round(e['misalignment_deg'], 4)} sigma {np.round(s['misalignment_deg']['sigma'], 4)} "
        f"deg; gyro bias err "
        f"{np.round(e['gyro_bias_deg_per_h'], 5)} sigma {np.round(s['gyro_bias_deg_per_h']['sigma'], 5)} deg/h; "
        f"accel bias err {np.round(e['accel_bias_ug'], 2)} sigma {np.round(s['accel_bias_ug']['sigma'], 2)} ug; "
        f"position RMSE {e['position_rmse_m']:.2f} m, final horizontal {e['final_horizontal_position_m']:.2f} m; "
        f"attitude RMSE {np.round(e['attitude_rmse_deg'], 4)} deg; wall {s['timing_s']['total']:.1f} s"
    )


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
def test_paper_3d_final_calibration_inside_3_sigma(seed: int) -> None:
    result, wall = _ekf(seed)
    s = summary(result, _log(seed))
    _print_summary(f"EKF paper-3d seed {seed}", s)
    print(
        f"EKF wall time {wall:.1f} s for {len(_log(seed).imu)} IMU samples; mean NIS per dof "
        f"{result.info['filter']['mean_nis_per_dof']:.3f}"
    )
    e = s["errors"]
    assert abs(e["scale_nsigma"]) < 3
    assert np.all(np.abs(e["misalignment_nsigma"]) < 3)
    assert np.all(np.abs(e["gyro_bias_nsigma"]) < 3)
    assert np.all(np.abs(e["accel_bias_nsigma"]) < 3)
    # innovations as large as the filter predicts
    assert 0.8 < result.info["filter"]["mean_nis_per_dof"] < 1.2


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
def test_paper_3d_convergence_as_figures_6_and_7(seed: int) -> None:
    """Scale from 0.8 as soon as the motion starts; yaw and pitch misalignment at 600 s; roll only with the
    descent from 660 s."""
    log = _log(seed)
    tl = _ekf(seed)[0].timeline
    assert tl is not None
    k_true = log.true_calibration.scale  # type: ignore[union-attr]
    prior = EstimatorConfig.paper().priors
    k_err = np.abs(tl.scale / k_true - 1.0)

    def at(t: float) -> int:
        return int(np.searchsorted(tl.t, t))

    moving = at(600.0)
    converged = tl.t[np.flatnonzero(k_err > 0.01)[-1] + 1]  # from here on within 1 %
    roll0, roll659, roll720 = tl.misalignment_sigma_deg[[moving, at(659.0), at(720.0)], 0]
    print(
        f"\nseed {seed}: scale {tl.scale[moving - 1]:.3f} +- {tl.scale_sigma[moving - 1]:.3f} at 599 s, "
        f"within 1 % of the truth from {converged:.0f} s, error at 660 s {100 * k_err[at(660.0)]:.3f} %; "
        f"pitch/yaw sigma at 660 s {np.round(tl.misalignment_sigma_deg[at(660.0), 1:], 3)} deg; roll sigma "
        f"{roll0:.3f} (600 s) {roll659:.3f} (659 s) {roll720:.3f} (720 s) deg, "
        f"prior {prior.misalignment_sigma_deg[0]}"
    )
    assert (
        tl.scale[moving - 1] == pytest.approx(prior.scale_initial)
        and tl.scale_sigma[moving - 1] > 0.49
    )
    assert converged <= 660.0
    assert np.all(
        tl.misalignment_sigma_deg[at(660.0), 1:] < 0.2 * np.array(prior.misalignment_sigma_deg[1:])
    )
    assert np.all(tl.misalignment_sigma_deg[: at(660.0), 0] > 0.9 * prior.misalignment_sigma_deg[0])
    assert roll720 < 0.5 * roll659


@pytest.mark.slow
def test_paper_3d_agrees_with_batch_smoother() -> None:
    """Filter and smoother on the same log: the final calibration (constant states: the filter's last
    estimate uses all the data) agrees within 2 combined sigmas, and so do the sigmas themselves (10 %);
    the filtered roll sigma at 720 s equals the smoother's on the log cut at 720 s."""
    seed = SEEDS[0]
    log = _log(seed)
    ekf = summary(_ekf(seed)[0], log)
    batch = summary(smooth_batch(log), log)
    _print_summary("batch", batch)
    for name in ("scale", "misalignment_deg", "gyro_bias_deg_per_h", "accel_bias_ug"):
        ve, vb = np.atleast_1d(ekf[name]["value"]), np.atleast_1d(batch[name]["value"])
        se, sb = np.atleast_1d(ekf[name]["sigma"]), np.atleast_1d(batch[name]["sigma"])
        ratio = (ve - vb) / np.hypot(se, sb)
        print(
            f"{name}: (EKF - batch) / combined sigma {np.round(ratio, 3)}; sigma EKF / batch {np.round(se / sb, 3)}"
        )
        assert np.all(np.abs(ratio) < 2)
        assert np.all(np.abs(se / sb - 1.0) < 0.15)
    print(
        f"position RMSE EKF {ekf['errors']['position_rmse_m']:.2f} m, "
        f"batch {batch['errors']['position_rmse_m']:.2f} m"
    )
    cut = smooth_batch(cut_log(log, 720.0, cut_truth=False))
    tl = _ekf(seed)[0].timeline
    assert tl is not None
    roll_ekf = tl.misalignment_sigma_deg[np.searchsorted(tl.t, 720.0), 0]
    print(
        f"roll sigma at 720 s: EKF {roll_ekf:.4f} deg, batch on 0-720 s {cut.misalignment_sigma_deg[0]:.4f} deg"
    )
    assert roll_ekf == pytest.approx(cut.misalignment_sigma_deg[0], rel=0.05)


@pytest.mark.slow
def test_result_shapes_and_covariances() -> None:
    result = _ekf(SEEDS[0])[0]
    n = len(result.t)
    assert result.estimator == "ekf" and result.timeline is not None and len(result.timeline.t) == n
    assert result.pose_cov.shape == (n, 6, 6) and result.vel_cov.shape == (n, 3, 3)
    assert result.pose_vel_cross is not None and result.pose_vel_cross.shape == (n, 6, 3)
    assert result.calib_joint_cov is not None and result.calib_joint_cov.shape == (10, 10)
    np.testing.assert_allclose(result.calib_joint_cov[:6, :6], result.bias_cov)
    assert result.calib_joint_cov[6, 6] == pytest.approx(result.scale_sigma**2)
    for cov in (result.pose_cov[-1], result.calib_joint_cov):
        np.testing.assert_allclose(cov, cov.T, atol=1e-15)
        assert np.linalg.eigvalsh(cov).min() > 0
    # pose_cov is in the body tangent: its map-frame attitude sigmas are the timeline's
    np.testing.assert_allclose(
        result.attitude_sigma_deg, result.timeline.attitude_sigma_deg, rtol=1e-9
    )
    # the vectorised timeline conversion is result.misalignment_rpy_and_cov
    np.testing.assert_allclose(
        result.timeline.misalignment_deg[-1], result.misalignment_deg, atol=1e-9
    )
    np.testing.assert_allclose(
        result.timeline.misalignment_sigma_deg[-1], result.misalignment_sigma_deg, rtol=1e-6
    )


@pytest.mark.slow
def test_beams_robust_random_walk_and_flat_earth_options() -> None:
    """Per-beam updates (with the Huber weight and random-walk biases) give the same calibration as the
    3-D velocity on 0-800 s of the noise-free log; the flat Earth model runs."""
    log = cut_log(_log(SEEDS[0], white_noise=False), 800.0, cut_truth=False)
    base = run_ekf(log)
    cfg = EstimatorConfig.paper()
    cfg.dvl.use_beams = True
    cfg.dvl.robust = "huber"
    cfg.imu.bias_model = "random_walk"
    beams = run_ekf(log, cfg)
    print(
        f"\n3-D: k {base.scale:.5f}, mis {np.round(base.misalignment_deg, 3)}; beams: k {beams.scale:.5f}, "
        f"mis {np.round(beams.misalignment_deg, 3)}"
    )
    assert beams.scale == pytest.approx(base.scale, abs=3 * base.scale_sigma)
    gap = dataclasses.replace(
        log,
        dvl=dataclasses.replace(
            log.dvl, valid=log.dvl.valid & ~((log.dvl.t > 640.0) & (log.dvl.t < 700.0))
        ),
    )  # a minute without bottom lock mid-manoeuvre
    dropped = run_ekf(gap)
    print(
        f"60 s DVL gap: k {dropped.scale:.5f} +- {dropped.scale_sigma:.5f}, {len(dropped.t)} updates"
    )
    # 59 pings fewer updates; the states keep their 1 s spacing across the dropout (estimators/inputs/gaps.py)
    assert dropped.info["counters"]["dvl_updates"] == base.info["counters"]["dvl_updates"] - 59
    assert dropped.info["counters"]["states_without_ping"] == 59 and len(dropped.t) == len(base.t)
    assert abs(dropped.scale - base.scale) < 3 * dropped.scale_sigma
    flat_cfg = EstimatorConfig.paper()
    flat_cfg.solver.earth_model = "flat"
    flat_cfg.alignment.initial_attitude_deg = (3.0, 0.0, 10.0)
    flat = run_ekf(log, flat_cfg)
    assert np.isfinite(flat.scale)
