"""Graph keys and their tangent dimensions: the one naming of the variables every estimator shares.

X(i) pose n_T_b of state i (Pose3: tangent [rotation, translation] in body axes), V(i) velocity n_v (m/s,
map), B(i) IMU bias [accel, gyro] (B(0) alone for a random-constant bias), K_SCALE the DVL scale factor
(a 1-vector), C_MISALIGN the calibrated DVL mounting b_R_d (Rot3, perturbed on the right), T_OFFSET the
DVL-IMU time offset dt_d (a 1-vector, s; only with [dvl] estimate_time_offset), L_LEVER the lever arm b_l from
the IMU to the DVL (a 3-vector in base_link, m; only with [dvl] estimate_lever_arm).
"""

from __future__ import annotations

import gtsam

K_SCALE = gtsam.symbol("k", 0)
C_MISALIGN = gtsam.symbol("c", 0)
T_OFFSET = gtsam.symbol("t", 0)  # DVL-IMU time offset dt_d, s (a 1-vector; docs/conventions.md)
L_LEVER = gtsam.symbol("l", 0)  # lever arm b_l IMU -> DVL, m, base_link (a 3-vector)

# tangent dimension of each variable type, by symbol character
DIMS = {"x": 6, "v": 3, "b": 6, "k": 1, "c": 3, "t": 1, "l": 3}


def X(i: int) -> int:
    return gtsam.symbol("x", i)


def V(i: int) -> int:
    return gtsam.symbol("v", i)


def B(i: int = 0) -> int:
    return gtsam.symbol("b", i)


def key_dim(key: int) -> int:
    """Tangent dimension of a variable from its key (GTSAM symbols keep the character in the top byte)."""
    return DIMS[chr(key >> 56)]
