"""The paper's ideal observer IO-DVLC (section 2.3, eq. 18): DVL scale and misalignment from the Type-I
segments alone, with no navigation filter.

On a segment of constant attitude (Type I) the IMU and the DVL see the same velocity change,

    k beta(t) = b_R_d gamma(t),    beta(t) = int_ts^t (b_f - b_f0) dtau,    gamma(t) = y(t) - y(ts) - y'(ts) (t - ts)

(eq. 18 with C_d^b = b_R_d). Both are built by integration only: the IMU is integrated between the 1 Hz
DVL epochs, and the derivative terms are never formed:
- when the constant-attitude interval holding the segment has a quiet stretch before it (no attitude
  change, no specific-force rate: static, or cruising), b_f0 is the mean specific force there, the
  specific force at zero acceleration, so beta is the IMU's velocity change; y(ts) is replaced by the
  segment mean (beta and gamma are centred), which removes the DVL noise of a single reference ping;
- otherwise b_f0 and y'(ts) are unknown and the straight-line part of both is removed (affine detrend).
Either way k beta~ = b_R_d gamma~ holds exactly for the noise-free processed vectors.

"Constant attitude" is taken as held relative to the local level (as an autopilot holds it; the simulator
does the same), and beta, gamma are expressed in the body axes at the reference. Terms that eq. 10
neglects are added (earth_terms): the gyro's residual rotation theta relative to the local level (gyro
minus the reference's mean rate, Earth rate and bias, minus the change of transport rate u x v / r)
applied to the specific force and the DVL velocity, the Coriolis term -2 w_ie x (v - v0) with the
measured Earth rate, and the vertical gravity gradient 2 g / r (h - h0). v, p and h come from the DVL at
the nominal calibration (k = 1, b_R_d0). Without these terms the misalignment errs by about 0.15 deg
and the scale from the descent by 0.2 % on noise-free paper-3d data; with them by below 0.001 deg and
0.001 %.

Estimates over the segments seen so far: the Wahba problem min sum |k beta~ - C gamma~|^2 over rotations C
(SVD of H = sum beta~ gamma~^T, det fixed to +1) and k = tr(C^T H) / sum |beta~|^2. Sigmas from the DVL
noise: var k = s^2 / sum |beta~|^2; the misalignment's body-axis information sum (|g|^2 I - g g^T) / s^2
over g = C gamma~, with the noise's own contribution removed (so an axis no segment excites is not given
a sigma computed from noise). Before a second direction of the specific-force rate is seen, the rotation
about the first is undetermined: the pure Wahba solution returns an arbitrary angle there (tens of
degrees, and through the Euler angles it spoils the pitch and yaw sigmas). A weak prior at the nominal
mounting (prior_sigma_deg, 10 deg by default; None for the paper's pure Wahba problem) keeps that axis at
the nominal mounting with the prior's sigma; on an excited axis (sigma 1 deg or less) its weight is 1 %
or less of the data's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig, IodvlcConfig
from gtsam_dvl.core.config.schema import SCHEMA_VERSION
from gtsam_dvl.core.earth import OMEGA_IE, WGS84_A
from gtsam_dvl.core.result import misalignment_rpy_and_cov
from gtsam_dvl.core.rotations import matrix_to_rpy_deg, rpy_deg_to_matrix
from gtsam_dvl.core.states import Estimate
from gtsam_dvl.core.summary import IoDvlcSummary
from gtsam_dvl.core.types import ImuData, LogData
from gtsam_dvl.estimators.inputs.mounting import log_in_base_link

MAX_SIGMA_RAD = np.pi  # sigma reported for a misalignment axis that no segment has excited
MAX_SCALE_SIGMA = 0.1  # timeline scale and misalignment are NaN until the scale is known this well


# The segment detector thresholds and observer options (TOML section [iodvlc]): gtsam_dvl.core.config.
IoDvlcOptions = IodvlcConfig


@dataclass
class Type1Segment:
    """A detected Type-I segment: constant attitude, non-zero specific-force rate. Times in s."""

    start_s: float
    end_s: float
    axis: np.ndarray  # unit principal axis of the specific-force rate, body
    interval: tuple[float, float]  # the constant-attitude interval holding it
    reference: tuple[float, float] | None  # quiet stretch giving b_f0; None: affine detrend

    def as_dict(self) -> dict[str, Any]:
        return {
            "start_s": self.start_s,
            "end_s": self.end_s,
            "axis": np.round(self.axis, 3).tolist(),
            "reference_s": list(self.reference) if self.reference else None,
        }


@dataclass
class SegmentEstimate:
    """Scale and misalignment from one segment alone."""

    start_s: float
    end_s: float
    scale: float
    scale_sigma: float
    misalignment_deg: np.ndarray
    misalignment_sigma_deg: np.ndarray


@dataclass
class IoDvlcResult:
    """IO-DVLC output: the timelines of the paper's Figures 4 and 5 and the final values.

    misalignment_deg = [roll, pitch, yaw] of R_c = b_R_d b_R_d0^T in body axes (docs/conventions.md). Timelines
    hold the estimate from the segments seen up to each DVL epoch (NaN before the first segment).
    """

    t: np.ndarray  # (N,) DVL epochs, s
    scale: np.ndarray  # (N,)
    scale_sigma: np.ndarray  # (N,)
    misalignment_deg: np.ndarray  # (N, 3)
    misalignment_sigma_deg: np.ndarray  # (N, 3)
    scale_pointwise: np.ndarray  # (N,) |gamma| / |beta| (eq. 18, step 1), NaN outside segments
    beta: np.ndarray  # (N, 3) m/s, processed beta of the segment holding each epoch, NaN outside
    gamma: np.ndarray  # (N, 3) m/s
    segments: list[Type1Segment]
    per_segment: list[SegmentEstimate]
    final_scale: float
    final_scale_sigma: float
    b_R_d: np.ndarray
    b_R_d0: np.ndarray
    final_misalignment_deg: np.ndarray
    final_misalignment_sigma_deg: np.ndarray
    noise_m_s: float
    timing_s: dict[str, float] = field(default_factory=dict)
    # the final estimates as every estimator reports them (core/result.EstimatorResult): "scale" and
    # "misalignment" (b_R_d, its covariance in GTSAM's right tangent, rad^2)
    calibration: dict[str, Estimate] = field(default_factory=dict)
    estimator: str = "io-dvlc"


# ----- segment detection -----------------------------------------------------------------------------


@dataclass
class _Windows:
    center: np.ndarray  # (W,) s
    const_att: np.ndarray  # (W,) bool
    rate: np.ndarray  # (W, 3) m/s^3


def _window_stats(imu: ImuData, opt: IoDvlcOptions) -> _Windows:
    """Per window: centre time, constant attitude (gyro), least-squares slope of the specific force."""
    t0 = float(imu.t[0])
    idx = np.floor(imu.t - t0 - 1e-9).astype(int).clip(0)
    n = int(idx[-1]) + 1
    counts = np.bincount(idx, minlength=n).astype(float)

    def bin_means(x: np.ndarray) -> np.ndarray:  # 1 s means
        return (
            np.stack([np.bincount(idx, x[:, i], n) for i in range(3)], axis=1)
            / np.maximum(counts, 1)[:, None]
        )

    f_mean, w_mean = bin_means(imu.b_f), bin_means(imu.b_omega)
    m = max(int(round(opt.window_s)), 2)
    if n < m:
        return _Windows(np.zeros(0), np.zeros(0, bool), np.zeros((0, 3)))
    tt = np.arange(m) - 0.5 * (m - 1)
    f_win = np.lib.stride_tricks.sliding_window_view(f_mean, m, axis=0)  # (W, 3, m)
    w_win = np.lib.stride_tricks.sliding_window_view(w_mean, m, axis=0)
    rate = f_win @ tt / np.sum(tt**2)
    w_avg = w_win.mean(axis=2)
    centre = t0 + np.arange(len(rate)) + 0.5 * m
    full = np.lib.stride_tricks.sliding_window_view(counts, m).min(axis=1) > 0
    const = (
        np.abs(np.linalg.norm(w_avg, axis=1) - OMEGA_IE)
        < np.radians(opt.gyro_threshold_deg_h) / 3600.0
    ) & full
    return _Windows(centre, const, rate)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) indices of the runs of True in mask."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1, strict=True))


def detect_type1_segments(imu: ImuData, options: IoDvlcOptions | None = None) -> list[Type1Segment]:
    """Type-I segments (constant attitude, non-zero specific-force rate) found in the IMU data alone."""
    opt = options or IoDvlcOptions()
    win = _window_stats(imu, opt)
    if len(win.center) == 0:
        return []
    active = win.const_att & (np.linalg.norm(win.rate, axis=1) > opt.sf_rate_threshold_m_s3)
    cos_max = np.cos(np.radians(opt.axis_change_deg))
    intervals = [
        (float(win.center[a] - 0.5), float(win.center[b] + 0.5)) for a, b in _runs(win.const_att)
    ]
    quiet_runs = [
        (float(win.center[a] - 0.5), float(win.center[b] + 0.5))
        for a, b in _runs(win.const_att & ~active)
    ]
    quiet_runs = [(a, b) for a, b in quiet_runs if b - a >= opt.min_quiet_s + opt.window_s]

    raw: list[
        tuple[int, int, np.ndarray]
    ] = []  # (first window, last window, scatter matrix of the rate)
    cur: list[Any] | None = None
    for i in range(len(win.center)):
        if not win.const_att[i]:
            if cur is not None:
                raw.append((cur[0], cur[1], cur[2]))
            cur = None
            continue
        if not active[i]:
            continue
        r = win.rate[i]
        if cur is not None:
            axis = np.linalg.eigh(cur[2])[1][:, -1]
            if win.center[i] - win.center[cur[1]] > opt.max_gap_s or abs(
                axis @ r
            ) < cos_max * np.linalg.norm(r):
                raw.append((cur[0], cur[1], cur[2]))
                cur = None
        if cur is None:
            cur = [i, i, np.outer(r, r)]
        else:
            cur[1], cur[2] = i, cur[2] + np.outer(r, r)
    if cur is not None:
        raw.append((cur[0], cur[1], cur[2]))

    segments = []
    for a, b, scatter in raw:
        start, end = float(win.center[a] - 0.5), float(win.center[b] + 0.5)
        if end - start < opt.min_segment_s:
            continue
        interval = next((iv for iv in intervals if iv[0] <= start and end <= iv[1]), (start, end))
        # the latest quiet stretch of the same interval that ends before the segment, trimmed by a window
        # at both ends so that no part of a manoeuvre leaks into the reference
        ref = None
        for qa, qb in quiet_runs:
            if interval[0] <= qa and qb <= start + 0.5:
                ref = (
                    max(qa + 0.5 * opt.window_s, qb - 0.5 * opt.window_s - opt.reference_s),
                    qb - 0.5 * opt.window_s,
                )
        segments.append(Type1Segment(start, end, np.linalg.eigh(scatter)[1][:, -1], interval, ref))
    return segments


# ----- the observer ----------------------------------------------------------------------------------


class _Integrals:
    """Cumulative integrals of the IMU (exact for interval-average samples) and the DVL velocity."""

    def __init__(self, imu: ImuData, t_dvl: np.ndarray, y: np.ndarray, b_R_d0: np.ndarray) -> None:
        t = imu.t
        dt = np.diff(t, prepend=t[0] - (np.median(np.diff(t)) if len(t) > 1 else 0.01))
        self.imu, self.dt = imu, dt
        self.t_knots = np.concatenate([[t[0] - dt[0]], t])
        self.F = np.concatenate([np.zeros((1, 3)), np.cumsum(imu.b_f * dt[:, None], axis=0)])
        self.W = np.concatenate([np.zeros((1, 3)), np.cumsum(imu.b_omega * dt[:, None], axis=0)])
        self.t_dvl, self.y, self.b_R_d0 = t_dvl, y, b_R_d0
        self.b_v = y @ b_R_d0.T  # body velocity at the nominal calibration (k = 1)
        steps = 0.5 * (self.b_v[1:] + self.b_v[:-1]) * np.diff(t_dvl)[:, None]
        self.b_p_dvl = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])

    def _interp(self, A: np.ndarray, t: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(t, self.t_knots, A[:, i]) for i in range(3)], axis=-1)

    def f_integral(self, t: np.ndarray) -> np.ndarray:
        return self._interp(self.F, t)

    def mean_f(self, a: float, b: float) -> np.ndarray:
        F = self._interp(self.F, np.array([a, b]))
        return (F[1] - F[0]) / (b - a)

    def mean_omega(self, a: float, b: float) -> np.ndarray:
        W = self._interp(self.W, np.array([a, b]))
        return (W[1] - W[0]) / (b - a)

    def b_p(self, t: np.ndarray) -> np.ndarray:
        """Dead-reckoned position in body axes (m) at times t, from the DVL at the nominal calibration."""
        return np.stack([np.interp(t, self.t_dvl, self.b_p_dvl[:, i]) for i in range(3)], axis=-1)

    def theta(self, t: np.ndarray, ref: _Reference) -> np.ndarray:
        """Rotation of the body relative to the local level (rad, first order) from the anchor to t: the gyro
        minus the reference rate (Earth rate and bias) minus the change of transport rate u x v / r."""
        dp = self.b_p(t) - self.b_p(np.array([ref.anchor]))[0] - np.outer(t - ref.anchor, ref.b_v)
        return (
            self._interp(self.W, t)
            - self._interp(self.W, np.array([ref.anchor]))[0]
            - np.outer(t - ref.anchor, ref.b_omega)
            - np.cross(ref.up, dp) / ref.radius
        )

    def rotated_f_integral(self, ts: float, t: np.ndarray, ref: _Reference) -> np.ndarray:
        """int_ts^t (b_f + theta x b_f) dtau at times t (>= ts): the specific force in the anchor's body axes."""
        imu = self.imu
        lo = int(np.searchsorted(imu.t, ts, side="right"))
        hi = min(int(np.searchsorted(imu.t, t[-1], side="left")), len(imu.t) - 1)
        i = np.arange(lo, hi + 1)
        th = self.theta(imu.t[i] - 0.5 * self.dt[i], ref)
        inc = (imu.b_f[i] + np.cross(th, imu.b_f[i])) * self.dt[i][:, None]
        knots = self.t_knots[lo : hi + 2]
        cum = np.concatenate([np.zeros((1, 3)), np.cumsum(inc, axis=0)])
        at = np.stack(
            [np.interp(np.concatenate([[ts], t]), knots, cum[:, j]) for j in range(3)], axis=-1
        )
        return at[1:] - at[0]


