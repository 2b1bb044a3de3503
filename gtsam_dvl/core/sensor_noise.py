"""Sensor noise read from the data: the quantisation step of a sample series, the white-noise floor it sets,
the Allan deviation of a rate series with its white density and bias instability, and a white plus first-order
Gauss-Markov fit of a residual series' autocovariance. Pure numpy; units are whatever the series is in.

Quantisation: a series quantised to multiples of q (a driver's fixed-point format, a text export with a fixed
number of decimals) carries the rounding error e, uniform on [-q/2, q/2], variance q^2/12. While the signal moves
over several steps between samples (motion, or noise larger than q) e is white: at a sample rate f its density is
q / sqrt(12 f) (unit/sqrt(Hz)), e.g. q = 1e-4 rad/s at 100 Hz gives 2.89e-6 rad/s/sqrt(Hz) = 0.596 deg/h/sqrt(Hz).

Allan deviation (IEEE Std 952, overlapping estimator) of a rate series x sampled at tau0 = 1/f, for tau = m tau0,
from the integral theta_k = tau0 sum_{i<k} x_i:
    sigma^2(tau) = sum_k (theta_{k+2m} - 2 theta_{k+m} + theta_k)^2 / (2 tau^2 (N + 1 - 2m)).
White rate noise of density N gives sigma(tau) = N / sqrt(tau) (slope -1/2 in log-log); the flat floor of
bias instability B is sigma_min = 0.664 B. allantools does the same; it is not a dependency, and the cumulative
sum form is a few lines, O(N) per tau.

Gauss-Markov fit: a residual r = w + g with w white (variance sw^2) and g first-order Gauss-Markov (variance
sg^2, time constant tau) has the autocovariance C(0) = sw^2 + sg^2, C(lag) = sg^2 exp(-lag / tau) for lag > 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError

# a series is quantised when at least this fraction of its values lies on the grid
ON_GRID_FRACTION = 0.99
# of the step: a value within this of a grid point lies on it (plus its storage rounding)
GRID_TOLERANCE = 1e-3
# a step is told from the storage format's own rounding only when it spans this many units in the last place
# of the series' largest value (float32 stores 9.8 m/s^2 to 9.5e-7: a 1e-4 step is 105 of them)
MIN_STEP_ULPS = 16.0
# the most frequent spacings between levels tried as steps, each divided by 1..MAX_DIVISOR
CANDIDATE_CLUSTERS = 4
MAX_DIVISOR = 6
# the refinement's passes use the levels within these many steps of the reference level: each pass makes the step
# precise enough for the next window (a step off by 1e-3 assigns k correctly up to a few hundred steps)
REFINE_WINDOWS = (32.0, 1024.0, 32768.0, np.inf)


def _storage_ulp(x: np.ndarray) -> np.ndarray:
    """Unit in the last place of each value in the precision it was stored in: float32 when every value is a
    float32 number (a float32 field read into float64), else float64."""
    as32 = x.astype(np.float32)
    if np.array_equal(as32.astype(np.float64), x):
        return np.spacing(np.abs(as32)).astype(np.float64)
    return np.spacing(np.abs(x))


def _clusters(d: np.ndarray, tol: float) -> list[tuple[int, float]]:
    """Sorted values d grouped where neighbours differ by at most tol plus 1e-3 of the value: (count, mean) per
    group, most populated first. The mean, not the median: the spacings of k q stored in float32 are 104 or 105
    units of 9.5e-7 at 9.8 for q = 1e-4, and only their mean telescopes to the step."""
    if not len(d):
        return []
    split = np.flatnonzero(np.diff(d) > tol + GRID_TOLERANCE * d[1:]) + 1
    groups = np.split(d, split)
    return sorted(((len(g), float(np.mean(g))) for g in groups), key=lambda c: -c[0])


def _fit_grid(
    levels: np.ndarray, counts: np.ndarray, ulp: np.ndarray, step: float, ref: float
) -> tuple[float, float, np.ndarray]:
    """Least squares of levels = a + k q over the integer multiples k, refined from step in passes over the
    levels within REFINE_WINDOWS steps of ref and a quarter step of the previous grid, weighted by how many samples
    sit on each level. Returns (q, a, k of each level with -1 where a level is off the grid: farther than
    GRID_TOLERANCE q plus its storage rounding), k counted from ref's level (k >= 0 there: abs(k))."""
    q, a = step, ref
    off = np.full(len(levels), -1.0)
    for window in REFINE_WINDOWS:
        k = np.round((levels - a) / q)
        near = (np.abs(levels - a - k * q) < 0.25 * q) & (np.abs(k) <= window)
        if near.sum() < 2 or np.ptp(k[near]) == 0:
            return q, a, off
        w, kk, xx = counts[near], k[near], levels[near]
        km, xm = np.average(kk, weights=w), np.average(xx, weights=w)
        q = float(np.sum(w * (kk - km) * (xx - xm)) / np.sum(w * (kk - km) ** 2))
        a = float(xm - km * q)
        if q <= 0:
            return step, ref, off
    k = np.round((levels - a) / q)
    k0 = np.round((ref - a) / q)
    on = np.abs(levels - a - k * q) <= GRID_TOLERANCE * q + ulp
    return q, a, np.where(on, np.abs(k - k0), -1.0)


