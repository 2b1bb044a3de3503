"""factors/dvl_bulk.py: the DVL factors of N rows at once against the per-factor error function (errors and
Jacobians to 1e-9) and against numerical derivatives on the manifold (tests/support/numerical.py), with and
without the time offset, the lever arm as a variable and beams, for pings at their state (no IMU motion) and
between keyframes (random IMU motion, gravity gradient, Earth rate)."""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
import pytest

from gtsam_dvl.factors import DvlOptions, OffsetInput, PingMotion, dvl_error
from gtsam_dvl.factors.dvl_bulk import BulkPings, dvl_ping_errors
from gtsam_dvl.factors.so3 import exp
from tests.support.numerical import numerical_jacobians

N = 12
N_STATES = 4
W_IE = np.array([6.3e-5, 0.0, -3.6e-5])  # Earth rate in an ENU map at 30 deg latitude, rad/s
OFFSET_N_G = np.array([0.0, 0.0, -9.79])
VARIANTS = [
    pytest.param(offset, lever, beam, id=f"offset{offset:d}-lever{lever:d}-beam{beam:d}")
    for offset, lever, beam in (
        (False, False, False),
        (True, False, False),
        (False, True, False),
        (True, True, False),
        (False, False, True),
        (False, True, True),
    )
]


def random_case(rng: np.random.Generator, moving: np.ndarray, beam: bool) -> dict[str, Any]:
    """N rows, those with moving[q] between keyframes (random IMU motion), the others at their state."""
    dt = np.where(moving, rng.uniform(0.2, 1.0, N), 0.0)
    mv, mm = moving[:, None], moving[:, None, None]

    def moved(shape: tuple[int, ...], sigma: float) -> np.ndarray:
        return np.where(mm if len(shape) == 2 else mv, rng.normal(0, sigma, (N, *shape)), 0.0)

    motion = PingMotion(
        dt,
        exp(moved((3,), 0.3)),
        moved((3,), 0.5),
        moved((3,), 0.2),
        moved((3, 3), 0.5),
        moved((3, 3), 0.5),
        moved((3, 3), 0.5),
        np.zeros((N, 9, 9)),
        W_IE,
        np.array([0.0, 0.0, -9.79]) + rng.normal(0, 1e-3, (N, 3)),
        rng.normal(0, 50, (N, 3)),
        rng.normal(0, 1.5e-6, (N, 3, 3)),
    )
    d_u = rng.normal(size=(N, 3))
    pings = BulkPings(
        state=np.sort(rng.integers(0, N_STATES, N)),
        y=rng.normal(0, 1.5, (N, 1 if beam else 3)),
        b_omega=rng.normal(0, 0.1, (N, 3)),
        motion=motion,
        d_u=d_u / np.linalg.norm(d_u, axis=1, keepdims=True) if beam else None,
        offset_b_a=rng.normal(0, 0.3, (N, 3)) + [0, 0, 9.79],
        offset_G=exp(rng.normal(0, 0.01, (N, 3))),
    )
    return {
        "pings": pings,
        "b_l": rng.normal(0, 0.5, 3),
        "poses": [
            gtsam.Pose3(gtsam.Rot3.Expmap(rng.normal(0, 1.0, 3)), rng.normal(0, 100, 3))
            for _ in range(N_STATES)
        ],
        "vels": [rng.normal(0, 1.5, 3) for _ in range(N_STATES)],
        "bias": gtsam.imuBias.ConstantBias(rng.normal(0, 1e-3, 3), rng.normal(0, 1e-4, 3)),
        "k": 1.013,
        "b_R_d": gtsam.Rot3.Expmap(rng.normal(0, 0.05, 3)),
        "dt_d": 0.37,
    }


