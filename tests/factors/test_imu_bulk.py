"""factors/imu_bulk.py: N IMU factors at once against GTSAM's own ImuFactor (errors and Jacobians to 1e-9), against
numerical derivatives on the manifold, and its pieces against GTSAM's (SE_2(3) Logmap, SO(3) Logmap near 0 and pi,
the bias Jacobian it recovers from a GTSAM factor against independent probes of the preintegration).

Cases: random preintegrations of 0.1-1.5 s (a few turning by more than pi), with and without Earth rate (the
rotating-frame and the inertial prediction), states far from the prediction (rotation errors of 0.3 rad, metres)
and near it (rotation errors of 1e-7 rad: the small-angle branches)."""

from __future__ import annotations

from functools import cache

import gtsam
import numpy as np
import pytest

from gtsam_dvl.factors.imu_bulk import ImuArrays, bias_jacobians, imu_errors, se23_log_n
from gtsam_dvl.factors.so3 import log
from tests.support.numerical import numerical_jacobians

W_IE = np.array([0.0, 6.3e-5, 3.6e-5])  # Earth rate in an ENU map at 30 deg latitude, rad/s
N_G = np.array([0.0, 0.0, -9.79])
N = 16


@cache
def factors(earth: bool) -> tuple[list[gtsam.ImuFactor], list[gtsam.PreintegrationParams]]:
    """N ImuFactors on keys 1..5 with random preintegrations (the last three turn by 3.3 to 5 rad: theta beyond
    pi)."""
    rng = np.random.default_rng(3 + earth)
    out, params = [], []
    for n in range(N):
        p = gtsam.PreintegrationParams(N_G)
        p.setGyroscopeCovariance(np.eye(3) * 1e-8)
        p.setAccelerometerCovariance(np.eye(3) * 1e-6)
        p.setIntegrationCovariance(np.eye(3) * 1e-9)
        if earth:
            p.setOmegaCoriolis(W_IE)
        pim = gtsam.PreintegratedImuMeasurements(p, gtsam.imuBias.ConstantBias())
        steps = int(rng.integers(20, 300))
        rate = rng.normal(0, 0.3, 3)
        # a turn of 3.3 to 5 rad over the interval: beyond pi (a Logmap would wrap), short of 2 pi
        if n >= N - 3:
            rate *= rng.uniform(3.3, 5.0) / (np.linalg.norm(rate) * steps * 0.005)
        for _ in range(steps):
            pim.integrateMeasurement(
                np.array([0.3, 0.1, 9.8]) + 0.3 * rng.standard_normal(3),
                rate + 0.05 * rng.standard_normal(3),
                0.005,
            )
        out.append(gtsam.ImuFactor(1, 2, 3, 4, 5, pim))
        params.append(p)
    return out, params


def states(rng: np.random.Generator, near: bool) -> dict[str, np.ndarray]:
    """Random states i, biases, and states j: far from the prediction, or (near) within 1e-7 rad of it."""
    s = {
        "R_i": np.array([gtsam.Rot3.Expmap(rng.normal(0, 1.0, 3)).matrix() for _ in range(N)]),
        "p_i": rng.normal(0, 1000, (N, 3)),
        "v_i": rng.normal(0, 2, (N, 3)),
        "b": np.concatenate([rng.normal(0, 1e-2, (N, 3)), rng.normal(0, 1e-3, (N, 3))], axis=1),
    }
    rot_sigma, pos_sigma = (1e-7, 1e-6) if near else (0.3, 3.0)
    s["R_j"] = np.array(
        [R @ gtsam.Rot3.Expmap(rng.normal(0, rot_sigma, 3)).matrix() for R in s["R_i"]]
    )
    s["p_j"] = s["p_i"] + rng.normal(0, pos_sigma, (N, 3))
    s["v_j"] = s["v_i"] + rng.normal(0, pos_sigma, (N, 3))
    return s


def arrays(earth: bool) -> ImuArrays:
    fs, _ = factors(earth)
    w = W_IE if earth else np.zeros(3)
    x, H, dt = bias_jacobians([f.preintegratedMeasurements() for f in fs], w)
    return ImuArrays(x, H, dt, w, np.zeros((N, 6, 3)))


