"""The online estimator's DVL factors of a ping: the batch smoother's (FactorMaker.dvl_factors_for on a state,
FactorMaker.dvl_keyframe_factors_for on the state before a ping between keyframes), except for a slow ping.

Slow pings do not inform the calibration (OnlineConfig.calibration_min_speed_m_s, default 0.1 m/s): below it the
DVL sees noise, the scale's Jacobian k R^T n_v is the velocity estimate's own noise, and linearising it at a
different velocity estimate each time a state leaves the window turns that noise into information: the scale's
sigma would shrink over the static phase, where the batch smoother's filtering sigma barely moves (linearised
once, at its solution). Such a ping keeps its DVL factor (the same
model, on pose, velocity, scale and misalignment: a zero-velocity update when static) with zero Jacobians for
scale and misalignment, which are "considered" at their current value (considered_calibration_factor; a slow ping
between keyframes likewise: online/between_pings.considered_keyframe_factor). Given up: the information of pings
slower than the threshold, (v / sigma)^2 per ping, nothing next to a manoeuvre (the final estimates agree with
the batch smoother's: docs/results.md, "Online estimator").
"""

from __future__ import annotations

import gtsam
import numpy as np

from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.states import correlated_error, dvl_factor_keys, water_current
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.selection import Ping
from gtsam_dvl.estimators.online.between_pings import considered_keyframe_factor
from gtsam_dvl.factors import DvlOptions, OffsetInput, PingMotion, make_dvl_factor

RateInput = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # FactorMaker.velocity_rate_input: b_a, mean b_omega, G


def considered_calibration_factor(
    noise: gtsam.noiseModel.Base,
    i: int,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    d_y: np.ndarray | None = None,
    beam: tuple[np.ndarray, float] | None = None,
    offset: tuple[RateInput, np.ndarray] | None = None,
    config: EstimatorConfig | None = None,
    water: bool = False,
) -> gtsam.CustomFactor:
    """The DVL factor of factors/ on [X_i, V_i, K, C] for a ping too slow to inform the calibration (module
    doc): same error, same Jacobians for pose and velocity, none for scale and misalignment, which are
    "considered" at their current estimate (the velocity's information scales with it). d_y: the 3-D velocity
    (m/s, dvl_link); beam: (d_u, y_j) for one beam; b_omega: the body rate at the ping (rad/s); b_l: the DVL's
    lever arm (m, base_link). offset = (rate_input, n_g): the time-offset model of factors/dvl.py
    (make_dvl_factor with an OffsetInput) on [X_i, V_i, K, C, T_OFFSET] (with d_y), its T_OFFSET Jacobian kept (it is
    the IMU's velocity rate, not the velocity's noise). The keys are states.dvl_factor_keys of config (None: the
    defaults, with the time offset estimated when offset is given); water: a water-track ping (on the current W_i
    too, when config uses them)."""
    if (beam is None) == (d_y is None) or (offset is not None and d_y is None):
        raise ValueError(
            "a considered-calibration DVL factor needs either d_y or beam (d_y with offset)"
        )
    if config is None:
        config = EstimatorConfig(dvl=DvlConfig(estimate_time_offset=offset is not None))
    offset_input = None
    if offset is not None:
        # the model's body rate is the rate input's mean over its window
        (b_a, b_omega, G), n_g = offset
        offset_input = OffsetInput(b_a, n_g, G)
    y: np.ndarray | float = beam[1] if beam is not None else np.asarray(d_y)
    water = water and water_current(config)
    options = DvlOptions(
        b_omega,
        b_l,
        None if beam is None else beam[0],
        offset_input,
        considered=True,
        error_variable=correlated_error(config),
        current_variable=water,
    )
    return make_dvl_factor(noise, dvl_factor_keys(config, i, water=water), y, options)


def ping_speed(p: Ping, use_beams: bool) -> float:
    """What the DVL saw of the speed (m/s): the 3-D velocity's norm, or the fastest valid beam (with beams)."""
    if use_beams and p.beams is not None:
        return float(np.abs(p.beams[1][p.beams[2]]).max())  # a beam sees at most the speed
    return float(np.linalg.norm(p.d_v))


def state_dvl_factors(
    maker: FactorMaker,
    i: int,
    p: Ping,
    b_omega: np.ndarray,
    min_speed_m_s: float,
    rate_input: RateInput | None = None,
) -> list[gtsam.NonlinearFactor]:
    """The DVL factors of ping p on state i (b_omega: the body rate at the ping, rad/s; rate_input: the time-offset
    model's IMU constants, with [dvl] estimate_time_offset): the batch smoother's, with the calibration considered
    when the ping is slower than min_speed_m_s (module doc)."""
    water = p.water_track and water_current(maker.config)  # (a water-track ping: its 3-D velocity)
    use_beams = maker.config.dvl.use_beams and p.beams is not None and not water
    if ping_speed(p, maker.config.dvl.use_beams) >= min_speed_m_s:
        return maker.dvl_factors_for(i, p.d_v, p.d_cov, b_omega, p.beams, rate_input, water)
    b_l = maker.mounting.b_l
    # the beams' factors, but never with the time offset (its model is on the 3-D velocity)
    if use_beams and p.beams is not None and rate_input is None:
        d_u, v, valid = p.beams
        noise1 = maker.beam_noise()
        return [
            considered_calibration_factor(
                noise1, i, b_omega, b_l, beam=(d_u[j], float(v[j])), config=maker.config
            )
            for j in np.flatnonzero(valid)
        ]
    noise = maker.dvl_noise(p.d_cov, water=water)
    offset = None if rate_input is None else (rate_input, maker.offset_gravity())
    return [
        considered_calibration_factor(
            noise, i, b_omega, b_l, d_y=p.d_v, offset=offset, config=maker.config, water=water
        )
    ]


def keyframe_dvl_factors(
    maker: FactorMaker,
    i: int,
    p: Ping,
    b_omega: np.ndarray,
    snap: PingMotion,
    motion: PingMotion,
    min_speed_m_s: float,
    rate_input: RateInput | None,
) -> list[gtsam.NonlinearFactor]:
    """The DVL factors of a ping between keyframes on state i through the IMU motion from it (snap, motion): the
    batch smoother's (FactorMaker.dvl_keyframe_factors_for), with the calibration considered for a slow ping (as
    in state_dvl_factors)."""
    water = p.water_track and water_current(maker.config)  # (a water-track ping: its 3-D velocity)
    use_beams = maker.config.dvl.use_beams and p.beams is not None and not water
    factors = maker.dvl_keyframe_factors_for(
        i,
        p.d_v,
        p.d_cov,
        b_omega,
        motion,
        snap.cov,
        p.beams if use_beams else None,
        rate_input,
        water,
    )
    if ping_speed(p, maker.config.dvl.use_beams) >= min_speed_m_s:
        return factors
    b_l = maker.mounting.b_l
    if rate_input is not None:  # estimate_time_offset (never with beams)
        b_a, b_omega_mean, G = rate_input
        return [
            considered_keyframe_factor(
                factors[0],
                p.d_v,
                b_omega_mean,
                b_l,
                motion,
                offset_input=(b_a, maker.offset_gravity(), G),
            )
        ]
    if use_beams and p.beams is not None:
        d_u, v, valid = p.beams
        return [
            considered_keyframe_factor(f, float(v[j]), b_omega, b_l, motion, d_u=d_u[j])
            for f, j in zip(factors, np.flatnonzero(valid).tolist(), strict=True)
        ]
    return [considered_keyframe_factor(factors[0], p.d_v, b_omega, b_l, motion)]
