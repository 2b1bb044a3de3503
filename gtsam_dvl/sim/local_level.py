"""Inertial quantities in the local-level ENU frame l at the vehicle: paper eq. 3 and 4 solved for the
IMU's true outputs.

    omega_ib^b = omega_lb^b + l_R_b^T (omega_ie^l + omega_el^l)
    f^b        = l_R_b^T (dv^l/dt + (2 omega_ie^l + omega_el^l) x v^l - g^l),   g^l = [0, 0, -gamma(lat, h)]

with the transport rate of the ENU frame omega_el^l = [-v_N/(R_N+h), v_E/(R_E+h), v_E tan(lat)/(R_E+h)].
"""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.earth import OMEGA_IE, normal_gravity, radii_of_curvature
from gtsam_dvl.sim.motion import MotionState


def l_omega_ie(lat: np.ndarray) -> np.ndarray:
    """Earth rate in the local level, (K, 3) rad/s."""
    zeros = np.zeros_like(lat)
    return np.stack([zeros, OMEGA_IE * np.cos(lat), OMEGA_IE * np.sin(lat)], axis=-1)


def l_omega_el(l_v: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Transport rate (local level relative to the Earth) in the local level, (K, 3) rad/s."""
    r_n, r_e = radii_of_curvature(lat)
    v_e, v_n = l_v[..., 0], l_v[..., 1]
    return np.stack([-v_n / (r_n + h), v_e / (r_e + h), v_e * np.tan(lat) / (r_e + h)], axis=-1)


def imu_truth(
    m: MotionState, lat: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(b_omega_ib rad/s, b_f m/s^2, l_R_b, b_omega_eb rad/s) at the states m and positions (lat, h)."""
    l_R_b = m.l_R_b()
    l_v = m.l_v()
    w_ie = l_omega_ie(lat)
    w_el = l_omega_el(l_v, lat, h)
    l_g = np.zeros_like(l_v)
    l_g[..., 2] = -normal_gravity(lat, h)
    l_acc = m.l_v_dot() + np.cross(2.0 * w_ie + w_el, l_v) - l_g
    b_omega_lb = m.b_omega_lb()
    b_omega_eb = b_omega_lb + np.einsum("kji,kj->ki", l_R_b, w_el)
    b_omega_ib = b_omega_eb + np.einsum("kji,kj->ki", l_R_b, w_ie)
    b_f = np.einsum("kji,kj->ki", l_R_b, l_acc)
    return b_omega_ib, b_f, l_R_b, b_omega_eb