@dataclass
class _Reference:
    """Zero-acceleration reference of a segment (the quiet stretch, or the segment itself)."""

    anchor: float  # s: where theta = 0
    b_f: np.ndarray  # mean specific force: the specific force at zero acceleration when quiet
    b_omega: np.ndarray  # mean gyro: Earth rate (+ bias, + transport rate when moving)
    b_v: np.ndarray  # mean DVL velocity at the nominal calibration, body
    b_p: np.ndarray  # mean dead-reckoned position, body
    up: np.ndarray  # unit vector up, body
    radius: float  # m, for the transport rate and the vertical gravity gradient


@dataclass
class _SegmentData:
    """Raw beta/gamma of one segment at its DVL epochs (before centring or detrending)."""

    seg: Type1Segment
    rows: np.ndarray  # indices into the DVL epoch arrays
    tau: np.ndarray  # t - ts
    beta: np.ndarray  # (n, 3)
    gamma: np.ndarray  # (n, 3)
    affine: bool


def _segment_data(seg: Type1Segment, ints: _Integrals, opt: IoDvlcOptions) -> _SegmentData | None:
    """beta and gamma in the body axes of the reference (or of the segment start); see the module doc."""
    t = ints.t_dvl
    rows = np.flatnonzero((t >= seg.start_s) & (t <= seg.end_s))
    if len(rows) < 3:
        return None
    te = t[rows]
    ts, tau = te[0], te - te[0]
    ra, rb = seg.reference if seg.reference is not None else (seg.start_s, seg.end_s)
    ref_rows = np.flatnonzero((t >= ra) & (t <= rb))
    b_f = ints.mean_f(ra, rb)
    ref = _Reference(
        0.5 * (ra + rb),
        b_f,
        ints.mean_omega(ra, rb),
        ints.b_v[ref_rows].mean(axis=0),
        ints.b_p_dvl[ref_rows].mean(axis=0),
        b_f / np.linalg.norm(b_f),
        WGS84_A,
    )
    if not opt.earth_terms:
        beta = ints.f_integral(te) - ints.f_integral(np.array([ts]))[0] - np.outer(tau, ref.b_f)
        return _SegmentData(
            seg, rows, tau, beta, ints.y[rows] - ints.y[rows[0]], seg.reference is None
        )
    th = ints.theta(te, ref) if opt.track_attitude else np.zeros((len(te), 3))
    y = ints.y[rows] + np.cross(th @ ints.b_R_d0, ints.y[rows])  # DVL velocity in the anchor's axes
    if opt.track_attitude:
        beta = ints.rotated_f_integral(ts, te, ref) - np.outer(tau, ref.b_f)
    else:
        beta = ints.f_integral(te) - ints.f_integral(np.array([ts]))[0] - np.outer(tau, ref.b_f)
    b_v = y @ ints.b_R_d0.T
    dh = (ints.b_p_dvl[rows] - ref.b_p) @ ref.up
    g = np.linalg.norm(ref.b_f)
    accel = -2.0 * np.cross(ref.b_omega, b_v - ref.b_v) + np.outer(
        2.0 * g / ref.radius * dh, ref.up
    )
    steps = 0.5 * (accel[1:] + accel[:-1]) * np.diff(tau)[:, None]
    beta = beta + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
    return _SegmentData(seg, rows, tau, beta, y - y[0], seg.reference is None)


