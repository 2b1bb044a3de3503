"""Pings between keyframes: the IMU motion from the keyframe before each ping up to the ping.

With `[solver] keyframe_spacing_s` > 0 the batch smoother (estimators/graph/log_graph.py) makes states only at keyframes
(selection.keyframe_mask) and DVL-dropout fillers; each other usable ping becomes a DVL factor on the state
before it (factors/dvl.py with a PingMotion) through the preintegrated IMU motion over [t_i, t_ping]. This
module integrates each keyframe interval's samples once, in time order, for the IMU factor (cut at the last sample
stamp at or before each ping, which splits no sample: the pieces of one integration over the whole interval), and
takes a snapshot at each ping (a PingMotion, factors/ping_motion.py) from a copy of that preintegration with the
rest of the sample straddling the ping: the zero-bias deltas dR, dv, their bias Jacobians and the covariance of
the preintegration error [rotation, position, velocity] (plus the motion-model covariance of any IMU gap held:
estimators/inputs/gaps.py). GTSAM 4.3's Python wrapper exposes deltaRij, deltaVij, preintMeasCov and the tangent
preintegrated() = [theta, p, v] but not the bias Jacobians. GTSAM's ImuFactor on the pim, evaluated with its
Jacobians at the identity state and its own prediction there (zero error, so the Logmap's derivative is the
identity), has the bias Jacobian [J_r(theta) H_theta; R_P^T A H_p; R_P^T (A H_v - Omega x A H_p)], R_P = A dR,
A = Exp(-Omega dt) with the parameters' Earth rate Omega (factors/imu_bulk.py): dR's right-tangent Jacobian dR_dbg
is its rotation rows, and dv_dba, dv_dbg follow from the velocity and position rows; exact to rounding, one
evaluation per ping. Up to ANALYTIC_MAX_ANGLE (J_r is singular at a whole turn); beyond it, central differences
of 12 predictions of the relative rotation dR^T R(b) (within 1e-9 relative of the former below it: the
difference is their truncation error, tests/estimators/test_keyframes.py). The keyframe factor applies the Earth
model.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.estimators.graph.factor_maker import integrate_pieces
from gtsam_dvl.estimators.inputs.gaps import Holds, ImuPieces, hold_covariance
from gtsam_dvl.factors import PingMotion
from gtsam_dvl.factors.so3 import skew

# m/s^2, central-difference step of the accelerometer bias (beyond ANALYTIC_MAX_ANGLE)
BIAS_STEP_ACC = 1e-2
BIAS_STEP_GYRO = 1e-4  # rad/s, central-difference step of the gyro bias (beyond ANALYTIC_MAX_ANGLE)
# rad, the largest |theta| whose Jacobians come from the factor's (J_r singular at 2 pi)
ANALYTIC_MAX_ANGLE = 5.5
_STATE0, _BIAS0, _POSE0, _Z3 = (
    gtsam.NavState(),
    gtsam.imuBias.ConstantBias(),
    gtsam.Pose3(),
    np.zeros(3),
)


def snapshot_params(params: gtsam.PreintegrationParams) -> gtsam.PreintegrationParams:
    """Parameters with params' noise, no gravity and no Earth rate (predict() then gives the deltas)."""
    out = gtsam.PreintegrationParams(np.zeros(3))
    out.setGyroscopeCovariance(params.getGyroscopeCovariance())
    out.setAccelerometerCovariance(params.getAccelerometerCovariance())
    out.setIntegrationCovariance(params.getIntegrationCovariance())
    return out


