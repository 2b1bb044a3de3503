"""The DVL measurement model: one function for one ping or N, with its options (docs/conventions.md, paper eq. 2
and 7 with the lever arm).

    h = k * d_R_b * ( b_v  +  dt_d * b_vdot  +  b_omega x b_l ),      d_R_b = b_R_d^T,   b_v = n_R_b^T n_v
    b_vdot = b_a + G n_R_b^T n_g - b_omega x b_v                        (time offset; otherwise dt_d = 0)
    h_j = d_u . h                                                       (one beam)
    (n_R_b, n_v) = the state at the ping through the IMU motion          (a ping between keyframes)
                   from keyframe i (factors/ping_motion.py ping_state)

h (m/s) is the velocity measured in dvl_link: the body velocity b_v of base_link in map, seen in dvl_link
(misalignment b_R_d: dvl_link -> base_link) at scale k, plus the lever arm's velocity b_omega x b_l.
Options, each reducing to the base case when off:
- time offset dt_d (s; the ping stamped t measures the velocity at t + dt_d), to first order in dt_d: b_a (m/s^2)
  the mean specific force over a window around the stamp (base_link; the Coriolis acceleration left out), G the
  mean body rotation since the stamp over that window, transposed (gravity seen in the body while b_a was
  measured), n_g the gravity in map (OffsetInput: FactorMaker.velocity_rate_input and offset_gravity);
- lever arm b_l (m, base_link): a known input, or a variable (its Jacobian k d_R_b [b_omega]_x: h is linear in
  b_l, so a lever arm is observable only from rotation, and one along the axis of every rotation is not);
- beam: the projection on the beam's unit vector d_u (dvl_link), so one, two or three good beams contribute;
- motion from a keyframe: the ping's attitude and velocity from keyframe i's pose, velocity and the IMU bias
  through the preintegrated motion (PingMotion).
b_omega (rad/s, base_link) is the body rate relative to map at the ping (with the time offset: its mean over the
window), a known input.

Keys (the variables, in this order): pose X = n_T_b (Pose3), velocity V = n_v (3-vector, map), [bias B
(ConstantBias, tangent [accelerometer, gyroscope]) with a motion], scale K (1-vector), misalignment C = b_R_d
(Rot3), [time offset T (1-vector, s)], [lever arm L (3-vector, m, base_link) when a variable]. With a motion X, V
are keyframe i's. Pose and b_R_d are perturbed on the right (GTSAM's retract), pose tangent [rotation,
translation]. Jacobians at the ping's state, M = I - dt_d [b_omega]_x, A = k d_R_b (d_u^T k d_R_b for a beam):

    rotation (right):  A (M [b_v]_x + dt_d G [n_R_b^T n_g]_x)       translation: 0 (the velocity is a variable)
    velocity:          A M n_R_b^T                                   scale: d_R_b u (projected), u the bracket
    b_R_d:             [k d_R_b u]_x (projected)                     time offset: A b_vdot
    lever arm:         A [b_omega]_x
and, for a filter that holds them in its state, the inputs': b_omega: A (dt_d [b_v]_x - [b_l]_x), b_a: dt_d A.
With a motion, the rotation and velocity Jacobians go through ping_state's to the keyframe's pose, velocity and
bias. Tests: the model against scipy's rotations (tests/factors/test_dvl_model.py), the ping state against GTSAM's
ImuFactor prediction (test_ping_motion.py), every Jacobian of every combination of options against numerical
derivatives (test_dvl.py).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .ping_motion import PingMotion, ping_state
from .so3 import cross, rotate, skew, unrotate

_EYE3 = np.eye(3)
_EYE3.setflags(write=False)
# (the translation block of a ping's pose Jacobian: np.concatenate copies it)
_Z33 = np.zeros((3, 3))
_Z33.setflags(write=False)


class OffsetInput(NamedTuple):
    """The IMU constants of the time-offset model at a ping (module doc): b_a (..., 3) m/s^2, n_g (3,) m/s^2 in map,
    G (..., 3, 3)."""

    b_a: np.ndarray
    n_g: np.ndarray
    G: np.ndarray


class DvlJacobians(NamedTuple):
    """dh per key (..., m, d), m = 3 (velocity) or 1 (beam); None where the key is not a variable. b_omega and b_a:
    per the inputs (dvl_model(inputs=True))."""

    pose: np.ndarray
    vel: np.ndarray
    bias: np.ndarray | None
    scale: np.ndarray
    b_R_d: np.ndarray
    offset: np.ndarray | None
    lever: np.ndarray | None
    b_omega: np.ndarray | None = None
    b_a: np.ndarray | None = None

    def variables(self) -> list[np.ndarray]:
        """The Jacobians of the variables, in the keys' order (module doc)."""
        return [J for J in self[:7] if J is not None]


