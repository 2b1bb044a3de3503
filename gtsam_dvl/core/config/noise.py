"""[noise]: the noise levels the estimators take from the data (estimators/models/noise_levels.py).

Datasheet densities and a DVL's stated noise describe the sensor, not the log: an IMU whose samples were
quantised by its driver or an export (steps of 1e-4 rad/s and 1e-4 m/s^2 are common) carries white noise of
q / sqrt(12) per sample on top of the sensor's own, and a real DVL's ping noise (5-9 mm/s on Teledyne- and
Nortek-class units) is rarely what its messages' covariance or the configured default says. With from_data on
(the default), every estimator

- finds the quantisation step of each IMU axis from the samples (core/sensor_noise.py) and raises the
  configured white-noise density to the root sum of squares of it and the rounding error's density
  q / sqrt(12 f) (imu_quantisation);
- measures each IMU axis's white noise on the log's initial static segment, when it lasts at least 60 s, from its
  Allan deviation, and raises the density used to it when it is larger (static_allan);
- fits a factor on every DVL sigma (a variance component: [dvl] noise_multiplier) from the whitened DVL
  residuals (fit_dvl): the batch smoother re-solves with the fitted factor until it changes by less than
  fit_tolerance (at most fit_passes solves); the online estimator and the EKF fit it on the pings of the first
  warmup_s seconds and hold it from then on;
- fits a factor on every depth sigma ([depth] noise_multiplier, fit_depth) and one on every GNSS fix's sigma
  ([gnss] noise_multiplier, fit_gnss) the same way, each from its own sensor's whitened residuals, jointly with
  the DVL's in the batch smoother's fit and solve loop (a log without depth samples or aiding fixes has no such
  factor and nothing to fit). The online estimator and the EKF hold the configured depth level and say so (they
  take no GNSS fixes);
- with fit_correlated (off by default), fits the DVL's correlated error's level and time constant ([dvl]
  correlated_sigma_m_s, correlated_tau_s) in the batch smoother's loop, within their bounds
  (estimators/models/correlated_fit.py: why it is off).

The fitted factor is clipped to [dvl_min_multiplier, dvl_max_multiplier] (a fit at a bound is reported: the
model does not fit, whatever the factor), the depth's to [depth_min_multiplier, depth_max_multiplier] and the
GNSS's to [gnss_min_multiplier, gnss_max_multiplier]. The fit starts from [dvl] noise_multiplier; fit_dvl =
false pins the DVL at it (fit_depth = false, fit_gnss = false: the depth and the fixes at theirs),
imu_quantisation = false pins the IMU densities as configured.
"""

from __future__ import annotations

from typing import ClassVar

from pydantic import Field

from gtsam_dvl.core.config.base import ConfigModel, Flag, Integer, NonNegative, Positive


class NoiseConfig(ConfigModel):
    SECTION: ClassVar[str] = "noise"

    from_data: Flag = True  # false: every level as configured (the "paper" configuration)
    imu_quantisation: Flag = True  # raise the IMU white noise to its quantisation floor
    # raise the IMU white noise to the one measured on an initial static segment (Allan deviation, at least 60 s)
    static_allan: Flag = True
    fit_dvl: Flag = True  # fit the DVL noise factor from the residuals
    fit_passes: Integer = Field(default=4, ge=1)  # batch: solves at most, the first included
    # batch: re-solve while the fitted factor changes by more than this fraction (0.03: the fit's own sampling
    # error on 400 pings of 3 axes is 2 %)
    fit_tolerance: Positive = 0.03
    # bounds of the fitted factor: 0.1-10 covers a stated noise ten times too large or too small
    dvl_min_multiplier: Positive = 0.1
    dvl_max_multiplier: Positive = 10.0
    # fit the depth sensor's and the GNSS fixes' noise factors from their residuals (batch smoother), each within
    # its bounds (0.1-10, as the DVL's)
    fit_depth: Flag = True
    fit_gnss: Flag = True
    depth_min_multiplier: Positive = 0.1
    depth_max_multiplier: Positive = 10.0
    gnss_min_multiplier: Positive = 0.1
    gnss_max_multiplier: Positive = 10.0
    # batch: fit the DVL's correlated error ([dvl] correlated_sigma_m_s, correlated_tau_s: a first-order Gauss-Markov
    # process) from the DVL residuals with the estimated error added back, within the bounds below; off by default:
    # on IMU + DVL logs the navigation solution absorbs the slow part of the DVL's error, the residuals do not show
    # it and the configured (or preset) level holds (estimators/models/correlated_fit.py)
    fit_correlated: Flag = False
    correlated_min_sigma_m_s: NonNegative = 0.0
    correlated_max_sigma_m_s: Positive = 0.05
    correlated_min_tau_s: Positive = 5.0
    correlated_max_tau_s: Positive = 600.0
    # re-solve while the fitted level or time constant changes by more than this fraction (the fit's own sampling
    # error on a 400 s, 1 Hz log is 15-30 % of the level)
    correlated_tolerance: Positive = 0.1
    # fewer rows of a sensor than this: no fit of its factor (its sampling error would exceed 10 %)
    min_rows: Integer = Field(default=60, ge=3)
    # online estimator and EKF: the fit's window from the first ping, s (then held)
    warmup_s: Positive = 120.0