def gtsam_eval(
    f: gtsam.ImuFactor, s: dict[str, np.ndarray], n: int
) -> tuple[np.ndarray, list[np.ndarray]]:
    Hs = [np.zeros((9, d), order="F") for d in (6, 3, 6, 3, 6)]
    e = f.evaluateError(
        gtsam.Pose3(gtsam.Rot3(s["R_i"][n]), s["p_i"][n]),
        s["v_i"][n],
        gtsam.Pose3(gtsam.Rot3(s["R_j"][n]), s["p_j"][n]),
        s["v_j"][n],
        gtsam.imuBias.ConstantBias(s["b"][n, :3], s["b"][n, 3:]),
        *Hs,
    )
    return np.asarray(e), Hs


@pytest.mark.parametrize("earth", [True, False])
@pytest.mark.parametrize("near", [False, True])
def test_errors_and_jacobians_are_gtsams(earth: bool, near: bool) -> None:
    """At the same states with their own prediction's state j: the error of each factor matches GTSAM's to 1e-9 of
    its largest component (near the prediction to 1e-11 absolutely: there the error is a difference of positions of
    kilometres, whose rounding is 1e-13), each Jacobian block to 1e-9."""
    s = states(np.random.default_rng(10 + 2 * earth + near), near)
    a = arrays(earth)
    if near:  # state j: GTSAM's prediction moved by the small perturbation above
        pred = [
            factors(earth)[0][n]
            .preintegratedMeasurements()
            .predict(
                gtsam.NavState(gtsam.Rot3(s["R_i"][n]), s["p_i"][n], s["v_i"][n]),
                gtsam.imuBias.ConstantBias(s["b"][n, :3], s["b"][n, 3:]),
            )
            for n in range(N)
        ]
        s["R_j"] = np.array(
            [p.attitude().matrix() @ (s["R_i"][n].T @ s["R_j"][n]) for n, p in enumerate(pred)]
        )
        s["p_j"] = np.array([p.position() for p in pred]) + (s["p_j"] - s["p_i"])
        s["v_j"] = np.array([p.velocity() for p in pred]) + (s["v_j"] - s["v_i"])
    e, J = imu_errors(
        a,
        s["R_i"],
        s["p_i"],
        s["v_i"],
        s["R_j"],
        s["p_j"],
        s["v_j"],
        s["b"],
        np.tile(N_G, (N, 1)),
        None,
        True,
    )
    assert J is not None
    for n, f in enumerate(factors(earth)[0]):
        e_ref, H_ref = gtsam_eval(f, s, n)
        assert np.abs(e[n] - e_ref).max() <= 1e-9 * np.abs(e_ref).max() + 1e-11
        for mine, ref in zip((J.pose_i, J.vel_i, J.pose_j, J.vel_j, J.bias), H_ref, strict=True):
            assert np.abs(mine[n] - ref).max() <= 1e-9 * np.abs(ref).max()


@pytest.mark.parametrize("near", [False, True])
def test_jacobians_against_numerical_derivatives(near: bool) -> None:
    """Each Jacobian against central differences of the model itself (tests/support/numerical.py: poses on the right,
    [rotation, translation]), to 1e-5 of the block's largest entry (the difference's truncation and rounding
    error)."""
    s = states(np.random.default_rng(20 + near), near)
    a = arrays(True)
    g = np.tile(N_G, (N, 1))
    _, J = imu_errors(
        a, s["R_i"], s["p_i"], s["v_i"], s["R_j"], s["p_j"], s["v_j"], s["b"], g, None, True
    )
    assert J is not None
    for n in range(0, N, 5):

        def err(
            pose_i: gtsam.Pose3,
            v_i: np.ndarray,
            pose_j: gtsam.Pose3,
            v_j: np.ndarray,
            b: np.ndarray,
            n: int = n,
        ) -> np.ndarray:
            st = {k: v.copy() for k, v in s.items()}
            st["R_i"][n], st["p_i"][n], st["v_i"][n] = (
                pose_i.rotation().matrix(),
                pose_i.translation(),
                v_i,
            )
            st["R_j"][n], st["p_j"][n], st["v_j"][n], st["b"][n] = (
                pose_j.rotation().matrix(),
                pose_j.translation(),
                v_j,
                b,
            )
            return imu_errors(
                a, st["R_i"], st["p_i"], st["v_i"], st["R_j"], st["p_j"], st["v_j"], st["b"], g
            )[0][n]

        x = [
            gtsam.Pose3(gtsam.Rot3(s["R_i"][n]), s["p_i"][n]),
            s["v_i"][n],
            gtsam.Pose3(gtsam.Rot3(s["R_j"][n]), s["p_j"][n]),
            s["v_j"][n],
            s["b"][n],
        ]
        for key, num in zip(
            ("pose_i", "vel_i", "pose_j", "vel_j", "bias"), numerical_jacobians(err, x), strict=True
        ):
            block = getattr(J, key)[n]
            assert np.abs(num - block).max() <= 1e-5 * np.abs(block).max(), (key, n)


