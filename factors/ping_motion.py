"""The IMU motion from a keyframe to a ping, and the ping's attitude and velocity predicted through it.

With states only at keyframes ([solver] keyframe_spacing_s), a ping at t_p between keyframes i and i+1 sees keyframe
i's attitude n_R_i, position n_p_i, velocity n_v_i and the IMU bias (b_a, b_g) through the preintegrated IMU motion
over [t_i, t_p] (dt = t_p - t_i; PingMotion: zero-bias deltas dR, dv, dp and their bias Jacobians, from GTSAM's
preintegration, estimators/graph/keyframes.py):

    n_R_b(t_p) = Exp(-[n_omega_ie] dt) n_R_i dR(b_g),          dR(b_g) = dR Exp(dR_dbg b_g)
    n_v(t_p)   = n_v_i + n_g(n_p_i) dt - 2 n_omega_ie x n_v_i dt + n_R_i dv(b_a, b_g)
                 - n_omega_ie x (n_R_i (dt dv + dp) + n_g dt^2),
                 dv(b_a, b_g) = dv + dv_dba b_a + dv_dbg b_g

(Earth rate w = n_omega_ie constant in the Earth-fixed map frame.) The last line is first order in w and exact
there: the Earth's turn of the body acting on the specific force (n_R_b(t) = Exp(-[w] t) n_R_i dR(t), so the
specific force integrated in map is n_R_i dv - w x n_R_i (dt dv - dp)), and the Coriolis term of the velocity
change within the interval (-2 w x (n_R_i dp + n_g dt^2 / 2)); dp is GTSAM's deltaPij. A static vehicle needs them:
without them the velocity predicted after 1 s is off by w x g / 2 = 3.6e-4 m/s, and an accelerating one by
2 w x dp. They are taken at zero bias (their bias dependence is below 1e-10 m/s). GTSAM's own prediction agrees to
1e-6 m/s over 0.8 s in a 0.3 rad/s turn at 0.5 m/s^2 (tests/factors/test_ping_motion.py). Normal gravity n_g at the
keyframe's position, to first order about a reference n_p0: n_g0 + n_G (n_p_i - n_p0), n_G the gravity gradient,
1.5e-6 s^-2 (over dt = 1 s its Jacobian is 1.5e-6 (m/s)/m, kept for exactness).

A ping at its own state is the motion of length zero (PingMotion.none: dt = 0, dR = I, zero deltas), which
gives the keyframe's own attitude and velocity. Every array has the same leading axes (one ping: (), N pings: (N,)).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, NamedTuple

import numpy as np

from . import so3
from .so3 import rotate

_FIELDS = ("dt", "dR", "dv", "dp", "dR_dbg", "dv_dba", "dv_dbg")
_TAIL = {
    "dt": (),
    "dR": (3, 3),
    "dv": (3,),
    "dp": (3,),
    "dR_dbg": (3, 3),
    "dv_dba": (3, 3),
    "dv_dbg": (3, 3),
    "cov": (9, 9),
    "n_g0": (3,),
    "n_p0": (3,),
    "n_G": (3, 3),
}


class EarthTerms(NamedTuple):
    """What ping_state needs of a motion and the Earth rate alone, computed once per PingMotion."""

    dt: Any  # dt as a column (..., 1), or a float for one ping
    earth_turn: np.ndarray  # Exp(-[w] dt) (..., 3, 3)
    v_v: np.ndarray  # I - 2 dt [w]_x (..., 3, 3)
    w_x: np.ndarray  # [w]_x (3, 3)
    c: np.ndarray  # dt dv + dp (..., 3)
    c_x: np.ndarray  # [c]_x (..., 3, 3)
    trans_G: np.ndarray  # (dt I - dt^2 [w]_x) n_G (..., 3, 3)


@dataclass
class PingMotion:
    """The IMU motion from a keyframe at t_i to pings at t_i + dt (module doc), for one ping or N.

    dt (s); dR (3x3): the body at the ping in the body at the keyframe, from the gyros with zero bias; dv (m/s): the
    specific force integrated in the keyframe's body axes with zero bias; dp (m): dv integrated once more (GTSAM's
    deltaPij); dR_dbg: dR's right tangent per gyro bias (s); dv_dba (s), dv_dbg (m/s per rad/s): dv per accelerometer
    and gyro bias; cov (9x9, [rotation, position, velocity]): the preintegration's covariance. The Earth
    model at the keyframe (motion(), needed by ping_state): n_omega_ie (3,) rad/s Earth rate in map (zero in the flat
    model); n_g0 (m/s^2) gravity in map at n_p0 (m, map), n_G (1/s^2) its gradient there (zero when flat)."""

    dt: Any
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dR_dbg: np.ndarray
    dv_dba: np.ndarray
    dv_dbg: np.ndarray
    cov: np.ndarray
    n_omega_ie: np.ndarray = field(default_factory=lambda: np.zeros(3))
    n_g0: np.ndarray | None = None
    n_p0: np.ndarray | None = None
    n_G: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.dt = float(self.dt) if np.ndim(self.dt) == 0 else np.asarray(self.dt, dtype=float)
        self.n_omega_ie = np.asarray(self.n_omega_ie, dtype=float).reshape(3)

    def checked(self) -> PingMotion:
        """self, if every array is finite and of the shape its leading axes (dt's) ask for, else ValueError naming
        the field."""
        lead = np.shape(self.dt)
        if not np.all(np.isfinite(self.dt)):
            raise ValueError(f"PingMotion.dt must be finite, got {self.dt}")
        for name in _FIELDS[1:] + ("cov", "n_g0", "n_p0", "n_G"):
            value = getattr(self, name)
            if value is not None and (
                np.shape(value) != lead + _TAIL[name] or not np.all(np.isfinite(value))
            ):
                raise ValueError(
                    f"PingMotion.{name} must be a finite array of shape {lead + _TAIL[name]}, "
                    f"got {value!r}"
                )
        if not np.all(np.isfinite(self.n_omega_ie)):
            raise ValueError(f"PingMotion.n_omega_ie must be finite, got {self.n_omega_ie}")
        return self

    @classmethod
    def none(cls, n: int | None = None) -> PingMotion:
        """No motion (dt = 0, dR = I, zero deltas): a ping at its own state; n pings, or one if n is None."""
        lead = () if n is None else (n,)
        z33 = np.zeros(lead + (3, 3))
        return cls(
            0.0 if n is None else np.zeros(n),
            np.broadcast_to(np.eye(3), lead + (3, 3)).copy(),
            np.zeros(lead + (3,)),
            np.zeros(lead + (3,)),
            z33,
            z33.copy(),
            z33.copy(),
            np.zeros(lead + (9, 9)),
        )

    def motion(
        self, n_omega_ie: np.ndarray, n_g0: np.ndarray, n_p0: np.ndarray, n_G: np.ndarray
    ) -> PingMotion:
        """These deltas with the Earth model at the keyframe (Earth rate rad/s and gravity m/s^2 in map, at n_p0 m,
        its gradient 1/s^2)."""
        return dataclasses.replace(self, n_omega_ie=n_omega_ie, n_g0=n_g0, n_p0=n_p0, n_G=n_G)

    def __len__(self) -> int:
        return len(self.dR) if self.dR.ndim == 3 else 1

    def __getitem__(self, index: Any) -> PingMotion:
        """The pings at index (an int, slice or index array: numpy's indexing), without checks; the Earth terms
        already computed go with them."""
        out = object.__new__(PingMotion)
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            setattr(out, f.name, value if value is None or f.name == "n_omega_ie" else value[index])
        if "earth" in self.__dict__:
            e = self.earth
            out.__dict__["earth"] = EarthTerms(*(x if x is e.w_x else x[index] for x in e))
        return out

    def get(self, q: int) -> PingMotion:
        """Ping q of these arrays, a single PingMotion (views)."""
        return self[q]

    def put(self, q: int, m: PingMotion) -> None:
        """Ping q of these arrays set to the single ping m's deltas and covariance."""
        for name in _FIELDS + ("cov",):
            value = getattr(m, name)
            if value is not None:
                getattr(self, name)[q] = value

    @classmethod
    def empty(cls, n: int) -> PingMotion:
        """Arrays for n pings, to be filled with put()."""
        return cls.none(n)

    @cached_property
    def earth(self) -> EarthTerms:
        """The terms of ping_state that depend on the motion and the Earth rate only."""
        if self.n_G is None:
            raise ValueError(
                "PingMotion without the Earth model: motion(n_omega_ie, n_g0, n_p0, n_G) first"
            )
        w = self.n_omega_ie
        w_x = so3.skew(w)
        single = isinstance(self.dt, float)
        dt = self.dt if single else self.dt[..., None]
        dt3 = dt if single else dt[..., None]
        c = dt * self.dv + self.dp
        return EarthTerms(
            dt,
            so3.exp(-w * dt),
            np.eye(3) - 2.0 * dt3 * w_x,
            w_x,
            c,
            so3.skew(c),
            (dt3 * np.eye(3) - dt3**2 * w_x) @ self.n_G,
        )


PingStateJacobians = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def ping_state(
    n_R_i: np.ndarray,
    n_p_i: np.ndarray,
    n_v_i: np.ndarray,
    b_a: np.ndarray,
    b_g: np.ndarray,
    m: PingMotion,
    with_jacobians: bool = True,
) -> tuple[np.ndarray, np.ndarray, PingStateJacobians | None]:
    """(n_R_b at the ping (..., 3, 3), n_v at the ping (..., 3), Jacobians) from keyframe i's attitude, position,
    velocity and the bias (b_a m/s^2, b_g rad/s) through m (module doc). Jacobians (A_R_pose (..., 3, 6), A_R_bias
    (..., 3, 6), A_v_pose (..., 3, 6), A_v_vel (..., 3, 3), A_v_bias (..., 3, 6)): A_R_* the right tangent of the
    ping's attitude, A_v_* its velocity, per the pose's right tangent [rotation, translation], the velocity and the
    bias tangent [accelerometer, gyroscope]; None without with_jacobians."""
    e = m.earth
    # (m.earth checked the Earth model)
    assert m.n_g0 is not None and m.n_p0 is not None and m.n_G is not None
    phi = rotate(m.dR_dbg, b_g)
    dR_c = m.dR @ so3.exp(phi)
    dv_c = m.dv + rotate(m.dv_dba, b_a) + rotate(m.dv_dbg, b_g)
    n_g = m.n_g0 + rotate(m.n_G, n_p_i - m.n_p0)
    n_R_p = e.earth_turn @ n_R_i @ dR_c
    n_v_p = (
        rotate(e.v_v, n_v_i)
        + n_g * e.dt
        + rotate(n_R_i, dv_c)
        - rotate(e.w_x, rotate(n_R_i, e.c) + n_g * e.dt**2)
    )
    if not with_jacobians:
        return n_R_p, n_v_p, None
    z33 = np.zeros(np.shape(dR_c))
    A_R_pose = np.concatenate((np.swapaxes(dR_c, -1, -2), z33), axis=-1)
    A_R_bias = np.concatenate((z33, so3.right_jacobian(phi) @ m.dR_dbg), axis=-1)
    A_v_pose = np.concatenate(
        (-n_R_i @ so3.skew(dv_c) + e.w_x @ n_R_i @ e.c_x, e.trans_G @ n_R_i), axis=-1
    )
    A_v_bias = np.concatenate((n_R_i @ m.dv_dba, n_R_i @ m.dv_dbg), axis=-1)
    return n_R_p, n_v_p, (A_R_pose, A_R_bias, A_v_pose, e.v_v, A_v_bias)


def keyframe_ping_covariance(
    cov_pim: np.ndarray, dR: np.ndarray, d_R_b: np.ndarray, b_v: np.ndarray, k: float = 1.0
) -> np.ndarray:
    """The preintegration noise over [t_i, t_p] mapped into the ping's 3-D velocity (..., 3, 3), m^2/s^2:
    J cov_pim J^T with J = k d_R_b [[b_v]_x, 0, dR^T] over GTSAM's preintegration error [rotation, position,
    velocity] (cov_pim (..., 9, 9)): a right rotation of the ping's attitude and a velocity increment in the
    keyframe's body axes. b_v (..., 3) m/s, base_link: the body velocity at the ping (e.g. from the ping at the
    prior calibration), d_R_b = b_R_d^T. With navigation-grade noise (10 micro-g/sqrt(Hz)) it is 1e-4 m/s over 1 s."""
    b_v = np.asarray(b_v, dtype=float)
    J = np.zeros(b_v.shape[:-1] + (3, 9))
    J[..., :3] = so3.skew(b_v)
    J[..., 6:] = np.swapaxes(np.asarray(dR, dtype=float), -1, -2)
    J = k * np.asarray(d_R_b, dtype=float) @ J
    return np.asarray(J @ cov_pim @ np.swapaxes(J, -1, -2))
