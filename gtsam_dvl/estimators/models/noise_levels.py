"""The noise levels every estimator takes from the data ([noise], core/config/noise.py).

IMU quantisation floor. A sample rounded to a step q carries a rounding error uniform on [-q/2, q/2]: white noise
of variance q^2 / 12 per sample while the vehicle moves (the signal sweeps many steps between samples), i.e. a
density of q / sqrt(12 f) at the sample rate f. It adds to the sensor's own white noise:

    N_used = sqrt(N_configured^2 + (q / sqrt(12 f))^2)

per sensor, with the largest step of its three axes (the preintegration takes one isotropic density). At 100 Hz and
q = 1e-4 rad/s that is 0.60 deg/h/sqrt(Hz), six times a FOG's 0.1.

DVL variance component. Every ping's covariance R_i (configured, from its message, or the default) is taken as
lambda^2 R_i, and lambda is fitted from the whitened residuals e_i = W_i r_i (W_i^T W_i = (lambda^2 R_i)^-1) at the
solution: lambda_new^2 = lambda^2 sum |e_i|^2 / (m n), the variance-component estimate of the group (Helmert /
Foerstner) with the redundancy of the DVL rows taken as their number: the other states absorb a small part of the
residual (on a 400 s, 1 Hz run: the calibration, biases, initial velocity and attitude, 15-20 of 1200 rows, so
lambda is low by about 1 %). Robust to bad pings: the rows beyond the robust kernel's threshold at a median-based
scale are left out, and the truncation of the chi^2 distribution there is corrected for exactly
(E[x | x <= c] = m F_{m+2}(c) / F_m(c) for x ~ chi^2_m). The batch smoother iterates fit and solve; the online
estimator and the EKF fit on a warm-up window and hold the factor.

Depth and GNSS variance components. The same fit, one factor per sensor group ([depth] noise_multiplier on every
depth sample's sigma, [gnss] noise_multiplier on every aiding fix's), each from its own group's whitened residuals
with its redundancy taken as its row count, fitted jointly with the DVL's in the batch smoother's loop (every
group's factor from the same solution, then one re-solve with all of them). The redundancy is lower here than the
DVL's where a sensor alone fixes a state: a depth sample pins the vertical position near it, against the DVL's and
the IMU's integrated vertical motion between samples, so a part of its residual is absorbed (the fitted sigma of a
1 Hz, 5 cm depth sensor with a 2 cm/s DVL is low by about 4 %, at 5 Hz by 0.5 %, measured over six simulated dives);
the fixes of one surface interval give the interval's position (3 of their rows; the sigma low by about 2 %).
Neither factor is robust: the fit leaves out the rows beyond SCREEN_K sigma at a median-based scale and corrects for
the truncation as the DVL's. The online estimator and the EKF hold the configured depth level and say so
(held_depth_level; neither takes GNSS fixes), and the DVL's correlated error's level, which the batch smoother
fits with [noise] fit_correlated (estimators/models/correlated_fit.py; held_levels).

Honest level. A real DVL's error is not white: its ping-to-ping scatter is 3-9 mm/s while its 30-60 s means stay
at a few mm/s (bottom type, attitude-dependent beam errors, the speed of sound), and those slow errors are what the
scale and misalignment see. A variance component fitted to the scatter alone weights the DVL as if its 30 s means
were scatter / sqrt(30): the calibration then chases the slow errors while chi^2/dof looks perfect. So the white fit
(above) is only the first of three levels (honest_multiplier):
- the long-window level: the residuals (with the estimated correlated error E added back) averaged over blocks of
  30 and 60 s, n_b mean_b(e)^2 averaged over blocks and axes (for white errors it is the white ratio; long_level),
  with its 90 % chi^2 interval. Where its lower end is above the white fit, the level is raised to it;
- the stated level (the configuration's, a preset's, the messages' covariance): never gone below unless an
  absolute reference observes the sensor's slow errors and the long-window level's upper end is below it. In an
  IMU + DVL log nothing does: at 30-60 s the IMU cannot tell a slow DVL error from the velocity (a 4 mm/s error
  over 60 s is a 7 micro-g acceleration), the navigation solution absorbs it and the residuals do not show it
  (measured: a 4 mm/s, 60 s Gauss-Markov error leaves 30 s means of 0.6 mm/s). GNSS fixes in the graph observe
  the DVL's; nothing in these logs observes the depth sensor's or the fixes' own slow errors.
The report keeps all three (white_sigma, long, stated_sigma) beside the level used. The online estimator and the
EKF fit on their warm-up window and hold the stated level as the floor (no absolute reference).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import chi2

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.sensor_noise import (
    allan_deviation,
    allan_fit,
    default_taus,
    imu_quantisation,
    quantisation_density,
)
from gtsam_dvl.core.types import ImuData, LogData
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.inputs.alignment import detect_static_end
from gtsam_dvl.estimators.models.correlated_fit import held_correlated_level


@dataclass
class NoiseReport:
    """Which noise levels an estimator used and why (result.info["noise"], the summary and the console)."""

    imu: dict[str, Any] = field(default_factory=dict)
    dvl: dict[str, Any] = field(default_factory=dict)
    # only for a log with depth factors (the batch smoother)
    depth: dict[str, Any] = field(default_factory=dict)
    # only for a log with aiding fixes (the batch smoother)
    gnss: dict[str, Any] = field(default_factory=dict)
    # the DVL's correlated error's level and time constant: fitted (batch) or held; only with [noise] fit_correlated
    dvl_correlated: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        out = {"imu": self.imu, "dvl": self.dvl}
        for name in (*SENSOR_GROUPS, "dvl_correlated"):  # a log without them reports as before
            if entry := getattr(self, name):
                out[name] = entry
        return out


def imu_rate_hz(imu: ImuData) -> float:
    """The IMU's sample rate from the median spacing of its stamps (Hz)."""
    dt = np.diff(np.asarray(imu.t, dtype=float))
    dt = dt[dt > 0]
    return float(1.0 / np.median(dt)) if len(dt) else math.nan


