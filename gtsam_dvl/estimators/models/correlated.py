"""The DVL's correlated velocity error: a first-order Gauss-Markov process per dvl_link axis, a state of every
epoch (E(i), core/keys.py), when [dvl] correlated_sigma_m_s > 0.

A bottom-tracking DVL's error is not white: beyond the ping noise it has an error correlated over tens of
seconds (the bottom's texture, the beams' footprints, the sound-speed layer). Modelled as white at the ping level
it averages out too fast, so the smoother's position sigma grows too slowly and the calibration, the vertical
accelerometer bias and the height over-trust the pings (docs/results.md, "Underway logs"). The model, the one
the simulator draws from (sim/dvl.py GaussMarkov):

    y = h(x) + E(t) + white,        dE = -E / tau dt + sqrt(2 sigma^2 / tau) dW        (per dvl_link axis)

discretised exactly between states i and j = i + 1, dt apart (and so over each propagation step of the EKF,
which carries E as the last three components of its error state):

    E_j = phi E_i + w,   phi = exp(-dt / tau),   w ~ N(0, sigma^2 (1 - phi^2) I),    E_0 ~ N(0, sigma^2 I)

sigma = correlated_sigma_m_s (m/s), tau = correlated_tau_s (s). The DVL factors of state i, and of the pings
between it and the next state, read E(i) (factors/dvl.py error_variable; a keyframe interval of a few seconds
is short against tau). The links are linear in the vectors E, so they are GTSAM's own linear factors
(LinearContainerFactor of a JacobianFactor, linearised at zero: exact) evaluated in C++, not Python
CustomFactors (which iSAM2 would call with a copy of the whole Values).

Its entry in the per-epoch registry (estimators/models/epoch_states.py DvlCorrelatedError) declares it to the
estimators with these functions: the batch graph, the online window, the EKF and the results read the registry.
"""

from __future__ import annotations

import gtsam
import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.keys import E

_EYE3 = np.eye(3)


def transition(config: EstimatorConfig, dt: float) -> tuple[float, float]:
    """(phi, q): E_j = phi E_i + w over dt seconds, w's variance q per axis (m^2/s^2)."""
    cfg = config.dvl
    phi = float(np.exp(-max(dt, 0.0) / cfg.correlated_tau_s))
    return phi, cfg.correlated_sigma_m_s**2 * (1.0 - phi * phi)


def _zeros(*keys: int) -> gtsam.Values:
    values = gtsam.Values()
    for k in keys:
        values.insert(k, np.zeros(3))
    return values


def link_factor(config: EstimatorConfig, i: int, j: int, dt: float) -> gtsam.NonlinearFactor:
    """E_j - phi E_i ~ N(0, q I) (module doc) between states i and j, dt seconds apart."""
    phi, q = transition(config, dt)
    # q has a floor: two states at the same stamp (dt = 0) would make an infinitely stiff link
    s = float(np.sqrt(max(q, 1e-12 * config.dvl.correlated_sigma_m_s**2)))
    jf = gtsam.JacobianFactor(
        E(i), -phi * _EYE3 / s, E(j), _EYE3 / s, np.zeros(3), gtsam.noiseModel.Unit.Create(3)
    )
    return gtsam.LinearContainerFactor(jf, _zeros(E(i), E(j)))


def prior_factor(config: EstimatorConfig, i: int = 0) -> gtsam.NonlinearFactor:
    """E_i ~ N(0, sigma^2 I): the stationary distribution, at the first state."""
    return gtsam.PriorFactorVector(
        E(i), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, config.dvl.correlated_sigma_m_s)
    )


def factors(config: EstimatorConfig, t_states: np.ndarray) -> list[gtsam.NonlinearFactor]:
    """The prior on E(0) and the links of the states at stamps t_states (s)."""
    dt = np.diff(np.asarray(t_states, dtype=float))
    return [prior_factor(config)] + [
        link_factor(config, i, i + 1, float(d)) for i, d in enumerate(dt)
    ]


def ekf_propagate(
    config: EstimatorConfig, P: np.ndarray, d_e: np.ndarray, cols: slice, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's covariance P and correlated-error estimate d_e (3,) m/s propagated over dt seconds: E's rows and
    columns of P times phi, q I added to its block, d_e times phi (module doc; the rest of P is propagated
    before, by the navigation error's transition)."""
    phi, q = transition(config, dt)
    out = P.copy()
    out[cols, :] *= phi
    out[:, cols] *= phi
    out[cols, cols] += q * _EYE3
    return out, phi * d_e


def info(config: EstimatorConfig, d_e: np.ndarray | None = None) -> dict[str, object]:
    """NavResult.info["dvl_correlated_error"]: the model's level and time constant and, from a smoother's estimate
    d_e (N, 3) of every state (estimators/models/epoch_states.py EpochEstimate), the RMS of the estimated error per
    dvl_link axis (m/s) over the states."""
    out: dict[str, object] = {
        "sigma_m_s": config.dvl.correlated_sigma_m_s,
        "tau_s": config.dvl.correlated_tau_s,
    }
    if d_e is not None and len(d_e):
        out["estimate_rms_m_s"] = np.sqrt(np.mean(np.asarray(d_e) ** 2, axis=0)).tolist()
    return out