def bulk(case: dict[str, Any], offset: bool, lever: bool, *x: Any, jacobians: bool = False) -> Any:
    """The rows' errors (and Jacobians) at the variables x = (poses..., vels..., bias, k, b_R_d, dt_d, b_l)."""
    p = case["pings"]
    poses, vels = x[:N_STATES], x[N_STATES : 2 * N_STATES]
    bias, k, b_R_d, dt_d, b_l = x[2 * N_STATES :]
    s = p.state
    e, J = dvl_ping_errors(
        p,
        np.array([poses[i].rotation().matrix() for i in s]),
        np.array([poses[i].translation() for i in s]),
        np.array([vels[i] for i in s]),
        np.tile(bias.accelerometer(), (N, 1)),
        np.tile(bias.gyroscope(), (N, 1)),
        float(k),
        b_R_d.matrix(),
        np.asarray(b_l, dtype=float),
        float(dt_d) if offset else None,
        OFFSET_N_G if offset else None,
        lever,
        jacobians,
    )
    return (e, J) if jacobians else e.reshape(-1)


def variables(case: dict[str, Any]) -> list[Any]:
    return [
        *case["poses"],
        *case["vels"],
        case["bias"],
        case["k"],
        case["b_R_d"],
        case["dt_d"],
        case["b_l"],
    ]


@pytest.mark.parametrize("offset, lever, beam", VARIANTS)
def test_matches_the_per_factor_error(offset: bool, lever: bool, beam: bool) -> None:
    rng = np.random.default_rng(3)
    moving = rng.random(N) < 0.6
    moving[:2] = [False, True]
    case = random_case(rng, moving, beam)
    p = case["pings"]
    e, J = bulk(case, offset, lever, *variables(case), jacobians=True)
    blocks = J.variables()
    worst = 0.0
    for q in range(N):
        i = int(p.state[q])
        options = DvlOptions(
            p.b_omega[q],
            case["b_l"],
            None if p.d_u is None else p.d_u[q],
            OffsetInput(p.offset_b_a[q], OFFSET_N_G, p.offset_G[q]) if offset else None,
            p.motion[q] if moving[q] else None,
            lever,
        )
        x = (
            [case["poses"][i], case["vels"][i]]
            + [case["bias"]] * bool(moving[q])
            + [case["k"], case["b_R_d"]]
            + [case["dt_d"]] * offset
            + [case["b_l"]] * lever
        )
        H: list[Any] = [None] * len(x)
        ref = dvl_error(x, p.y[q], options, H)
        if not moving[q]:  # a ping at its state has no bias columns: zero in the bulk's
            assert np.array_equal(J.bias[q], np.zeros_like(J.bias[q]))
            H.insert(2, J.bias[q])
        assert np.allclose(e[q], ref, rtol=0, atol=1e-12 * (1 + np.abs(ref).max()))
        for got, want in zip(blocks, H, strict=True):
            worst = max(worst, float(np.abs(got[q] - want).max() / (1.0 + np.abs(want).max())))
    assert worst < 1e-9


@pytest.mark.parametrize("offset, lever, beam", VARIANTS)
def test_jacobians_against_numerical_derivatives(offset: bool, lever: bool, beam: bool) -> None:
    rng = np.random.default_rng(5)
    case = random_case(rng, np.arange(N) % 3 != 0, beam)
    p = case["pings"]
    x = variables(case)
    _, J = bulk(case, offset, lever, *x, jacobians=True)
    numeric = numerical_jacobians(lambda *v: bulk(case, offset, lever, *v), x)
    m = p.dim

    def rows(per_row: np.ndarray, state: int | None = None) -> np.ndarray:
        """The (N m, d) Jacobian of the flattened errors, zero in the rows of other states."""
        out = per_row.copy()
        if state is not None:
            out[p.state != state] = 0.0
        return out.reshape(N * m, -1)

    expected = (
        [rows(J.pose, i) for i in range(N_STATES)]
        + [rows(J.vel, i) for i in range(N_STATES)]
        + [rows(J.bias), rows(J.scale), rows(J.b_R_d)]
    )
    expected.append(rows(J.offset) if offset else np.zeros((N * m, 1)))
    if lever:  # (a known lever arm is an input, not a variable)
        expected.append(rows(J.lever))
    for n, (want, got) in enumerate(zip(numeric, expected, strict=False)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6, err_msg=f"variable {n}")
