"""Noise levels from the data (estimators/models/noise_levels.py): the DVL's variance component fitted by the batch
smoother, the EKF and the online estimator against the simulated noise, and the robust ratio on its own."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf.filter import run_ekf
from gtsam_dvl.estimators.models.noise_levels import truncated_chi2_mean, variance_ratio
from gtsam_dvl.estimators.online import smooth_online
from tests.support.scenarios import simulate_variant

TRUE_NOISE_M_S = 0.007  # the simulated DVL's white noise per axis (a Teledyne/Nortek-class ping)
STATED_M_S = 0.02  # the configuration's: the paper's 2 cm/s, three times too large


@pytest.fixture(scope="module")
def log() -> LogData:
    return simulate_variant(4, dvl={"noise_m_s": TRUE_NOISE_M_S})


def _stated(**noise: object) -> EstimatorConfig:
    return EstimatorConfig.from_dict({"dvl": {"noise_m_s": STATED_M_S}, "noise": dict(noise)})


def test_truncated_chi2_mean_matches_sampling() -> None:
    rng = np.random.default_rng(0)
    x = chi2.rvs(3, size=2_000_000, random_state=rng)
    c = 4.0**2
    assert truncated_chi2_mean(3, c) == pytest.approx(x[x <= c].mean(), rel=2e-3)


def test_variance_ratio_is_robust_to_gross_errors() -> None:
    """Whitened errors with sigma 0.35 (a noise stated 2.9 times too large) and 3 % of rows 30 sigma off: the
    ratio is 0.35^2 within its sampling error (2 % on 3000 rows of 3), the bad rows left out."""
    rng = np.random.default_rng(1)
    ew = 0.35 * rng.standard_normal((3000, 3))
    bad = rng.random(3000) < 0.03
    ew[bad] += 30 * 0.35
    ratio, used = variance_ratio(ew, robust_k=4.0)
    assert ratio == pytest.approx(0.35**2, rel=0.06)
    assert used == pytest.approx((~bad).sum(), abs=5)


def test_batch_fits_the_dvl_noise(log: LogData) -> None:
    """Stated 2 cm/s, simulated 7 mm/s white: the white fit finds the simulated sigma within 5 % (the fit's sampling
    error on 2500 rows is 1.4 %, its redundancy bias about 1 %) and reports it, but the DVL keeps the stated level:
    the scatter alone cannot show that the 30-60 s means are as good, and nothing in an IMU + DVL log observes them
    (issue 31: a level fitted to the scatter lets the calibration chase the slow errors). So the run equals the one
    with the fit off: chi^2/dof the stated noise's square ratio (0.12), the same scale sigma, the truth within it."""
    fitted = smooth_batch(log, _stated())
    dvl = fitted.info["noise"]["dvl"]
    assert dvl["white_sigma"] == pytest.approx(TRUE_NOISE_M_S, rel=0.05)
    assert dvl["stated_sigma"] == pytest.approx(STATED_M_S) and dvl["sigma_m_s"] == pytest.approx(
        STATED_M_S
    )
    assert dvl["multiplier"] == 1.0 and "held at the stated level" in dvl["why"]
    long = dvl[
        "long"
    ]  # white noise: the 30-60 s means show no more than the scatter (the states absorb a part)
    assert long["sigma_lo"] < dvl["white_sigma"]
    assert fitted.config["dvl"]["noise_multiplier"] == 1.0
    plain = smooth_batch(log, _stated(from_data=False))
    for r in (fitted, plain):
        s = r.info["solver"]
        assert 2 * s["final_error"] / s["dof"] == pytest.approx(
            (TRUE_NOISE_M_S / STATED_M_S) ** 2, rel=0.15
        )
    assert plain.info["noise"]["dvl"] == {}
    assert fitted.calibration["scale"].sigma[0] == pytest.approx(
        plain.calibration["scale"].sigma[0], rel=0.02
    )
    assert log.true_calibration is not None
    k, sk = fitted.calibration["scale"].value[0], fitted.calibration["scale"].sigma[0]
    assert abs(k - log.true_calibration.scale) < 3 * sk