MAX_MULTIPLE = 1000  # a verified grid is tried at up to this many times its step


def _coarsest_multiple(k: np.ndarray, counts: np.ndarray) -> int:
    """The largest m such that the levels whose multiple k (from the reference level) is divisible by m hold
    ON_GRID_FRACTION of the samples on at least two levels (a step needs two): a grid verified at q/m (a candidate
    from the spacings of values partly off the grid) is then taken at its coarsest step."""
    on = k >= 0
    kk, w, total = k[on].astype(np.int64), counts[on], counts.sum()
    for m in range(MAX_MULTIPLE, 1, -1):
        kept = kk % m == 0
        if w[kept].sum() >= ON_GRID_FRACTION * total and np.ptp(kk[kept]) > 0:
            return m
    return 1


def quantisation_step(x: np.ndarray) -> float | None:
    """The step q of a series quantised to multiples of q, from its values alone; None for a constant series, an
    unquantised one, or one of which fewer than ON_GRID_FRACTION of the values lie on any grid.

    1. The distinct levels of the finite values, levels closer than the storage rounding merged (a float32
       field stores k q to half a unit in the last place; float64 to 1e-16 relative).
    2. Candidate steps: the most frequent spacings between neighbouring levels (on a quantised series most
       neighbours are one step apart; values off the grid give scattered spacings; only the levels that hold
       two samples or more count when they hold ON_GRID_FRACTION of the samples), each divided by
       1..MAX_DIVISOR (a sparse series may show only multiples of q).
    3. Each candidate refined by least squares of the levels on their integer multiples (levels = a + k q, so a
       grid offset is allowed), then verified: the fraction of samples within GRID_TOLERANCE q (plus the
       storage rounding) of the grid.
    4. The largest candidate verified on ON_GRID_FRACTION of the samples, taken at the coarsest multiple of it
       that still holds them (a grid of step q also holds every value on the grids of q/2, q/3...; values off
       the grid can make the spacings show only such a fraction of q). A step below MIN_STEP_ULPS storage units
       of the largest value is the storage format's own rounding: None.
    On a simulated series (noise over many steps) q comes out to 1e-6 relative or better, in float64 and float32
    storage (tests/core/test_sensor_noise.py)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    if len(x) < 2:
        return None
    ulp_all = _storage_ulp(x)
    levels, first, counts = np.unique(x, return_index=True, return_counts=True)
    ulp = ulp_all[first]
    # merge levels within two storage units (the same k q stored by two routes)
    keep = np.concatenate([[True], np.diff(levels) > 2.0 * np.maximum(ulp[1:], ulp[:-1])])
    counts = np.bincount(np.cumsum(keep) - 1, weights=counts)
    levels, ulp = levels[keep], ulp[keep]
    if len(levels) < 2:
        return None
    min_step = MIN_STEP_ULPS * float(np.max(ulp))
    # the spacings between the levels that repeat, when they hold the samples (values off the grid rarely repeat)
    repeated = counts >= 2
    populated = (
        levels[repeated]
        if (repeated.sum() >= 2 and counts[repeated].sum() >= ON_GRID_FRACTION * counts.sum())
        else levels
    )
    spacings = np.sort(np.diff(populated))
    ref = float(levels[np.argmax(counts)])  # the most populated level: on the grid
    candidates = sorted(
        {
            c / m
            for _, c in _clusters(spacings, 2.0 * float(np.max(ulp)))[:CANDIDATE_CLUSTERS]
            for m in range(1, MAX_DIVISOR + 1)
        },
        reverse=True,
    )
    needed = ON_GRID_FRACTION * counts.sum()
    for c in candidates:
        if c < min_step:
            continue
        q, _, k = _fit_grid(levels, counts, ulp, c, ref)
        if counts[k >= 0].sum() < needed or q < min_step:
            continue
        m = _coarsest_multiple(k, counts)
        if m > 1:  # refit at the coarser step
            q, _, k = _fit_grid(levels, counts, ulp, m * q, ref)
        if counts[k >= 0].sum() >= needed:
            return q
    return None


def imu_quantisation(b_omega: np.ndarray, b_f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The quantisation step of every gyro axis (rad/s, (3,)) and accelerometer axis (m/s^2, (3,)) of the IMU
    samples b_omega, b_f (N, 3) as logged; nan where an axis is not quantised (quantisation_step)."""

    def steps(x: np.ndarray) -> np.ndarray:
        return np.array(
            [np.nan if (s := quantisation_step(x[:, k])) is None else s for k in range(3)]
        )

    return steps(np.asarray(b_omega, dtype=float)), steps(np.asarray(b_f, dtype=float))