def apply_imu_floor(imu: ImuData, config: EstimatorConfig, report: NoiseReport) -> EstimatorConfig:
    """config with each IMU white-noise density raised by the quantisation floor of its samples (module doc), the
    steps and the densities used written into report.imu. Unchanged when [noise] from_data or imu_quantisation is
    off, or the samples are not quantised."""
    n = config.noise
    if not (n.from_data and n.imu_quantisation) or len(imu.t) < 100:
        return config
    gyro_q, accel_q = imu_quantisation(np.asarray(imu.b_omega), np.asarray(imu.b_f))
    rate = imu_rate_hz(imu)
    update: dict[str, float] = {}
    for name, steps, unit, key, per in (
        ("gyro", gyro_q, "rad/s", "gyro_noise_deg_per_h_rthz", DEG_PER_H),
        ("accel", accel_q, "m/s^2", "accel_noise_ug_rthz", UG),
    ):
        configured = float(getattr(config.imu, key))
        entry: dict[str, Any] = {
            "step": [None if not np.isfinite(s) else float(s) for s in steps],
            "configured": configured,
            "used": configured,
        }
        finite = steps[np.isfinite(steps)]
        if len(finite) and np.isfinite(rate):
            q = float(finite.max())
            floor = quantisation_density(q, rate) / per  # in the configuration's unit
            used = math.hypot(configured, floor)
            entry.update(floor=floor, used=used)
            update[key] = used
            unit_cfg = "deg/h/sqrt(Hz)" if name == "gyro" else "micro-g/sqrt(Hz)"
            if used > 1.01 * configured:
                entry["why"] = (
                    f"{name} quantised at {q:.2g} {unit} ({rate:.0f} Hz): white noise {used:.3g} "
                    f"{unit_cfg} instead of {configured:.3g} (floor q/sqrt(12 f) = {floor:.3g})"
                )
            else:  # a floor far below the sensor's own noise changes nothing worth a line of its own
                entry["why"] = (
                    f"{name} quantised at {q:.2g} {unit} ({rate:.0f} Hz): its floor q/sqrt(12 f) = "
                    f"{floor:.3g} {unit_cfg} is below the configured {configured:.3g}, which stands"
                )
        report.imu[name] = entry
    if not update:
        return config
    return config.model_copy(update={"imu": config.imu.model_copy(update=update)})


