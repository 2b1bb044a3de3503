"""The DVL factor: one GTSAM CustomFactor for every option of the DVL measurement model (factors/dvl_model.py).

    measured y = h(x) + noise,   error = h(x) - y

h is the model's prediction: the 3-D velocity in dvl_link (m/s), or one beam's velocity with DvlOptions.d_u; with
a time offset, a lever arm as a variable, a ping seen through the IMU motion from a keyframe, as the options say.
Keys, in this order (DvlOptions.key_names): pose X = n_T_b, velocity V = n_v, [bias B with a motion], scale K,
misalignment C = b_R_d, [time offset T with an OffsetInput], [lever arm L when lever_variable], [the DVL's
correlated velocity error E (a 3-vector in dvl_link, m/s, added to h: its Jacobian I, or d_u^T for a beam) when
error_variable], [the horizontal water current W = [c_east, c_north] (m/s, map) of a water-track ping when
current_variable: h then reads the velocity relative to the water, n_v - [W, 0], and its Jacobian is minus the
velocity's first two columns]. make_dvl_factor is the one constructor, dvl_error the same error as a pure
function (tests, callers that wrap the factor). The wrappers below it keep the signatures the online estimator
and bench/ call.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import gtsam
import numpy as np

from ._common import (
    JacobianSlots,
    Vector3Like,
    as_finite_float,
    as_scale,
    as_unit_vector3,
    as_vector3,
    check_noise,
    fill_slots,
)
from .dvl_model import DvlJacobians, OffsetInput, dvl_model
from .ping_motion import PingMotion
from .so3 import cross


@dataclass(slots=True)
class DvlOptions:
    """A ping's known inputs and the model's options (factors/dvl_model.py): b_omega (rad/s, base_link) the body rate
    relative to map (with a time offset: its mean over the offset's window), b_l (m, base_link) the lever arm (its
    value unused when lever_variable), d_u a beam's unit vector (dvl_link), offset the time offset's IMU
    constants, motion the IMU motion from the keyframe (with its Earth model: PingMotion.motion). considered: the
    scale and misalignment "considered" (zero Jacobians: a ping too slow to inform the calibration, the online
    estimator's; its error is the same)."""

    b_omega: np.ndarray
    b_l: np.ndarray
    d_u: np.ndarray | None = None
    offset: OffsetInput | None = None
    motion: PingMotion | None = None
    lever_variable: bool = False
    considered: bool = False
    error_variable: bool = False
    current_variable: bool = False

    def key_names(self) -> list[str]:
        return (
            ["pose", "vel"]
            + ["bias"] * (self.motion is not None)
            + ["scale", "b_R_d"]
            + ["offset"] * (self.offset is not None)
            + ["lever"] * self.lever_variable
            + ["error"] * self.error_variable
            + ["current"] * self.current_variable
        )

    @property
    def dim(self) -> int:
        return 3 if self.d_u is None else 1

    def checked(self) -> DvlOptions:
        """A copy with finite inputs of the right shapes (copied: the factor must not see later changes to the
        caller's arrays), or ValueError naming the one that is not."""
        offset = self.offset
        if offset is not None:
            G = np.array(offset.G, dtype=float)
            if G.shape != (3, 3) or not np.all(np.isfinite(G)):
                raise ValueError(f"G must be a finite 3x3 matrix, got {G}")
            offset = OffsetInput(as_vector3("b_a", offset.b_a), as_vector3("n_g", offset.n_g), G)
        if self.motion is not None and self.motion.checked().n_G is None:
            raise ValueError("the factor's PingMotion needs its Earth model (PingMotion.motion)")
        return replace(
            self,
            b_omega=as_vector3("b_omega", self.b_omega),
            b_l=as_vector3("b_l", self.b_l),
            d_u=None if self.d_u is None else as_unit_vector3("d_u", self.d_u),
            offset=offset,
        )

    def jacobians(self, J: DvlJacobians) -> list[np.ndarray]:
        """The Jacobians per key (those of the scale and misalignment zero when considered)."""
        out = J.variables() + ([self.error_jacobian()] if self.error_variable else [])
        out += [current_jacobian(J.vel)] if self.current_variable else []
        if self.considered:
            i = 2 + (self.motion is not None)
            out[i], out[i + 1] = np.zeros_like(out[i]), np.zeros_like(out[i + 1])
        return out

    def error_jacobian(self) -> np.ndarray:
        """d h / d E of the correlated error: I (3x3), or a beam's d_u^T (1x3)."""
        return np.eye(3) if self.d_u is None else self.d_u.reshape(1, 3).copy()


def current_jacobian(J_vel: np.ndarray) -> np.ndarray:
    """d h / d W of a water-track ping's current W = [c_east, c_north] (m/s, map): h reads the velocity relative to
    the water, n_v - [W, 0], so its Jacobian is minus the velocity's first two columns (..., m, 2)."""
    return -np.asarray(J_vel)[..., :2]


def _water_relative(n_v: np.ndarray, current: np.ndarray) -> np.ndarray:
    """n_v - [c_east, c_north, 0] (m/s, map)."""
    c = np.asarray(current, dtype=float).reshape(2)
    return np.asarray(n_v, dtype=float) - np.array([c[0], c[1], 0.0])


def _evaluate(
    o: DvlOptions,
    pose: gtsam.Pose3,
    n_v: np.ndarray,
    bias: gtsam.imuBias.ConstantBias | None,
    k: float,
    b_R_d: np.ndarray,
    dt_d: float | None,
    b_l: np.ndarray | None,
    jacobians: bool,
    lever_v: np.ndarray | None = None,
) -> tuple[np.ndarray, DvlJacobians | None]:
    """dvl_model on the variables' values (bias: with o.motion; b_l None: the known o.b_l, whose b_omega x b_l is
    lever_v if given)."""
    n_p = bias_a = bias_g = None
    if bias is not None:
        n_p, bias_a, bias_g = pose.translation(), bias.accelerometer(), bias.gyroscope()
    return dvl_model(
        pose.rotation().matrix(),
        n_v,
        k,
        b_R_d,
        o.b_omega,
        o.b_l if b_l is None else b_l,
        d_u=o.d_u,
        dt_d=dt_d,
        offset=o.offset,
        motion=o.motion,
        n_p=n_p,
        bias_a=bias_a,
        bias_g=bias_g,
        jacobians=jacobians,
        lever=o.lever_variable,
        lever_v=None if b_l is not None else lever_v,
    )


def dvl_error(
    x: Sequence[Any], y: np.ndarray | float, options: DvlOptions, H: JacobianSlots | None = None
) -> np.ndarray:
    """e = h(x) - y, (3,) or (1,) for a beam; x the variables in the keys' order (options.key_names(): Pose3,
    3-vector, [ConstantBias], scale (float or 1-vector), Rot3, [time offset], [lever arm]). With H (a list of one
    slot per key, None or preallocated arrays), the Jacobians are written into it."""
    names = options.key_names()
    if len(x) != len(names):
        raise ValueError(
            f"the DVL factor with these options has {len(names)} variables {names}, got {len(x)}"
        )
    v = dict(zip(names, x, strict=True))
    n_v = np.asarray(v["vel"], dtype=float)
    if "current" in v:  # a water-track ping: the velocity relative to the water
        n_v = _water_relative(n_v, v["current"])
    h, J = _evaluate(
        options,
        v["pose"],
        n_v,
        v.get("bias"),
        as_scale(v["scale"]),
        v["b_R_d"].matrix(),
        as_scale(v["offset"]) if "offset" in v else None,
        np.asarray(v["lever"], dtype=float).reshape(3) if "lever" in v else None,
        H is not None,
    )
    if "error" in v:
        e = np.asarray(v["error"], dtype=float).reshape(3)
        h = h + (e if options.d_u is None else np.asarray(options.d_u, dtype=float) @ e)
    if H is not None and J is not None:
        fill_slots(H, options.jacobians(J))
    return h - np.asarray(y, dtype=float).reshape(-1)


def make_dvl_factor(
    noise: gtsam.noiseModel.Base, keys: Sequence[int], y: Vector3Like | float, options: DvlOptions
) -> gtsam.CustomFactor:
    """The DVL factor on keys (in options.key_names()' order, module doc) of a ping's velocity y (m/s, dvl_link), or
    a beam's velocity (a float) with options.d_u. noise: a GTSAM noise model of the factor's dimension (3, or 1 for
    a beam; possibly robust). Values must hold a Pose3, a 3-vector, [a ConstantBias], a 1-vector, a Rot3, [a
    1-vector], [a 3-vector] at the keys. Raises ValueError on non-finite or wrongly shaped inputs, a wrong number
    of keys, or a noise model of the wrong dimension."""
    o = options.checked()
    check_noise(noise, o.dim)
    names = o.key_names()
    if len(keys) != len(names):
        raise ValueError(
            f"the DVL factor with these options takes {len(names)} keys {names}, got {len(keys)}"
        )
    y_c = as_vector3("d_y", y) if o.d_u is None else np.array([as_finite_float("y_j", y)])
    at = dict(zip(names, keys, strict=True))
    pose_k, vel_k, scale_k, rot_k = at["pose"], at["vel"], at["scale"], at["b_R_d"]
    bias_k, offset_k, lever_k, error_k = (
        at.get("bias"),
        at.get("offset"),
        at.get("lever"),
        at.get("error"),
    )
    current_k = at.get("current")
    J_error = o.error_jacobian() if error_k is not None else None
    lever_v = cross(o.b_omega, o.b_l)  # a known lever arm's velocity, once (not per linearisation)
    # the keys' Jacobians in DvlJacobians (-1: the correlated error's, J_error; -2: the current's)
    fields = [
        -1 if name == "error" else -2 if name == "current" else DvlJacobians._fields.index(name)
        for name in names
    ]

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        n_v = values.atPoint3(vel_k)  # (a Vector or a Point3 entry)
        if current_k is not None:  # a water-track ping: the velocity relative to the water
            n_v = _water_relative(n_v, values.atVector(current_k))
        # (the per-ping path: no second call layer)
        if bias_k is None and lever_k is None and offset_k is None:
            h, J = dvl_model(
                values.atPose3(pose_k).rotation().matrix(),
                n_v,
                values.atVector(scale_k).item(),
                values.atRot3(rot_k).matrix(),
                o.b_omega,
                o.b_l,
                d_u=o.d_u,
                jacobians=H is not None,
                lever_v=lever_v,
            )
        else:
            h, J = _evaluate(
                o,
                values.atPose3(pose_k),
                n_v,
                None if bias_k is None else values.atConstantBias(bias_k),
                # a Python float: cheaper arithmetic than np.float64
                values.atVector(scale_k).item(),
                values.atRot3(rot_k).matrix(),
                None if offset_k is None else values.atVector(offset_k).item(),
                None if lever_k is None else values.atPoint3(lever_k),
                H is not None,
                lever_v,
            )
        if error_k is not None:
            e = values.atVector(error_k)
            h = h + (e if o.d_u is None else o.d_u @ e)
        if H is not None and J is not None:
            if o.considered:
                for i, Jk in enumerate(o.jacobians(J)):
                    H[i] = Jk
            else:  # (J's fields of the keys, found once)
                for i, field in enumerate(fields):
                    H[i] = (
                        J[field]
                        if field >= 0
                        else J_error
                        if field == -1
                        else current_jacobian(J.vel)
                    )
        return h - y_c

    return gtsam.CustomFactor(noise, list(keys), error_func)


# ----- the signatures the online estimator (estimators/online/estimator.py) and bench/bench_factors.py call -------
def _at_state(
    b_omega: Any, b_l: Any, d_u: Any = None, offset: OffsetInput | None = None
) -> DvlOptions:
    """DvlOptions of a ping at a state with a known lever arm."""
    return DvlOptions(
        np.asarray(b_omega, dtype=float),
        np.asarray(b_l, dtype=float),
        None if d_u is None else np.asarray(d_u, dtype=float),
        offset,
    )


def dvl_velocity_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    d_y: np.ndarray,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """dvl_error of the 3-D velocity at a state: keys [pose, velocity, scale, b_R_d]."""
    return dvl_error([n_T_b, n_v, k, b_R_d], d_y, _at_state(b_omega, b_l), H)


def dvl_beam_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    d_u: np.ndarray,
    y_j: float,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """dvl_error of one beam (unit vector d_u, velocity y_j) at a state: keys [pose, velocity, scale, b_R_d]."""
    return dvl_error([n_T_b, n_v, k, b_R_d], y_j, _at_state(b_omega, b_l, d_u), H)


def dvl_velocity_offset_error(
    n_T_b: gtsam.Pose3,
    n_v: np.ndarray,
    k: float | np.ndarray,
    b_R_d: gtsam.Rot3,
    dt: float | np.ndarray,
    d_y: np.ndarray,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    b_a: np.ndarray,
    n_g: np.ndarray,
    G: np.ndarray | None = None,
    H: JacobianSlots | None = None,
) -> np.ndarray:
    """dvl_error of the 3-D velocity with the time offset dt (s): keys [pose, velocity, scale, b_R_d, offset]."""
    offset = OffsetInput(
        np.asarray(b_a, dtype=float),
        np.asarray(n_g, dtype=float),
        np.eye(3) if G is None else np.asarray(G, dtype=float),
    )
    return dvl_error([n_T_b, n_v, k, b_R_d, dt], d_y, _at_state(b_omega, b_l, offset=offset), H)


def make_dvl_velocity_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    d_y: Vector3Like,
    b_omega: Vector3Like,
    b_l: Vector3Like,
) -> gtsam.CustomFactor:
    """make_dvl_factor of the 3-D velocity d_y at a state, lever arm b_l known."""
    return make_dvl_factor(
        noise, [pose_key, vel_key, scale_key, b_R_d_key], d_y, _at_state(b_omega, b_l)
    )


def make_dvl_beam_factor(
    noise: gtsam.noiseModel.Base,
    pose_key: int,
    vel_key: int,
    scale_key: int,
    b_R_d_key: int,
    d_u: Vector3Like,
    y_j: float,
    b_omega: Vector3Like,
    b_l: Vector3Like,
) -> gtsam.CustomFactor:
    """make_dvl_factor of one beam (unit vector d_u, velocity y_j) at a state, lever arm b_l known."""
    return make_dvl_factor(
        noise, [pose_key, vel_key, scale_key, b_R_d_key], y_j, _at_state(b_omega, b_l, d_u)
    )
