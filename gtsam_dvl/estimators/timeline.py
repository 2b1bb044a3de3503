"""Filtering covariance timeline from a linearised graph: how information about the calibration and biases
accrued over the log.

A square-root information filter run over the graph's linearisation (at the batch solution, or at the
truth for mission planning): the state [X_i (6), V_i (3), B (6), K (1), C (3)] (and the DVL time offset T (1)
and lever arm L (3) when they are estimated) is carried from epoch to
epoch by stacking its square-root information with the IMU factor's and the next epoch's DVL factors'
whitened Jacobian rows, QR-factoring with X_i, V_i first, and keeping the bottom-right triangle (the
marginal information of the rest). Its covariance at epoch i is the filtering marginal given data up to
epoch i; at the last epoch it equals the smoother's marginal of the calibration block.

Written by hand (numpy QR on 31x28 blocks, about 0.1 ms an epoch; a little larger with T and L) because
GTSAM's Python API does not expose the intermediate marginal factors of a sequential elimination.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, L_LEVER, T_OFFSET, B, V, X, key_dim
from gtsam_dvl.core.result import Timeline, misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_rpy_deg
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.bulk import BulkGraph
from gtsam_dvl.estimators.graph import LogGraph


def _epoch_of(keys: list[int]) -> int:
    """The latest state index a factor touches (-1: shared keys only)."""
    idx = [gtsam.Symbol(k).index() for k in keys if chr(gtsam.Symbol(k).chr()) in "xv"]
    return max(idx) if idx else -1


def _rows(factor: gtsam.GaussianFactor, columns: dict[int, slice], width: int) -> np.ndarray:
    """The factor's whitened [A | b] scattered into the filter's column layout (b last)."""
    jf = gtsam.JacobianFactor(factor)
    A, b = jf.jacobian()
    out = np.zeros((A.shape[0], width + 1))
    col = 0
    for k in jf.keys():
        d = key_dim(k)
        out[:, columns[k]] = A[:, col:col + d]
        col += d
    out[:, -1] = b
    return out


def _qr_r(a: np.ndarray) -> np.ndarray:
    """The R factor of a QR decomposition (numpy's mode="r"; its stubs type the result as a tuple)."""
    return np.asarray(np.linalg.qr(a, mode="r"))


def filtering_timeline(builder: LogGraph, graph: gtsam.NonlinearFactorGraph | BulkGraph,
                       values: gtsam.Values) -> Timeline:
    """Filtering estimates are those of `values` (the smoother's); the sigmas are the filtering marginals
    at each epoch. Only the random-constant bias model (the paper's) is supported."""
    if builder.config.imu.bias_model != "constant":
        raise ValueError("filtering_timeline supports the random-constant bias model only")
    linear = graph.linearize(values)
    n = len(builder.epochs)
    by_epoch: list[list[gtsam.GaussianFactor]] = [[] for _ in range(n)]
    for i in range(linear.size()):
        f = linear.at(i)
        e = _epoch_of(list(f.keys()))
        by_epoch[max(e, 0)].append(f)

    # filter layout at epoch i: [X_i, V_i, shared]; transition layout adds X_{i+1}, V_{i+1} after X_i, V_i.
    # shared: [B, K, C] and, when estimated, T (time offset) and L (lever arm)
    dvl_cfg = builder.config.dvl
    shared = [B(0), K_SCALE, C_MISALIGN] + [T_OFFSET] * dvl_cfg.estimate_time_offset \
        + [L_LEVER] * dvl_cfg.estimate_lever_arm
    shared_cols: dict[int, slice] = {}
    for k in shared:
        start = shared_cols[shared[shared.index(k) - 1]].stop if shared_cols else 0
        shared_cols[k] = slice(start, start + key_dim(k))
    n_shared = sum(key_dim(k) for k in shared)
    m = 9 + n_shared  # filter state size
    R = np.zeros((0, m + 1))  # square-root information rows over [X_i, V_i, shared] + rhs
    sig_scale, sig_mis, sig_gyro, sig_acc, sig_att, sig_t, sig_l = [], [], [], [], [], [], []
    for i in range(n):
        if i == 0:
            cols = {X(0): slice(0, 6), V(0): slice(6, 9), **{k: slice(9 + s.start, 9 + s.stop)
                                                           for k, s in shared_cols.items()}}
            stack = np.vstack([_rows(f, cols, m) for f in by_epoch[0]])
            R = _qr_r(stack)[:m]
        else:
            cols = {X(i - 1): slice(0, 6), V(i - 1): slice(6, 9), X(i): slice(9, 15), V(i): slice(15, 18),
                    **{k: slice(18 + s.start, 18 + s.stop) for k, s in shared_cols.items()}}
            prev = np.zeros((R.shape[0], m + 10))
            prev[:, 0:9] = R[:, 0:9]
            prev[:, 18:m + 9] = R[:, 9:m]
            prev[:, m + 9] = R[:, m]
            stack = np.vstack([prev] + [_rows(f, cols, m + 9) for f in by_epoch[i]])
            full = _qr_r(stack)
            R = full[9:m + 9, 9:]  # marginal information of [X_i, V_i, shared] after eliminating X_{i-1}, V_{i-1}
        Rinv = np.linalg.inv(R[:, :m])
        cov = Rinv @ Rinv.T
        sig_acc.append(np.sqrt(np.diag(cov)[9:12]) / UG)
        sig_gyro.append(np.sqrt(np.diag(cov)[12:15]) / DEG_PER_H)
        sig_scale.append(np.sqrt(cov[15, 15]))
        b_R_d = values.atRot3(C_MISALIGN).matrix()
        sig_mis.append(np.sqrt(np.diag(misalignment_rpy_and_cov(b_R_d, builder.log.mounting.b_R_d0,
                                                                cov[16:19, 16:19])[1])))
        n_R_b = values.atPose3(X(i)).rotation().matrix()
        sig_att.append(np.degrees(np.sqrt(np.diag(n_R_b @ cov[0:3, 0:3] @ n_R_b.T))))
        if T_OFFSET in shared_cols:
            j = 9 + shared_cols[T_OFFSET].start
            sig_t.append(np.sqrt(cov[j, j]))
        if L_LEVER in shared_cols:
            sl = slice(9 + shared_cols[L_LEVER].start, 9 + shared_cols[L_LEVER].stop)
            sig_l.append(np.sqrt(np.diag(cov[sl, sl])))

    bias = values.atConstantBias(B(0))
    b_R_d = values.atRot3(C_MISALIGN).matrix()
    mis = matrix_to_rpy_deg(b_R_d @ builder.log.mounting.b_R_d0.T)
    ones = np.ones((n, 1))
    return Timeline(
        t=np.array([e.t for e in builder.epochs]),
        scale=np.full(n, float(values.atVector(K_SCALE)[0])), scale_sigma=np.array(sig_scale),
        misalignment_deg=ones * mis, misalignment_sigma_deg=np.array(sig_mis),
        gyro_bias_deg_per_h=ones * (np.asarray(bias.gyroscope()) / DEG_PER_H),
        gyro_bias_sigma_deg_per_h=np.array(sig_gyro),
        accel_bias_ug=ones * (np.asarray(bias.accelerometer()) / UG), accel_bias_sigma_ug=np.array(sig_acc),
        attitude_sigma_deg=np.array(sig_att),
        time_offset_s=np.full(n, float(values.atVector(T_OFFSET)[0])) if sig_t else None,
        time_offset_sigma_s=np.array(sig_t) if sig_t else None,
        lever_arm_m=ones * np.asarray(values.atVector(L_LEVER)) if sig_l else None,
        lever_arm_sigma_m=np.array(sig_l) if sig_l else None,
    )