# A static segment shorter than this gives no Allan fit: the tau^-1/2 line is read at taus up to a tenth of the
# segment, and a density from under 60 s of data (600 clusters at 0.1 s, 60 at 1 s) has a sampling error of 10-20 %.
STATIC_MIN_S = 60.0
# An axis whose static samples scatter by less than this many quantisation steps is dominated by the rounding:
# at rest the rounding error is not white (the signal sits on one or two steps), so its Allan deviation says
# nothing about the sensor (a FOG at rest under q = 1e-4 rad/s).
STATIC_MIN_STEPS = 2.0
# The measured density raises the one used only when it exceeds it by this factor: the fit's sampling error on a
# 60-120 s segment is 10-20 %, and a datasheet density is a bound, so a measured value near it changes nothing.
STATIC_RAISE_FACTOR = 1.2


def apply_static_noise(
    imu: ImuData, static_end_s: float, config: EstimatorConfig, report: NoiseReport
) -> EstimatorConfig:
    """config with each IMU white-noise density raised to the one measured on the log's initial static segment
    (imu.t[0] to static_end_s, estimators/inputs/alignment.py detect_static_end), when the segment is at least
    STATIC_MIN_S long: the overlapping Allan deviation of every axis not dominated by its quantisation
    (STATIC_MIN_STEPS), its tau^-1/2 line's density and its bias instability (core/sensor_noise.py allan_fit),
    the largest over the axes. Raised only (STATIC_RAISE_FACTOR): a short segment cannot show that a sensor is
    better than its datasheet. What was measured goes into report.imu[sensor]["static"], also when nothing
    changes. Unchanged when [noise] from_data or static_allan is off."""
    n = config.noise
    t = np.asarray(imu.t, dtype=float)
    if not (n.from_data and n.static_allan) or not len(t) or static_end_s - t[0] < STATIC_MIN_S:
        return config
    sel = t <= static_end_s
    rate = imu_rate_hz(imu)
    duration = float(static_end_s - t[0])
    update: dict[str, float] = {}
    for name, x, key, per, unit in (
        (
            "gyro",
            np.asarray(imu.b_omega)[sel],
            "gyro_noise_deg_per_h_rthz",
            DEG_PER_H,
            "deg/h/sqrt(Hz)",
        ),
        ("accel", np.asarray(imu.b_f)[sel], "accel_noise_ug_rthz", UG, "micro-g/sqrt(Hz)"),
    ):
        entry = report.imu.setdefault(name, {})
        steps = entry.get("step") or [None, None, None]
        taus = default_taus(len(x), rate)
        taus = taus[taus <= duration / 10.0]
        densities, instabilities, skipped = [], [], []
        for k in range(3):
            q = steps[k]
            if q is not None and np.std(x[:, k]) < STATIC_MIN_STEPS * q:
                skipped.append("xyz"[k])
                continue
            if len(taus) < 3 or not np.isfinite(x[:, k]).all():
                skipped.append("xyz"[k])
                continue
            fit = allan_fit(*allan_deviation(x[:, k], rate, taus))
            densities.append(fit.white_density / per)
            instabilities.append(fit.bias_instability / per)  # deg/h or micro-g
        current = float(getattr(config.imu, key))  # the quantisation floor's, when it applied
        static: dict[str, Any] = {"segment_s": duration, "axes_skipped_quantised": skipped}
        if densities:
            measured = max(densities)
            static.update(
                density=measured, density_per_axis=densities, bias_instability=max(instabilities)
            )
            if measured > STATIC_RAISE_FACTOR * current:
                update[key] = measured
                entry.update(
                    used=measured, configured=entry.get("configured", getattr(config.imu, key))
                )
                static["why"] = (
                    f"{name} white noise {measured:.3g} {unit} measured on the first {duration:.0f} s "
                    f"(static, Allan deviation) instead of {current:.3g}"
                )
        entry["static"] = static
    if not update:
        return config
    return config.model_copy(update={"imu": config.imu.model_copy(update=update)})


def imu_levels(log: LogData, config: EstimatorConfig, report: NoiseReport) -> EstimatorConfig:
    """The IMU white-noise densities every estimator uses on log: the quantisation floor (apply_imu_floor), then
    the density measured on an initial static segment (apply_static_noise)."""
    config = apply_imu_floor(log.imu, config, report)
    n = config.noise
    if not (n.from_data and n.static_allan) or len(log.imu.t) < 100:
        return config
    return apply_static_noise(
        log.imu, detect_static_end(log.imu, log.dvl, config.alignment), config, report
    )


