"""factors/dvl_bulk.py: the DVL factors of N pings at once against the per-factor functions (errors and
Jacobians to 1e-9) and against numerical derivatives on the manifold, with and without the time offset, for
pings at their state (no IMU motion) and between keyframes (random IMU motion, gravity gradient, Earth rate)."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from gtsam_dvl.factors import PingMotion
from gtsam_dvl.factors.dvl_bulk import PingArrays, dvl_ping_errors, ping_constants, so3_exp_n
from gtsam_dvl.factors.dvl_keyframe import dvl_keyframe_error
from gtsam_dvl.factors.dvl_velocity import dvl_velocity_error, dvl_velocity_offset_error

N = 12
W_IE = np.array([6.3e-5, 0.0, -3.6e-5])  # Earth rate in an ENU map at 30 deg latitude, rad/s
OFFSET_N_G = np.array([0.0, 0.0, -9.79])


def random_case(rng: np.random.Generator, moving: np.ndarray) -> dict:
    """N pings, those with moving[q] between keyframes (random IMU motion), the others at their state."""
    n_states = 4
    state = np.sort(rng.integers(0, n_states, N))
    dt = np.where(moving, rng.uniform(0.2, 1.0, N), 0.0)
    dR = so3_exp_n(np.where(moving[:, None], rng.normal(0, 0.3, (N, 3)), 0.0))
    mv = moving[:, None]
    mm = moving[:, None, None]
    pings = PingArrays(
        state=state, d_y=rng.normal(0, 1.5, (N, 3)), b_omega=rng.normal(0, 0.1, (N, 3)),
        b_v_lever=np.zeros((N, 3)), dt=dt, dR=dR, dv=np.where(mv, rng.normal(0, 0.5, (N, 3)), 0.0),
        dp=np.where(mv, rng.normal(0, 0.2, (N, 3)), 0.0),
        dR_dbg=np.where(mm, rng.normal(0, 0.5, (N, 3, 3)), 0.0),
        dv_dba=np.where(mm, rng.normal(0, 0.5, (N, 3, 3)), 0.0),
        dv_dbg=np.where(mm, rng.normal(0, 0.5, (N, 3, 3)), 0.0),
        n_g0=np.array([0.0, 0.0, -9.79]) + rng.normal(0, 1e-3, (N, 3)), n_p0=rng.normal(0, 50, (N, 3)),
        n_G=rng.normal(0, 1.5e-6, (N, 3, 3)), offset_b_a=rng.normal(0, 0.3, (N, 3)) + [0, 0, 9.79],
        offset_G=so3_exp_n(rng.normal(0, 0.01, (N, 3))))
    b_l = rng.normal(0, 0.5, 3)
    pings.b_v_lever = np.cross(pings.b_omega, b_l)
    poses = [gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 1.0, 3)), rng.normal(0, 100, 3)) for _ in range(n_states)]
    vels = [rng.normal(0, 1.5, 3) for _ in range(n_states)]
    bias = gtsam.imuBias.ConstantBias(rng.normal(0, 1e-3, 3), rng.normal(0, 1e-4, 3))
    return dict(pings=pings, b_l=b_l, poses=poses, vels=vels, bias=bias, k=1.013,
                b_R_d=gtsam.Rot3.Expmap(rng.normal(0, 0.05, 3)), dt_d=0.37)


def bulk(case: dict, offset: bool, jacobians: bool = True, poses=None, vels=None, bias=None, k=None, b_R_d=None,
         dt_d=None):
    p = case["pings"]
    poses = case["poses"] if poses is None else poses
    vels = case["vels"] if vels is None else vels
    bias = case["bias"] if bias is None else bias
    s = p.state
    n_R_i = np.array([poses[i].rotation().matrix() for i in s])
    n_p_i = np.array([poses[i].translation() for i in s])
    n_v_i = np.array([vels[i] for i in s])
    b_a = np.tile(bias.accelerometer(), (N, 1))
    b_g = np.tile(bias.gyroscope(), (N, 1))
    return dvl_ping_errors(p, ping_constants(p, W_IE), W_IE, n_R_i, n_p_i, n_v_i, b_a, b_g,
                           case["k"] if k is None else k, (case["b_R_d"] if b_R_d is None else b_R_d).matrix(),
                           (case["dt_d"] if dt_d is None else dt_d) if offset else None,
                           OFFSET_N_G if offset else None, jacobians)


def motion_of(p: PingArrays, q: int) -> PingMotion:
    return PingMotion(float(p.dt[q]), p.dR[q], p.dv[q], p.dp[q], p.dR_dbg[q], p.dv_dba[q], p.dv_dbg[q], W_IE,
                      p.n_g0[q], p.n_p0[q], p.n_G[q])


@pytest.mark.parametrize("offset", [False, True])
def test_matches_per_factor_functions(offset: bool) -> None:
    rng = np.random.default_rng(3)
    moving = rng.random(N) < 0.6
    moving[:2] = [False, True]
    case = random_case(rng, moving)
    p = case["pings"]
    e, J = bulk(case, offset)
    assert J is not None
    worst = 0.0
    for q in range(N):
        i = int(p.state[q])
        pose, vel, bias = case["poses"][i], case["vels"][i], case["bias"]
        k, b_R_d = np.array([case["k"]]), case["b_R_d"]
        if moving[q]:
            H = [None] * (6 if offset else 5)
            ref = dvl_keyframe_error(pose, vel, bias, k, b_R_d, p.d_y[q], p.b_omega[q], case["b_l"], motion_of(p, q),
                                     np.array([case["dt_d"]]) if offset else None,
                                     (p.offset_b_a[q], OFFSET_N_G, p.offset_G[q]) if offset else None, H=H)
            blocks = [J.pose[q], J.vel[q], J.bias[q], J.scale[q], J.b_R_d[q]] + ([J.offset[q]] if offset else [])
        else:
            H = [None] * (5 if offset else 4)
            if offset:
                ref = dvl_velocity_offset_error(pose, vel, k, b_R_d, np.array([case["dt_d"]]), p.d_y[q], p.b_omega[q],
                                                case["b_l"], p.offset_b_a[q], OFFSET_N_G, p.offset_G[q], H)
            else:
                ref = dvl_velocity_error(pose, vel, k, b_R_d, p.d_y[q], p.b_omega[q], case["b_l"], H)
            # a ping at its state has no bias columns: zero in the bulk's
            assert np.array_equal(J.bias[q], np.zeros((3, 6)))
            blocks = [J.pose[q], J.vel[q], J.scale[q], J.b_R_d[q]] + ([J.offset[q]] if offset else [])
        assert np.allclose(e[q], ref, rtol=0, atol=1e-12 * (1 + np.abs(ref).max()))
        for got, want in zip(blocks, H, strict=True):
            worst = max(worst, float(np.abs(got - want).max() / (1.0 + np.abs(want).max())))
    assert worst < 1e-9


@pytest.mark.parametrize("offset", [False, True])
def test_jacobians_against_numerical_derivatives(offset: bool) -> None:
    rng = np.random.default_rng(5)
    moving = np.arange(N) % 3 != 0
    case = random_case(rng, moving)
    p = case["pings"]
    _, J = bulk(case, offset)
    assert J is not None
    h = 1e-6

    def numeric(perturb) -> np.ndarray:
        cols = []
        for sign in (1, -1):
            cols.append(bulk(case, offset, False, **perturb(sign * h))[0])
        return (cols[0] - cols[1]) / (2 * h)

    # pose and velocity of each state, rotation and translation on the right (GTSAM retract)
    for i in range(4):
        on = p.state == i
        for d in range(6):
            def pose_step(eps, d=d, i=i):
                xi = np.zeros(6)
                xi[d] = eps
                poses = list(case["poses"])
                poses[i] = poses[i].retract(xi)
                return {"poses": poses}
            assert np.allclose(numeric(pose_step)[on], J.pose[on][:, :, d], atol=1e-6)
        for d in range(3):
            def vel_step(eps, d=d, i=i):
                vels = [v.copy() for v in case["vels"]]
                vels[i][d] += eps
                return {"vels": vels}
            assert np.allclose(numeric(vel_step)[on], J.vel[on][:, :, d], atol=1e-6)
    for d in range(6):
        def bias_step(eps, d=d):
            x = case["bias"].vector().copy()
            x[d] += eps
            return {"bias": gtsam.imuBias.ConstantBias(x[:3], x[3:])}
        assert np.allclose(numeric(bias_step), J.bias[:, :, d], atol=1e-6)
    assert np.allclose(numeric(lambda eps: {"k": case["k"] + eps}), J.scale[:, :, 0], atol=1e-6)
    for d in range(3):
        def c_step(eps, d=d):
            phi = np.zeros(3)
            phi[d] = eps
            return {"b_R_d": case["b_R_d"].retract(phi)}
        assert np.allclose(numeric(c_step), J.b_R_d[:, :, d], atol=1e-6)
    if offset:
        assert np.allclose(numeric(lambda eps: {"dt_d": case["dt_d"] + eps}), J.offset[:, :, 0], atol=1e-6)