def quantisation_density(step: float, rate_hz: float) -> float:
    """White-noise density of the rounding error of a step q at rate f: the error's sigma q / sqrt(12) per sample
    over the bandwidth f, q / sqrt(12 f) (unit/sqrt(Hz))."""
    return float(step / np.sqrt(12.0 * rate_hz))


def default_taus(n: int, rate_hz: float, per_decade: int = 10) -> np.ndarray:
    """Log-spaced averaging times m / rate_hz, m = 1 .. n // 4 (longer ones average fewer than n/2 independent
    differences), per_decade per decade, distinct integers m."""
    m_max = max(1, n // 4)
    m = np.unique(
        np.round(np.logspace(0.0, np.log10(m_max), max(2, int(per_decade * np.log10(m_max)) + 1)))
    )
    return m.astype(int) / rate_hz


def allan_deviation(
    x: np.ndarray, rate_hz: float, taus: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of the rate series x (N,) sampled at rate_hz (module doc), at taus (s; each
    rounded to a whole number of samples; default_taus when None). Returns (taus used, adev) in x's unit."""
    x = np.asarray(x, dtype=float).ravel()
    n = len(x)
    if n < 3 or not np.isfinite(x).all():
        raise GtsamDvlError(
            f"Allan deviation: need at least 3 finite samples, got {n} (finite: "
            f"{int(np.isfinite(x).sum())})"
        )
    tau0 = 1.0 / rate_hz
    taus = default_taus(n, rate_hz) if taus is None else np.asarray(taus, dtype=float)
    m = np.round(taus / tau0).astype(int)
    if (m < 1).any() or (2 * m > n).any():
        raise GtsamDvlError(
            f"Allan deviation: taus must lie in [{tau0:g}, {n // 2 * tau0:g}] s for {n} samples at "
            f"{rate_hz:g} Hz"
        )
    # the integral, centred so that the cumulative sum keeps its precision on a large mean (Earth rate, gravity)
    theta = np.concatenate([[0.0], np.cumsum(x - x.mean())]) * tau0
    adev = np.empty(len(m))
    for i, mi in enumerate(m):
        d2 = theta[2 * mi :] - 2.0 * theta[mi:-mi] + theta[: -2 * mi]
        adev[i] = np.sqrt(np.mean(d2**2) / (2.0 * (mi * tau0) ** 2))
    return m * tau0, adev


@dataclass(frozen=True)
class AllanFit:
    """What an Allan deviation curve gives: white density N (unit/sqrt(Hz) = unit sqrt(s)) and bias instability B
    (unit). bias_bound: the minimum is at the longest tau, so B is only an upper bound (the record is too short
    to reach the flat floor)."""

    white_density: float
    bias_instability: float
    bias_bound: bool


WHITE_SLOPE_RANGE = (-0.6, -0.4)  # local log-log slopes counted as the tau^-1/2 line
BIAS_INSTABILITY_FACTOR = 0.664  # sigma_min = 0.664 B for flicker (1/f) rate noise (IEEE Std 952)


def allan_fit(taus: np.ndarray, adev: np.ndarray) -> AllanFit:
    """White density from the tau^-1/2 line: over the first run of points (from the shortest tau, before the
    minimum) whose local slopes lie in WHITE_SLOPE_RANGE (the shortest tau alone if its slope does not), N = the
    geometric mean of adev sqrt(tau), i.e. the line's value at tau = 1 s. Bias instability B = min(adev) / 0.664.
    """
    taus, adev = np.asarray(taus, dtype=float), np.asarray(adev, dtype=float)
    i_min = int(np.argmin(adev))
    log_t, log_a = np.log(taus), np.log(adev)
    slopes = np.diff(log_a) / np.diff(log_t) if len(taus) > 1 else np.zeros(0)
    white = (slopes >= WHITE_SLOPE_RANGE[0]) & (slopes <= WHITE_SLOPE_RANGE[1])
    # the first run of white slopes; point i and i + 1 belong to the line when slope i does
    start = int(np.argmax(white)) if white.any() else 0
    stop = start + (
        int(np.argmin(white[start:])) if not white[start:].all() else len(white) - start
    )
    last = min(stop, i_min) if white.any() else 0
    on_line = slice(start, max(last, start) + 1)
    density = float(np.exp(np.mean(log_a[on_line] + 0.5 * log_t[on_line])))
    return AllanFit(density, float(adev[i_min] / BIAS_INSTABILITY_FACTOR), i_min == len(taus) - 1)


@dataclass(frozen=True)
class GaussMarkovFit:
    """White sigma sw, Gauss-Markov sigma sg and time constant (s) of a residual series; significant: sg^2 is
    above three times its sampling noise under white noise alone (else sg and tau mean nothing)."""

    white_sigma: float
    gm_sigma: float
    gm_tau_s: float
    significant: bool
    samples: int
    # the sampling std of sg^2 under white noise, as a sigma (sqrt of it): for reports
    gm_sigma_noise: float


# of the nominal spacing: a pair whose stamp difference is this close to k dt is at lag k
LAG_TOLERANCE = 0.25
SIGNIFICANCE_SIGMAS = 3.0


def autocovariance(
    t: np.ndarray, r: np.ndarray, dt_nominal: float, max_lag: int
) -> tuple[np.ndarray, np.ndarray]:
    """The empirical autocovariance of the mean-removed columns of r (N, K) at lags 0..max_lag samples, pooled
    over the columns: at lag k the mean product of the pairs whose stamps differ by k dt_nominal within
    LAG_TOLERANCE dt_nominal (gaps in the stamps leave pairs out). Returns (C (max_lag + 1,), pairs per lag)."""
    c, n = np.zeros(max_lag + 1), np.zeros(max_lag + 1, dtype=int)
    # lags at once: the pair search in bulk, bounded memory
    chunk = max(1, 2_000_000 // max(len(t), 1))
    for k0 in range(0, max_lag + 1, chunk):
        lags = np.arange(k0, min(k0 + chunk, max_lag + 1))
        target = t[None, :] + lags[:, None] * dt_nominal  # (lags, N)
        j = np.clip(np.searchsorted(t, target), 0, len(t) - 1)
        jm = np.clip(j - 1, 0, len(t) - 1)
        j = np.where(np.abs(t[jm] - target) < np.abs(t[j] - target), jm, j)
        ok = np.abs(t[j] - target) <= LAG_TOLERANCE * dt_nominal
        products = np.einsum("lnk,nk->ln", r[j], r)
        n[lags] = ok.sum(axis=1) * r.shape[1]
        c[lags] = np.where(ok, products, 0.0).sum(axis=1) / np.maximum(n[lags], 1)
    return c, n


def mean_variance_factor(n: int, dt: float, tau: np.ndarray) -> np.ndarray:
    """Var(mean) / sg^2 of n samples dt apart of a Gauss-Markov process of time constant tau (s):
    (1 / n^2) sum_ij phi^|i - j| = ((1 + phi) / (1 - phi) - 2 phi (1 - phi^n) / (n (1 - phi)^2)) / n, phi =
    exp(-dt / tau). The autocovariance of the mean-removed series is low by about this (times sg^2) at every lag
    (about 2 tau / T for a record of T >> tau seconds: 0.3 at tau 60 s over 400 s)."""
    phi = np.exp(-dt / np.asarray(tau, dtype=float))
    return ((1.0 + phi) / (1.0 - phi) - 2.0 * phi * (1.0 - phi**n) / (n * (1.0 - phi) ** 2)) / n


def _exponential_fit(
    c: np.ndarray, pairs: np.ndarray, dt: float, lags: int, n_mean: int = 0
) -> tuple[float, float, float]:
    """Weighted least squares of sg^2 exp(-k dt / tau) to c[1..lags], weights pairs[1..lags]: tau on a log grid of
    TAU_GRID points from dt to 10 lags dt, sg^2 in closed form for each (sg^2 = sum_k a_k C(k)); the tau of the
    smallest weighted residual. n_mean > 0: the model is sg^2 (exp(-k dt / tau) - mean_variance_factor(n_mean)),
    the autocovariance of a series of n_mean samples whose mean was removed. Returns (sg^2, tau, std of that sg^2
    under white noise: sqrt(sum_k a_k^2 C(0)^2 / n_k))."""
    k = np.arange(1, lags + 1, dtype=float)
    w, ck = pairs[1 : lags + 1].astype(float), c[1 : lags + 1]
    taus = np.geomspace(dt, 10.0 * lags * dt, TAU_GRID)
    e = np.exp(-np.outer(1.0 / taus, k) * dt)  # (taus, lags)
    if n_mean > 0:
        e = e - mean_variance_factor(n_mean, dt, taus)[:, None]
    a = w * e / np.sum(w * e * e, axis=1, keepdims=True)
    sg2 = a @ ck
    best = int(np.argmin(np.sum(w * (ck - sg2[:, None] * e) ** 2, axis=1)))
    noise = float(np.sqrt(np.sum(a[best] ** 2 * c[0] ** 2 / np.maximum(w, 1.0))))
    return float(sg2[best]), float(taus[best]), noise


TAU_GRID = 200
MIN_LAGS = 10


def gauss_markov_fit(
    t: np.ndarray,
    r: np.ndarray,
    dt_nominal: float,
    max_lag: int | None = None,
    mean_corrected: bool = False,
) -> GaussMarkovFit:
    """Fit of sw, sg and tau to a residual series r (N,) or (N, K) (K axes pooled, each mean-removed) stamped
    t (N,) s, nominally dt_nominal apart (module doc). The autocovariance C at lags 0..L samples (autocovariance;
    L = max_lag, default min(N // 10, 600)), then a weighted least-squares fit of sg^2 exp(-k dt / tau) to
    lags 1..L (_exponential_fit), weights the pairs per lag (white noise's autocovariance at lag k has variance
    C(0)^2 / n_k); a grid over tau with sg^2 in closed form has no starting point to choose, which a scipy
    curve fit would need. Without max_lag the fit is repeated twice on lags 1..tau / dt (at least MIN_LAGS):
    the lags far beyond tau carry only the sampling noise, correlated from lag to lag (over 100 seeds of
    sw 7 mm/s, sg 3 mm/s, tau 60 s, 3600 samples at 1 Hz: tau within a factor 2 in 95 of them instead of 89).
    sw^2 = C(0) - sg^2, floored at 0. Significant when sg^2 > SIGNIFICANCE_SIGMAS times its sampling std under
    white noise (on white noise alone: 2 of 100 seeds). mean_corrected: the fit's model allows for the variance
    the removed mean took (mean_variance_factor, n the samples per axis, dt_nominal apart): without it sg and tau
    come out low on a record a few tau long (100 seeds of sw 7 mm/s, sg 2 mm/s, tau 60 s, 400 samples of 3 axes:
    sg 1.71 +- 0.36 mm/s and tau's median 38 s; with it 2.17 +- 0.59 mm/s and 58 s)."""
    t = np.asarray(t, dtype=float).ravel()
    r = np.asarray(r, dtype=float).reshape(len(t), -1)
    ok = np.isfinite(t) & np.isfinite(r).all(axis=1)
    t, r = t[ok], r[ok]
    n = len(t)
    if n < 2 * MIN_LAGS:
        raise GtsamDvlError(
            f"Gauss-Markov fit: need at least {2 * MIN_LAGS} finite residuals, got {n}"
        )
    order = np.argsort(t, kind="stable")
    t, r = t[order], r[order] - r.mean(axis=0)
    lags = max(MIN_LAGS, min(n // 10, 600)) if max_lag is None else int(max_lag)
    c, pairs = autocovariance(t, r, dt_nominal, lags)
    n_mean = n if mean_corrected else 0
    sg2, tau, noise = _exponential_fit(c, pairs, dt_nominal, lags, n_mean)
    for _ in range(2 if max_lag is None else 0):
        sg2, tau, noise = _exponential_fit(
            c, pairs, dt_nominal, int(np.clip(round(tau / dt_nominal), MIN_LAGS, lags)), n_mean
        )
    c0 = c[0]
    sg2 = min(max(sg2, 0.0), c0)
    return GaussMarkovFit(
        float(np.sqrt(c0 - sg2)),
        float(np.sqrt(sg2)),
        tau,
        bool(sg2 > SIGNIFICANCE_SIGMAS * noise),
        n * r.shape[1],
        float(np.sqrt(noise)),
    )


@dataclass
class AllanCurve:
    """One axis's Allan deviation: taus (s), adev (deg/h or micro-g), its fit (None when the curve is zero: the
    samples never left their quantisation level)."""

    sensor: str  # "gyro" or "accel"
    axis: str
    taus: np.ndarray
    adev: np.ndarray
    white_density: float | None  # deg/h/sqrt(Hz) or micro-g/sqrt(Hz)
    bias_instability: float | None  # deg/h or micro-g
    bias_bound: bool

    def as_dict(self) -> dict[str, Any]:
        return {
            "axis": self.axis,
            "white_density": self.white_density,
            "bias_instability": self.bias_instability,
            "bias_instability_is_upper_bound": self.bias_bound,
            "tau_s": self.taus.tolist(),
            "adev": self.adev.tolist(),
        }