def dvl_fit_enabled(config: EstimatorConfig) -> bool:
    """Whether the DVL noise factor is fitted ([noise] from_data and fit_dvl); the fit starts from [dvl]
    noise_multiplier. A result's configuration holds the configuration as given and info["noise"] the levels
    used (NavResult.noise_config joins them), so that a result's configuration, reloaded, reproduces the run."""
    return config.noise.from_data and config.noise.fit_dvl


# the sensor groups whose factor the batch smoother fits besides the DVL's: [noise] fit_<name>, bounds
# <name>_min_multiplier and <name>_max_multiplier, the factor [<name>] noise_multiplier
SENSOR_GROUPS = ("depth", "gnss")
SENSOR_LABEL = {"dvl": "DVL", "depth": "depth", "gnss": "GNSS"}
# the depth and GNSS factors are not robust: their fits leave out the rows beyond this many sigma at a
# median-based scale (as the DVL's at its kernel's threshold), the truncation corrected for
SCREEN_K = 4.0


def sensor_fit_enabled(config: EstimatorConfig, sensor: str) -> bool:
    """Whether the batch smoother fits sensor's noise factor ("dvl", "depth", "gnss"; [noise] from_data and
    fit_<sensor>)."""
    return config.noise.from_data and bool(getattr(config.noise, f"fit_{sensor}"))


def sensor_multiplier(config: EstimatorConfig, sensor: str) -> float:
    """The noise factor sensor's factors are built with ([<sensor>] noise_multiplier)."""
    return float(getattr(config, sensor).noise_multiplier)


def with_sensor_multiplier(
    config: EstimatorConfig, sensor: str, multiplier: float
) -> EstimatorConfig:
    """config with [<sensor>] noise_multiplier set."""
    section = getattr(config, sensor)
    return config.model_copy(
        update={sensor: section.model_copy(update={"noise_multiplier": multiplier})}
    )


def held_depth_level(log: LogData, config: EstimatorConfig, estimator: str) -> dict[str, Any]:
    """report.depth of an estimator that holds the configured depth level (the online estimator, the EKF): said
    when the log has depth samples that it uses and [noise] would fit them in the batch smoother; else {}."""
    depth = log.depth
    if (
        depth is None
        or not len(depth)
        or not config.depth.use
        or not sensor_fit_enabled(config, "depth")
    ):
        return {}
    m = config.depth.noise_multiplier
    stated = (
        f"noise_m = {config.depth.noise_m:g} m"
        if config.depth.noise_m > 0
        else f"the messages' variance, default_noise_m = {config.depth.default_noise_m:g} m without one"
    )
    return {
        "configured": m,
        "multiplier": m,
        "held": True,
        "why": f"depth noise as configured ({stated}, x {m:.3g}): the {estimator} holds it (the batch smoother "
        "fits it from the residuals)",
    }


def held_levels(log: LogData, config: EstimatorConfig, estimator: str, report: NoiseReport) -> None:
    """report.depth and report.dvl_correlated of an estimator that holds the configured levels (held_depth_level,
    estimators/models/correlated_fit.py held_correlated_level)."""
    report.depth = held_depth_level(log, config, estimator)
    report.dvl_correlated = held_correlated_level(config, estimator)


def truncated_chi2_mean(m: int, c: float) -> float:
    """E[x | x <= c] for x ~ chi^2 with m degrees of freedom: m F_{m+2}(c) / F_m(c)."""
    return float(m * chi2.cdf(c, m + 2) / chi2.cdf(c, m))


def variance_ratio(ew: np.ndarray, robust_k: float) -> tuple[float, int]:
    """The factor on the variance of whitened errors ew (N, m) that makes them unit variance (module doc), and
    the rows used: those whose squared norm is within robust_k^2 at a median-based first scale, with the
    truncated chi^2 mean as expectation. (nan, 0) when no row is finite."""
    ew = np.asarray(ew, dtype=float).reshape(len(ew), -1)
    return chi2_ratio(np.einsum("ni,ni->n", ew, ew), ew.shape[1], robust_k)


