"""factors/dvl_model.py: the DVL measurement model against an independent formula (scipy's rotations), for one
ping and for N at once (broadcast over leading axes: the same numbers as ping by ping), its options reducing to the
base case when off, and the inputs' Jacobians (the EKF's bias columns) against numerical derivatives. The variables'
Jacobians are checked through every option of the factor (tests/factors/test_dvl.py)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.factors import OffsetInput, dvl_model
from tests.support.numerical import numerical_jacobians

N = 7
N_G = np.array([0.0, 0.0, -9.79])


def pings(seed: int) -> dict[str, Any]:
    """N pings' states and inputs, and the calibration."""
    rng = np.random.default_rng(seed)
    d_u = rng.normal(size=(N, 3))
    return {
        "n_R_b": Rotation.random(N, random_state=rng),
        "n_v": rng.normal(0, 1.5, (N, 3)),
        "k": 1.013,
        "b_R_d": Rotation.from_rotvec(rng.normal(0, 0.05, 3)) * Rotation.from_rotvec([np.pi, 0, 0]),
        "b_omega": rng.normal(0, 0.2, (N, 3)),
        "b_l": rng.normal(0, 0.6, 3),
        "dt_d": 0.21,
        "b_a": rng.normal(0, 0.3, (N, 3)) + [0, 0, 9.79],
        "G": Rotation.from_rotvec(rng.normal(0, 0.02, (N, 3))),
        "d_u": d_u / np.linalg.norm(d_u, axis=1, keepdims=True),
    }


def reference(p: dict[str, Any], offset: bool) -> np.ndarray:
    """k b_R_d^T (b_v + dt_d (b_a + G n_R_b^T n_g - b_omega x b_v) + b_omega x b_l) with scipy's rotations."""
    b_v = p["n_R_b"].inv().apply(p["n_v"])
    u = b_v + np.cross(p["b_omega"], p["b_l"])
    if offset:
        b_vdot = p["b_a"] + p["G"].apply(p["n_R_b"].inv().apply(N_G)) - np.cross(p["b_omega"], b_v)
        u = u + p["dt_d"] * b_vdot
    return np.asarray(p["k"] * p["b_R_d"].inv().apply(u))


def model(p: dict[str, Any], offset: bool, beam: bool, q: Any = slice(None), **kw: Any) -> Any:
    return dvl_model(
        p["n_R_b"].as_matrix()[q],
        p["n_v"][q],
        p["k"],
        p["b_R_d"].as_matrix(),
        p["b_omega"][q],
        p["b_l"],
        d_u=p["d_u"][q] if beam else None,
        dt_d=p["dt_d"] if offset else None,
        offset=OffsetInput(p["b_a"][q], N_G, p["G"].as_matrix()[q]) if offset else None,
        **kw,
    )


@pytest.mark.parametrize("offset", [False, True])
@pytest.mark.parametrize("beam", [False, True])
def test_the_model_is_the_formula_for_one_ping_or_n(offset: bool, beam: bool) -> None:
    p = pings(1)
    ref = reference(p, offset)
    if beam:
        ref = np.einsum("ni,ni->n", p["d_u"], ref)[:, None]
    h, J = model(p, offset, beam)
    assert J is not None and h.shape == (N, 1 if beam else 3)
    np.testing.assert_allclose(h, ref, rtol=0, atol=1e-13)
    for q in range(N):
        h_q, J_q = model(p, offset, beam, q)
        assert J_q is not None
        np.testing.assert_allclose(h_q, h[q], rtol=0, atol=1e-14)
        for got, want in zip(J_q.variables(), J.variables(), strict=True):
            np.testing.assert_allclose(got, want[q], rtol=0, atol=1e-13)
    h_only, none = model(p, offset, beam, jacobians=False)
    assert none is None
    np.testing.assert_array_equal(h_only, h)


def test_a_zero_offset_is_the_base_model() -> None:
    p = dict(pings(2), dt_d=0.0)
    np.testing.assert_allclose(
        model(p, True, False)[0], model(p, False, False)[0], rtol=0, atol=1e-15
    )


@pytest.mark.parametrize("offset", [False, True])
def test_input_jacobians_against_numerical_derivatives(offset: bool) -> None:
    """dh/d(b_omega) and dh/d(b_a): the columns a filter with the biases in its state needs."""
    p = pings(3)
    _, J = model(p, offset, False, 0, inputs=True)
    assert J is not None and J.b_omega is not None

    def h(b_omega: np.ndarray, b_a: np.ndarray) -> np.ndarray:
        q = dict(p, b_omega=np.array([b_omega]), b_a=np.array([b_a]))
        return np.asarray(model(q, offset, False, 0, jacobians=False)[0])

    num_w, num_a = numerical_jacobians(h, [p["b_omega"][0], p["b_a"][0]])
    np.testing.assert_allclose(J.b_omega, num_w, rtol=0, atol=1e-8)
    if offset:
        assert J.b_a is not None
        np.testing.assert_allclose(J.b_a, num_a, rtol=0, atol=1e-8)
    else:
        assert J.b_a is None and not num_a.any()