def test_bias_jacobian_against_independent_probes() -> None:
    """bias_jacobians (one evaluateError per factor, inverted) against predictions from the identity with each bias
    component (the rotating-frame prediction from rest at the origin: A Exp(theta_c), A dp_c + gravity terms,
    A dv_c - Omega x p + gravity terms, so that differences between probes are A H b, linear in b)."""
    fs, _ = factors(True)
    x, H, dt = bias_jacobians([f.preintegratedMeasurements() for f in fs], W_IE)
    for n, f in enumerate(fs):
        pim = f.preintegratedMeasurements()
        assert np.array_equal(x[n], pim.preintegrated()) and dt[n] == pim.deltaTij()
        if np.linalg.norm(x[n, :3]) > 2.5:  # a Logmap of the probe would wrap
            continue
        A = gtsam.Rot3.Expmap(-W_IE * dt[n]).matrix()

        def probe(
            b: np.ndarray, pim: gtsam.PreintegratedImuMeasurements = pim, A: np.ndarray = A
        ) -> np.ndarray:
            s = pim.predict(gtsam.NavState(), gtsam.imuBias.ConstantBias(b[:3], b[3:]))
            v_lifted = s.velocity() + np.cross(W_IE, s.position())
            return np.concatenate(
                [
                    gtsam.Rot3.Logmap(gtsam.Rot3(A.T @ s.attitude().matrix())),
                    A.T @ s.position(),
                    A.T @ v_lifted,
                ]
            )

        y0 = probe(np.zeros(6))
        assert np.abs(y0[:3] - x[n, :3]).max() < 1e-12
        ref = np.empty((9, 6))
        for k, h in enumerate((1.0, 1.0, 1.0, 1e-2, 1e-2, 1e-2)):
            b = np.zeros(6)
            b[k] = h
            ref[:, k] = (probe(b) - y0) / h
        assert np.abs(H[n] - ref).max() <= 1e-8 * np.abs(ref).max(), n


def test_logmaps_are_gtsams() -> None:
    """se23_log_n against NavState.Logmap, so3.log against Rot3.Logmap: small, ordinary and near-pi angles."""
    rng = np.random.default_rng(5)
    angles = np.array([1e-9, 1e-7, 1e-3, 0.05, 0.5, 2.0, 3.0, np.pi - 1e-4, np.pi - 1e-7])
    axes = rng.normal(0, 1, (len(angles), 3))
    phi = axes / np.linalg.norm(axes, axis=1)[:, None] * angles[:, None]
    R = np.array([gtsam.Rot3.Expmap(w).matrix() for w in phi])
    assert np.abs(log(R) - phi).max() < 1e-8
    p, v = rng.normal(0, 5, (len(angles), 3)), rng.normal(0, 2, (len(angles), 3))
    xi, _ = se23_log_n(R[:7], p[:7], v[:7])
    for n in range(7):
        ref = gtsam.NavState.Logmap(gtsam.NavState(gtsam.Rot3(R[n]), p[n], v[n]))
        assert np.abs(xi[n] - ref).max() <= 1e-10 * (1 + np.abs(ref).max())