def test_batch_raises_a_dvl_stated_too_small(log: LogData) -> None:
    """Stated 3 mm/s, simulated 7 mm/s: the fit raises the level to the simulated one within 5 %; chi^2/dof after
    the fit within [0.9, 1.1]."""
    r = smooth_batch(log, EstimatorConfig.from_dict({"dvl": {"noise_m_s": 0.003}}))
    dvl = r.info["noise"]["dvl"]
    assert dvl["sigma_m_s"] == pytest.approx(TRUE_NOISE_M_S, rel=0.05)
    assert dvl["multiplier"] == pytest.approx(TRUE_NOISE_M_S / 0.003, rel=0.05)
    assert r.noise_config is not None and r.noise_config.dvl.noise_multiplier == dvl["multiplier"]
    s = r.info["solver"]
    assert 0.9 <= 2 * s["final_error"] / s["dof"] <= 1.1


def test_batch_raises_the_dvl_to_its_slow_error() -> None:
    """Simulated 5 mm/s white plus a 6 mm/s Gauss-Markov error over 60 s, stated 5 mm/s (the scatter): the fit
    raises the level to what the 30-60 s means show (more than 1.5 times the scatter, its interval's lower end
    above the white fit), says so, and the scale's truth is within 3 of the sigmas it then reports. The model here
    has no correlated-error state ([dvl] correlated_sigma_m_s = 0), so nothing else absorbs the slow error."""
    slow = simulate_variant(
        4, dvl={"noise_m_s": 0.005, "correlated_sigma_m_s": 0.006, "correlated_tau_s": 60.0}
    )
    r = smooth_batch(
        slow, EstimatorConfig.from_dict({"dvl": {"noise_m_s": 0.005, "correlated_sigma_m_s": 0.0}})
    )
    dvl = r.info["noise"]["dvl"]
    print(dvl)
    # the scatter holds the white noise and the slow error's fast part: between the two, below their sum's
    assert 0.005 < dvl["white_sigma"] < math.hypot(0.005, 0.006)
    assert (
        dvl["sigma_m_s"] > 1.5 * dvl["white_sigma"] and dvl["long"]["sigma_lo"] > dvl["white_sigma"]
    )
    assert "raised to what its" in dvl["why"]
    assert slow.true_calibration is not None
    k, sk = r.calibration["scale"].value[0], r.calibration["scale"].sigma[0]
    assert abs(k - slow.true_calibration.scale) < 3 * sk


def test_ekf_fits_the_dvl_noise(log: LogData) -> None:
    """The EKF's covariance matching over the warm-up window: stated 2 cm/s, simulated 7 mm/s, the filter keeps
    the stated level (it has no absolute reference for the slow errors), NIS/dof then the stated noise's square
    ratio's neighbourhood (below 0.5); stated 3 mm/s, the fit raises it to the simulated sigma within 8 % (880 rows
    over 300 s: 3 % sampling error), NIS/dof after it in [0.85, 1.15]."""
    r = run_ekf(log, _stated(warmup_s=300.0))
    dvl = r.info["noise"]["dvl"]
    assert dvl["multiplier"] == 1.0
    assert r.info["filter"]["mean_nis_per_dof"] < 0.5
    low = run_ekf(
        log, EstimatorConfig.from_dict({"dvl": {"noise_m_s": 0.003}, "noise": {"warmup_s": 300.0}})
    )
    dvl = low.info["noise"]["dvl"]
    assert dvl["sigma_m_s"] == pytest.approx(TRUE_NOISE_M_S, rel=0.08)
    assert dvl["settled"]
    assert 0.85 <= low.info["filter"]["mean_nis_per_dof"] <= 1.15