def chi2_ratio(x2: np.ndarray, m: int, robust_k: float) -> tuple[float, int]:
    """variance_ratio of the squared norms x2 (N,) of whitened errors of dimension m."""
    x2 = np.asarray(x2, dtype=float)
    inside = robust_inside(x2, m, robust_k)
    used = int(inside.sum())
    if not used:
        return math.nan, 0
    return float(x2[inside].mean() / truncated_chi2_mean(m, robust_k**2)), used


def robust_inside(x2: np.ndarray, m: int, robust_k: float) -> np.ndarray:
    """The rows (N,) bool of squared norms x2 of whitened errors of dimension m that are finite and within
    robust_k^2 at a median-based scale: the rows every fit of a noise level uses."""
    x2 = np.asarray(x2, dtype=float)
    finite = np.isfinite(x2)
    if not finite.any():
        return finite
    s0 = float(np.median(x2[finite]) / chi2.median(m))  # robust first scale
    return finite & (np.where(finite, x2, np.inf) <= robust_k**2 * max(s0, 1e-300))


# The time scales the calibration lives on (s): a real DVL's error is not white there (bottom type, attitude-dependent
# beam errors, the speed of sound): its ping-to-ping scatter is 3-9 mm/s while its 30-60 s means stay at a few mm/s.
# A level fitted to the scatter alone weights the DVL as if those means were scatter / sqrt(30-60), and the scale and
# misalignment then chase the slow errors while chi^2/dof looks perfect.
LONG_WINDOWS_S = (30.0, 60.0)
LONG_CONFIDENCE = 0.90  # the two-sided interval of a long-window level (chi^2 on blocks x axes degrees of freedom)
LONG_MIN_BLOCKS = 3  # fewer blocks of a window than this: it says nothing
LONG_MIN_ROWS = 5  # a block with fewer rows is left out (a dropout, the log's end)


@dataclass(frozen=True)
class LongLevel:
    """The variance factor on the current level that a sensor's residuals show when averaged over window_s: the
    mean over blocks and axes of n_b mean_b(e)^2 (e whitened at the current level; for white errors its expectation
    is the white ratio), with its LONG_CONFIDENCE interval [lo, hi] on dof = blocks x axes."""

    ratio: float
    lo: float
    hi: float
    window_s: float
    blocks: int
    dof: int

    def as_dict(self, sigma_m_s: float) -> dict[str, float]:
        """The level as an equivalent white sigma (m/s or m: sigma_m_s is the current level's) with its interval."""
        return {
            "window_s": self.window_s,
            "blocks": self.blocks,
            "sigma": sigma_m_s * math.sqrt(self.ratio),
            "sigma_lo": sigma_m_s * math.sqrt(self.lo),
            "sigma_hi": sigma_m_s * math.sqrt(self.hi),
        }


def long_level(
    t: np.ndarray,
    ew: np.ndarray,
    excess: np.ndarray | None = None,
    windows: tuple[float, ...] = LONG_WINDOWS_S,
) -> LongLevel | None:
    """The LongLevel of whitened errors ew (N, m) at times t (N,) s, the window of LONG_WINDOWS_S whose ratio is the
    largest (the slow error's time scale is not known); excess (N,): each row's expected variance beyond the noise's
    (a filter's innovation carries its prediction's, tr HPH / tr R), taken off. None when no window has
    LONG_MIN_BLOCKS blocks."""
    t = np.asarray(t, dtype=float)
    if not len(t):  # (a sensor with no residual rows: an empty ew has no width to reshape to)
        return None
    ew = np.asarray(ew, dtype=float).reshape(len(t), -1)
    best: LongLevel | None = None
    for T in windows:
        block = np.floor((t - t[0]) / T).astype(int)
        counts = np.bincount(block)
        full = np.flatnonzero(counts >= LONG_MIN_ROWS)
        if len(full) < LONG_MIN_BLOCKS:
            continue
        sums = np.stack(
            [
                np.bincount(block, weights=ew[:, a], minlength=len(counts))
                for a in range(ew.shape[1])
            ],
            1,
        )
        n_b = counts[full].astype(float)
        stat = (sums[full] ** 2 / n_b[:, None]).mean()  # n_b mean_b^2 = sum_b^2 / n_b
        if excess is not None:
            stat -= float(
                np.bincount(block, weights=excess, minlength=len(counts))[full].sum() / n_b.sum()
            )
        ratio = max(float(stat), 0.0)
        dof = len(full) * ew.shape[1]
        a = 0.5 * (1.0 - LONG_CONFIDENCE)
        level = LongLevel(
            ratio,
            ratio * dof / chi2.ppf(1.0 - a, dof),
            ratio * dof / chi2.ppf(a, dof),
            T,
            len(full),
            dof,
        )
        if best is None or level.ratio > best.ratio:
            best = level
    return best


