"""Keyframes that keep every ping's information ([solver] keyframe_spacing_s; estimators/graph/keyframes.py,
factors/ping_motion.py): on a 5 Hz DVL version of paper-3d-short, the batch smoother with 1 s keyframes (a
fifth of the states, the other pings as factors on the keyframe before them through the IMU motion) against a
state per ping:

- the calibration sigmas (scale, misalignment, biases) within 5 % of the state-per-ping solution, and the
  estimates (scale, misalignment, biases, final position) within 0.2 of its sigma;
- both within 3 sigma of the simulated truth;
- every usable ping used (keyframes + pings between them = usable pings).

On the paper's 1 Hz logs 1 s keyframes make a state of every ping: the same epochs as keyframe_spacing_s = 0.

The snapshots' bias Jacobians (from the tangent's linearity in the bias) against the central differences of 12
predictions they replaced (a copy here): within 1e-9 relative, the deltas and covariance bit for bit.
"""

from __future__ import annotations

import time
from functools import cache

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig, ImuConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.graph import keyframes
from gtsam_dvl.estimators.graph.keyframes import (
    ANALYTIC_MAX_ANGLE,
    ping_snapshots,
    snapshot,
    snapshot_params,
)
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.inputs.gaps import ImuPieces, find_gaps, sample_starts_with_gaps
from gtsam_dvl.estimators.inputs.selection import sample_starts
from gtsam_dvl.factors import PingMotion
from tests.support.numerical import numerical_jacobian
from tests.support.scenarios import simulate_variant

SEED = 7


@cache
def run_log(dvl_hz: float) -> LogData:
    """paper-3d-short (120 s static, 60 s legs, the paper's sensors) with the DVL at dvl_hz."""
    return simulate_variant(SEED, rates={"dvl_hz": dvl_hz})


def config(spacing_s: float) -> EstimatorConfig:
    cfg = EstimatorConfig.paper()
    return cfg.model_copy(
        update={"solver": cfg.solver.model_copy(update={"keyframe_spacing_s": spacing_s})}
    )


@cache
def solve(spacing_s: float) -> tuple[NavResult, float]:
    t0 = time.perf_counter()
    r = smooth_batch(run_log(5.0), config(spacing_s))
    return r, time.perf_counter() - t0