def snapshot(
    pim: gtsam.PreintegratedImuMeasurements,
    extra_cov: np.ndarray | None = None,
    n_omega: np.ndarray | None = None,
) -> PingMotion:
    """The snapshot of pim now (bias estimate zero; module doc). n_omega: the Earth rate (rad/s, map) its
    parameters hold, None or zeros for none (their gravity does not matter)."""
    theta = np.asarray(pim.preintegrated(), dtype=float)[:3]
    n_omega_ie = np.zeros(3) if n_omega is None else np.asarray(n_omega, dtype=float)
    dR = pim.deltaRij().matrix()
    if float(theta @ theta) <= ANALYTIC_MAX_ANGLE**2:
        # GTSAM's ImuFactor on this pim, evaluated with its Jacobians at X_i = identity, v_i = 0 and X_j = the
        # prediction there: its error is zero and the Logmap's derivative the identity, so its bias Jacobian is
        # [J_r(theta) H_theta; R_P^T A H_p; R_P^T (A H_v - Omega x A H_p)] with R_P = A dR, A = Exp(-Omega dt)
        # (factors/imu_bulk.py): the rotation rows are dR_dbg themselves, and H_v = [dv_dba, dv_dbg] is
        # dR (velocity rows) + Omega x dR (position rows), since A^T [Omega]x A = [Omega]x. One evaluation
        # instead of six predictions (docs/results.md, Speed).
        pred = pim.predict(_STATE0, _BIAS0)
        Hs = [np.empty((9, d), order="F") for d in (6, 3, 6, 3, 6)]
        gtsam.ImuFactor(0, 1, 2, 3, 4, pim).evaluateError(
            _POSE0, _Z3, pred.pose(), pred.velocity(), _BIAS0, *Hs
        )
        H5 = Hs[4]
        dR_dbg = H5[0:3, 3:6].copy()
        dv_db = dR @ H5[6:9]
        if n_omega_ie.any():  # (a matrix product: np.cross costs more a call on 3-vectors)
            dv_db += skew(n_omega_ie) @ (dR @ H5[3:6])
        dv_dba, dv_dbg = dv_db[:, :3], dv_db[:, 3:]
    else:
        dR_dbg, dv_dba, dv_dbg = _central_differences(pim, n_omega_ie)
    cov = np.asarray(pim.preintMeasCov(), dtype=float)
    if extra_cov is not None:
        cov = cov + extra_cov
    return PingMotion(
        float(pim.deltaTij()),
        dR,
        np.asarray(pim.deltaVij(), dtype=float),
        np.asarray(pim.deltaPij(), dtype=float),
        dR_dbg,
        dv_dba,
        dv_dbg,
        cov,
    )


