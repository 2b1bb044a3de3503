"""The DVL factor of a ping between keyframes (factors/dvl_keyframe.py): the ping's attitude and velocity
predicted from the keyframe through the preintegrated IMU motion, then the DVL model.

- The predicted ping state equals GTSAM's own ImuFactor prediction (pim.predict with gravity and Earth rate in
  the parameters) from a snapshot taken by estimators/keyframes.py, at a non-zero bias.
- Every Jacobian (pose, velocity, bias, scale, misalignment, time offset, lever arm; 3-D and beam) against
  central differences on the manifold (gtsam.utils.numerical_derivative), and the CustomFactor's
  linearisation equal to the error function's.
- At dt = 0 with no motion the factor is the plain 3-D factor (and the time-offset factor).
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, C, K, L, T, V, X
from gtsam.utils.numerical_derivative import numericalDerivative11
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.estimators.gaps import find_gaps
from gtsam_dvl.estimators.keyframes import ping_snapshots
from gtsam_dvl.estimators.selection import sample_starts
from gtsam_dvl.factors import (
    PingMotion,
    dvl_keyframe_error,
    dvl_velocity_error,
    dvl_velocity_offset_error,
    keyframe_ping_covariance,
    make_dvl_keyframe_factor,
)
from gtsam_dvl.factors.dvl_keyframe import ping_state

W_IE = 7.292115e-5 * np.array([0.0, np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])  # map ENU at 30 deg
N_G0 = np.array([1e-5, -2e-5, -9.79])


def _motion(seed: int, dt: float = 0.6) -> PingMotion:
    rng = np.random.default_rng(seed)
    return PingMotion(dt, Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix(), rng.normal(size=3),
                      rng.normal(size=3),
                      dt * np.eye(3) + 0.01 * rng.normal(size=(3, 3)), -dt * np.eye(3) + 0.01 * rng.normal(size=(3, 3)),
                      0.3 * rng.normal(size=(3, 3)), W_IE, N_G0, rng.normal(size=3) * 100,
                      1.5e-6 * np.diag([-1.0, -1.0, 2.0]) + 1e-7 * rng.normal(size=(3, 3)))


def _state(seed: int) -> dict:
    rng = np.random.default_rng(100 + seed)
    return {"pose": gtsam.Pose3(gtsam.Rot3(Rotation.from_rotvec(rng.normal(size=3)).as_matrix()),
                                rng.normal(size=3) * 200),
            "n_v": rng.normal(size=3) * 2,
            # large biases so that the bias correction's curvature is exercised
            "bias": gtsam.imuBias.ConstantBias(0.05 * rng.normal(size=3), 0.02 * rng.normal(size=3)),
            "k": np.array([1.0 + 0.01 * rng.normal()]),
            "rot": gtsam.Rot3(Rotation.from_rotvec(0.05 * rng.normal(size=3)).as_matrix() @ np.diag([1.0, -1, -1])),
            "dt_d": np.array([rng.uniform(-1.0, 1.0)]), "b_l": rng.normal(size=3),
            "b_omega": 0.1 * rng.normal(size=3), "b_a": 0.2 * rng.normal(size=3) + np.array([0, 0, 9.8]),
            "G": Rotation.from_rotvec(0.02 * rng.normal(size=3)).as_matrix(),
            "d_u": np.array([0.5, -0.5, -np.sqrt(0.5)])}


VARIANTS = ["plain", "lever", "offset", "offset_lever", "beam", "beam_lever"]


def _variables(s: dict, variant: str) -> list:
    out = [s["pose"], s["n_v"], s["bias"], s["k"], s["rot"]]
    if "offset" in variant:
        out.append(s["dt_d"])
    if "lever" in variant:
        out.append(s["b_l"])
    return out


def _error(variant: str, s: dict, m: PingMotion, d_y: np.ndarray | float):
    offset, lever, beam = "offset" in variant, "lever" in variant, "beam" in variant

    def e(*x: object, H: list | None = None) -> np.ndarray:
        pose, n_v, bias, k, rot = x[:5]
        dt_d = x[5] if offset else None
        b_l = x[-1] if lever else s["b_l"]
        return dvl_keyframe_error(pose, n_v, bias, k, rot, d_y, s["b_omega"], b_l, m, dt_d,
                                  (s["b_a"], N_G0, s["G"]) if offset else None, lever,
                                  s["d_u"] if beam else None, H)
    return e


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("seed", range(3))
def test_jacobians_match_numerical_derivatives_and_the_factor(variant: str, seed: int) -> None:
    s, m = _state(seed), _motion(seed)
    beam = "beam" in variant
    d_y: np.ndarray | float = 0.3 if beam else np.array([0.3, -0.2, 0.1])  # a non-zero residual
    e = _error(variant, s, m, d_y)
    x = _variables(s, variant)
    H: list = [None] * len(x)
    e0 = e(*x, H=H)
    for n in range(len(x)):
        Jn = numericalDerivative11(lambda xn, n=n: e(*(x[:n] + [xn] + x[n + 1:])), x[n], delta=1e-6)
        scale = max(1.0, float(np.max(np.abs(Jn))))
        np.testing.assert_allclose(H[n], Jn, rtol=0.0, atol=1e-7 * scale, err_msg=f"{variant}: block {n}")

    keys = [X(0), V(0), B(0), K(0), C(0)] + ([T(0)] if "offset" in variant else []) + (
        [L(0)] if "lever" in variant else [])
    factor = make_dvl_keyframe_factor(
        gtsam.noiseModel.Unit.Create(1 if beam else 3), *keys[:5], d_y, s["b_omega"], s["b_l"], m,
        offset_key=T(0) if "offset" in variant else None,
        offset_input=(s["b_a"], N_G0, s["G"]) if "offset" in variant else None,
        lever_key=L(0) if "lever" in variant else None, d_u=s["d_u"] if beam else None)
    values = gtsam.Values()
    for key, val in zip(keys, x, strict=True):
        if isinstance(val, gtsam.Pose3):
            values.insert(key, val)
        elif isinstance(val, gtsam.Rot3):
            values.insert(key, val)
        elif isinstance(val, gtsam.imuBias.ConstantBias):
            values.insert(key, val)
        else:
            values.insert(key, np.asarray(val, dtype=float))
    np.testing.assert_allclose(factor.unwhitenedError(values), e0, atol=1e-12)
    A, b = factor.linearize(values).jacobian()
    np.testing.assert_allclose(b, -e0, atol=1e-12)
    dims = np.cumsum([6, 3, 6, 1, 3] + ([1] if "offset" in variant else []) + ([3] if "lever" in variant else []))
    for n, J in enumerate(np.split(A, dims[:-1], axis=1)):
        np.testing.assert_allclose(J, H[n], atol=1e-12, err_msg=f"{variant}: factor block {n}")


def test_no_motion_is_the_plain_factor() -> None:
    """dt = 0, identity dR, zero dv: the keyframe factor is the 3-D factor at the keyframe (and the offset one)."""
    s = _state(0)
    z = np.zeros((3, 3))
    m = PingMotion(0.0, np.eye(3), np.zeros(3), np.zeros(3), z, z, z, W_IE, N_G0, np.zeros(3), z)
    d_y = np.array([0.3, -0.2, 0.1])
    e = dvl_keyframe_error(s["pose"], s["n_v"], s["bias"], s["k"], s["rot"], d_y, s["b_omega"], s["b_l"], m)
    e_plain = dvl_velocity_error(s["pose"], s["n_v"], s["k"], s["rot"], d_y, s["b_omega"], s["b_l"])
    np.testing.assert_allclose(e, e_plain, atol=1e-14)
    e = dvl_keyframe_error(s["pose"], s["n_v"], s["bias"], s["k"], s["rot"], d_y, s["b_omega"], s["b_l"], m,
                           s["dt_d"], (s["b_a"], N_G0, s["G"]))
    e_off = dvl_velocity_offset_error(s["pose"], s["n_v"], s["k"], s["rot"], s["dt_d"], d_y, s["b_omega"], s["b_l"],
                                      s["b_a"], N_G0, s["G"])
    np.testing.assert_allclose(e, e_off, atol=1e-14)


def test_ping_state_is_gtsams_prediction() -> None:
    """A turning, accelerating 100 Hz IMU over 0.8 s with pings inside samples: the snapshot at each ping
    (estimators/keyframes.py) through ping_state gives pim.predict's attitude and velocity (gravity and
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
    snaps = ping_snapshots(t_i, pings, params, t, starts, b_f, b_omega, find_gaps(t, 5.0), ImuConfig())
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
        print(f"ping at {t_p} s: attitude {angle:.2e} rad, velocity {np.max(np.abs(n_v_p - ref.velocity())):.2e} m/s "
              "from GTSAM's prediction")
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
    b_f = b_f + 0.5 * 0.01 * np.cross(b_w, b_f)  # each delta-v rotated back to its sample's start, as the graph does
    snap = ping_snapshots(0.0, [1.0], params, t, sample_starts(t), b_f, b_w, find_gaps(t, 5.0), ImuConfig())[0]
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
    snap = ping_snapshots(0.0, [1.0], params, t, sample_starts(t), np.tile([0, 0, 9.8], (100, 1)),
                          np.zeros((100, 3)), find_gaps(t, 5.0), ImuConfig())[0]
    cov = keyframe_ping_covariance(snap.cov, snap.dR, np.eye(3), np.array([2.0, 0.0, 0.0]))
    sigma = np.sqrt(np.diag(cov))
    print(f"preintegration noise in a ping 1 s after its keyframe: {sigma} m/s")
    assert np.all(sigma > 5e-5) and np.all(sigma < 2e-4)