def honest_multiplier(
    white: float,
    current: float,
    stated: float,
    long: LongLevel | None,
    bounds: tuple[float, float],
    can_lower: bool,
) -> tuple[float, str]:
    """The multiplier a sensor's factors take (module doc, "Honest level"): the white fit `white`, raised to the
    long-window level when that is significantly above it (its interval's lower end above white); never below the
    stated multiplier unless can_lower (an independent absolute reference observes the sensor's slow errors) and
    the long-window level's upper end is below it. current: the multiplier long's errors were whitened at. Clipped
    to bounds. Returns it and the reason in words ("" when the white fit stands)."""
    used, why = white, ""
    m_long = m_lo = m_hi = math.nan
    if long is not None:
        m_long, m_lo, m_hi = (current * math.sqrt(r) for r in (long.ratio, long.lo, long.hi))
        if m_lo > white:
            used, why = (
                m_long,
                (
                    f"raised to what its {long.window_s:g} s means show (x {m_long:.3g}, "
                    f"{LONG_CONFIDENCE:.0%} interval x {m_lo:.3g}-{m_hi:.3g}; white x {white:.3g})"
                ),
            )
    if used < stated:
        if not can_lower:
            used, why = (
                stated,
                (
                    f"held at the stated level (x {stated:.3g}; white x {white:.3g}): the scatter does "
                    "not show the slow errors the calibration sees, and no absolute reference in the "
                    "log observes them"
                ),
            )
        elif long is None or m_hi >= stated:
            used, why = (
                stated,
                (
                    f"held at the stated level (x {stated:.3g}; white x {white:.3g}): its "
                    f"{LONG_WINDOWS_S[0]:g}-{LONG_WINDOWS_S[-1]:g} s means do not show it better"
                ),
            )
    return min(max(used, bounds[0]), bounds[1]), why


def multiplier_bounds(config: EstimatorConfig, sensor: str = "dvl") -> tuple[float, float]:
    """[noise] <sensor>_min_multiplier and <sensor>_max_multiplier."""
    n = config.noise
    return float(getattr(n, f"{sensor}_min_multiplier")), float(
        getattr(n, f"{sensor}_max_multiplier")
    )


def fitted_multiplier(
    current: float, ratio: float, config: EstimatorConfig, sensor: str = "dvl"
) -> tuple[float, bool]:
    """The new multiplier current * sqrt(ratio), clipped to sensor's [noise] bounds; and whether it hit one."""
    lo, hi = multiplier_bounds(config, sensor)
    raw = current * math.sqrt(ratio)
    clipped = min(max(raw, lo), hi)
    return clipped, clipped != raw


def dvl_fit_report(
    config: EstimatorConfig,
    multiplier: float,
    rows: int,
    passes: int,
    at_bound: bool,
    sigma_m_s: float,
    how: str,
) -> dict[str, Any]:
    """report.dvl of a fit: the factor, the median ping sigma it gives, the rows and passes, and the line."""
    n = config.noise
    why = (
        f"DVL noise fitted from {rows} residual rows ({how}): sigma x {multiplier:.3g} = {sigma_m_s * 1e3:.2g} "
        f"mm/s per axis"
    )
    if at_bound:
        why += (
            f", at the bound [{n.dvl_min_multiplier:g}, {n.dvl_max_multiplier:g}] of [noise]: the DVL model "
            "does not fit its data whatever the noise level"
        )
    return {
        "multiplier": multiplier,
        "sigma_m_s": sigma_m_s,
        "rows": rows,
        "passes": passes,
        "at_bound": at_bound,
        "how": how,
        "why": why,
    }