def _central_differences(
    pim: gtsam.PreintegratedImuMeasurements, n_omega: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dR_dbg, dv_dba, dv_dbg) by central differences of pim.predict from the identity at rest (the relative
    rotation dR^T R(b): no wrap at pi), the prediction's Earth rate undone: R_P = A Exp(theta_c) and
    v_P = gravity terms + A dv_c - Omega x p_P, A = Exp(-Omega dt)."""
    zero = np.zeros(3)
    A = gtsam.Rot3.Expmap(-n_omega * pim.deltaTij())

    def predict(b_a: np.ndarray, b_g: np.ndarray) -> tuple[gtsam.Rot3, np.ndarray]:
        s = pim.predict(_STATE0, gtsam.imuBias.ConstantBias(b_a, b_g))
        v = np.asarray(s.velocity(), dtype=float) + np.cross(
            n_omega, np.asarray(s.position(), dtype=float)
        )
        return A.inverse() * s.attitude(), A.unrotate(v)

    dR = pim.deltaRij()
    dR_dbg, dv_dba, dv_dbg = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = BIAS_STEP_ACC
        dv_dba[:, k] = (predict(e, zero)[1] - predict(-e, zero)[1]) / (2 * BIAS_STEP_ACC)
        e[k] = BIAS_STEP_GYRO
        (R_p, v_p), (R_m, v_m) = predict(zero, e), predict(zero, -e)
        dv_dbg[:, k] = (v_p - v_m) / (2 * BIAS_STEP_GYRO)
        dR_dbg[:, k] = (gtsam.Rot3.Logmap(dR.between(R_p)) - gtsam.Rot3.Logmap(dR.between(R_m))) / (
            2 * BIAS_STEP_GYRO
        )
    return dR_dbg, dv_dba, dv_dbg


def clone(pim: gtsam.PreintegratedImuMeasurements) -> gtsam.PreintegratedImuMeasurements:
    """A copy of pim, sharing its parameters (through an ImuFactor: cheaper than Python's copy.copy, which pickles)."""
    return gtsam.ImuFactor(0, 1, 2, 3, 4, pim).preintegratedMeasurements()


def integrate(pim: gtsam.PreintegratedImuMeasurements, imu: ImuPieces, a: float, b: float) -> Holds:
    """Integrate the pieces of (a, b] of imu into pim; returns what was held."""
    idx, dt, held = imu.pieces(a, b)
    integrate_pieces(pim, imu.b_f[idx], imu.b_omega[idx], dt.tolist())
    return held


def last_stamp_at_or_before(imu_t: np.ndarray, t: float) -> float:
    """The cut of a preintegration at a ping t: the last sample stamp at or before it (-inf: none). A cut at a stamp
    splits no sample and no gap, so an interval integrated in parts cut there has the pieces, in the order, of
    one integration over the whole (FactorMaker.preintegrate_interval)."""
    k = int(np.searchsorted(imu_t, t, side="right")) - 1
    return float(imu_t[k]) if k >= 0 else -np.inf


def snapshot_at(
    pim: gtsam.PreintegratedImuMeasurements,
    a: float,
    t_p: float,
    spans: list[tuple[float, float]],
    t_state: float,
    imu: ImuPieces,
    imu_cfg: ImuConfig,
    n_omega: np.ndarray | None,
) -> PingMotion:
    """The snapshot at ping t_p of an interval's preintegration from t_state that has integrated (t_state, a] (a, the
    interval's cut at or before t_p, last_stamp_at_or_before) and held spans: a copy of it with (a, t_p] added, the
    hold covariance of everything held up to t_p (module doc)."""
    part = clone(pim)
    held = integrate(part, imu, a, t_p)
    all_spans = spans + list(held.spans)
    extra = hold_covariance(imu_cfg, Holds(tuple(all_spans)), t_p - t_state) if all_spans else None
    return snapshot(part, extra, n_omega)


def interval_with_snapshots(
    t_state: float,
    t_end: float,
    t_pings: list[float],
    params: gtsam.PreintegrationParams,
    imu: ImuPieces,
    imu_cfg: ImuConfig,
) -> tuple[gtsam.PreintegratedImuMeasurements, Holds, list[PingMotion]]:
    """The IMU factor's preintegration over (t_state, t_end] (with params, a new PreintegrationParams of its own),
    what it held, and the snapshots at the pings t_pings (sorted, inside the interval) taken on the way: the
    interval is integrated once, cut at the last sample stamp at or before each ping, and each ping's snapshot is
    a copy with the rest up to the ping (snapshot_at). imu: the samples (ImuPieces).

    Without an IMU gap in the interval its pieces are found once and cut at the pings (interval_cut_by_cut does
    the same with the pieces of each cut, as the online estimator does: the same pieces, durations and order, so
    the same bits, tests/estimators/test_keyframes.py; 9 look-ups in the log's sample arrays an interval
    against 1)."""
    idx, dt, held = imu.pieces(t_state, t_end)
    if held:
        return interval_cut_by_cut(t_state, t_end, t_pings, params, imu, imu_cfg)
    pim = gtsam.PreintegratedImuMeasurements(params, _BIAS0)
    n_omega = params.getOmegaCoriolis()
    out: list[PingMotion] = []
    ends = imu.t[idx]  # each piece's sample stamp: the cuts
    rows_f, rows_w, dts = imu.b_f[idx], imu.b_omega[idx], dt.tolist()
    done, a = 0, t_state
    for t_p in t_pings:
        # the pieces up to the last stamp at or before t_p
        k = int(np.searchsorted(ends, t_p, side="right"))
        if k > done:
            integrate_pieces(pim, rows_f[done:k], rows_w[done:k], dts[done:k])
            done, a = k, float(ends[k - 1])
        part = clone(pim)
        if done < len(idx):  # the sample straddling the ping, from the cut (imu_pieces' duration)
            j = int(idx[done])
            d = min(float(imu.t[j]), t_p) - max(float(imu.starts[j]), a)
            if d > 0.0:
                part.integrateMeasurement(imu.b_f[j], imu.b_omega[j], d)
        out.append(snapshot(part, None, n_omega))
    integrate_pieces(pim, rows_f[done:], rows_w[done:], dts[done:])
    return pim, Holds(), out


def interval_cut_by_cut(
    t_state: float,
    t_end: float,
    t_pings: list[float],
    params: gtsam.PreintegrationParams,
    imu: ImuPieces,
    imu_cfg: ImuConfig,
) -> tuple[gtsam.PreintegratedImuMeasurements, Holds, list[PingMotion]]:
    """interval_with_snapshots with the pieces of each cut found on their own (pieces_with_holds), across IMU gaps
    too (their holds' pieces, and the hold covariance of everything held up to each ping in its snapshot)."""
    pim = gtsam.PreintegratedImuMeasurements(params, _BIAS0)
    n_omega = params.getOmegaCoriolis()
    out: list[PingMotion] = []
    a = t_state
    spans: list[tuple[float, float]] = []
    for t_p in t_pings:
        t_cut = last_stamp_at_or_before(imu.t, t_p)
        if t_cut > a:
            spans += list(integrate(pim, imu, a, t_cut).spans)
            a = t_cut
        out.append(snapshot_at(pim, a, t_p, spans, t_state, imu, imu_cfg, n_omega))
    spans += list(integrate(pim, imu, a, t_end).spans)
    return pim, Holds(tuple(spans)), out


def ping_snapshots(
    t_state: float,
    t_pings: list[float],
    params: gtsam.PreintegrationParams,
    imu: ImuPieces,
    imu_cfg: ImuConfig,
) -> list[PingMotion]:
    """The snapshots at the pings t_pings (sorted, after t_state) of interval_with_snapshots from t_state up to
    the last ping (params: as the IMU factors')."""
    t_end = t_pings[-1] if t_pings else t_state
    return interval_with_snapshots(t_state, t_end, t_pings, params, imu, imu_cfg)[2]
