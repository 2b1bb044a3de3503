"""What every factor constructor shares: the validation of its inputs (so that every factor rejects bad input with
the same messages), the noise model's check and the filling of GTSAM's Jacobian slots."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import gtsam
import numpy as np

# A 3-vector given by the caller: an array or a sequence of numbers (not Any, so that mypy checks every call)
Vector3Like = np.ndarray | Sequence[float]


class JacobianSlots(Protocol):
    """What a Jacobian output list must support: a Python list or GTSAM's opaque JacobianVector."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int, /) -> Any: ...

    def __setitem__(self, index: int, value: np.ndarray, /) -> None: ...


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
    # a copy: the factor must not see later changes to the caller's array
    arr = np.array(x, dtype=float)
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


def check_noise(noise: Any, dim: int) -> None:
    """The noise model must be a GTSAM noise model of the factor's dimension."""
    if not isinstance(noise, gtsam.noiseModel.Base):
        raise TypeError(f"noise must be a gtsam noise model, got {type(noise).__name__}")
    if noise.dim() != dim:
        raise ValueError(f"noise model has dimension {noise.dim()}, this factor needs {dim}")
