"""Filtering covariance timeline from a linearised graph: how information about the calibration and biases
accrued over the log.

A square-root information filter run over the graph's linearisation (at the batch solution, or at the
truth for mission planning): the state [X_i (6), V_i (3)] and the shared states' keys (core/states.py: B (6),
K (1), C (3), and the DVL time offset T (1) and lever arm L (3) when they are estimated) is carried from epoch to
epoch by stacking its square-root information with the IMU factor's and the next epoch's DVL factors'
whitened Jacobian rows, QR-factoring with X_i, V_i first, and keeping the bottom-right triangle (the
marginal information of the rest). Its covariance at epoch i is the filtering marginal given data up to
epoch i; at the last epoch it equals the smoother's marginal of the calibration block.

Written by hand (numpy QR on 31x28 blocks an epoch, a little larger with T and L) because
GTSAM's Python API does not expose the intermediate marginal factors of a sequential elimination.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gtsam_dvl.core.keys import X, key_dim
from gtsam_dvl.core.result import Timeline, misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_rpy_deg
from gtsam_dvl.core.states import columns, read_values, shared_keys
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.graph.bulk import BulkGraph
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.models.epoch_states import enabled_epoch_states, state_keys


def _epoch_of(keys: list[int], chars: str) -> int:
    """The latest state index a factor touches among the per-state keys (symbols chars; -1: shared keys only)."""
    idx = [gtsam.Symbol(k).index() for k in keys if chr(gtsam.Symbol(k).chr()) in chars]
    return max(idx) if idx else -1


def _rows(factor: gtsam.GaussianFactor, columns: dict[int, slice], width: int) -> np.ndarray:
    """The factor's whitened [A | b] scattered into the filter's column layout (b last)."""
    jf = gtsam.JacobianFactor(factor)
    A, b = jf.jacobian()
    out = np.zeros((A.shape[0], width + 1))
    col = 0
    for k in jf.keys():
        d = key_dim(k)
        out[:, columns[k]] = A[:, col : col + d]
        col += d
    out[:, -1] = b
    return out


def _qr_r(a: np.ndarray) -> np.ndarray:
    """The R factor of a QR decomposition (numpy's mode="r"; its stubs type the result as a tuple)."""
    return np.asarray(np.linalg.qr(a, mode="r"))


def _factors_by_epoch(
    builder: LogGraph, graph: gtsam.NonlinearFactorGraph | BulkGraph, values: gtsam.Values
) -> list[list[gtsam.GaussianFactor]]:
    """The graph's linearisation at values, each factor with the latest state it touches (those on the shared
    keys alone with the first)."""
    linear = graph.linearize(values)
    chars = "xv" + "".join(s.char for s in enabled_epoch_states(builder.config))
    by_epoch: list[list[gtsam.GaussianFactor]] = [[] for _ in range(len(builder.epochs))]
    for i in range(linear.size()):
        f = linear.at(i)
        e = _epoch_of(list(f.keys()), chars)
        by_epoch[max(e, 0)].append(f)
    return by_epoch


class _Layout:
    """The filter's columns. At epoch i: [X_i, V_i, (per-epoch states of i), shared]; the transition layout adds
    state i+1's after state i's. The per-epoch states: those the configuration carries
    (estimators/models/epoch_states.py: the DVL's correlated error E_i, the water current W_i, ...); shared: the keys
    of the shared states the configuration estimates (core/states.py: B, K, C, and T, L) and the per-epoch states'
    extra variables (the water current's layer boundaries)."""

    def __init__(self, builder: LogGraph) -> None:
        self.cfg = builder.config
        self.d = sum(key_dim(k) for k in state_keys(self.cfg, 0))  # the epoch's own state
        shared = shared_keys(self.cfg) + builder.extra_keys
        self.shared_cols: dict[int, slice] = {}
        start = 0
        for k in shared:
            self.shared_cols[k] = slice(start, start + key_dim(k))
            start += key_dim(k)
        self.m = self.d + start  # filter state size
        self.state_cols = columns(shared, self.cfg, start=self.d)  # each shared state's columns

    def own(self, i: int, at: int) -> dict[int, slice]:
        """State i's keys' columns from column at."""
        out: dict[int, slice] = {}
        for k in state_keys(self.cfg, i):
            out[k] = slice(at, at + key_dim(k))
            at += key_dim(k)
        return out

    def shared(self, at: int) -> dict[int, slice]:
        """The shared keys' columns from column at."""
        return {k: slice(at + s.start, at + s.stop) for k, s in self.shared_cols.items()}


def _filtering_covariances(
    builder: LogGraph, by_epoch: list[list[gtsam.GaussianFactor]], values: gtsam.Values
) -> tuple[dict[str, list[np.ndarray]], list[np.ndarray]]:
    """The square-root information filter (module doc): each shared state's covariance at each epoch, and the
    attitude's sigmas (deg, map axes)."""
    lay = _Layout(builder)
    d, m = lay.d, lay.m
    blocks: dict[str, list[np.ndarray]] = {name: [] for name in lay.state_cols}
    R = np.zeros((0, m + 1))  # square-root information rows over [X_i, V_i, shared] + rhs
    sig_att = []
    for i in range(len(builder.epochs)):
        if i == 0:
            cols = {**lay.own(0, 0), **lay.shared(d)}
            stack = np.vstack([_rows(f, cols, m) for f in by_epoch[0]])
            R = _qr_r(stack)[:m]
        else:
            cols = {**lay.own(i - 1, 0), **lay.own(i, d), **lay.shared(2 * d)}
            prev = np.zeros((R.shape[0], m + d + 1))
            prev[:, 0:d] = R[:, 0:d]
            prev[:, 2 * d : m + d] = R[:, d:m]
            prev[:, m + d] = R[:, m]
            stack = np.vstack([prev] + [_rows(f, cols, m + d) for f in by_epoch[i]])
            full = _qr_r(stack)
            # marginal information of [X_i, V_i, (per-epoch states), shared] after eliminating epoch i-1's
            R = full[d : m + d, d:]
        Rinv = np.linalg.inv(R[:, :m])
        cov = Rinv @ Rinv.T
        for name, c in lay.state_cols.items():
            blocks[name].append(cov[c, c])
        n_R_b = values.atPose3(X(i)).rotation().matrix()
        sig_att.append(np.degrees(np.sqrt(np.diag(n_R_b @ cov[0:3, 0:3] @ n_R_b.T))))
    return blocks, sig_att


def filtering_timeline(
    builder: LogGraph, graph: gtsam.NonlinearFactorGraph | BulkGraph, values: gtsam.Values
) -> Timeline:
    """Filtering estimates are those of `values` (the smoother's); the sigmas are the filtering marginals
    at each epoch. Only the random-constant bias model (the paper's) is supported."""
    if builder.config.imu.bias_model != "constant":
        raise ValueError("filtering_timeline supports the random-constant bias model only")
    cfg = builder.config
    n = len(builder.epochs)
    blocks, sig_att = _filtering_covariances(
        builder, _factors_by_epoch(builder, graph, values), values
    )
    est = read_values(values, cfg)
    sig = {name: np.sqrt(np.einsum("nii->ni", np.array(b))) for name, b in blocks.items()}
    b_R_d0 = builder.log.mounting.b_R_d0
    sig_mis = [
        np.sqrt(np.diag(misalignment_rpy_and_cov(est["misalignment"], b_R_d0, c)[1]))
        for c in blocks["misalignment"]
    ]
    mis = matrix_to_rpy_deg(est["misalignment"] @ b_R_d0.T)
    ones = np.ones((n, 1))
    offset, lever = "time_offset" in est, "lever_arm" in est
    return Timeline(
        t=np.array([e.t for e in builder.epochs]),
        scale=np.full(n, float(est["scale"][0])),
        scale_sigma=sig["scale"][:, 0],
        misalignment_deg=ones * mis,
        misalignment_sigma_deg=np.array(sig_mis),
        gyro_bias_deg_per_h=ones * (est["gyro_bias"] / DEG_PER_H),
        gyro_bias_sigma_deg_per_h=sig["gyro_bias"] / DEG_PER_H,
        accel_bias_ug=ones * (est["accel_bias"] / UG),
        accel_bias_sigma_ug=sig["accel_bias"] / UG,
        attitude_sigma_deg=np.array(sig_att),
        time_offset_s=np.full(n, float(est["time_offset"][0])) if offset else None,
        time_offset_sigma_s=sig["time_offset"][:, 0] if offset else None,
        lever_arm_m=ones * est["lever_arm"] if lever else None,
        lever_arm_sigma_m=sig["lever_arm"] if lever else None,
    )
