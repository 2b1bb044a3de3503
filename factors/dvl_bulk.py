"""The DVL factors of a whole log evaluated at once with numpy: errors and Jacobians of N measurement rows.

Why: evaluated one by one through GTSAM's CustomFactor, each DVL factor costs a Python call per linearisation
or error evaluation, and on a 5 Hz log with 1 s keyframes there are 18,000 of them per hour, evaluated about ten
times per solve (the timings: docs/results.md, Speed). The batch smoother owns its Gauss-Newton loop
(estimators/graph/solver.py), so it can evaluate them all in a few vectorised numpy operations instead
(estimators/graph/bulk.py turns the result into GTSAM Jacobian factors). The model is the per-factor one,
factors/dvl_model.py, called on stacks: every row is a ping between keyframes, seen from the state before it through its
IMU motion (factors/ping_motion.py); a ping at its own state has the motion of length zero (PingMotion.none), which
gives the state's own attitude and velocity, the per-factor Jacobians and zero bias columns. A row is a ping's 3-D
velocity, or with beams one beam.

Keys per row (the carrier's order in estimators/graph/bulk.py): [pose X_i (rotation, translation), velocity V_i,
bias B ([accelerometer, gyroscope]), scale k, misalignment b_R_d] + [time offset dt_d] + [lever arm b_l].
tests/factors/test_dvl_bulk.py checks errors and Jacobians against the per-factor ones to 1e-9 and the
Jacobians against numerical derivatives.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from .dvl_model import DvlJacobians, OffsetInput, dvl_model
from .ping_motion import PingMotion


@dataclass
class BulkPings:
    """N measurement rows, each of one ping (m = 3: its velocity) or of one beam (m = 1).

    state (N,): index of the row's state in the state arrays; y (N, m) m/s: the velocity in dvl_link, or the beam's;
    d_u (N, 3): the beams' unit vectors (dvl_link), None for 3-D rows; b_omega (N, 3) rad/s: the body rate relative
    to map at the ping (with the time offset: the mean over its window, FactorMaker.velocity_rate_input); motion:
    the IMU motion from the state to the ping, with the Earth model at the state (PingMotion of N). With the time
    offset: offset_b_a (N, 3) m/s^2 and offset_G (N, 3, 3) (FactorMaker.velocity_rate_input), else None."""

    state: np.ndarray
    y: np.ndarray
    b_omega: np.ndarray
    motion: PingMotion
    d_u: np.ndarray | None = None
    offset_b_a: np.ndarray | None = None
    offset_G: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.state)

    @property
    def dim(self) -> int:
        """Rows per measurement: 3 for the velocity, 1 for a beam."""
        return int(self.y.shape[1])

    def part(self, sl: slice) -> BulkPings:
        """The rows sl (views)."""
        parts: dict[str, Any] = {
            f.name: None if getattr(self, f.name) is None else getattr(self, f.name)[sl]
            for f in fields(self)
        }
        return BulkPings(**parts)


def dvl_ping_errors(
    p: BulkPings,
    n_R_i: np.ndarray,
    n_p_i: np.ndarray,
    n_v_i: np.ndarray,
    b_a: np.ndarray,
    b_g: np.ndarray,
    k: float,
    b_R_d: np.ndarray,
    b_l: np.ndarray,
    dt_d: float | None = None,
    offset_n_g: np.ndarray | None = None,
    lever: bool = False,
    jacobians: bool = True,
) -> tuple[np.ndarray, DvlJacobians | None]:
    """Errors e = h - y (N, m) of the rows (module doc) and, with jacobians, their Jacobians (N, m, d) per key.

    n_R_i (N, 3, 3), n_p_i (N, 3) m, n_v_i (N, 3) m/s: each row's state attitude, position and velocity; b_a, b_g
    (N, 3): the bias at that state (m/s^2, rad/s); k the scale, b_R_d (3, 3) the misalignment, b_l (3,) m the lever
    arm (lever: a variable, its Jacobian too); dt_d (s) the time offset with offset_n_g (3,) the offset model's
    gravity in map (FactorMaker.offset_gravity), or None for the model without offset."""
    offset = None
    if dt_d is not None:
        assert p.offset_b_a is not None and p.offset_G is not None and offset_n_g is not None
        offset = OffsetInput(p.offset_b_a, np.asarray(offset_n_g, dtype=float), p.offset_G)
    h, J = dvl_model(
        n_R_i,
        n_v_i,
        k,
        b_R_d,
        p.b_omega,
        b_l,
        d_u=p.d_u,
        dt_d=dt_d,
        offset=offset,
        motion=p.motion,
        n_p=n_p_i,
        bias_a=b_a,
        bias_g=b_g,
        jacobians=jacobians,
        lever=lever,
    )
    return h - p.y, J
