"""A filter's states are judged with the calibration they were estimated with (analysis/health.py
state_calibration): a filter whose scale converged from 0.95 to 1 over the log fits every ping with the scale of
its time; the same states judged with the final scale would show residuals of the convergence, not of the data."""

from __future__ import annotations

import numpy as np
import pytest

from gtsam_dvl.analysis.health import dvl_residuals, is_filtered, state_calibration
from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.result import NavResult, Timeline
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import DvlData, ImuData, LogData
from tests.support.results import nominal_estimates

N = 60
SIGMA_M_S = 0.02


def _filtered(estimator: str) -> tuple[NavResult, LogData]:
    """N states at 1 Hz moving at 2 m/s along map x and body x; the filter's scale ramps from 0.95 to 1 and its
    yaw misalignment from 2 deg to 0; each ping is what the state predicts with the calibration of its time."""
    t = np.arange(N, dtype=float)
    k_t = np.linspace(0.95, 1.0, N)
    yaw_t = np.linspace(2.0, 0.0, N)
    n_v = np.tile([2.0, 0.0, 0.0], (N, 1))
    eye = np.tile(np.eye(3), (N, 1, 1))
    d_v = np.stack([k_t[i] * rpy_deg_to_matrix([0.0, 0.0, yaw_t[i]]).T @ n_v[i] for i in range(N)])
    zeros3 = np.zeros((N, 3))
    timeline = Timeline(
        t=t,
        scale=k_t,
        scale_sigma=np.full(N, 0.01),
        misalignment_deg=np.stack([np.zeros(N), np.zeros(N), yaw_t], axis=1),
        misalignment_sigma_deg=np.ones((N, 3)),
        gyro_bias_deg_per_h=zeros3,
        gyro_bias_sigma_deg_per_h=zeros3,
        accel_bias_ug=zeros3,
        accel_bias_sigma_ug=zeros3,
        attitude_sigma_deg=zeros3,
    )
    result = NavResult(
        estimator,
        t,
        np.cumsum(n_v, axis=0),
        eye,
        n_v,
        np.tile(np.eye(6), (N, 1, 1)) * 1e-6,
        eye * 1e-6,
        b_R_d0=np.eye(3),
        b_omega=zeros3,
        timeline=timeline,
        dvl_pings=np.arange(N),
        **nominal_estimates(bias_var=1e-12),
    )
    log = LogData(
        imu=ImuData(t=t, b_omega=zeros3, b_f=zeros3),
        dvl=DvlData(t, d_v, np.tile(np.eye(3) * SIGMA_M_S**2, (N, 1, 1)), np.ones(N, dtype=bool)),
    )
    return result, log


@pytest.mark.parametrize("estimator", ["ekf", "batch"])
def test_a_filter_is_judged_with_the_calibration_of_its_time(estimator: str) -> None:
    result, log = _filtered(estimator)
    # (white: chi2 against SIGMA_M_S alone)
    res = dvl_residuals(result, log, DvlConfig(correlated_sigma_m_s=0.0))
    k, b_R_d, _, _ = state_calibration(result, log)
    # each state with the scale and misalignment the filter held then: the pings fit
    if estimator == "ekf":
        assert is_filtered(result)
        assert k[0] == pytest.approx(0.95) and k[-1] == pytest.approx(1.0)
        np.testing.assert_allclose(b_R_d[0], rpy_deg_to_matrix([0.0, 0.0, 2.0]), atol=1e-12)
        assert res.rms() < 1e-9
    else:  # a smoother's states share the final calibration: the same data misfit by the early scale's 5 %
        assert not is_filtered(result) and np.all(k == 1.0)
        # 5 % of 2 m/s along x, 2 deg of it across
        first = log.dvl.d_v[0] - np.array([2.0, 0.0, 0.0])
        assert np.linalg.norm(first) > 0.1
        assert res.chi2[0] == pytest.approx(float(first @ first) / SIGMA_M_S**2, rel=1e-9)
        assert res.rms() > 1.5  # 2.0: the misfit falls linearly to 0 at the end


def test_attitude_at_a_shifted_time_follows_the_states_geodesic() -> None:
    """attitude_at against scipy's Slerp between the states (an independent formula) inside the states' span, and a
    state's own rate beyond it; in a turn that starts just after a state the old extrapolation by the state's rate
    was off by the turn's whole rotation (issue 31: realistic-turns residuals 2.1x their stated noise)."""
    from scipy.spatial.transform import Rotation, Slerp

    from gtsam_dvl.analysis.health import attitude_at

    t = np.arange(6.0)
    yaw = np.radians([0.0, 0.0, 30.0, 65.0, 90.0, 90.0])  # a turn starting after t = 1
    rot = Rotation.from_euler(
        "zyx", np.c_[yaw, np.radians(np.full(6, 3.0)), np.radians(np.arange(6.0))]
    )
    b_omega = np.tile([0.0, 0.0, 0.2], (6, 1))
    t_q = np.array([0.3, 1.0, 1.5, 2.25, 4.9, 5.0])
    got = attitude_at(t, rot.as_matrix(), b_omega, t_q)
    want = Slerp(t, rot)(t_q).as_matrix()
    assert np.abs(got - want).max() < 1e-12
    beyond = attitude_at(t, rot.as_matrix(), b_omega, np.array([5.5, -0.5]))
    assert (
        np.abs(beyond[0] - rot[5].as_matrix() @ Rotation.from_rotvec([0, 0, 0.1]).as_matrix()).max()
        < 1e-12
    )
    assert (
        np.abs(
            beyond[1] - rot[0].as_matrix() @ Rotation.from_rotvec([0, 0, -0.1]).as_matrix()
        ).max()
        < 1e-12
    )
