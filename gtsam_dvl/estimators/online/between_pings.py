"""Pings between keyframes, online: the pings between two states, on the state before them as the batch has them.

With `[solver] keyframe_spacing_s` > 0 the online estimator makes states where the batch smoother does (the
keyframes of selection.keyframe_mask, decided ping by ping with the same selection.KeyframeRule, and the DVL-dropout
fillers); every other usable ping becomes the batch smoother's DVL factor on the state before it through the
IMU motion up to the ping (factors/dvl.py with a PingMotion, FactorMaker.dvl_keyframe_factors_for). This module
holds what the online estimator needs for them and the batch path has no use for:

- StatePreintegration: the next IMU factor's preintegration from the newest state, integrated as the samples
  come, and the IMU motion to each ping between keyframes taken from it on the way (the batch smoother's
  keyframes.interval_with_snapshots, one ping at a time: the same pieces in the same order, so the snapshots
  are the same to the last bit: tests/estimators/test_online_keyframes.py).
- KeyframeGravity: the keyframe factors' normal gravity and gradient, evaluated at the state's position and
  reused while the state stays within GRAVITY_REUSE_M of where it was evaluated (the factor's gravity is first
  order about the reference, n_g0 + G (p - n_p0): 100 m away its error is the second-order term, about
  3 g / R^2 (100 m)^2 / 2 = 4e-9 m/s^2: nothing; an evaluation costs more than the rest of a state's epoch, and
  reused it runs once every 50 s at 2 m/s).
- considered_keyframe_factor: a slow ping's keyframe factor with the scale and misalignment "considered"
  (zero Jacobians, online/dvl_factors.py module doc, calibration_min_speed_m_s), as the online estimator's slow pings at
  a state.
- predict_at_ping: the estimate reported after a ping between states, predicted from the newest state through
  the same motion model, with its covariance propagated to first order.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.core.keys import E, W
from gtsam_dvl.estimators.graph.keyframes import integrate, last_stamp_at_or_before, snapshot_at
from gtsam_dvl.estimators.inputs.gaps import Holds, ImuPieces
from gtsam_dvl.estimators.online.window import STATE_DIM, StateEstimate
from gtsam_dvl.factors import DvlOptions, OffsetInput, PingMotion, make_dvl_factor, ping_state
from gtsam_dvl.factors.so3 import skew

# KeyframeGravity: distance from the reference within which it is reused (module doc)
GRAVITY_REUSE_M = 100.0


class StatePreintegration:
    """The IMU factor's preintegration from the newest state (FactorMaker.preintegrate_interval), integrated as the
    samples come: `snapshot_at(t_p, ...)` at each ping between keyframes integrates the pieces up to the last
    sample stamp at or before the ping (a cut at a stamp splits no sample and no gap, so the pieces and their order
    are preintegrate_interval's) and returns the ping's IMU motion (a copy with the rest up to the ping:
    keyframes.snapshot_at), and `close(t_b, ...)` the rest up to the next state at t_b, returning (pim, params,
    held) as preintegrate_interval does. The batch smoother integrates each interval the same way
    (keyframes.interval_with_snapshots): the same pims and snapshots to the last bit (tests/estimators/
    test_online_keyframes.py), most of the work done before the state's epoch."""

    def __init__(self, make_params: Any, imu_cfg: ImuConfig) -> None:
        # FactorMaker.make_params: a new PreintegrationParams per IMU factor
        self._make_params = make_params
        self.imu_cfg = imu_cfg
        self.t_state = -np.inf
        self._a = -np.inf
        self._pim: gtsam.PreintegratedImuMeasurements | None = None
        self._params: gtsam.PreintegrationParams | None = None
        self._spans: list[tuple[float, float]] = []

    def reset(self, t_state: float) -> None:
        self.t_state, self._a, self._pim, self._params, self._spans = (
            t_state,
            t_state,
            None,
            None,
            [],
        )

    def snapshot_at(self, t_p: float, imu: ImuPieces) -> PingMotion:
        """The IMU motion from the state to the ping at t_p (imu: the samples buffered since before the state,
        as ImuPieces, with the buffer's gaps)."""
        self.advance(last_stamp_at_or_before(imu.t, t_p), imu)
        # no sample stamp yet between the state and the ping
        if self._pim is None or self._params is None:
            self._params = self._make_params()
            self._pim = gtsam.PreintegratedImuMeasurements(
                self._params, gtsam.imuBias.ConstantBias()
            )
        return snapshot_at(
            self._pim,
            self._a,
            t_p,
            self._spans,
            self.t_state,
            imu,
            self.imu_cfg,
            self._params.getOmegaCoriolis(),
        )

    def advance(self, t_cut: float, imu: ImuPieces) -> None:
        if t_cut <= self._a:
            return
        if self._pim is None:
            self._params = self._make_params()
            self._pim = gtsam.PreintegratedImuMeasurements(
                self._params, gtsam.imuBias.ConstantBias()
            )
        self._spans += list(integrate(self._pim, imu, self._a, t_cut).spans)
        self._a = t_cut

    def close(
        self, t_b: float, imu: ImuPieces
    ) -> tuple[gtsam.PreintegratedImuMeasurements, gtsam.PreintegrationParams, Holds]:
        self.advance(t_b, imu)
        if self._pim is None or self._params is None:  # t_b at the state: an empty interval
            self._params = self._make_params()
            self._pim = gtsam.PreintegratedImuMeasurements(
                self._params, gtsam.imuBias.ConstantBias()
            )
        return self._pim, self._params, Holds(tuple(self._spans))


class KeyframeGravity:
    """Normal gravity (m/s^2, map) and its gradient (1/s^2) for the keyframe factors of a state at n_p (m, map):
    FactorMaker.keyframe_gravity, reused within GRAVITY_REUSE_M of where it was last evaluated (module doc).
    `at(n_p)` returns (n_p0, n_g0, n_G)."""

    def __init__(self, evaluate: Any) -> None:
        self._evaluate = evaluate  # FactorMaker.keyframe_gravity
        self._ref: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.evaluations = 0

    def at(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n_p = np.asarray(n_p, dtype=float)
        ref = self._ref
        if ref is None or float(np.sum((n_p - ref[0]) ** 2)) > GRAVITY_REUSE_M**2:
            g, G = self._evaluate(n_p[None, :])
            ref = self._ref = (
                n_p.copy(),
                np.asarray(g[0], dtype=float),
                np.asarray(G[0], dtype=float),
            )
            self.evaluations += 1
        return ref


def considered_keyframe_factor(
    f: gtsam.NonlinearFactor,
    d_y: np.ndarray | float,
    b_omega: np.ndarray,
    b_l: np.ndarray,
    motion: PingMotion,
    d_u: np.ndarray | None = None,
    offset_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> gtsam.CustomFactor:
    """The keyframe factor f (FactorMaker.dvl_keyframe_factors_for: keys [X_i, V_i, B, K, C] + [T_OFFSET] with
    offset_input) of a ping too slow to inform the calibration: the same noise, error and Jacobians for pose,
    velocity, bias (and time offset), none for the scale and misalignment (online/dvl_factors.py module doc; DvlOptions
    considered). d_y, b_omega, d_u, offset_input: what f was made from (for the time offset, b_omega is the rate
    input's mean body rate)."""
    if not isinstance(f, gtsam.NoiseModelFactor):
        raise TypeError(f"a keyframe DVL factor is a NoiseModelFactor, got {type(f).__name__}")
    offset = None if offset_input is None else OffsetInput(*offset_input)
    keys = list(f.keys())
    # the correlated DVL error E(i) and a water-track ping's current W(i), when modelled, are the factor's last
    # keys (states.dvl_factor_keys)
    chars = [k >> 56 for k in keys]
    options = DvlOptions(
        b_omega,
        b_l,
        d_u,
        offset,
        motion,
        considered=True,
        error_variable=E(0) >> 56 in chars,
        current_variable=W(0) >> 56 in chars,
    )
    return make_dvl_factor(f.noiseModel(), keys, d_y, options)


def predict_at_ping(s: StateEstimate, t: float, snap: PingMotion, m: PingMotion) -> StateEstimate:
    """The state at a ping at t between states, predicted from state s (the newest state, its bias and
    calibration with their joint covariance) through the IMU motion m = snap.motion(...): attitude and velocity
    by the keyframe factor's own model (factors/ping_motion.ping_state, the Earth model included), position
    p_i + v_i dt + n_g dt^2 / 2 + n_R_i dp - n_omega_ie x v_i dt^2 (the Coriolis term; the Earth rate's effect on
    the specific force, w dt^3 g / 6 = 1e-5 m at 1 s, left out). dp's bias Jacobians are not in the snapshot: dp
    is corrected with dt / 2 times dv's accelerometer-bias Jacobian and dt / 3 times its gyro-bias Jacobian (exact
    at constant attitude and specific force; in a turn at w rad/s the first is off by |b_a| w dt^3 / 12: 2e-5 m
    at 200 micro-g, 0.2 rad/s, 0.8 s, against position sigmas of metres). Covariance: the state's propagated to
    first order, plus the preintegration's noise up to the ping (snap.cov). The bias, scale, misalignment and time
    offset are the state's. Returns a StateEstimate at t (predicted_from_t = s.t)."""
    R_i = s.pose.rotation().matrix()
    p_i = np.asarray(s.pose.translation(), dtype=float)
    v_i = np.asarray(s.n_v, dtype=float)
    b_a = np.asarray(s.bias.accelerometer(), dtype=float)
    b_g = np.asarray(s.bias.gyroscope(), dtype=float)
    R_p, v_p, A = ping_state(R_i, p_i, v_i, b_a, b_g, m)
    assert A is not None and m.n_g0 is not None and m.n_p0 is not None and m.n_G is not None
    A_R_pose, A_R_bias, A_v_pose, A_v_vel, A_v_bias = A
    dt = float(m.dt)
    n_g = m.n_g0 + m.n_G @ (p_i - m.n_p0)
    w_x = skew(m.n_omega_ie)
    dp_c = m.dp + dt / 2.0 * (m.dv_dba @ b_a) + dt / 3.0 * (m.dv_dbg @ b_g)
    p_p = p_i + v_i * dt + 0.5 * dt**2 * n_g + R_i @ dp_c - dt**2 * (w_x @ v_i)
    cov = s.cov
    if np.all(np.isfinite(cov)):
        J = np.eye(STATE_DIM)
        J[0:3, 0:9] = 0.0
        J[0:3, 0:6] = A_R_pose
        J[0:3, 9:15] = A_R_bias
        R_pT = R_p.T
        J[3:6, 0:3] = R_pT @ (-R_i @ skew(dp_c))
        J[3:6, 3:6] = R_pT @ (R_i + 0.5 * dt**2 * m.n_G @ R_i)
        J[3:6, 6:9] = R_pT @ (dt * np.eye(3) - dt**2 * w_x)
        J[3:6, 9:12] = R_pT @ R_i @ (dt / 2.0 * m.dv_dba)
        J[3:6, 12:15] = R_pT @ R_i @ (dt / 3.0 * m.dv_dbg)
        J[6:9, 0:6] = A_v_pose
        J[6:9, 6:9] = A_v_vel
        J[6:9, 9:15] = A_v_bias
        # the preintegration's error [rotation, position, velocity] into [rot, trans, n_v]
        Jq = np.zeros((9, 9))
        Jq[0:3, 0:3] = np.eye(3)
        Jq[3:6, 3:6] = R_pT @ R_i
        Jq[6:9, 6:9] = R_i
        cov = J @ cov @ J.T
        cov[0:9, 0:9] += Jq @ snap.cov @ Jq.T
        cov = 0.5 * (cov + cov.T)
    return StateEstimate(
        index=s.index,
        t=t,
        pose=gtsam.Pose3(gtsam.Rot3(R_p), p_p),
        n_v=v_p,
        bias=s.bias,
        scale=s.scale,
        b_R_d=s.b_R_d,
        cov=cov,
        time_offset_s=s.time_offset_s,
        time_offset_sigma_s=s.time_offset_sigma_s,
        predicted_from_t=s.t,
        calibration=s.calibration,
    )
