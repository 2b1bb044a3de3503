"""Sensor noise from the data (core/sensor_noise.py) against simulated series: the quantisation step of quantised
IMU-like series (float64 and float32 storage, values off the grid, unquantised and constant series), its
white-noise density, the Allan deviation of white noise, and the white plus Gauss-Markov fit."""

from __future__ import annotations

import numpy as np
import pytest

from gtsam_dvl.core.sensor_noise import (
    allan_deviation,
    allan_fit,
    gauss_markov_fit,
    imu_quantisation,
    quantisation_density,
    quantisation_step,
)
from gtsam_dvl.core.units import DEG_PER_H
from tests.support.numerical import gauss_markov

RATE_HZ = 100.0
N = 60_000  # 10 minutes at 100 Hz


def moving_gyro(rng: np.random.Generator) -> np.ndarray:
    """A turning vehicle's gyro axis, rad/s: a slow random rate plus 5e-6 rad/s white noise per sample."""
    return np.cumsum(rng.normal(0.0, 1e-4, N)) * 0.01 + rng.normal(0.0, 5e-6, N)


def accelerometer_z(rng: np.random.Generator) -> np.ndarray:
    """Specific force along z, m/s^2: 9.8 with a slow swell and 1e-3 white noise."""
    return 9.8 + 0.05 * np.sin(np.arange(N) / 500.0) + rng.normal(0.0, 1e-3, N)


def quantised(x: np.ndarray, q: float) -> np.ndarray:
    return np.round(x / q) * q


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("q", [1e-4, 2.0**-20, 1e-5, 1e-6])
def test_step_of_a_quantised_gyro_within_1e_6(seed: int, q: float) -> None:
    step = quantisation_step(quantised(moving_gyro(np.random.default_rng(seed)), q))
    assert step is not None and step == pytest.approx(q, rel=1e-6)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("q", [1e-4, 1e-3])
def test_step_of_an_accelerometer_stored_as_float32(seed: int, q: float) -> None:
    """float32 stores 9.8 to 9.5e-7: k q is off its grid by up to 0.5 % of a 1e-4 step, and the spacings between
    levels are 104 or 105 float32 units."""
    x = (
        quantised(accelerometer_z(np.random.default_rng(seed)), q)
        .astype(np.float32)
        .astype(np.float64)
    )
    step = quantisation_step(x)
    assert step is not None and step == pytest.approx(q, rel=1e-6)


@pytest.mark.parametrize("seed", [1, 2])
def test_values_off_the_grid(seed: int) -> None:
    """0.5 % of the samples moved off the grid: the step is found (within 1e-5: the values off the grid leave fewer
    neighbouring levels to refine it on); 3 %: not quantised (fewer than 99 % on it)."""
    rng = np.random.default_rng(seed)
    q = 1e-3
    for fraction, expected in ((0.005, q), (0.03, None)):
        x = quantised(accelerometer_z(rng), q)
        off = rng.random(N) < fraction
        x[off] += rng.uniform(0.05, 0.95, off.sum()) * q
        step = quantisation_step(x)
        if expected is None:
            assert step is None
        else:
            assert step is not None and step == pytest.approx(expected, rel=1e-5)


def test_text_export_with_fixed_decimals() -> None:
    x = np.array([float(f"{v:.3f}") for v in accelerometer_z(np.random.default_rng(4))[:5000]])
    step = quantisation_step(x)
    assert step is not None and step == pytest.approx(1e-3, rel=1e-6)


@pytest.mark.parametrize("seed", [1, 2])
def test_unquantised_and_constant_series_have_no_step(seed: int) -> None:
    rng = np.random.default_rng(seed)
    assert quantisation_step(accelerometer_z(rng)) is None
    assert quantisation_step(accelerometer_z(rng).astype(np.float32).astype(np.float64)) is None
    assert quantisation_step(moving_gyro(rng)) is None
    assert quantisation_step(np.full(1000, 9.8)) is None
    assert quantisation_step(np.array([np.nan, 1.0])) is None