def test_online_fits_the_dvl_noise_on_its_warmup(log: LogData) -> None:
    """The online smoother's residuals 10 s after each ping over the first 300 s: the white sigma is the simulated
    one within 8 %, reported; the level used stays the stated one (as the batch smoother's: no absolute reference),
    the result's noise_config and configuration carry it."""
    r = smooth_online(log, _stated(warmup_s=300.0))
    dvl = r.info["noise"]["dvl"]
    assert dvl["white_sigma"] == pytest.approx(TRUE_NOISE_M_S, rel=0.08)
    assert dvl["multiplier"] == 1.0 and "held at the stated level" in dvl["why"]
    assert r.noise_config is not None and r.noise_config.dvl.noise_multiplier == pytest.approx(
        dvl["multiplier"]
    )
    assert r.config["dvl"]["noise_multiplier"] == 1.0


def test_paper_configuration_takes_the_stated_noise(log: LogData) -> None:
    cfg = EstimatorConfig.named("paper")
    assert not cfg.noise.from_data
    r = smooth_batch(log, cfg)
    assert r.info["noise"] == {"imu": {}, "dvl": {}}
    assert r.config["dvl"]["noise_multiplier"] == 1.0


def test_static_segment_measures_the_imu_white_noise() -> None:
    """paper-3d-short's 120 s static start with a gyro five times noisier than the configured 0.1 deg/h/sqrt(Hz):
    the density used is the simulated 0.5 within 15 % (Allan deviation of 120 s at taus up to 12 s: about 10 %
    sampling error), and the accelerometer, simulated at its configured 10 micro-g/sqrt(Hz), is left as
    configured (its measured density, within 15 % of 10, is reported)."""
    from gtsam_dvl.estimators.models.noise_levels import NoiseReport, imu_levels

    noisy = simulate_variant(3, imu={"gyro_noise_deg_per_h_per_sqrt_hz": 0.5})
    report = NoiseReport()
    used = imu_levels(noisy, EstimatorConfig(), report)
    gyro, accel = report.imu["gyro"]["static"], report.imu["accel"]["static"]
    print(gyro, accel)
    assert 100.0 <= gyro["segment_s"] <= 125.0
    assert used.imu.gyro_noise_deg_per_h_rthz == pytest.approx(0.5, rel=0.15)
    assert "measured on the first" in gyro["why"]
    assert accel["density"] == pytest.approx(10.0, rel=0.15) and "why" not in accel
    assert used.imu.accel_noise_ug_rthz == EstimatorConfig().imu.accel_noise_ug_rthz
    # off: as configured
    off = imu_levels(
        noisy, EstimatorConfig.from_dict({"noise": {"static_allan": False}}), NoiseReport()
    )
    assert off.imu.gyro_noise_deg_per_h_rthz == EstimatorConfig().imu.gyro_noise_deg_per_h_rthz


def test_static_segment_of_a_quantised_imu_at_rest_is_not_read() -> None:
    """A FOG at rest under a 1e-4 rad/s step sits on one or two steps: its gyro axes are skipped (the rounding
    error is not white there), the quantisation floor alone applies."""
    from gtsam_dvl.estimators.models.noise_levels import NoiseReport, imu_levels

    log = simulate_variant(3)
    q = 1e-4
    imu = log.imu
    quantised = type(imu)(
        **{
            **imu.__dict__,
            "b_omega": np.round(np.asarray(imu.b_omega) / q) * q,
            "b_f": np.round(np.asarray(imu.b_f) / q) * q,
        }
    )
    log = type(log)(**{**log.__dict__, "imu": quantised})
    report = NoiseReport()
    imu_levels(log, EstimatorConfig(), report)
    gyro = report.imu["gyro"]
    assert gyro["step"] == pytest.approx([q, q, q], rel=0.01)
    assert sorted(gyro["static"]["axes_skipped_quantised"]) == ["x", "y", "z"]
    assert "density" not in gyro["static"]
    # the console's words: the gyro's floor (0.6 deg/h/sqrt(Hz)) raises the configured 0.1, the accelerometer's
    # (0.29 micro-g/sqrt(Hz)) is far below its configured 10 and changes nothing
    assert "white noise 0.6" in gyro["why"] and "instead of 0.1" in gyro["why"]
    accel = report.imu["accel"]
    assert accel["used"] == pytest.approx(10.0, rel=1e-3) and "which stands" in accel["why"]
