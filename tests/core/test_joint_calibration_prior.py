"""A vehicle's calibration as the prior (core/states.py calibration_prior, prior_factors, initial_values): one joint
Gaussian over the keys of the states it holds that the configuration estimates, exact on the manifold around the
file's values, replacing those states' configured priors."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from gtsam_dvl.core import states
from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import C_MISALIGN, K_SCALE, L_LEVER, T_OFFSET, B
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_exp
from gtsam_dvl.core.types import Mounting

MOUNTING = Mounting(b_R_d0=rpy_deg_to_matrix([180.0, 0.0, 45.0]))
NAMES = ("scale", "misalignment", "time_offset", "lever_arm")


def _calibration(names: tuple[str, ...] = NAMES, seed: int = 0) -> VehicleCalibration:
    """Values near the mounting and a covariance with strong correlations (SI; the misalignment's right tangent)."""
    rng = np.random.default_rng(seed)
    values = {
        "scale": np.array([1.0021]),
        "misalignment": MOUNTING.b_R_d0 @ rpy_deg_to_matrix([0.3, -0.2, 0.7]),
        "time_offset": np.array([-0.12]),
        "lever_arm": np.array([0.4, -0.1, 0.2]),
    }
    sig = {
        "scale": [3e-4],
        "misalignment": np.radians([0.05, 0.08, 0.3]),
        "time_offset": [0.01],
        "lever_arm": [0.05, 0.05, 0.08],
    }
    s = np.concatenate([sig[n] for n in names])
    corr = rng.normal(size=(len(s), len(s)))
    corr = corr @ corr.T + len(s) * np.eye(len(s))
    d = np.sqrt(np.diag(corr))
    cov = np.diag(s) @ (corr / np.outer(d, d)) @ np.diag(s)
    return VehicleCalibration(
        "auv-1", "2026-11-02T10:15:00Z", names, {n: values[n] for n in names}, cov
    )


def _config(offset: bool = True, lever: bool = True) -> EstimatorConfig:
    return EstimatorConfig.from_dict(
        {"dvl": {"estimate_time_offset": offset, "estimate_lever_arm": lever}}
    )


def _perturbed(values: gtsam.Values, d: dict[str, np.ndarray]) -> gtsam.Values:
    """values with each state moved by d (a vector's difference; the rotation on the right, b_R_d Exp(d))."""
    out = gtsam.Values(values)
    out.update(K_SCALE, values.atVector(K_SCALE) + d["scale"])
    out.update(
        C_MISALIGN, gtsam.Rot3(values.atRot3(C_MISALIGN).matrix() @ so3_exp(d["misalignment"]))
    )
    out.update(T_OFFSET, values.atVector(T_OFFSET) + d["time_offset"])
    out.update(L_LEVER, values.atVector(L_LEVER) + d["lever_arm"])
    return out


def test_one_joint_prior_replaces_the_configured_ones_and_starts_at_the_file() -> None:
    cfg, cal = _config(), _calibration()
    factors = states.prior_factors(cfg, MOUNTING, cal)
    on = sorted(tuple(sorted(f.keys())) for f in factors)
    assert on == sorted([(B(0),), tuple(sorted([K_SCALE, C_MISALIGN, T_OFFSET, L_LEVER]))])
    values = states.initial_values(cfg, MOUNTING, cal)
    read = states.read_values(values, cfg)
    for n in NAMES:
        np.testing.assert_array_equal(read[n], cal.values[n])
    # the others at their configured priors
    np.testing.assert_array_equal(read["accel_bias"], np.zeros(3))
    # without a calibration: the configuration's, one prior per key
    assert len(states.prior_factors(cfg, MOUNTING)) == 5


def test_joint_prior_is_the_exact_gaussian_about_the_file_values() -> None:
    """Error 0 at the mean; at a perturbed value 0.5 d^T Sigma^-1 d with d the tangent difference (the rotation's
    b_R_d0^T b_R_d logarithm), in the file's order; its Jacobians are those of that error (finite differences)."""
    cfg, cal = _config(), _calibration()
    factor = states.calibration_prior(cfg, cal)
    assert factor is not None
    values = states.initial_values(cfg, MOUNTING, cal)
    assert factor.error(values) == pytest.approx(0.0, abs=1e-18)
    rng = np.random.default_rng(3)
    for scale in (1.0, 30.0):  # within the sigmas, and far out (0.2 rad of rotation)
        d = {
            n: scale * rng.normal(size=sl.stop - sl.start) * np.sqrt(np.diag(cal.cov)[sl])
            for n, sl in cal.slices().items()
        }
        moved = _perturbed(values, d)
        delta = np.concatenate([d[n] for n in NAMES])
        expected = 0.5 * delta @ np.linalg.solve(cal.cov, delta)
        assert factor.error(moved) == pytest.approx(expected, rel=1e-9)
        # the Jacobian of the whitened error in each key's tangent against central differences
        lin = factor.linearize(moved)
        A, _ = lin.jacobian()
        col = 0
        for k in factor.keys():
            dim = moved.atRot3(k).matrix().shape[0] if k == C_MISALIGN else len(moved.atVector(k))
            for c in range(dim):
                h = np.zeros(dim)
                h[c] = 1e-6
                plus, minus = _retracted(moved, k, h), _retracted(moved, k, -h)
                num = (factor.whitenedError(plus) - factor.whitenedError(minus)) / 2e-6
                np.testing.assert_allclose(A[:, col + c], num, atol=1e-5 * np.abs(num).max() + 1e-9)
            col += dim


def _retracted(values: gtsam.Values, key: int, h: np.ndarray) -> gtsam.Values:
    out = gtsam.Values(values)
    if key == C_MISALIGN:
        out.update(key, gtsam.Rot3(values.atRot3(key).matrix() @ so3_exp(h)))
    else:
        out.update(key, values.atVector(key) + h)
    return out


def test_states_not_estimated_leave_their_marginal_block() -> None:
    """A file with the time offset and lever arm, a configuration estimating neither: the prior is the marginal of
    scale and misalignment (the block of the joint covariance); a calibration of the scale alone keeps the
    misalignment's configured prior."""
    cfg, cal = _config(offset=False, lever=False), _calibration()
    factor = states.calibration_prior(cfg, cal)
    assert factor is not None and sorted(factor.keys()) == sorted([K_SCALE, C_MISALIGN])
    values = states.initial_values(cfg, MOUNTING, cal)
    d = np.array([2e-4, 1e-3, -2e-3, 4e-3])
    moved = gtsam.Values(values)
    moved.update(K_SCALE, values.atVector(K_SCALE) + d[:1])
    moved.update(C_MISALIGN, gtsam.Rot3(values.atRot3(C_MISALIGN).matrix() @ so3_exp(d[1:])))
    block = cal.block(["scale", "misalignment"])
    assert factor.error(moved) == pytest.approx(0.5 * d @ np.linalg.solve(block, d), rel=1e-9)
    only_scale = _calibration(("scale",))
    keys = sorted(tuple(f.keys()) for f in states.prior_factors(cfg, MOUNTING, only_scale))
    assert keys == sorted([(B(0),), (K_SCALE,), (C_MISALIGN,)])
    assert states.read_values(states.initial_values(cfg, MOUNTING, only_scale), cfg)[
        "misalignment"
    ] == pytest.approx(MOUNTING.b_R_d0)


def test_a_key_held_in_part_is_refused() -> None:
    cal = VehicleCalibration(
        "auv-1",
        "2026-11-02T10:15:00Z",
        ("accel_bias",),
        {"accel_bias": np.zeros(3)},
        np.eye(3) * 1e-8,
    )
    with pytest.raises(GtsamDvlError, match="holds part of the gyro bias's variable"):
        states.prior_factors(_config(), MOUNTING, cal)


def test_from_result_without_the_shared_joint_keeps_the_calibration_block() -> None:
    """A result without shared_joint_cov (the online estimator's): the file's scale and misalignment jointly from
    calib_joint_cov ([accel, gyro] bias, scale, misalignment), the time offset's marginal beside them."""
    from types import SimpleNamespace

    from gtsam_dvl.core.calibration import from_result
    from gtsam_dvl.core.states import Estimate

    cfg = _config(offset=True, lever=False)
    cal = _calibration(("scale", "misalignment", "time_offset"))
    block = np.eye(10) * 1e-9
    block[6:, 6:] = cal.block(["scale", "misalignment"])
    result = SimpleNamespace(
        calibration={n: Estimate(cal.values[n], cal.block([n])) for n in cal.states},
        shared_joint_cov=None,
        calib_joint_cov=block,
        t0_ns=0,
        config={},
    )
    out = from_result(result, cfg, "auv-1")
    assert out.states == cal.states
    np.testing.assert_allclose(
        out.block(["scale", "misalignment"]), cal.block(["scale", "misalignment"])
    )
    np.testing.assert_allclose(out.block(["time_offset"]), cal.block(["time_offset"]))
    assert np.all(out.cov[:4, 4] == 0.0)