def test_static_gyro_with_noise_below_the_step() -> None:
    """At rest a navigation-grade gyro's noise (5e-6 rad/s per sample) is far below the step: the samples sit on
    two or three levels, which still give the step."""
    rng = np.random.default_rng(5)
    x = quantised(7.0e-5 + rng.normal(0.0, 5e-6, N), 1e-4)
    step = quantisation_step(x)
    assert step is not None and step == pytest.approx(1e-4, rel=1e-6)


def test_imu_quantisation_per_axis() -> None:
    rng = np.random.default_rng(6)
    b_omega = np.column_stack(
        [quantised(moving_gyro(rng), 1e-4), moving_gyro(rng), quantised(moving_gyro(rng), 1e-5)]
    )
    b_f = np.column_stack(
        [
            quantised(accelerometer_z(rng) - 9.8, 1e-4),
            accelerometer_z(rng),
            quantised(accelerometer_z(rng), 1e-4),
        ]
    )
    gyro, accel = imu_quantisation(b_omega, b_f)
    np.testing.assert_allclose(gyro[[0, 2]], [1e-4, 1e-5], rtol=1e-6)
    np.testing.assert_allclose(accel[[0, 2]], [1e-4, 1e-4], rtol=1e-6)
    assert np.isnan(gyro[1]) and np.isnan(accel[1])


def test_quantisation_density() -> None:
    """q = 1e-4 rad/s at 100 Hz: q / sqrt(12 * 100) = 2.89e-6 rad/s/sqrt(Hz) = 0.596 deg/h/sqrt(Hz); and the
    rounding error of a series whose noise spans several steps has that density (its per-sample sigma q / sqrt(12),
    within 2 %)."""
    assert quantisation_density(1e-4, 100.0) / DEG_PER_H == pytest.approx(0.5955, abs=5e-4)
    x = accelerometer_z(np.random.default_rng(7))
    error = quantised(x, 1e-4) - x
    assert np.std(error) / np.sqrt(RATE_HZ) == pytest.approx(
        quantisation_density(1e-4, RATE_HZ), rel=0.02
    )


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_allan_deviation_of_white_noise(seed: int) -> None:
    """White rate noise of density N: adev = N / sqrt(tau) (within 3 % up to 0.1 s, where the estimate averages
    thousands of independent differences), N read back within 10 %, and the bias instability below
    1.5 N / sqrt(longest tau) / 0.664 (white noise has no floor: the curve falls to the longest tau)."""
    rng = np.random.default_rng(seed)
    density = 2e-3
    # a constant offset (Earth rate, gravity) is removed
    x = 5.0 + rng.normal(0.0, density * np.sqrt(RATE_HZ), N)
    taus, adev = allan_deviation(x, RATE_HZ)
    short = taus <= 0.1
    np.testing.assert_allclose(adev[short], density / np.sqrt(taus[short]), rtol=0.03)
    fit = allan_fit(taus, adev)
    assert fit.white_density == pytest.approx(density, rel=0.10)
    assert fit.bias_instability < 1.5 * density / np.sqrt(taus[-1]) / 0.664


def test_allan_deviation_finds_a_bias_floor() -> None:
    """White noise plus a bias that wanders (a random walk slow enough to give a floor): the minimum lies inside
    the taus (not bounded) and the white density is still read within 10 %."""
    rng = np.random.default_rng(8)
    density = 2e-3
    x = rng.normal(0.0, density * np.sqrt(RATE_HZ), N) + np.cumsum(rng.normal(0.0, 1e-5, N))
    fit = allan_fit(*allan_deviation(x, RATE_HZ))
    assert fit.white_density == pytest.approx(density, rel=0.10)
    assert not fit.bias_bound


