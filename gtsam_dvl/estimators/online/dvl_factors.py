"""The online estimator's DVL factors of a ping: the batch smoother's (FactorMaker.dvl_factors_for on a state,
FactorMaker.dvl_keyframe_factors_for on the state before a ping between keyframes), except for a slow ping.

Slow pings do not inform the calibration (OnlineConfig.calibration_min_speed_m_s, default 0.1 m/s): below it the
DVL sees noise, the scale's Jacobian k R^T n_v is the velocity estimate's own noise, and linearising it at a
different velocity estimate each time a state leaves the window turns that noise into information: the scale's
sigma would shrink over the static phase, where the batch smoother's filtering sigma barely moves (linearised
once, at its solution). Such a ping keeps its DVL factor (the same
model, on pose, velocity, scale and misalignment: a zero-velocity update when static) with zero Jacobians for
scale and misalignment, which are "considered" at their current value (considered_calibration_factor; a slow ping
between keyframes likewise: online/keyframes.considered_keyframe_factor). Given up: the information of pings
slower than the threshold, (v / sigma)^2 per ping, nothing next to a manoeuvre (the final estimates agree with
the batch smoother's: docs/results.md, "Online estimator").
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, T_OFFSET, V, X
from gtsam_dvl.estimators.factor_maker import FactorMaker
from gtsam_dvl.estimators.keyframes import PimSnapshot
from gtsam_dvl.estimators.online.keyframes import considered_keyframe_factor
from gtsam_dvl.estimators.selection import Ping
from gtsam_dvl.factors import PingMotion, dvl_beam_error, dvl_velocity_error, dvl_velocity_offset_error

RateInput = tuple[np.ndarray, np.ndarray, np.ndarray]  # FactorMaker.velocity_rate_input: b_a, mean b_omega, G


def considered_calibration_factor(noise: gtsam.noiseModel.Base, i: int, b_omega: np.ndarray, b_l: np.ndarray,
                                  d_y: np.ndarray | None = None,
                                  beam: tuple[np.ndarray, float] | None = None,
                                  offset: tuple[RateInput, np.ndarray] | None = None) -> gtsam.CustomFactor:
    """The DVL factor of factors/ on [X_i, V_i, K, C] for a ping too slow to inform the calibration (module
    doc): same error, same Jacobians for pose and velocity, none for scale and misalignment, which are
    "considered" at their current estimate (the velocity's information scales with it). d_y: the 3-D velocity
    (m/s, dvl_link); beam: (d_u, y_j) for one beam; b_omega: the body rate at the ping (rad/s); b_l: the DVL's
    lever arm (m, base_link). offset = (rate_input, n_g): the time-offset model of factors/dvl.py
    (make_dvl_factor with an OffsetInput) on [X_i, V_i, K, C, T_OFFSET] (with d_y), its T_OFFSET Jacobian kept (it is
    the IMU's velocity rate, not the velocity's noise)."""
    if (beam is None) == (d_y is None) or (offset is not None and d_y is None):
        raise ValueError("a considered-calibration DVL factor needs either d_y or beam (d_y with offset)")

    def error_func(this: gtsam.CustomFactor, values: gtsam.Values, H: Any) -> np.ndarray:
        pose, n_v = values.atPose3(X(i)), values.atVector(V(i))
        k, b_R_d = values.atVector(K_SCALE), values.atRot3(C_MISALIGN)
        slots: list[Any] | None = None if H is None else [None] * (4 if offset is None else 5)
        if offset is not None:
            assert d_y is not None  # checked above; tells mypy
            (b_a, b_omega_mean, G), n_g = offset
            e = dvl_velocity_offset_error(pose, n_v, k, b_R_d, values.atVector(T_OFFSET), d_y, b_omega_mean, b_l,
                                          b_a, n_g, G, slots)
            if H is not None and slots is not None:
                H[0], H[1], H[4] = slots[0], slots[1], slots[4]
                H[2], H[3] = np.zeros((3, 1)), np.zeros((3, 3))
            return e
        if beam is not None:
            e = dvl_beam_error(pose, n_v, k, b_R_d, beam[0], beam[1], b_omega, b_l, slots)
        else:
            assert d_y is not None  # checked above; tells mypy
            e = dvl_velocity_error(pose, n_v, k, b_R_d, d_y, b_omega, b_l, slots)
        if H is not None and slots is not None:
            H[0], H[1] = slots[0], slots[1]
            H[2], H[3] = np.zeros((len(e), 1)), np.zeros((len(e), 3))
        return e

    keys = [X(i), V(i), K_SCALE, C_MISALIGN] + ([T_OFFSET] if offset is not None else [])
    return gtsam.CustomFactor(noise, keys, error_func)


def ping_speed(p: Ping, use_beams: bool) -> float:
    """What the DVL saw of the speed (m/s): the 3-D velocity's norm, or the fastest valid beam (with beams)."""
    if use_beams and p.beams is not None:
        return float(np.abs(p.beams[1][p.beams[2]]).max())  # a beam sees at most the speed
    return float(np.linalg.norm(p.d_v))


def state_dvl_factors(maker: FactorMaker, i: int, p: Ping, b_omega: np.ndarray, min_speed_m_s: float,
                      rate_input: RateInput | None = None) -> list[gtsam.NonlinearFactor]:
    """The DVL factors of ping p on state i (b_omega: the body rate at the ping, rad/s; rate_input: the time-offset
    model's IMU constants, with [dvl] estimate_time_offset): the batch smoother's, with the calibration considered
    when the ping is slower than min_speed_m_s (module doc)."""
    use_beams = maker.config.dvl.use_beams and p.beams is not None
    if ping_speed(p, maker.config.dvl.use_beams) >= min_speed_m_s:
        return maker.dvl_factors_for(i, p.d_v, p.d_cov, b_omega, p.beams, rate_input)
    b_l = maker.mounting.b_l
    if rate_input is not None:  # estimate_time_offset (never with beams)
        return [considered_calibration_factor(maker.dvl_noise(p.d_cov), i, b_omega, b_l, d_y=p.d_v,
                                              offset=(rate_input, maker.offset_gravity()))]
    if use_beams and p.beams is not None:
        d_u, v, valid = p.beams
        noise1 = maker.beam_noise()
        return [considered_calibration_factor(noise1, i, b_omega, b_l, beam=(d_u[j], float(v[j])))
                for j in np.flatnonzero(valid)]
    return [considered_calibration_factor(maker.dvl_noise(p.d_cov), i, b_omega, b_l, d_y=p.d_v)]


def keyframe_dvl_factors(maker: FactorMaker, i: int, p: Ping, b_omega: np.ndarray, snap: PimSnapshot,
                         motion: PingMotion, min_speed_m_s: float,
                         rate_input: RateInput | None) -> list[gtsam.NonlinearFactor]:
    """The DVL factors of a ping between keyframes on state i through the IMU motion from it (snap, motion): the
    batch smoother's (FactorMaker.dvl_keyframe_factors_for), with the calibration considered for a slow ping (as
    in state_dvl_factors)."""
    use_beams = maker.config.dvl.use_beams and p.beams is not None
    factors = maker.dvl_keyframe_factors_for(i, p.d_v, p.d_cov, b_omega, motion, snap.cov,
                                             p.beams if use_beams else None, rate_input)
    if ping_speed(p, maker.config.dvl.use_beams) >= min_speed_m_s:
        return factors
    b_l = maker.mounting.b_l
    if rate_input is not None:  # estimate_time_offset (never with beams)
        b_a, b_omega_mean, G = rate_input
        return [considered_keyframe_factor(factors[0], p.d_v, b_omega_mean, b_l, motion,
                                           offset_input=(b_a, maker.offset_gravity(), G))]
    if use_beams and p.beams is not None:
        d_u, v, valid = p.beams
        return [considered_keyframe_factor(f, float(v[j]), b_omega, b_l, motion, d_u=d_u[j])
                for f, j in zip(factors, np.flatnonzero(valid).tolist(), strict=True)]
    return [considered_keyframe_factor(factors[0], p.d_v, b_omega, b_l, motion)]
