"""The DVL measurement model shared by the 3-D velocity factor and the per-beam factor.

    h(x) = k * d_R_b * ( n_R_b^T * n_v  +  b_omega x b_l ),   d_R_b = b_R_d^T

n_R_b (base_link -> map) and b_R_d (dvl_link -> base_link) are perturbed on the right, as GTSAM's
Pose3 and Rot3 retract do; the pose tangent is [rotation, translation]. Validation helpers for the factor
constructors live here too, so both factors reject bad input with the same messages.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import gtsam
import numpy as np

# A 3-vector given by the caller: an array or a sequence of numbers (not Any, so that mypy checks every call)
Vector3Like = np.ndarray | Sequence[float]

_Z33 = np.zeros((3, 3))
_Z33.setflags(write=False)  # shared by every Jacobian through np.concatenate, which copies it


class JacobianSlots(Protocol):
    """What a Jacobian output list must support: a Python list or GTSAM's opaque JacobianVector."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int, /) -> Any: ...

    def __setitem__(self, index: int, value: np.ndarray, /) -> None: ...



def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors, written out: np.cross's axis handling costs 15 us a call, more than the rest of a
    DVL factor's prediction."""
    a0, a1, a2 = np.asarray(a, dtype=float).tolist()
    b0, b1, b2 = np.asarray(b, dtype=float).tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])

def _skew(x: float, y: float, z: float) -> np.ndarray:
    """[a]_x with a = (x, y, z): [a]_x b = a x b. Built from floats: cheaper than indexing an array."""
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def predict_dvl_velocity(
    n_R_b: np.ndarray,
    n_v: np.ndarray,
    k: float,
    d_R_b: np.ndarray,
    b_v_lever: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """h = k * d_R_b * (n_R_b^T n_v + b_v_lever), the DVL velocity in dvl_link, (3,).

    n_R_b, d_R_b: 3x3 matrices; b_v_lever = b_omega x b_l, constant per measurement. When H is given,
    H[0..3] are set to dh/d(pose) 3x6, dh/d(n_v) 3x3, dh/dk 3x1, dh/d(b_R_d) 3x3:
        n_R_b Exp(dth):  R^T n_v -> R^T n_v + [R^T n_v]_x dth  =>  [k d_R_b [n_R_b^T n_v]_x, 0]
        n_v:             k d_R_b n_R_b^T
        k:               d_R_b b_v
        b_R_d Exp(dph):  d_R_b -> Exp(-dph) d_R_b           =>  k [d_R_b b_v]_x
    The translation block is zero: the velocity is a separate variable.
    """
    b_v_rel = n_v @ n_R_b  # n_R_b^T n_v without forming the transpose
    d_v = d_R_b @ (b_v_rel + b_v_lever)
    if H is not None:
        k_d_R_b = k * d_R_b
        H[0] = np.concatenate((k_d_R_b @ _skew(*b_v_rel.tolist()), _Z33), axis=1)
        H[1] = k_d_R_b @ n_R_b.T
        H[2] = d_v.reshape(3, 1)
        H[3] = _skew(*(k * d_v).tolist())
    return k * d_v


def predict_dvl_velocity_lever(
    n_R_b: np.ndarray,
    n_v: np.ndarray,
    k: float,
    d_R_b: np.ndarray,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """predict_dvl_velocity with the lever arm b_l (m, base_link) a variable: h = k d_R_b (n_R_b^T n_v +
    b_omega x b_l), b_omega the body rate relative to map (rad/s, base_link, a known input). H[0..3] as in
    predict_dvl_velocity and H[4] = dh/d(b_l) 3x3:
        b_l + dl:  b_omega x (b_l + dl) = b_omega x b_l + [b_omega]_x dl  =>  k d_R_b [b_omega]_x
    (exact: h is linear in b_l).
    """
    h = predict_dvl_velocity(n_R_b, n_v, k, d_R_b, cross3(b_omega, b_l), H)
    if H is not None:
        H[4] = lever_jacobian(k, d_R_b, b_omega)
    return h


def lever_jacobian(k: float, d_R_b: np.ndarray, b_omega: np.ndarray) -> np.ndarray:
    """d/d(b_l) of k d_R_b (b_omega x b_l): k d_R_b [b_omega]_x, 3x3 (the lever arm's Jacobian of every DVL
    model here, whatever else the model adds)."""
    return np.asarray(k * d_R_b @ _skew(*b_omega.tolist()))


def fill_slots(H: JacobianSlots, computed: list[np.ndarray]) -> None:
    """Copy Jacobians into H: in place where a slot holds a preallocated array of the right shape
    (the GTSAM OptionalJacobian habit), by assignment otherwise (None or an empty slot)."""
    if len(H) != len(computed):
        raise ValueError(f"H must have {len(computed)} slots (one per key), got {len(H)}")
    for i, J in enumerate(computed):
        slot = H[i]
        if isinstance(slot, np.ndarray) and slot.shape == J.shape and slot.flags.writeable:
            slot[...] = J
        else:
            H[i] = J


def as_scale(k: float | np.ndarray) -> float:
    """The scale factor as a float, from a number or the 1-vector stored in Values."""
    arr = np.asarray(k, dtype=float)
    if arr.size != 1:
        raise ValueError(f"scale k must be a scalar or a 1-vector, got shape {arr.shape}")
    return float(arr.reshape(()))


def as_vector3(name: str, x: Any) -> np.ndarray:
    """A finite float64 3-vector, or ValueError naming the argument."""
    arr = np.array(x, dtype=float)  # a copy: the factor must not see later changes to the caller's array
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr}")
    arr.setflags(write=False)
    return arr


def as_finite_float(name: str, x: Any) -> float:
    """A finite scalar, or ValueError naming the argument."""
    arr = np.asarray(x, dtype=float)
    if arr.size != 1:
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    value = float(arr.reshape(()))
    if not np.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value}")
    return value


def as_unit_vector3(name: str, x: Any, tol: float = 1e-6) -> np.ndarray:
    """A finite 3-vector of norm 1 within tol (float32 beam vectors from a message pass), else ValueError.

    Not renormalised: the measurement y_j was taken along exactly this vector.
    """
    arr = as_vector3(name, x)
    norm = float(np.linalg.norm(arr))
    if abs(norm - 1.0) > tol:
        raise ValueError(f"{name} must be a unit vector, got norm {norm}")
    return arr


def lever_velocity(b_omega: Any, b_l: Any) -> np.ndarray:
    """b_omega x b_l: the DVL's velocity relative to base_link's origin, in base_link, m/s."""
    v = np.cross(as_vector3("b_omega", b_omega), as_vector3("b_l", b_l))
    v.setflags(write=False)
    return v


def check_noise(noise: Any, dim: int) -> None:
    """The noise model must be a GTSAM noise model of the factor's dimension."""
    if not isinstance(noise, gtsam.noiseModel.Base):
        raise TypeError(f"noise must be a gtsam noise model, got {type(noise).__name__}")
    if noise.dim() != dim:
        raise ValueError(f"noise model has dimension {noise.dim()}, this factor needs {dim}")