def with_levels(entry: dict[str, Any], levels: dict[str, Any], used: float) -> None:
    """entry (a fit's report) with the levels behind it (honest_multiplier): the white fit's sigma, the long-window
    level's, the stated one, and why the used level is not the white fit. Sigmas in the entry's unit (sigma_m_s of
    the DVL, sigma_m of depth and GNSS), scaled from the used multiplier's."""
    key = "sigma_m_s" if "sigma_m_s" in entry else "sigma_m"
    sigma = float(entry.get(key, math.nan))
    per = sigma / used if used > 0 else math.nan  # the sigma at multiplier 1
    entry["white_sigma"] = per * levels["white_multiplier"]
    entry["stated_sigma"] = per * levels["stated_multiplier"]
    long = levels["long"]
    # as_dict at the multiplier the residuals were whitened at: scale to m/s or m
    if long is not None:
        entry["long"] = {k: (v * per if k.startswith("sigma") else v) for k, v in long.items()}
    if levels["honest_why"]:
        entry["why"] += "; " + levels["honest_why"]


def sensor_fit_report(
    config: EstimatorConfig,
    sensor: str,
    configured: float,
    configured_sigma_m: float,
    multiplier: float,
    rows: int,
    passes: int,
    at_bound: bool,
    how: str,
) -> dict[str, Any]:
    """report.depth or report.gnss of a batch fit: the factor configured and fitted, the median sigma each gives
    (m; a fix's per axis), the rows and passes, whether the factor is at a bound, and the line."""
    lo, hi = multiplier_bounds(config, sensor)
    label = SENSOR_LABEL[sensor]
    sigma_m = configured_sigma_m * multiplier / configured
    why = (
        f"{label} noise fitted from {rows} residual rows ({how}): sigma x {multiplier:.3g} = {sigma_m:.3g} m"
        f"{' per axis' if sensor == 'gnss' else ''} (configured x {configured:.3g} = {configured_sigma_m:.3g} m)"
    )
    if at_bound:
        why += (
            f", at the bound [{lo:g}, {hi:g}] of [noise]: the {label} model does not fit its data whatever "
            "the noise level"
        )
    return {
        "configured": configured,
        "configured_sigma_m": configured_sigma_m,
        "multiplier": multiplier,
        "sigma_m": sigma_m,
        "rows": rows,
        "passes": passes,
        "at_bound": at_bound,
        "how": how,
        "why": why,
    }


def sensor_not_fitted(sensor: str, multiplier: float, rows: int, min_rows: int) -> dict[str, Any]:
    """report.<sensor> when its rows are too few for a fit: the factor stays as configured."""
    return {
        "configured": multiplier,
        "multiplier": multiplier,
        "rows": rows,
        "at_bound": False,
        "why": f"{SENSOR_LABEL[sensor]} noise not fitted: {rows} usable residual rows, fewer than [noise] "
        f"min_rows = {min_rows}; its configured level (x {multiplier:.3g}) holds",
    }


def median_ping_sigma(config: EstimatorConfig, d_cov: np.ndarray) -> float:
    """The median over pings of the per-axis sigma a ping is given (ping_covariance, with the multiplier), m/s."""
    from gtsam_dvl.estimators.inputs.selection import ping_covariance

    if config.dvl.use_beams:
        return config.dvl.beam_sigma_m_s()
    cov = ping_covariance(config.dvl, np.asarray(d_cov, dtype=float).reshape(-1, 3, 3))
    return (
        float(np.median(np.sqrt(np.trace(cov, axis1=1, axis2=2) / 3.0))) if len(cov) else math.nan
    )


def with_multiplier(config: EstimatorConfig, multiplier: float) -> EstimatorConfig:
    """config with [dvl] noise_multiplier set."""
    return config.model_copy(
        update={"dvl": config.dvl.model_copy(update={"noise_multiplier": multiplier})}
    )


