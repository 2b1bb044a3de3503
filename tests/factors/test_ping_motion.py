"""The IMU motion from a keyframe to a ping (factors/ping_motion.py): the ping's attitude and velocity predicted
through it equal GTSAM's own ImuFactor prediction (pim.predict with gravity and Earth rate in the parameters) from
a snapshot taken by estimators/graph/keyframes.py, at a non-zero bias; a static vehicle stays still under Earth rate;
the
preintegration's noise mapped into the ping; ping_state's Jacobians against numerical derivatives; one record for
one ping or N (indexing, put, broadcasting), checked on request."""

from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.estimators.graph.keyframes import ping_snapshots
from gtsam_dvl.estimators.inputs.gaps import ImuPieces, find_gaps
from gtsam_dvl.estimators.inputs.selection import sample_starts
from gtsam_dvl.factors import PingMotion, keyframe_ping_covariance, ping_state
from tests.support.numerical import numerical_jacobians

# map ENU at 30 deg
W_IE = 7.292115e-5 * np.array([0.0, np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])
N_G0 = np.array([1e-5, -2e-5, -9.79])


def test_ping_state_is_gtsams_prediction() -> None:
    """A turning, accelerating 100 Hz IMU over 0.8 s with pings inside samples: the snapshot at each ping
    (estimators/graph/keyframes.py) through ping_state gives pim.predict's attitude and velocity (gravity and
    Earth rate in GTSAM's parameters, no second-order Coriolis), at a non-zero bias."""
    rng = np.random.default_rng(7)
    t = np.arange(1, 101) * 0.01
    b_omega = np.array([0.02, -0.05, 0.3]) + 0.01 * rng.normal(size=(100, 3))
    b_f = np.array([0.5, 0.1, 9.8]) + 0.2 * rng.normal(size=(100, 3))
    starts = sample_starts(t)
    params = gtsam.PreintegrationParams(N_G0)
    params.setGyroscopeCovariance(np.eye(3) * 1e-12)
    params.setAccelerometerCovariance(np.eye(3) * 1e-8)
    params.setIntegrationCovariance(np.eye(3) * 1e-10)
    params.setOmegaCoriolis(W_IE)
    t_i, pings = 0.005, [0.3, 0.555, 0.8]
    imu = ImuPieces(t, starts, b_f, b_omega, find_gaps(t, 5.0))
    snaps = ping_snapshots(t_i, pings, params, imu, ImuConfig())
    bias = gtsam.imuBias.ConstantBias(np.array([3e-3, -2e-3, 1e-3]), np.array([1e-4, 2e-4, -3e-4]))
    n_R_i = Rotation.from_rotvec([0.1, -0.2, 1.0]).as_matrix()
    n_p_i, n_v_i = np.array([10.0, 20.0, -5.0]), np.array([1.5, -0.5, 0.1])
    for t_p, snap in zip(pings, snaps, strict=True):
        # the reference integrates (t_i, t_p] in one go, as the snapshot does (the interval's preintegration cut
        # at sample stamps, then the sample straddling the ping up to it)
        pim = gtsam.PreintegratedImuMeasurements(params, gtsam.imuBias.ConstantBias())
        for i in range(100):
            dt = min(t[i], t_p) - max(starts[i], t_i)
            if dt > 0:
                pim.integrateMeasurement(b_f[i], b_omega[i], dt)
        assert snap.dt == pytest.approx(t_p - t_i, abs=1e-12)
        ref = pim.predict(gtsam.NavState(gtsam.Rot3(n_R_i), n_p_i, n_v_i), bias)
        m = snap.motion(W_IE, N_G0, n_p_i, np.zeros((3, 3)))
        n_R_p, n_v_p, _ = ping_state(n_R_i, n_p_i, n_v_i, bias.accelerometer(), bias.gyroscope(), m)
        angle = np.linalg.norm(gtsam.Rot3.Logmap(ref.attitude().between(gtsam.Rot3(n_R_p))))
        print(
            f"ping at {t_p} s: attitude {angle:.2e} rad, velocity {np.max(np.abs(n_v_p - ref.velocity())):.2e} m/s "
            "from GTSAM's prediction"
        )
        assert angle < 1e-9
        np.testing.assert_allclose(n_v_p, ref.velocity(), atol=1e-6)


def test_a_static_vehicle_stays_still_under_earth_rate() -> None:
    """A vehicle at rest in the rotating map frame: its gyros read the Earth rate, its accelerometers hold
    gravity. The predicted ping state after 1 s keeps the attitude and zero velocity (the Earth-turn term of the
    specific force is needed: without it the velocity is off by w x g / 2 = 3.6e-4 m/s)."""
    t = np.arange(1, 101) * 0.01
    n_R_b = Rotation.from_rotvec([0.05, -0.02, 0.7]).as_matrix()
    params = gtsam.PreintegrationParams(N_G0)
    b_w, b_f = np.tile(n_R_b.T @ W_IE, (100, 1)), np.tile(n_R_b.T @ -N_G0, (100, 1))
    # each delta-v rotated back to its sample's start, as the graph does
    b_f = b_f + 0.5 * 0.01 * np.cross(b_w, b_f)
    imu = ImuPieces(t, sample_starts(t), b_f, b_w, find_gaps(t, 5.0))
    snap = ping_snapshots(0.0, [1.0], params, imu, ImuConfig())[0]
    m = snap.motion(W_IE, N_G0, np.zeros(3), np.zeros((3, 3)))
    n_R_p, n_v_p, _ = ping_state(n_R_b, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), m)
    angle = np.linalg.norm(Rotation.from_matrix(n_R_b.T @ n_R_p).as_rotvec())
    print(f"static 1 s: attitude {angle:.1e} rad, velocity {np.linalg.norm(n_v_p):.1e} m/s")
    assert angle < 1e-10
    assert np.linalg.norm(n_v_p) < 1e-7  # second order in the Earth rate


