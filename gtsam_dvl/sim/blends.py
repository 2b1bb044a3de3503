"""Smooth blends on tau in [0, 1] with their derivatives d/dtau, for C2 (or smoother) motion profiles.

Each returns (value, derivative). At tau = 0 and 1 the derivatives up to the second vanish, so a profile
built from them joins constant neighbours with continuous velocity, acceleration and jerk: the
specific-force rate stays continuous across segment boundaries. Outside [0, 1] callers clamp tau, which
extends the end values with zero derivatives (still C2).
"""

from __future__ import annotations

import numpy as np


def step5(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic smooth step 10 t^3 - 15 t^4 + 6 t^5: 0 -> 1, first and second derivatives 0 at both ends."""
    v = tau**3 * (10.0 + tau * (-15.0 + 6.0 * tau))
    d = 30.0 * tau**2 * (1.0 - tau) ** 2
    return v, d


def bump6(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bump 64 t^3 (1 - t)^3: 0 -> 1 (at tau = 0.5) -> 0, derivatives up to the second 0 at both ends.

    Its integral over [0, 1] is 64/140 = 0.4571...
    """
    u = tau * (1.0 - tau)
    v = 64.0 * u**3
    d = 192.0 * u**2 * (1.0 - 2.0 * tau)
    return v, d


def step7(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Septic smooth step 35 t^4 - 84 t^5 + 70 t^6 - 20 t^7: 0 -> 1, derivatives up to the third 0 at the
    ends. Its derivative is 140 t^3 (1 - t)^3 = (140/64) bump6, so a turn's roll can follow its yaw rate."""
    v = tau**4 * (35.0 + tau * (-84.0 + tau * (70.0 - 20.0 * tau)))
    d = 140.0 * (tau * (1.0 - tau)) ** 3
    return v, d