def estimates(r: NavResult) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(values, sigmas, names): scale, misalignment (deg), accelerometer bias (micro-g), gyro bias (deg/h), final
    position (m, map axes)."""
    n_R_b = r.n_R_b[-1]
    # translation tangent in body axes
    pos_sigma = np.sqrt(np.diag(n_R_b @ r.pose_cov[-1][3:, 3:] @ n_R_b.T))
    values = np.concatenate(
        [[r.scale], r.misalignment_deg, r.accel_bias / UG, r.gyro_bias / DEG_PER_H, r.n_p[-1]]
    )
    sigmas = np.concatenate(
        [
            [r.scale_sigma],
            r.misalignment_sigma_deg,
            r.accel_bias_sigma_ug,
            r.gyro_bias_sigma_deg_per_h,
            pos_sigma,
        ]
    )
    names = (
        ["scale", "mis_roll", "mis_pitch", "mis_yaw"]
        + [f"b_a_{a}" for a in "xyz"]
        + [f"b_g_{a}" for a in "xyz"]
        + [f"p_{a}" for a in "xyz"]
    )
    return values, sigmas, names


def truth(log: LogData, r: NavResult) -> np.ndarray:
    tc, tb, tr = log.true_calibration, log.true_imu_bias, log.truth
    assert tc is not None and tb is not None and tr is not None
    j = int(np.argmin(np.abs(tr.t - r.t[-1])))
    return np.concatenate(
        [
            [tc.scale],
            tc.misalignment_deg,
            np.array(tb.accel_m_s2) / UG,
            np.array(tb.gyro_rad_s) / DEG_PER_H,
            tr.n_p[j],
        ]
    )


@pytest.mark.slow
def test_one_second_keyframes_match_a_state_per_ping_on_a_5_hz_dvl() -> None:
    log = run_log(5.0)
    (per_ping, wall_ping), (keyed, wall_key) = solve(0.0), solve(1.0)
    c = keyed.info["counters"]
    usable = per_ping.info["counters"]["keyframes"]
    print(
        f"\n5 Hz DVL, {len(log.dvl)} pings: state per ping {len(per_ping.t)} states in {wall_ping:.1f} s; "
        f"1 s keyframes {len(keyed.t)} states ({c['keyframes']} keyframes + {c['states_without_ping']} without "
        f"ping, {c['pings_between_keyframes']} pings between) in {wall_key:.1f} s "
        "(wall times on a shared machine)"
    )
    assert c["keyframes"] + c["pings_between_keyframes"] == usable  # every usable ping is used
    assert len(keyed.t) < 0.25 * len(per_ping.t)
    assert np.all(np.diff(keyed.t)[:-1] > 0.9)  # the last usable ping is a keyframe too
    v0, s0, names = estimates(per_ping)
    v1, s1, _ = estimates(keyed)
    true = truth(log, per_ping)
    sigma_ratio = s1 / s0 - 1.0
    shift = (v1 - v0) / s0
    for k, name in enumerate(names):
        print(
            f"  {name:10s} per ping {v0[k]:+.6g} +- {s0[k]:.3g}, keyframes {v1[k]:+.6g} +- {s1[k]:.3g}: "
            f"sigma {100 * sigma_ratio[k]:+.3f} %, shift {shift[k]:+.4f} sigma; truth {true[k]:+.6g} "
            f"({(v0[k] - true[k]) / s0[k]:+.2f} / {(v1[k] - true[k]) / s1[k]:+.2f} sigma)"
        )
    calibration = slice(0, 10)  # scale, misalignment, biases
    assert np.all(np.abs(sigma_ratio[calibration]) < 0.05)
    assert np.all(np.abs(shift) < 0.2)
    assert np.all(np.abs(v0 - true) < 3 * s0)
    assert np.all(np.abs(v1 - true) < 3 * s1)


@pytest.mark.slow
def test_health_checks_every_ping_with_keyframes() -> None:
    """The health's DVL residuals take every usable ping, those between keyframes too (interpolated between
    states), and stay near 1 (whitened) as with a state per ping."""
    from gtsam_dvl.analysis.health import dvl_residuals

    log = run_log(5.0)
    per_ping, keyed = solve(0.0)[0], solve(1.0)[0]
    r0 = dvl_residuals(per_ping, log, config(0.0).dvl)
    r1 = dvl_residuals(keyed, log, config(1.0).dvl)
    n0, n1 = int((r0.dof > 0).sum()), int((r1.dof > 0).sum())
    print(
        f"\nhealth residuals: per ping {n0} pings, rms {r0.rms():.3f}; keyframes {n1} pings, rms {r1.rms():.3f}"
    )
    assert n1 == n0 == per_ping.info["counters"]["keyframes"]
    assert abs(r1.rms() - r0.rms()) < 0.02 * r0.rms()
    assert 0.8 < r0.rms() < 1.2


def test_one_hz_log_with_one_second_keyframes_has_a_state_per_ping() -> None:
    log = run_log(1.0)
    g0, g1 = LogGraph(log, config(0.0)), LogGraph(log, config(1.0))
    assert [e.t for e in g0.epochs] == [e.t for e in g1.epochs]
    assert [e.dvl_index for e in g0.epochs] == [e.dvl_index for e in g1.epochs]
    assert g1.counters["pings_between_keyframes"] == 0 and not any(e.between for e in g1.epochs)


def test_spacing_beyond_the_state_spacing_is_refused() -> None:
    cfg = config(2.0)
    with pytest.raises(GtsamDvlError, match="keyframe_spacing_s"):
        LogGraph(run_log(1.0), cfg)


# ----- snapshots (estimators/graph/keyframes.py) ----------------------------------------------------------------


def reference_snapshot(
    pim: gtsam.PreintegratedImuMeasurements,
    extra_cov: np.ndarray | None = None,
    n_omega: np.ndarray | None = None,
) -> PingMotion:
    """keyframes.snapshot before the tangent's Jacobians: central differences of pim.predict over the bias
    [accelerometer, gyroscope] (steps 1e-2 m/s^2 and 1e-4 rad/s), 12 predictions; for parameters without Earth
    rate."""
    assert n_omega is None or not np.any(n_omega)
    state0 = gtsam.NavState()
    dR = pim.deltaRij()
    dv = np.asarray(pim.deltaVij(), dtype=float)

    def rotation_and_velocity(bias: gtsam.imuBias.ConstantBias) -> np.ndarray:
        s = pim.predict(state0, bias)
        return np.concatenate(
            [gtsam.Rot3.Logmap(dR.between(s.attitude())), np.asarray(s.velocity(), dtype=float)]
        )

    J = numerical_jacobian(
        rotation_and_velocity, [gtsam.imuBias.ConstantBias()], 0, delta=[1e-2] * 3 + [1e-4] * 3
    )
    dR_dbg, dv_dba, dv_dbg = J[:3, 3:], J[3:, :3], J[3:, 3:]
    cov = np.asarray(pim.preintMeasCov(), dtype=float)
    if extra_cov is not None:
        cov = cov + extra_cov
    dt = float(pim.deltaTij())
    return PingMotion(
        dt, dR.matrix(), dv, np.asarray(pim.deltaPij(), dtype=float), dR_dbg, dv_dba, dv_dbg, cov
    )


def _params() -> gtsam.PreintegrationParams:
    """The paper's IMU noise (0.1 deg/h/sqrt(Hz), 10 micro-g/sqrt(Hz)), as the graph's snapshot parameters."""
    params = gtsam.PreintegrationParams(np.array([0.0, 0.0, -9.8]))
    params.setGyroscopeCovariance(np.eye(3) * (0.1 * np.pi / 180 / 60) ** 2)
    params.setAccelerometerCovariance(np.eye(3) * (10e-6 * 9.80665) ** 2)
    params.setIntegrationCovariance(np.eye(3) * 1e-10)
    return snapshot_params(params)


def _rotating_params(n_omega_ie: np.ndarray) -> gtsam.PreintegrationParams:
    """_params()'s noise with gravity (9.79 m/s^2 down) and the Earth rate n_omega_ie (rad/s, map axes): the
    parameters of an IMU factor, whose snapshots must not depend on either."""
    params = gtsam.PreintegrationParams(np.array([0.0, 0.0, -9.79]))
    noise = _params()
    params.setGyroscopeCovariance(noise.getGyroscopeCovariance())
    params.setAccelerometerCovariance(noise.getAccelerometerCovariance())
    params.setIntegrationCovariance(noise.getIntegrationCovariance())
    params.setOmegaCoriolis(n_omega_ie)
    return params


def _assert_same(new: PingMotion, ref: PingMotion, worst: dict[str, float]) -> None:
    for name in ("dt", "dR", "dv", "dp", "cov"):
        assert np.array_equal(getattr(new, name), getattr(ref, name)), name
    for name in ("dR_dbg", "dv_dba", "dv_dbg"):
        a, b = getattr(new, name), getattr(ref, name)
        # dv_dbg is 0 after one sample
        rel = float(np.linalg.norm(a - b) / max(float(np.linalg.norm(b)), 1e-300))
        worst[name] = max(worst.get(name, 0.0), rel)
        assert rel < 1e-9, f"{name}: {rel:.2e} relative at dt {ref.dt:.4f} s"


def test_snapshot_jacobians_match_the_central_differences() -> None:
    """Random turning, accelerating IMU traces at 50-400 Hz over 1.5 s (turn rates up to about 2 rad/s, some to
    8 rad/s, so |theta| beyond ANALYTIC_MAX_ANGLE too), one near-identity (1e-7 rad/s): the snapshot after every
    few samples matches the reference."""
    rng = np.random.default_rng(11)
    worst: dict[str, float] = {}
    angles = []
    for trial in range(24):
        pim = gtsam.PreintegratedImuMeasurements(_params(), gtsam.imuBias.ConstantBias())
        hz = float(rng.choice([50.0, 100.0, 200.0, 400.0]))
        # about z up to 4.5 rad/s in every third trial: |theta| beyond a whole turn's ANALYTIC_MAX_ANGLE
        rate = (
            np.full(3, 1e-7)
            if trial == 0
            else rng.normal(0.0, [0.3, 0.3, 4.5 if trial % 3 == 0 else 1.2])
        )
        rate_noise = 0.0 if trial == 0 else 0.05
        b_f = np.array([0.3, -0.2, 9.8]) + rng.normal(0.0, 0.5, 3)
        for i in range(int(1.5 * hz)):
            pim.integrateMeasurement(
                b_f + rng.normal(0.0, 0.2, 3), rate + rng.normal(0.0, rate_noise, 3), 1.0 / hz
            )
            if i % 9 == 0:
                _assert_same(snapshot(pim), reference_snapshot(pim), worst)
                angles.append(float(np.linalg.norm(np.asarray(pim.preintegrated())[:3])))
    print(
        f"{len(angles)} snapshots, |theta| {min(angles):.1e} to {max(angles):.2f} rad; worst relative "
        f"difference {worst}"
    )
    assert min(angles) < 1e-6 and max(angles) > ANALYTIC_MAX_ANGLE


@pytest.mark.parametrize("gap", [False, True])
def test_interval_pieces_found_once_are_the_cut_by_cut_ones(gap: bool) -> None:
    """interval_with_snapshots (the interval's pieces found once, cut at the pings) against interval_cut_by_cut
    (each cut's pieces on their own, as the online estimator integrates): the same preintegration and snapshots
    to the last bit, with pings inside samples, exactly at a stamp and before the interval's first stamp; with an
    IMU gap the two are one code path."""
    rng = np.random.default_rng(9)
    t = 0.0013 + np.arange(1, 401) * 0.005
    if gap:
        t = t[(t <= 0.8) | (t > 1.1)]
    b_omega = np.array([0.05, -0.1, 0.8]) + 0.02 * rng.normal(size=(len(t), 3))
    b_f = np.array([0.5, 0.1, 9.8]) + 0.2 * rng.normal(size=(len(t), 3))
    gaps = find_gaps(t, 5.0)
    assert len(gaps) == gap
    starts = sample_starts_with_gaps(t, gaps)
    t_state, t_end = 0.0115, 1.7
    pings = [
        0.0131,
        0.3,
        float(t[100]),
        0.7777,
        1.05,
        1.3,
        1.69,
    ]  # (0.0131: before the first stamp after t_state)
    params = _rotating_params(np.array([0.0, 6.3e-5, 3.6e-5]))
    args = (t_state, t_end, pings, params, ImuPieces(t, starts, b_f, b_omega, gaps), ImuConfig())
    pim_a, held_a, snaps_a = keyframes.interval_with_snapshots(*args)
    pim_b, held_b, snaps_b = keyframes.interval_cut_by_cut(*args)
    assert held_a == held_b and bool(held_a) == gap
    for name in ("deltaVij", "deltaPij", "preintMeasCov", "deltaTij", "preintegrated"):
        assert np.array_equal(getattr(pim_a, name)(), getattr(pim_b, name)()), name
    for sa, sb in zip(snaps_a, snaps_b, strict=True):
        for name in ("dt", "dR", "dv", "dp", "dR_dbg", "dv_dba", "dv_dbg", "cov"):
            assert np.array_equal(getattr(sa, name), getattr(sb, name)), name
    assert snaps_a[0].dt == pytest.approx(
        pings[0] - t_state, abs=1e-12
    ) and pim_a.deltaTij() == pytest.approx(t_end - t_state, abs=1e-12)


def test_snapshot_does_not_depend_on_the_parameters_earth_rate_or_gravity() -> None:
    """The same samples preintegrated with the IMU factor's parameters (gravity, Earth rate: the snapshots are taken
    from its preintegration) and with neither: the same snapshot (the increments and their bias Jacobians are the
    preintegration's own; snapshot undoes the rotating-frame prediction it evaluates through)."""
    rng = np.random.default_rng(8)
    # 50 times the Earth's rate, so that a wrong term would show
    w_ie = np.array([0.0, 6.3e-5, 3.6e-5]) * 50
    earth = _rotating_params(w_ie)
    a = gtsam.PreintegratedImuMeasurements(earth, gtsam.imuBias.ConstantBias())
    b = gtsam.PreintegratedImuMeasurements(_params(), gtsam.imuBias.ConstantBias())
    for _ in range(180):
        f, w = (
            np.array([0.4, 0.1, 9.8]) + rng.normal(0.0, 0.3, 3),
            np.array([0.1, -0.2, 0.6]) + rng.normal(0, 0.05, 3),
        )
        a.integrateMeasurement(f, w, 0.005)
        b.integrateMeasurement(f, w, 0.005)
    sa, sb = snapshot(a, None, w_ie), snapshot(b)
    for name in ("dt", "dR", "dv", "dp", "cov", "dR_dbg", "dv_dba", "dv_dbg"):
        x, y = getattr(sa, name), getattr(sb, name)
        assert np.abs(x - y).max() <= 1e-10 * max(np.abs(y).max(), 1e-300), name


def test_snapshot_velocity_is_affine_in_the_bias() -> None:
    """What the tangent's Jacobians rest on: GTSAM's predicted velocity is the snapshot's dv + dv_dba b_a +
    dv_dbg b_g at any bias (to rounding), and its attitude dR Exp(dR_dbg b_g) to second order in b_g."""
    rng = np.random.default_rng(2)
    pim = gtsam.PreintegratedImuMeasurements(_params(), gtsam.imuBias.ConstantBias())
    for _ in range(100):
        pim.integrateMeasurement(
            np.array([0.4, 0.1, 9.8]) + rng.normal(0.0, 0.3, 3),
            np.array([0.1, -0.2, 0.6]) + rng.normal(0.0, 0.05, 3),
            0.01,
        )
    s = snapshot(pim)
    for b_a, b_g in (
        (np.array([3e-3, -2e-3, 1e-3]), np.array([1e-4, 2e-4, -3e-4])),
        (np.array([0.5, 0.2, -0.3]), np.array([0.02, -0.01, 0.03])),
    ):
        pred = pim.predict(gtsam.NavState(), gtsam.imuBias.ConstantBias(b_a, b_g))
        np.testing.assert_allclose(
            pred.velocity(), s.dv + s.dv_dba @ b_a + s.dv_dbg @ b_g, rtol=0, atol=1e-12
        )
        first_order = gtsam.Rot3(s.dR) * gtsam.Rot3.Expmap(s.dR_dbg @ b_g)
        angle = float(np.linalg.norm(gtsam.Rot3.Logmap(pred.attitude().between(first_order))))
        assert angle < float(np.linalg.norm(b_g)) ** 2


def test_ping_snapshots_across_a_gap_match_the_reference(monkeypatch: pytest.MonkeyPatch) -> None:
    """ping_snapshots over a 200 Hz trace with a held IMU gap (its motion-model covariance added): the same
    snapshots with the reference."""
    rng = np.random.default_rng(4)
    t = np.arange(1, 401) * 0.005
    t = t[(t <= 0.8) | (t > 1.1)]  # 0.3 s without samples
    b_omega = np.array([0.05, -0.1, 0.8]) + 0.02 * rng.normal(size=(len(t), 3))
    b_f = np.array([0.5, 0.1, 9.8]) + 0.2 * rng.normal(size=(len(t), 3))
    gaps = find_gaps(t, 5.0)
    assert len(gaps) == 1
    pings = [0.3, 0.7, 1.05, 1.3, 1.9]
    args = (
        0.002,
        pings,
        _params(),
        ImuPieces(t, sample_starts(t), b_f, b_omega, gaps),
        ImuConfig(),
    )
    new = ping_snapshots(*args)
    monkeypatch.setattr(keyframes, "snapshot", reference_snapshot)
    ref = ping_snapshots(*args)
    worst: dict[str, float] = {}
    for a, b in zip(new, ref, strict=True):
        _assert_same(a, b, worst)
    assert not np.array_equal(new[2].cov, new[1].cov + 0.0)  # the hold's covariance is in
    print(f"worst relative difference {worst}")