def test_preintegration_noise_in_the_ping_is_small_at_navigation_grade() -> None:
    """The paper's IMU (10 micro-g/sqrt(Hz), 0.1 deg/h/sqrt(Hz)) over 1 s at 2 m/s: about 1e-4 m/s, against the
    DVL's 2 cm/s."""
    t = np.arange(1, 101) * 0.01
    params = gtsam.PreintegrationParams(N_G0)
    params.setGyroscopeCovariance(np.eye(3) * (0.1 * np.pi / 180 / 60) ** 2)
    params.setAccelerometerCovariance(np.eye(3) * (10e-6 * 9.80665) ** 2)
    params.setIntegrationCovariance(np.eye(3) * 1e-10)
    level = ImuPieces(
        t, sample_starts(t), np.tile([0, 0, 9.8], (100, 1)), np.zeros((100, 3)), find_gaps(t, 5.0)
    )
    snap = ping_snapshots(0.0, [1.0], params, level, ImuConfig())[0]
    cov = keyframe_ping_covariance(snap.cov, snap.dR, np.eye(3), np.array([2.0, 0.0, 0.0]))
    sigma = np.sqrt(np.diag(cov))
    print(f"preintegration noise in a ping 1 s after its keyframe: {sigma} m/s")
    assert np.all(sigma > 5e-5) and np.all(sigma < 2e-4)


@pytest.mark.parametrize("seed", range(3))
def test_ping_state_jacobians_match_numerical_derivatives(
    seed: int, random_motion: Callable[..., PingMotion]
) -> None:
    """A_R_* (the ping attitude's right tangent) and A_v_* per the pose's right tangent, the velocity and the bias."""
    m = random_motion(seed)
    rng = np.random.default_rng(50 + seed)
    pose = gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(size=3)), rng.normal(size=3) * 200)
    n_v = rng.normal(size=3) * 2
    bias = gtsam.imuBias.ConstantBias(0.05 * rng.normal(size=3), 0.02 * rng.normal(size=3))
    n_R_p, _, A = ping_state(
        pose.rotation().matrix(), pose.translation(), n_v, bias.accelerometer(), bias.gyroscope(), m
    )
    assert A is not None
    A_R_pose, A_R_bias, A_v_pose, A_v_vel, A_v_bias = A

    def attitude(p: gtsam.Pose3, v: np.ndarray, b: gtsam.imuBias.ConstantBias) -> np.ndarray:
        R = ping_state(
            p.rotation().matrix(), p.translation(), v, b.accelerometer(), b.gyroscope(), m, False
        )[0]
        return gtsam.Rot3.Logmap(gtsam.Rot3(n_R_p).between(gtsam.Rot3(R)))

    def velocity(p: gtsam.Pose3, v: np.ndarray, b: gtsam.imuBias.ConstantBias) -> np.ndarray:
        return ping_state(
            p.rotation().matrix(), p.translation(), v, b.accelerometer(), b.gyroscope(), m, False
        )[1]

    num_R = numerical_jacobians(attitude, [pose, n_v, bias])
    num_v = numerical_jacobians(velocity, [pose, n_v, bias])
    for got, want in zip(
        (A_R_pose, np.zeros((3, 3)), A_R_bias, A_v_pose, A_v_vel, A_v_bias),
        num_R + num_v,
        strict=True,
    ):
        np.testing.assert_allclose(
            got, want, rtol=0.0, atol=1e-7 * max(1.0, float(np.abs(want).max()))
        )


def test_one_record_for_one_ping_or_n(random_motion: Callable[..., PingMotion]) -> None:
    """N pings' arrays filled with put, read back with get and indexing; ping_state over the N at once equals it
    ping by ping; none() is the motion of length zero; checked() names a bad field."""
    ms = [random_motion(seed) for seed in range(4)]
    arrays = PingMotion.empty(4)
    for q, m in enumerate(ms):
        arrays.put(q, m)
    arrays = arrays.motion(
        W_IE,
        np.array([m.n_g0 for m in ms]),
        np.array([m.n_p0 for m in ms]),
        np.array([m.n_G for m in ms]),
    )
    assert len(arrays) == 4 and arrays.get(2).dt == ms[2].dt
    np.testing.assert_array_equal(arrays[1:3].dv, np.array([ms[1].dv, ms[2].dv]))
    rng = np.random.default_rng(9)
    n_R = Rotation.random(4, random_state=rng).as_matrix()
    n_p, n_v, b_a, b_g = (rng.normal(size=(4, 3)) for _ in range(4))
    R_all, v_all, A_all = ping_state(n_R, n_p, n_v, b_a, b_g, arrays)
    assert A_all is not None
    for q, m in enumerate(ms):
        R, v, A = ping_state(n_R[q], n_p[q], n_v[q], b_a[q], b_g[q], m)
        assert A is not None
        np.testing.assert_allclose(R_all[q], R, atol=1e-14)
        np.testing.assert_allclose(v_all[q], v, atol=1e-12)
        for got, want in zip(A_all, A, strict=True):
            np.testing.assert_allclose(got[q], want, atol=1e-12)
    still = PingMotion.none().motion(W_IE, N_G0, np.zeros(3), np.zeros((3, 3)))
    R, v, _ = ping_state(n_R[0], n_p[0], n_v[0], b_a[0], b_g[0], still)
    np.testing.assert_allclose(R, n_R[0], atol=1e-15)
    np.testing.assert_allclose(v, n_v[0], atol=1e-15)
    bad = random_motion(0)
    bad.dv = np.array([np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="dv"):
        bad.checked()
