"""Rotation conventions shared by every module.

Euler angles are ZYX (R = Rz(yaw) Ry(pitch) Rx(roll)) about the axes of the frame they rotate from,
as in docs/conventions.md. Quaternions are stored [x, y, z, w] (ROS order). Angles are radians unless a
name ends in _deg. skew, so3_exp and so3_log are factors/so3.py's (one 3-vector or a stack).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gtsam_dvl.factors.so3 import exp as so3_exp
from gtsam_dvl.factors.so3 import log as so3_log
from gtsam_dvl.factors.so3 import skew


def _rotation() -> Any:
    """scipy's Rotation, imported when first needed: scipy.spatial costs about 0.45 s to import, which every
    command-line process would pay at start (gtsam_dvl.core.types imports this module) whether it rotates or not."""
    from scipy.spatial.transform import Rotation

    return Rotation


__all__ = [
    "matrix_to_quat_xyzw",
    "matrix_to_rpy",
    "matrix_to_rpy_deg",
    "quat_xyzw_to_matrix",
    "rpy_deg_to_matrix",
    "rpy_to_matrix",
    "skew",
    "so3_exp",
    "so3_log",
]


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), radians."""
    return _rotation().from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def rpy_deg_to_matrix(rpy_deg: np.ndarray | list[float] | tuple[float, ...]) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) from [roll, pitch, yaw] in degrees."""
    r, p, y = np.radians(np.asarray(rpy_deg, dtype=float))
    return rpy_to_matrix(float(r), float(p), float(y))


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """[roll, pitch, yaw] in radians of R = Rz(yaw) Ry(pitch) Rx(roll); works on (...,3,3)."""
    ypr = _rotation().from_matrix(R).as_euler("ZYX")
    return ypr[..., ::-1].copy()


def matrix_to_rpy_deg(R: np.ndarray) -> np.ndarray:
    return np.degrees(matrix_to_rpy(R))


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    return _rotation().from_matrix(R).as_quat()


def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    return _rotation().from_quat(q).as_matrix()