def _processed(d: _SegmentData, n: int) -> tuple[np.ndarray, np.ndarray]:
    """beta~, gamma~ of the first n epochs: centred, or with the straight line removed (affine)."""
    beta, gamma, tau = d.beta[:n], d.gamma[:n], d.tau[:n]
    A = np.stack([np.ones(n), tau], axis=1) if d.affine else np.ones((n, 1))
    proj = A @ np.linalg.pinv(A)
    return beta - proj @ beta, gamma - proj @ gamma


@dataclass
class _Sums:
    H: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))  # sum beta~ gamma~^T
    Sbb: float = 0.0  # sum |beta~|^2
    Sgg: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))  # sum gamma~ gamma~^T
    dof: float = 0.0  # epochs minus fitted constants: the noise's share of Sgg

    def plus(self, beta: np.ndarray, gamma: np.ndarray, dof: float) -> _Sums:
        return _Sums(
            self.H + beta.T @ gamma,
            self.Sbb + float(np.sum(beta**2)),
            self.Sgg + gamma.T @ gamma,
            self.dof + dof,
        )


def _solve(
    s: _Sums, sigma: float, b_R_d0: np.ndarray, prior_sigma: float | None
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """(k, sigma_k, b_R_d, body-axis covariance of b_R_d) from the sums: the Wahba problem by SVD, with the
    weak prior |Log(b_R_d b_R_d0^T)|^2 / prior_sigma^2 = (3 - tr(b_R_d^T b_R_d0)) / prior_sigma^2 when given
    (it adds b_R_d0 s^2 / (2 prior_sigma^2) to H, taking k = 1 in its weight)."""
    H = s.H if prior_sigma is None else s.H + b_R_d0 * sigma**2 / (2.0 * prior_sigma**2)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    if s.Sbb <= 0.0:  # no velocity change yet (the first epochs of a noise-free segment)
        return np.nan, np.inf, R, np.eye(3) * MAX_SIGMA_RAD**2
    k = float(np.trace(R.T @ s.H) / s.Sbb)
    Sgg = s.Sgg - s.dof * sigma**2 * np.eye(3)  # remove the noise's expected share
    info = (np.trace(Sgg) * np.eye(3) - R @ Sgg @ R.T) / sigma**2
    lam, V = np.linalg.eigh(0.5 * (info + info.T))
    # the noise subtraction can overshoot on an axis that holds no signal
    lam = np.maximum(lam, 0.0)
    if prior_sigma is not None:
        lam = lam + 1.0 / prior_sigma**2
    cov = V @ np.diag(1.0 / np.maximum(lam, 1.0 / MAX_SIGMA_RAD**2)) @ V.T
    return k, sigma / np.sqrt(s.Sbb), R, cov


def _misalignment(
    R: np.ndarray, cov_body: np.ndarray, b_R_d0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    rpy, cov = misalignment_rpy_and_cov(R, b_R_d0, R.T @ cov_body @ R)
    return rpy, np.sqrt(np.diag(cov))


def run_iodvlc(
    log: LogData, options: IoDvlcOptions | EstimatorConfig | None = None
) -> IoDvlcResult:
    """Detect the Type-I segments and estimate the DVL scale and misalignment from them (IO-DVLC). options:
    IoDvlcOptions, or an EstimatorConfig (its [iodvlc] section); None: the defaults."""
    opt = options.iodvlc if isinstance(options, EstimatorConfig) else options or IoDvlcOptions()
    opt.validate()
    log = log_in_base_link(log)  # IMU samples in base_link (estimators/inputs/mounting.py)
    t_start = time.perf_counter()
    dvl, b_R_d0 = log.dvl, log.mounting.b_R_d0
    ok = (
        dvl.valid
        & np.all(np.isfinite(dvl.d_v), axis=1)
        & (dvl.t >= log.imu.t[0])
        & (dvl.t <= log.imu.t[-1])
    )
    t, y = dvl.t[ok], dvl.d_v[ok]
    sigma = opt.noise_m_s or float(
        np.sqrt(np.median(np.trace(dvl.d_cov[ok], axis1=1, axis2=2)) / 3.0)
    )
    segments = detect_type1_segments(log.imu, opt)
    prior = None if opt.prior_sigma_deg is None else float(np.radians(opt.prior_sigma_deg))
    ints = _Integrals(log.imu, t, y, b_R_d0)
    data = [d for d in (_segment_data(s, ints, opt) for s in segments) if d is not None]
    series = _Series.empty(len(t))
    per_segment, final = _sweep(data, series, sigma, b_R_d0, prior, opt.min_beta_m_s)
    rpy, rpy_sig = _misalignment(final[2], final[3], b_R_d0)
    b_R_d, cov_body = final[2], final[3]
    calibration = {
        "scale": Estimate(np.array([final[0]]), np.array([[final[1] ** 2]])),
        "misalignment": Estimate(b_R_d.copy(), b_R_d.T @ cov_body @ b_R_d),
    }
    return IoDvlcResult(
        t=t,
        scale=series.scale,
        scale_sigma=series.scale_sig,
        misalignment_deg=series.mis,
        misalignment_sigma_deg=series.mis_sig,
        scale_pointwise=series.pointwise,
        beta=series.beta,
        gamma=series.gamma,
        segments=segments,
        per_segment=per_segment,
        final_scale=float(final[0]),
        final_scale_sigma=float(final[1]),
        b_R_d=final[2],
        b_R_d0=b_R_d0,
        final_misalignment_deg=rpy,
        final_misalignment_sigma_deg=rpy_sig,
        noise_m_s=sigma,
        timing_s={"total": time.perf_counter() - t_start},
        calibration=calibration,
    )


@dataclass
class _Series:
    """The per-epoch figures of the sweep at the n DVL epochs (NaN where nothing is known): the scale and the
    misalignment (deg) with their sigmas, the pointwise scale |gamma| / |beta|, beta and gamma."""

    scale: np.ndarray
    scale_sig: np.ndarray
    mis: np.ndarray
    mis_sig: np.ndarray
    pointwise: np.ndarray
    beta: np.ndarray
    gamma: np.ndarray

    @classmethod
    def empty(cls, n: int) -> _Series:
        return cls(
            np.full(n, np.nan),
            np.full(n, np.nan),
            np.full((n, 3), np.nan),
            np.full((n, 3), np.nan),
            np.full(n, np.nan),
            np.full((n, 3), np.nan),
            np.full((n, 3), np.nan),
        )

    def fill(
        self, est: tuple[float, float, np.ndarray, np.ndarray], rows: slice, b_R_d0: np.ndarray
    ) -> None:
        """The estimate est at the epochs rows (_fill)."""
        _fill(est, rows, self.scale, self.scale_sig, self.mis, self.mis_sig, b_R_d0)


def _sweep(
    data: list[_SegmentData],
    series: _Series,
    sigma: float,
    b_R_d0: np.ndarray,
    prior: float | None,
    min_beta_m_s: float,
) -> tuple[list[SegmentEstimate], tuple[float, float, np.ndarray, np.ndarray]]:
    """The segments in time order, each epoch's estimate from every segment so far (into series; the epochs
    between segments keep the last one). Returns each segment's estimate alone and the final estimate (scale,
    its sigma, b_R_d, its covariance; the nominal calibration, NaN scale, when no segment gives one)."""
    n = len(series.scale)
    done = _Sums()
    per_segment = []
    last: tuple[float, float, np.ndarray, np.ndarray] | None = None
    next_row = 0
    for d in data:
        n_fit = 2 if d.affine else 1
        if last is not None:  # epochs up to the segment's first estimate keep the last one
            series.fill(last, slice(next_row, d.rows[n_fit + 1]), b_R_d0)
        for m in range(n_fit + 2, len(d.rows) + 1):
            b, g = _processed(d, m)
            last = _solve(done.plus(b, g, m - n_fit), sigma, b_R_d0, prior)
            series.fill(last, slice(d.rows[m - 1], d.rows[m - 1] + 1), b_R_d0)
        b, g = _processed(d, len(d.rows))
        done = done.plus(b, g, len(d.rows) - n_fit)
        series.beta[d.rows], series.gamma[d.rows] = b, g
        nb = np.linalg.norm(b, axis=1)
        series.pointwise[d.rows] = np.where(
            nb > min_beta_m_s, np.linalg.norm(g, axis=1) / np.maximum(nb, 1e-12), np.nan
        )
        alone = _solve(_Sums().plus(b, g, len(d.rows) - n_fit), sigma, b_R_d0, prior)
        rpy, rpy_sig = _misalignment(alone[2], alone[3], b_R_d0)
        per_segment.append(
            SegmentEstimate(d.seg.start_s, d.seg.end_s, alone[0], alone[1], rpy, rpy_sig)
        )
        next_row = d.rows[-1] + 1
    if last is None:
        return per_segment, (np.nan, np.nan, b_R_d0.copy(), np.eye(3) * MAX_SIGMA_RAD**2)
    series.fill(last, slice(next_row, n), b_R_d0)
    return per_segment, last


def _fill(
    est: tuple[float, float, np.ndarray, np.ndarray],
    rows: slice,
    scale: np.ndarray,
    scale_sig: np.ndarray,
    mis: np.ndarray,
    mis_sig: np.ndarray,
    b_R_d0: np.ndarray,
) -> None:
    if not est[1] < MAX_SCALE_SIGMA:  # the first epochs of the first segment: nothing is known yet
        return
    rpy, rpy_sig = _misalignment(est[2], est[3], b_R_d0)
    scale[rows], scale_sig[rows] = est[0], est[1]
    mis[rows], mis_sig[rows] = rpy, rpy_sig


def iodvlc_summary(result: IoDvlcResult, log: LogData) -> dict[str, Any]:
    """The summary JSON for IO-DVLC: scale and misalignment only, with errors against the truth if known (through
    core/summary.py IoDvlcSummary; the dict written)."""
    out: dict[str, Any] = {
        "schema_version": SCHEMA_VERSION,
        "estimator": "io-dvlc",
        "log": log.source,
        "scale": {"value": result.final_scale, "sigma": result.final_scale_sigma},
        "misalignment_deg": {
            "value": result.final_misalignment_deg.tolist(),
            "sigma": result.final_misalignment_sigma_deg.tolist(),
            "convention": "R_c = Rz(yaw) Ry(pitch) Rx(roll) in body FLU axes, b_R_d = R_c b_R_d0",
        },
        "segments": [s.as_dict() for s in result.segments],
        "per_segment": [
            {
                "start_s": p.start_s,
                "end_s": p.end_s,
                "scale": p.scale,
                "scale_sigma": p.scale_sigma,
                "misalignment_deg": p.misalignment_deg.tolist(),
                "misalignment_sigma_deg": p.misalignment_sigma_deg.tolist(),
            }
            for p in result.per_segment
        ],
        "dvl_noise_m_s": result.noise_m_s,
        "timing_s": result.timing_s,
    }
    cal = log.true_calibration
    if cal is not None and np.isfinite(result.final_scale):
        err_rpy = matrix_to_rpy_deg(
            result.b_R_d @ result.b_R_d0.T @ rpy_deg_to_matrix(cal.misalignment_deg).T
        )
        out["errors"] = {
            "scale_ppm": (result.final_scale - cal.scale) / cal.scale * 1e6,
            "scale_nsigma": (result.final_scale - cal.scale) / result.final_scale_sigma,
            "misalignment_deg": err_rpy.tolist(),
            "misalignment_nsigma": (err_rpy / result.final_misalignment_sigma_deg).tolist(),
        }
    return IoDvlcSummary.model_validate(out).to_json_dict()
