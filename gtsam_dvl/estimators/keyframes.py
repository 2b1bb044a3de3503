"""Pings between keyframes: the IMU motion from the keyframe before each ping up to the ping.

With `[solver] keyframe_spacing_s` > 0 the batch smoother (estimators/graph.py) makes states only at keyframes
(selection.keyframe_mask) and DVL-dropout fillers; each other usable ping becomes a DVL factor on the state
before it (factors/dvl_keyframe.py) through the preintegrated IMU motion over [t_i, t_ping]. This module
integrates each keyframe interval's samples once, in time order, and takes a snapshot of the preintegration at
each ping (PimSnapshot): the zero-bias deltas dR, dv, their bias Jacobians and the covariance of the
preintegration error [rotation, position, velocity] (plus the motion-model covariance of any IMU gap held:
estimators/gaps.py). GTSAM 4.3's Python wrapper exposes deltaRij, deltaVij, preintMeasCov and the tangent
preintegrated() = [theta, p, v] but not the bias Jacobians. The snapshot's parameters have no gravity and no
Earth rate, so GTSAM's ImuFactor on the pim, evaluated with its Jacobians at the identity state and its own
prediction there (zero error, so the Logmap's derivative is the identity), has the bias Jacobian
[J_r(theta) H_theta; dR^T H_p; dR^T H_v] (factors/imu_bulk.py): dR's right-tangent Jacobian dR_dbg is its rotation
rows, and dR times its velocity rows are dv_dba, dv_dbg; exact to rounding, one evaluation per ping. Up to
ANALYTIC_MAX_ANGLE (J_r is singular at a whole turn); beyond it, central differences of 12 predictions of the
relative rotation dR^T R(b) (within 1e-9 relative of the former below it: the difference is their truncation
error, tests/estimators/test_keyframes.py). The keyframe factor applies the Earth model.

This integrates the samples of a keyframe interval up to its last ping a second time (the IMU factor's
preintegration, graph._preintegrate, goes once over the whole interval): at 5 Hz pings and 1 s keyframes that
is 0.8 s of samples more per second of log.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.estimators.gaps import Gaps, Holds, hold_covariance, pieces_with_holds
from gtsam_dvl.factors import PingMotion

BIAS_STEP_ACC = 1e-2  # m/s^2, central-difference step of the accelerometer bias (beyond ANALYTIC_MAX_ANGLE)
BIAS_STEP_GYRO = 1e-4  # rad/s, central-difference step of the gyro bias (beyond ANALYTIC_MAX_ANGLE)
ANALYTIC_MAX_ANGLE = 5.5  # rad, the largest |theta| whose Jacobians come from the factor's (J_r singular at 2 pi)
_STATE0, _BIAS0, _POSE0, _Z3 = gtsam.NavState(), gtsam.imuBias.ConstantBias(), gtsam.Pose3(), np.zeros(3)


@dataclass(frozen=True)
class PimSnapshot:
    """The preintegration from a keyframe to a ping (module doc): dt (s), dR (3x3, body at the ping in the
    keyframe's body), dv (3,) m/s in the keyframe's body axes, dp (3,) m dv integrated once more (deltaPij),
    dR_dbg, dv_dba, dv_dbg (3x3 each: dR's right
    tangent and dv per gyro / accelerometer bias), cov (9x9, [rotation, position, velocity])."""

    dt: float
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dR_dbg: np.ndarray
    dv_dba: np.ndarray
    dv_dbg: np.ndarray
    cov: np.ndarray

    def motion(self, n_omega_ie: np.ndarray, n_g0: np.ndarray, n_p0: np.ndarray, n_G: np.ndarray) -> PingMotion:
        """The keyframe factor's PingMotion (factors/dvl_keyframe.py): these deltas with the Earth model at the
        keyframe (Earth rate rad/s and gravity m/s^2 in map, at n_p0 m, its gradient 1/s^2)."""
        return PingMotion(self.dt, self.dR, self.dv, self.dp, self.dR_dbg, self.dv_dba, self.dv_dbg, n_omega_ie,
                          n_g0, n_p0, n_G)


@dataclass
class SnapshotArrays:
    """Many pings' PimSnapshots as arrays (N, ...): 1 kB a ping instead of 4 kB of small numpy objects (a day of
    5 Hz pings between 1 s keyframes: 0.35 GB instead of 1.4 GB)."""

    dt: np.ndarray
    dR: np.ndarray
    dv: np.ndarray
    dp: np.ndarray
    dR_dbg: np.ndarray
    dv_dba: np.ndarray
    dv_dbg: np.ndarray
    cov: np.ndarray

    @classmethod
    def empty(cls, n: int) -> SnapshotArrays:
        return cls(np.zeros(n), np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3)),
                   np.zeros((n, 3, 3)), np.zeros((n, 3, 3)), np.zeros((n, 9, 9)))

    def __len__(self) -> int:
        return len(self.dt)

    def put(self, q: int, s: PimSnapshot) -> None:
        self.dt[q], self.dR[q], self.dv[q], self.dp[q] = s.dt, s.dR, s.dv, s.dp
        self.dR_dbg[q], self.dv_dba[q], self.dv_dbg[q], self.cov[q] = s.dR_dbg, s.dv_dba, s.dv_dbg, s.cov

    def get(self, q: int) -> PimSnapshot:
        return PimSnapshot(float(self.dt[q]), self.dR[q], self.dv[q], self.dp[q], self.dR_dbg[q], self.dv_dba[q],
                           self.dv_dbg[q], self.cov[q])


def snapshot_params(params: gtsam.PreintegrationParams) -> gtsam.PreintegrationParams:
    """Parameters with params' noise, no gravity and no Earth rate (predict() then gives the deltas)."""
    out = gtsam.PreintegrationParams(np.zeros(3))
    out.setGyroscopeCovariance(params.getGyroscopeCovariance())
    out.setAccelerometerCovariance(params.getAccelerometerCovariance())
    out.setIntegrationCovariance(params.getIntegrationCovariance())
    return out