def _t(R: np.ndarray) -> np.ndarray:
    return R.T if R.ndim == 2 else np.swapaxes(R, -1, -2)


def dvl_model(
    n_R_b: np.ndarray,
    n_v: np.ndarray,
    k: float,
    b_R_d: np.ndarray,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    *,
    d_u: np.ndarray | None = None,
    dt_d: float | None = None,
    offset: OffsetInput | None = None,
    motion: PingMotion | None = None,
    n_p: Any = None,
    bias_a: Any = None,
    bias_g: Any = None,
    jacobians: bool = True,
    lever: bool = False,
    inputs: bool = False,
    lever_v: np.ndarray | None = None,
) -> tuple[np.ndarray, DvlJacobians | None]:
    """The predicted measurement h (..., 3), or (..., 1) for a beam, and its Jacobians (module doc).

    n_R_b (..., 3, 3), n_v (..., 3) m/s: the ping's attitude and velocity in map, or with motion keyframe i's, with
    its position n_p (..., 3) m and the IMU bias bias_a (m/s^2), bias_g (rad/s) (..., 3). k the scale, b_R_d (3, 3)
    the misalignment; b_omega (..., 3) rad/s, b_l (3,) or (..., 3) m. d_u (..., 3): a beam's unit vector. dt_d (s)
    with offset: the time-offset model. lever: the lever arm's Jacobian too (a variable); inputs: b_omega's and
    b_a's. jacobians=False: h alone (None for the Jacobians). lever_v: b_omega x b_l, if the caller has it (a factor
    with a known lever arm computes it once, not per linearisation)."""
    A_motion = None
    if motion is not None:
        n_R_b, n_v, A_motion = ping_state(n_R_b, n_p, n_v, bias_a, bias_g, motion, jacobians)
    b_v = unrotate(n_R_b, n_v)
    u = b_v + (cross(b_omega, b_l) if lever_v is None else lever_v)
    if dt_d is not None:
        if offset is None:
            raise ValueError("the time offset dt_d needs its OffsetInput")
        b_g0 = unrotate(n_R_b, offset.n_g)
        b_vdot = offset.b_a + rotate(offset.G, b_g0) - cross(b_omega, b_v)
        u = u + dt_d * b_vdot
    d_v = unrotate(b_R_d, u)  # d_R_b u
    kd_v = k * d_v
    if d_u is None:
        h = kd_v
    else:
        h = (
            d_u @ kd_v
            if d_u.ndim == 1 and kd_v.ndim == 1
            else np.einsum("...i,...i->...", d_u, kd_v)
        )[..., None]
    if not jacobians:
        return h, None
    A = k * _t(b_R_d)  # k d_R_b
    P = None if d_u is None else d_u[..., None, :]  # the beam's projection (..., 1, 3)
    if P is not None:
        A = P @ A
    if dt_d is None:
        h_R = A @ skew(b_v)
        h_v = A @ _t(n_R_b)
        J_offset = None
    else:
        assert offset is not None
        AM = A @ (_EYE3 - dt_d * skew(b_omega))
        h_R = AM @ skew(b_v) + dt_d * (A @ offset.G) @ skew(b_g0)
        h_v = AM @ _t(n_R_b)
        J_offset = A @ b_vdot[..., None]
    J_scale = d_v[..., None] if P is None else P @ d_v[..., None]
    J_rot = skew(kd_v) if P is None else P @ skew(kd_v)
    J_lever = A @ skew(b_omega) if lever else None
    J_omega = J_acc = None
    if inputs:
        b_l_x = skew(np.broadcast_to(b_l, np.shape(b_v)))
        J_omega = -(A @ b_l_x) if dt_d is None else A @ (dt_d * skew(b_v) - b_l_x)
        J_acc = None if dt_d is None else dt_d * A
    if A_motion is None:
        J_pose = np.concatenate(
            (h_R, _Z33[: len(h_R)] if h_R.ndim == 2 else np.zeros(h_R.shape)), axis=-1
        )
        return h, DvlJacobians(J_pose, h_v, None, J_scale, J_rot, J_offset, J_lever, J_omega, J_acc)
    A_R_pose, A_R_bias, A_v_pose, A_v_vel, A_v_bias = A_motion
    return h, DvlJacobians(
        h_R @ A_R_pose + h_v @ A_v_pose,
        h_v @ A_v_vel,
        h_R @ A_R_bias + h_v @ A_v_bias,
        J_scale,
        J_rot,
        J_offset,
        J_lever,
        J_omega,
        J_acc,
    )