@dataclass
class WarmupFit:
    """The DVL's variance component fitted on the pings of a warm-up window ([noise] warmup_s from the first
    ping), then held (the online estimator and the EKF). Either from the pings' whitened residuals (add_whitened:
    the smoother's, once the pings that followed have updated the states around the ping) or by covariance
    matching of the filter's innovations (add_innovation: E[nu nu^T] = H P H^T + R, so
    lambda^2 = lambda_0^2 sum(nu.nu - tr H P H^T) / sum tr R over the pings whose tr H P H^T <= tr R, i.e. whose
    innovation is mostly measurement noise; Mehra's innovation-based adaptive estimation, unbiased when P is the
    P of the right R: the EKF filters the window again with each fit). Robust as variance_ratio: the rows beyond
    the kernel's threshold at a median-based scale are left out."""

    config: EstimatorConfig  # its [dvl] noise_multiplier: the factor the window was processed with
    # the stated multiplier (the configuration's before any fit; None: config's): the fit never goes below it
    # (honest_multiplier: a filter has no absolute reference that observes the DVL's slow errors)
    stated: float | None = None
    t_first: float = math.nan
    sigma_m_s: float = math.nan  # the median ping sigma at the configuration's multiplier (m/s)
    report: dict[str, Any] = field(default_factory=dict)
    _ew: list[np.ndarray] = field(default_factory=list)
    _innov: list[tuple[float, float, float, float, int]] = field(default_factory=list)

    def start(self, t_first: float, sigma_m_s: float) -> None:
        self.t_first, self.sigma_m_s = t_first, sigma_m_s

    @property
    def t_end(self) -> float:
        return self.t_first + self.config.noise.warmup_s

    def add_whitened(self, ew: np.ndarray) -> None:
        self._ew.append(np.asarray(ew, dtype=float).reshape(1, -1))

    def add_innovation(self, nu: np.ndarray, hph: np.ndarray, R: np.ndarray, nis: float) -> None:
        tr_hph, tr_r = float(np.trace(hph)), float(np.trace(R))
        if tr_hph <= tr_r:
            self._innov.append((float(nu @ nu), tr_hph, tr_r, nis, len(nu)))

    def finish(self, how: str) -> float:
        """The multiplier fitted from what was collected (the configuration's when too few rows, or when the fit
        is within [noise] fit_tolerance of it); report says how."""
        n = self.config.noise
        current = self.config.dvl.noise_multiplier
        ratio, rows = math.nan, 0
        if self._ew:
            ew = np.concatenate([e.reshape(-1, 1) for e in self._ew])
            dims = {e.shape[1] for e in self._ew}
            if len(dims) == 1:
                ew = np.concatenate(self._ew)
            ratio, used = variance_ratio(ew, self.config.dvl.robust_threshold())
            rows = used * ew.shape[1]
        elif self._innov:
            a = np.array(self._innov)
            m = int(np.median(a[:, 4]))
            s0 = float(np.median(a[:, 3]) / chi2.median(m))
            c = self.config.dvl.robust_threshold() ** 2
            keep = a[:, 3] <= c * max(s0, 1e-300)
            rows = int(a[keep, 4].sum())
            if keep.any():
                ratio = (
                    float((a[keep, 0] - a[keep, 1]).sum() / a[keep, 2].sum())
                    * m
                    / truncated_chi2_mean(m, c)
                )
        self._ew, self._innov = [], []
        if rows < n.min_rows or not np.isfinite(ratio) or ratio <= 0:
            self.report = {
                "multiplier": current,
                "rows": rows,
                "why": f"DVL noise not fitted: {rows} usable rows in the first {n.warmup_s:g} s "
                f"(fewer than [noise] min_rows = {n.min_rows}, or no positive variance left)",
            }
            return current
        white, at_bound = fitted_multiplier(current, ratio, self.config)
        stated = current if self.stated is None else self.stated
        new, why = honest_multiplier(
            white, current, stated, None, multiplier_bounds(self.config), False
        )
        at_bound = at_bound and new == white
        if abs(new / current - 1.0) <= n.fit_tolerance:
            # within the tolerance the factor the window was processed with is kept, as the batch fit does: a
            # result's configuration, reloaded, then reproduces its estimates instead of moving by the fit's scatter
            new = current
        self.report = dvl_fit_report(
            self.config,
            new,
            rows,
            1,
            at_bound,
            self.sigma_m_s * new / current,
            f"{how} over the first {n.warmup_s:g} s, then held",
        )
        with_levels(
            self.report,
            {
                "white_multiplier": white,
                "stated_multiplier": stated,
                "honest_why": why,
                "long": None,
            },
            new,
        )
        return new
