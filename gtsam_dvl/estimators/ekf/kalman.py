"""The error-state Kalman filter's update and covariance propagation (filter.py runs them): the Joseph-form update
with the chi^2 gate and the robust kernel, the injection of the error into the nominal state, and the covariance
through an interval's transition.

The error state is strapdown.py's navigation and calibration error (N_ERR), then the time offset when estimated
(core/states.py ekf_layout), then the water current's layer boundaries, then the blocks of the per-epoch states the
configuration carries (estimators/models/epoch_states.py; FilterState.epoch_slices).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from gtsam_dvl.estimators.ekf.strapdown import N_ERR, FilterState


def robust_weight(kernel: str, k: float, r: float) -> float:
    """Weight of a measurement whose whitened innovation has norm r under the robust kernel [dvl] robust with
    threshold k (GTSAM's mEstimator weights): 1 for "none"; "huber": 1 up to k, k / r beyond; "cauchy":
    1 / (1 + (r / k)^2)."""
    if kernel == "huber":
        return 1.0 if r <= k else k / r
    if kernel == "cauchy":
        return 1.0 / (1.0 + (r / k) ** 2)
    return 1.0


def gate_threshold(probability: float, dof: int) -> float:
    """The chi^2 gate on the normalised innovation squared of a dof-dimensional measurement: its quantile of
    probability ([ekf] gate_probability; 1 gates nothing)."""
    return math.inf if probability >= 1.0 else float(chi2.ppf(probability, dof))


def update(
    fs: FilterState,
    H: np.ndarray,
    innovation: np.ndarray,
    Rm: np.ndarray,
    kernel: str = "none",
    k: float = 3.0,
    gate_nis: float = math.inf,
    consider: np.ndarray | None = None,
) -> tuple[float, bool, bool]:
    """Kalman update (Joseph form) and injection of the error into the nominal state (FilterState.inject), unless
    the normalised innovation squared exceeds gate_nis (gate_threshold): then nothing changes. The robust kernel's
    weight (robust_weight, on the whitened innovation's norm) inflates the measurement noise by 1 / weight.

    consider: error-state indices held as "consider" states (a Schmidt-Kalman filter: their gain rows zero, so
    they keep their values while their uncertainty still enters every other state's covariance; the Joseph form
    is exact for any gain).

    Returns the normalised innovation squared, whether the kernel reduced the measurement's weight and
    whether the gate rejected it.
    """
    P = fs.P
    S = H @ P @ H.T + Rm
    nis = float(innovation @ np.linalg.solve(S, innovation))
    if nis > gate_nis:
        return nis, False, True
    w = robust_weight(kernel, k, math.sqrt(max(nis, 0.0)))
    down = w < 1.0
    if down:
        Rm = Rm / w
        S = H @ P @ H.T + Rm
    K = np.linalg.solve(S, H @ P).T
    if consider is not None:
        K[consider, :] = 0.0
    dx = K @ innovation
    IKH = np.eye(len(P)) - K @ H
    P = IKH @ P @ IKH.T + K @ Rm @ K.T
    fs.P = 0.5 * (P + P.T)
    fs.inject(dx)
    return nis, down, False


def propagate_covariance(P: np.ndarray, Phi: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P through the navigation error's transition Phi (19, 19) and process noise Q; the time offset (if P has
    it) is a constant: its row and column are carried by Phi alone."""
    if len(P) == N_ERR:
        return np.asarray(Phi @ P @ Phi.T + Q)
    out = P.copy()
    out[:N_ERR, :N_ERR] = Phi @ P[:N_ERR, :N_ERR] @ Phi.T + Q
    out[:N_ERR, N_ERR:] = Phi @ P[:N_ERR, N_ERR:]
    out[N_ERR:, :N_ERR] = out[:N_ERR, N_ERR:].T
    return out
