"""An independent strapdown integration of a simulated log's IMU against its truth (tests/sim/test_sim_physics.py
and test_sensor_errors.py): the simulator's IMU must reproduce the truth's motion to 1 % of the white-noise drift."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gtsam_dvl.core import earth
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.types import LogData

N_G = 0.1 * np.pi / 180.0 / 3600.0  # gyro noise density, rad/s/sqrt(Hz)
N_A = 10.0 * 9.80665e-6  # accelerometer noise density, m/s^2/sqrt(Hz)
A, F = (
    6378137.0,
    1.0 / 298.257223563,
)  # WGS-84 (written apart from gtsam_dvl.core.earth: an independent check)
E2 = F * (2.0 - F)


def _gravity(frame: LocalFrame, n_p: np.ndarray) -> np.ndarray:
    """Normal gravity at map positions (K, 3); latitude by Bowring's closed form (1e-15 rad near the surface)."""
    e_p = frame.e_p0 + n_p @ frame.e_R_n.T
    b = A * (1.0 - F)
    rho = np.hypot(e_p[:, 0], e_p[:, 1])
    th = np.arctan2(e_p[:, 2] * A, rho * b)
    lat = np.arctan2(
        e_p[:, 2] + (A * A - b * b) / (b * b) * b * np.sin(th) ** 3, rho - E2 * A * np.cos(th) ** 3
    )
    lon = np.arctan2(e_p[:, 1], e_p[:, 0])
    h = rho * np.cos(lat) + e_p[:, 2] * np.sin(lat) - A * np.sqrt(1.0 - E2 * np.sin(lat) ** 2)
    e_up = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    return -earth.normal_gravity(lat, h)[:, None] * (e_up @ frame.e_R_n)


def strapdown(
    log: LogData, frame: LocalFrame, t_start: float, T: float
) -> tuple[float, float, float]:
    """(attitude rad, velocity m/s, position m) error after T seconds from the truth at t_start."""
    imu, truth = log.imu, log.truth
    assert truth is not None
    dt = 0.01
    bg = np.array(log.metadata["truth"]["imu"]["gyro_bias_rad_s"])
    ba = np.array(log.metadata["truth"]["imu"]["accel_bias_m_s2"])
    k0, k1 = round(t_start / dt), round((t_start + T) / dt)
    i0, i1 = np.searchsorted(truth.t, [t_start - 1e-9, t_start + T - 1e-9])
    assert abs(imu.t[k0] - truth.t[i0]) < 1e-9 and abs(imu.t[k1] - truth.t[i1]) < 1e-9
    dth = (imu.b_omega[k0 : k1 + 1] - bg) * dt  # sample k0 is the "previous" one of the first step
    dv = (imu.b_f[k0 : k1 + 1] - ba) * dt
    th, th_p, vv, vv_p = dth[1:], dth[:-1], dv[1:], dv[:-1]
    phi = th + np.cross(th_p, th) / 12.0  # two-sample coning
    # rotation compensation to second order (the 1/6 term: without it the turn error is 0.2 % of the bound,
    # converging as dt^2) plus two-sample sculling
    dv_b = vv + np.cross(th, vv) / 2 + np.cross(th, np.cross(th, vv)) / 6
    dv_b += (np.cross(th_p, vv) + np.cross(vv_p, th)) / 12
    w = frame.n_omega_ie
    E = Rotation.from_rotvec(-w * dt).as_matrix()  # exact Earth rotation of the map frame per step
    E_half = Rotation.from_rotvec(-w * dt / 2).as_matrix()
    steps = Rotation.from_rotvec(phi).as_matrix()
    C = np.empty((len(phi) + 1, 3, 3))
    C[0] = Rotation.from_quat(truth.n_q_b[i0]).as_matrix()
    for j, R in enumerate(steps):
        C[j + 1] = E @ C[j] @ R
    dv_sf = np.einsum("ij,kjl,kl->ki", E_half, C[:-1], dv_b)
    # velocity and position by the trapezoidal rule on gravity and Coriolis, implicit in (v, p): solved by
    # fixed-point iteration over the whole window (contraction ~1e-2 per pass)
    v0, p0 = truth.n_v[i0], truth.n_p[i0]
    p = np.broadcast_to(p0, (len(phi) + 1, 3)).copy()
    v = np.broadcast_to(v0, (len(phi) + 1, 3)).copy()
    for _ in range(30):
        a = _gravity(frame, p) - 2.0 * np.cross(w, v)
        v_new = v0 + np.concatenate(
            [[0 * v0], np.cumsum(dv_sf + 0.5 * (a[:-1] + a[1:]) * dt, axis=0)]
        )
        p_new = p0 + np.concatenate(
            [[0 * p0], np.cumsum(0.5 * (v_new[:-1] + v_new[1:]) * dt, axis=0)]
        )
        change = np.max(np.abs(p_new - p))
        v, p = v_new, p_new
        if change < 1e-12:
            break
    C_true = Rotation.from_quat(truth.n_q_b[i1]).as_matrix()
    e_att = float(np.linalg.norm(Rotation.from_matrix(C_true.T @ C[-1]).as_rotvec()))
    return (
        e_att,
        float(np.linalg.norm(v[-1] - truth.n_v[i1])),
        float(np.linalg.norm(p[-1] - truth.n_p[i1])),
    )


def _check_window(
    log: LogData, frame: LocalFrame, label: str, t_start: float, T: float = 60.0
) -> None:
    errors = strapdown(log, frame, t_start, T)
    bounds = (N_G * np.sqrt(T), N_A * np.sqrt(T), N_A * np.sqrt(T**3 / 3.0))
    ratios = [e / b for e, b in zip(errors, bounds, strict=True)]
    print(
        f"{label:>14} {t_start:6.0f}-{t_start + T:.0f} s: attitude {errors[0]:.2e} rad ({ratios[0]:.1e}), "
        f"velocity {errors[1]:.2e} m/s ({ratios[1]:.1e}), position {errors[2]:.2e} m ({ratios[2]:.1e}) "
        "[ratio to the white-noise drift]"
    )
    assert max(ratios) < 0.01
