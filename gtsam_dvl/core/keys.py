"""Graph keys and their tangent dimensions: the one naming of the variables every estimator shares.

X(i) pose n_T_b of state i (Pose3: tangent [rotation, translation] in body axes), V(i) velocity n_v (m/s,
map), B(i) IMU bias [accel, gyro] (B(0) alone for a random-constant bias), E(i) the DVL's correlated velocity
error (m/s, dvl_link; only when the configuration models it), W(i) the horizontal water current [east, north]
(m/s, map; only when water-track pings are used, estimators/models/current.py), S(b) the change of the current across
the boundary b between depth layers b and b + 1 (deeper minus shallower, [east, north] m/s, map; only with
[current] layer_thickness_m > 0). The keys of the shared states
(core/states.py names what each is, its prior and units): K_SCALE the DVL scale factor (a 1-vector),
C_MISALIGN the calibrated DVL mounting b_R_d (Rot3, perturbed on the right), T_OFFSET the DVL-IMU time offset
dt_d (a 1-vector, s; only with [dvl] estimate_time_offset), L_LEVER the lever arm b_l from the IMU to the DVL
(a 3-vector in base_link, m; only with [dvl] estimate_lever_arm), K_WATER the water-track pings' own scale factor
(a 1-vector; only with [current] water_track_scale and water-track pings used).
"""

from __future__ import annotations

import gtsam

# tangent dimension of each variable type, by symbol character
DIMS = {"x": 6, "v": 3, "b": 6, "e": 3, "w": 2, "s": 2}


def shared_key(char: str, dim: int) -> int:
    """The key of a shared variable (index 0 of its symbol character), its tangent dimension recorded in DIMS."""
    DIMS[char] = dim
    return gtsam.symbol(char, 0)


K_SCALE = shared_key("k", 1)
C_MISALIGN = shared_key("c", 3)
T_OFFSET = shared_key("t", 1)  # DVL-IMU time offset dt_d, s (a 1-vector; docs/conventions.md)
L_LEVER = shared_key("l", 3)  # lever arm b_l IMU -> DVL, m, base_link (a 3-vector)
# the water-track pings' own scale factor (a 1-vector; [current] water_track_scale)
K_WATER = shared_key("q", 1)


def X(i: int) -> int:
    return gtsam.symbol("x", i)


def V(i: int) -> int:
    return gtsam.symbol("v", i)


def B(i: int = 0) -> int:
    return gtsam.symbol("b", i)


def E(i: int) -> int:
    """The DVL's correlated (Gauss-Markov) velocity error at state i: a 3-vector in dvl_link, m/s (only with
    [dvl] correlated_sigma_m_s > 0; estimators/models/correlated.py)."""
    return gtsam.symbol("e", i)


def W(i: int) -> int:
    """The horizontal water current at state i: [east, north] in map, m/s (only when water-track pings are used;
    estimators/models/current.py)."""
    return gtsam.symbol("w", i)


def S(b: int) -> int:
    """The change of the water current across the boundary between depth layers b and b + 1 (the deeper's minus
    the shallower's, [east, north] in map, m/s; only with [current] layer_thickness_m > 0: estimators/models/current.py,
    "Layers")."""
    return gtsam.symbol("s", b)


def key_dim(key: int) -> int:
    """Tangent dimension of a variable from its key (GTSAM symbols keep the character in the top byte)."""
    return DIMS[chr(key >> 56)]