def test_gauss_markov_fit_over_seeds() -> None:
    """sw 7 mm/s, sg 3 mm/s, tau 60 s, 3600 samples at 1 Hz. Measured over 100 seeds (0-99): sg within 30 % in
    99, tau within a factor 2 in 95 (5-95 %: 0.57-1.59 of the truth), sw within 3 % in all, significant in all;
    white noise alone significant in 2. Here 12 seeds: sg within 30 % and significant in every one, tau within
    a factor 2 in at least 10, sw within 5 % in every one; white noise alone significant in at most 1."""
    sg_ok = tau_ok = sw_ok = significant = false_alarms = 0
    seeds = range(12)
    for seed in seeds:
        rng = np.random.default_rng(seed)
        t = np.arange(3600.0)
        fit = gauss_markov_fit(
            t, rng.normal(0.0, 0.007, 3600) + gauss_markov(3600, 1.0, 0.003, 60.0, rng), 1.0
        )
        sg_ok += abs(fit.gm_sigma / 0.003 - 1.0) < 0.3
        tau_ok += 0.5 < fit.gm_tau_s / 60.0 < 2.0
        sw_ok += abs(fit.white_sigma / 0.007 - 1.0) < 0.05
        significant += fit.significant
        false_alarms += gauss_markov_fit(t, rng.normal(0.0, 0.007, 3600), 1.0).significant
    n = len(seeds)
    assert (sg_ok, significant, sw_ok) == (n, n, n)
    assert tau_ok >= n - 2
    assert false_alarms <= 1


def test_gauss_markov_fit_with_gaps_and_pooled_axes() -> None:
    """Three axes pooled, a tenth of the pings missing (dropouts) and stamps jittered by 20 ms: sg within 30 %
    and tau within a factor 2 (seed 3), sw within 5 %."""
    rng = np.random.default_rng(3)
    n = 3600
    r = np.column_stack(
        [rng.normal(0.0, 0.007, n) + gauss_markov(n, 1.0, 0.003, 60.0, rng) for _ in range(3)]
    )
    keep = rng.random(n) > 0.1
    t = np.arange(n, dtype=float) + rng.normal(0.0, 0.02, n)
    fit = gauss_markov_fit(t[keep], r[keep], 1.0)
    assert fit.significant and fit.samples == 3 * int(keep.sum())
    assert fit.gm_sigma == pytest.approx(0.003, rel=0.3)
    assert 30.0 < fit.gm_tau_s < 120.0
    assert fit.white_sigma == pytest.approx(0.007, rel=0.05)


def test_gauss_markov_fit_on_a_short_record_with_the_mean_allowed_for() -> None:
    """sw 7 mm/s, sg 2 mm/s, tau 60 s, 400 s at 1 Hz on 3 axes (a 400 s underway log's DVL residuals): the removed
    mean takes about 2 tau / T = 30 % of sg^2, so the plain fit comes out low. Measured over 100 seeds (0-99):
    plain sg 1.71 +- 0.36 mm/s, tau's median 38 s; mean_corrected sg 2.17 +- 0.59 mm/s, tau's median 58 s. Here
    20 seeds: the mean of the corrected sg within 20 % of 2 mm/s (its std over 20 seeds: 0.59 / sqrt(20) = 0.13
    mm/s, 7 %), tau's median within a factor 1.6 of 60 s, the plain sg's mean below the corrected one's."""
    plain, corrected, taus = [], [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        r = np.column_stack(
            [
                rng.normal(0.0, 0.007, 400) + gauss_markov(400, 1.0, 0.002, 60.0, rng)
                for _ in range(3)
            ]
        )
        t = np.arange(400.0)
        plain.append(gauss_markov_fit(t, r, 1.0).gm_sigma)
        fit = gauss_markov_fit(t, r, 1.0, mean_corrected=True)
        corrected.append(fit.gm_sigma)
        taus.append(fit.gm_tau_s)
    assert np.mean(corrected) == pytest.approx(0.002, rel=0.2)
    assert 60.0 / 1.6 < np.median(taus) < 60.0 * 1.6
    assert np.mean(plain) < np.mean(corrected)