def snapshot(pim: gtsam.PreintegratedImuMeasurements, extra_cov: np.ndarray | None = None) -> PimSnapshot:
    """The snapshot of pim now (its parameters from snapshot_params, bias estimate zero; module doc)."""
    theta = np.asarray(pim.preintegrated(), dtype=float)[:3]
    if float(theta @ theta) <= ANALYTIC_MAX_ANGLE**2:
        # GTSAM's ImuFactor on this pim, evaluated with its Jacobians at X_i = identity, v_i = 0 and X_j = the
        # prediction there: its error is zero and the Logmap's derivative the identity, so its bias Jacobian is
        # [J_r(theta) H_theta; dR^T H_p; dR^T H_v] (factors/imu_bulk.py, with no gravity or Earth rate): the
        # rotation rows are dR_dbg themselves and dR times the velocity rows are [dv_dba, dv_dbg]. One evaluation
        # instead of six predictions (30 us against 50 us a ping).
        pred = pim.predict(_STATE0, _BIAS0)
        Hs = [np.empty((9, d), order="F") for d in (6, 3, 6, 3, 6)]
        gtsam.ImuFactor(0, 1, 2, 3, 4, pim).evaluateError(_POSE0, _Z3, pred.pose(), pred.velocity(), _BIAS0, *Hs)
        dR = pred.attitude().matrix()
        dR_dbg = Hs[4][0:3, 3:6].copy()
        dv_db = dR @ Hs[4][6:9]
        dv_dba, dv_dbg = dv_db[:, :3], dv_db[:, 3:]
    else:
        dR_dbg, dv_dba, dv_dbg = _central_differences(pim)
        dR = pim.deltaRij().matrix()
    cov = np.asarray(pim.preintMeasCov(), dtype=float)
    if extra_cov is not None:
        cov = cov + extra_cov
    return PimSnapshot(float(pim.deltaTij()), dR, np.asarray(pim.deltaVij(), dtype=float),
                       np.asarray(pim.deltaPij(), dtype=float), dR_dbg, dv_dba, dv_dbg, cov)


def _central_differences(pim: gtsam.PreintegratedImuMeasurements) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dR_dbg, dv_dba, dv_dbg) by central differences of pim.predict (the relative rotation dR^T R(b): no
    wrap at pi)."""
    zero = np.zeros(3)

    def predict(b_a: np.ndarray, b_g: np.ndarray) -> tuple[gtsam.Rot3, np.ndarray]:
        s = pim.predict(_STATE0, gtsam.imuBias.ConstantBias(b_a, b_g))
        return s.attitude(), np.asarray(s.velocity(), dtype=float)

    dR = pim.deltaRij()
    dR_dbg, dv_dba, dv_dbg = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = BIAS_STEP_ACC
        dv_dba[:, k] = (predict(e, zero)[1] - predict(-e, zero)[1]) / (2 * BIAS_STEP_ACC)
        e[k] = BIAS_STEP_GYRO
        (R_p, v_p), (R_m, v_m) = predict(zero, e), predict(zero, -e)
        dv_dbg[:, k] = (v_p - v_m) / (2 * BIAS_STEP_GYRO)
        dR_dbg[:, k] = (gtsam.Rot3.Logmap(dR.between(R_p)) - gtsam.Rot3.Logmap(dR.between(R_m))) / (2 * BIAS_STEP_GYRO)
    return dR_dbg, dv_dba, dv_dbg


def ping_snapshots(t_state: float, t_pings: list[float], params: gtsam.PreintegrationParams, imu_t: np.ndarray,
                   starts: np.ndarray, b_f: np.ndarray, b_omega: np.ndarray, gaps: Gaps,
                   imu_cfg: ImuConfig) -> list[PimSnapshot]:
    """The snapshots at the pings t_pings (sorted, after t_state) of one preintegration from t_state; samples
    i cover (starts[i], imu_t[i]] (b_f rotation-compensated, as for the IMU factors); a gap is held
    (pieces_with_holds) and its motion-model covariance added (hold_covariance)."""
    pim = gtsam.PreintegratedImuMeasurements(snapshot_params(params), gtsam.imuBias.ConstantBias())
    out: list[PimSnapshot] = []
    a = t_state
    spans: list[tuple[float, float]] = []
    for t_p in t_pings:
        idx, dt, held = pieces_with_holds(imu_t, starts, gaps, a, t_p)
        for f_i, w_i, dt_i in zip(b_f[idx], b_omega[idx], dt.tolist(), strict=True):  # rows: no per-sample indexing
            pim.integrateMeasurement(f_i, w_i, dt_i)
        spans += list(held.spans)
        extra = hold_covariance(imu_cfg, Holds(tuple(spans)), t_p - t_state) if spans else None
        out.append(snapshot(pim, extra))
        a = t_p
    return out
