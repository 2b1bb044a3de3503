"""The screen for bogus DVL pings (PingScreen, screen_pings) and the reason codes of every ping rejection, for
estimators/inputs/selection.py, which applies them for the batch smoother, the online estimator and the EKF.

A ping is bogus (with `dvl.screen`) when it is an exact zero velocity while moving, a velocity repeated bit for bit
(a frozen output), or a velocity change the IMU cannot explain. A real DVL's velocity is noisy: a stationary
vehicle reads near zero, never exact zeros, and no reading repeats bit for bit, whatever the vehicle does (a frozen
output in a steady turn shows the IMU no change either). A simulator without noise does both, at rest and at
constant velocity: its logs say so (DvlData.noise_free), and there a repeat is bogus only while the IMU shows
motion ("while moving"). Exact zeros, a frozen output and a gross jump are what a DVL that lost bottom lock but
still flags its velocity valid reports; the robust kernel (`dvl.robust`) takes care of the milder outliers.

The screen is causal: it compares a ping with the previous accepted ping and the IMU samples stamped between
the two (at most SCREEN_WINDOW_S before the ping), so that the online estimator, which sees pings one by one,
makes the batch smoother's and the EKF's decisions (it waits until the IMU reaches the ping).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gtsam_dvl.core.config import DvlConfig
from gtsam_dvl.core.types import DvlData, ImuData

# Rejection reasons, in the counters every estimator reports.
USABLE = 0
UNUSABLE = 1  # no valid velocity or beam
TOO_FAST = 2  # faster than dvl.max_speed_m_s
ZERO_WHILE_MOVING = 3  # exactly 0.0 in every component while moving (PingScreen)
REPEATED = 4  # bit-identical to the previous accepted ping, not zero: a frozen output (PingScreen)
IMPLAUSIBLE_ACCEL = 5  # a velocity change the IMU cannot explain (PingScreen)
WATER_TRACK = 6  # the DVL measured relative to the water (DvlData.water_track), not over ground
# at or before the first IMU sample: nothing to propagate from (not a fault of the ping)
BEFORE_IMU = 7
AFTER_IMU = 8  # after the last IMU sample (not a fault of the ping)
REASONS = {
    UNUSABLE: "dvl_unusable",
    TOO_FAST: "dvl_too_fast",
    ZERO_WHILE_MOVING: "dvl_zero_while_moving",
    REPEATED: "dvl_repeated",
    IMPLAUSIBLE_ACCEL: "dvl_implausible_accel",
    WATER_TRACK: "dvl_water_track",
    BEFORE_IMU: "dvl_before_imu",
    AFTER_IMU: "dvl_after_imu",
}
SCREEN_WINDOW_S = 60.0  # the screen looks at most this far back in the IMU


def _turned_back(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """exp(theta_i)^T v for rotation vectors theta (N, 3): v, fixed in the start frame, seen from frames turned
    by theta_i (Rodrigues)."""
    angle = np.linalg.norm(theta, axis=1)
    small = angle < 1e-12
    k = theta / np.where(small, 1.0, angle)[:, None]
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return np.asarray(v * c - np.cross(k, v) * s + k * (k @ v)[:, None] * (1.0 - c))


def screened_value(
    d_v: np.ndarray, beams: tuple[np.ndarray, np.ndarray, np.ndarray] | None, cfg: DvlConfig
) -> np.ndarray:
    """What PingScreen compares of a ping: the 3-D velocity (3,), or with dvl.use_beams and beams
    (d_u, v, valid) the beam velocities (B,), NaN where invalid."""
    if cfg.use_beams and beams is not None:
        return np.where(np.asarray(beams[2], dtype=bool), np.asarray(beams[1], dtype=float), np.nan)
    return np.asarray(d_v, dtype=float)


@dataclass
class PingScreen:
    """The screen for bogus pings (module doc; thresholds and rules in DvlConfig's doc), one ping at a time.

    The previous accepted ping (last_t, last_y) is the reference. The IMU samples stamped in
    (max(last_t, t - SCREEN_WINDOW_S), t] give the evidence for ping t. In body axes dv/dt = f + g - omega x v;
    gravity g is unknown to the IMU alone, but it turns with the body as the gyro says, so the change of
    f + g since the window's first sample is df = f - exp(theta)^T f_0 (theta the gyro's angle since then)
    and omega x v changes by at most |omega - omega_0| |v_prev|. With a_0 the acceleration at the window's
    start (the DVL's |dv/dt| between the two previous accepted pings, last_rate), the velocity changed by
    at least | |a_0| T - |sum df dt| | - sum |omega - omega_0| |v_prev| dt over the window's T seconds: motion
    when that exceeds dvl.motion_dv_m_s (a turn at constant velocity, or a vehicle turning on the spot, is no
    motion of the DVL's velocity). The velocity change the IMU allows: dv_imu = sum of dt
    (|df| + |omega - omega_0| |v_prev|), plus dvl.max_accel_m_s2 dt for the acceleration at the window's
    start, which the IMU alone cannot see (gravity hides it). A ping bit-identical to the reference and not zero
    is a frozen output whatever the IMU shows (with repeats_need_motion, a noise-free simulation's, only while
    it shows motion). With dvl.use_beams the screen compares the beam velocities (zero and repeat rules only).
    The online estimator feeds push_imu() and calls check_buffered(); the whole-log estimators call
    screen_pings, which makes check()'s decisions in bulk and runs _classify only where the bulk cannot decide
    (this class is its reference)."""

    cfg: DvlConfig
    # a noise-free simulation (DvlData.noise_free): a repeat is bogus only while the IMU shows motion
    repeats_need_motion: bool = False
    last_t: float = -np.inf
    last_y: np.ndarray | None = None
    last_rate: float = 0.0  # |dv/dt| between the two previous accepted pings (3-D velocity), m/s^2
    _t: list[np.ndarray] = field(default_factory=list)
    _w: list[np.ndarray] = field(default_factory=list)
    _f: list[np.ndarray] = field(default_factory=list)

    def check(
        self, t: float, y: np.ndarray, imu_t: np.ndarray, imu_w: np.ndarray, imu_f: np.ndarray
    ) -> int:
        """Reason code of ping t with value y (screened_value), given IMU stamps imu_t (sorted) with gyro
        imu_w (rad/s) and specific force imu_f (m/s^2) holding at least the window's samples; an accepted
        ping becomes the reference."""
        cfg = self.cfg
        code = USABLE
        if cfg.screen and self.last_y is not None:
            code = self._classify(t, y, imu_t, imu_w, imu_f)
        if code == USABLE:
            if self.last_y is not None and not self.cfg.use_beams and t > self.last_t:
                self.last_rate = float(np.linalg.norm(y - self.last_y)) / (t - self.last_t)
            self.last_t, self.last_y = t, np.array(y, dtype=float)
        return code

    def _classify(
        self, t: float, y: np.ndarray, imu_t: np.ndarray, imu_w: np.ndarray, imu_f: np.ndarray
    ) -> int:
        cfg, last = self.cfg, self.last_y
        assert last is not None
        t_from = max(self.last_t, t - SCREEN_WINDOW_S)
        lo, hi = (
            int(np.searchsorted(imu_t, t_from, side="right")),
            int(np.searchsorted(imu_t, t, side="right")),
        )
        # with beams, the largest beam velocity: a lower bound of the speed
        prev_speed = (
            float(np.nanmax(np.abs(last))) if cfg.use_beams else float(np.linalg.norm(last))
        )
        imu_motion, dv_imu = False, 0.0
        if hi - lo >= 1:
            tw, w, f = imu_t[lo:hi], imu_w[lo:hi], imu_f[lo:hi]
            dt = np.diff(tw, prepend=t_from)
            # the specific force's change that gravity turning with the body (the gyro's angle since the
            # window's start, about a fixed axis) does not explain: the change of the body's acceleration
            df = f - _turned_back(np.cumsum(w * dt[:, None], axis=0), f[0])
            # what the change of the turn rate can do to a body velocity of the previous ping's size
            dw_v = np.linalg.norm(w - w[0], axis=1) * prev_speed
            # the acceleration at the window's start is the DVL's between the previous two pings; whatever its
            # direction, |a_0 dt + sum df dt| >= | |a_0| dt - |sum df dt| |
            dv_low = abs(float(np.linalg.norm(dt @ df)) - self.last_rate * (t - t_from)) - float(
                dt @ dw_v
            )
            imu_motion = dv_low > cfg.motion_dv_m_s
            dv_imu = float(dt @ (np.linalg.norm(df, axis=1) + dw_v))
        valid = np.isfinite(y)
        zero = valid.any() and bool(np.all(y[valid] == 0.0))
        if zero and (imu_motion or prev_speed > cfg.moving_speed_m_s):
            return ZERO_WHILE_MOVING
        if (
            (imu_motion or not self.repeats_need_motion)
            and valid.any()
            and not zero
            and y.shape == last.shape
            and np.array_equal(y, last, equal_nan=True)
        ):
            return REPEATED  # a frozen output
        if not cfg.use_beams:  # the 3-D velocity only: beams may change validity from ping to ping
            allowed = (
                cfg.max_accel_m_s2 * (t - self.last_t)
                + cfg.accel_imu_factor * dv_imu
                + cfg.jump_margin_m_s
            )
            if float(np.linalg.norm(y - last)) > allowed:
                return IMPLAUSIBLE_ACCEL
        return USABLE

    # ----- online: IMU samples buffered as they come ---------------------------------------------
    def push_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> None:
        """IMU samples in time order (after every earlier one pushed)."""
        if len(t):
            self._t.append(np.asarray(t, dtype=float))
            self._w.append(np.asarray(w, dtype=float))
            self._f.append(np.asarray(f, dtype=float))
            # no ping for long: bounded memory
            if self._t[0][0] < self._t[-1][-1] - 3 * SCREEN_WINDOW_S:
                T, W, F = np.concatenate(self._t), np.concatenate(self._w), np.concatenate(self._f)
                keep = int(np.searchsorted(T, T[-1] - 2 * SCREEN_WINDOW_S, side="right"))
                self._t, self._w, self._f = [T[keep:]], [W[keep:]], [F[keep:]]

    def reaches(self, t: float) -> bool:
        """Whether the buffered IMU samples reach ping time t (the screen can decide)."""
        return bool(self._t) and float(self._t[-1][-1]) >= t

    def check_buffered(self, t: float, y: np.ndarray) -> int:
        """check() on the buffered samples (reaches(t) must hold), then drop the samples no later ping needs."""
        if len(self._t) > 1:
            self._t, self._w, self._f = (
                [np.concatenate(self._t)],
                [np.concatenate(self._w)],
                [np.concatenate(self._f)],
            )
        T, W, F = (
            (self._t[0], self._w[0], self._f[0])
            if self._t
            else (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
        )
        code = self.check(t, y, T, W, F)
        keep = int(np.searchsorted(T, max(self.last_t, t - SCREEN_WINDOW_S), side="right"))
        if keep:
            self._t, self._w, self._f = (
                ([T[keep:]], [W[keep:]], [F[keep:]]) if keep < len(T) else ([], [], [])
            )
        return code


def screen_pings(dvl: DvlData, idx: np.ndarray, imu: ImuData, cfg: DvlConfig) -> np.ndarray:
    """PingScreen's reason code for each of the pings idx (usable by classify_pings, in time order): the
    decisions of PingScreen.check fed the pings one by one (the reference, and the online estimator's path),
    computed in bulk.

    Every ping's evidence is first computed at once assuming the ping before it was accepted and was the
    reference (_bulk_screen: the IMU samples between consecutive pings are disjoint windows). A walk through
    the pings then takes that code wherever the assumption holds (the previous ping accepted with the one
    before it as its own reference, so that last_rate is the assumed one too) and the bulk evidence is clear
    of every threshold; elsewhere (after a rejection, a window capped at SCREEN_WINDOW_S, a value within
    _BAND of a threshold, a window longer than the bulk handles) it runs PingScreen's own check on the true
    reference."""
    m = len(idx)
    code = np.zeros(m, dtype=np.int8)
    if not cfg.screen or m == 0:
        return code  # check() accepts every ping without the screen
    t = np.asarray(dvl.t, dtype=float)[idx]
    b = dvl.beams
    if cfg.use_beams and b is not None:  # screened_value's choice
        y = np.where(
            np.asarray(b.valid[idx], dtype=bool), np.asarray(b.v[idx], dtype=float), np.nan
        )
    else:
        y = np.asarray(dvl.d_v, dtype=float)[idx]
    bulk, sure = _bulk_screen(t, y, imu, cfg, dvl.noise_free)
    screen = PingScreen(cfg, repeats_need_motion=dvl.noise_free)
    t_list, bulk_list, sure_list = t.tolist(), bulk.tolist(), sure.tolist()
    last = -1  # the reference: the last accepted ping
    # the pings whose velocity change last_rate is (None: 0.0)
    rate_of: tuple[int, int] | None = None
    for n in range(m):
        # the pair the bulk assumed for last_rate: none for the first reference, and never with beams
        assumed = None if cfg.use_beams or n < 2 else (n - 2, n - 1)
        if last < 0:
            c = USABLE
        elif last == n - 1 and sure_list[n] and rate_of == assumed:
            c = bulk_list[n]
        else:
            screen.last_t, screen.last_y = t_list[last], np.array(y[last], dtype=float)
            screen.last_rate = (
                0.0
                if rate_of is None
                else (
                    float(np.linalg.norm(y[rate_of[1]] - y[rate_of[0]]))
                    / (t_list[rate_of[1]] - t_list[rate_of[0]])
                )
            )
            c = screen._classify(t_list[n], y[n], imu.t, imu.b_omega, imu.b_f)
        code[n] = c
        if c == USABLE:
            # check()'s update of last_rate
            if last >= 0 and not cfg.use_beams and t_list[n] > t_list[last]:
                rate_of = (last, n)
            last = n
    return code


# Relative margin around each threshold within which the bulk screen leaves the decision to PingScreen: the bulk
# evaluates PingScreen's formulas on the same samples, differing only in the order of the window sums and in
# dot products (a few ulps, 1e-16 relative, times the window's samples), far inside this.
_BAND = 1e-9
# IMU samples per block of the bulk screen (bounded memory on long logs)
_BULK_MAX_SAMPLES = 1 << 14


def _window_sums(imu: ImuData, t_from: np.ndarray, lo: np.ndarray, cnt: np.ndarray) -> np.ndarray:
    """PingScreen._classify's window sums for windows of cnt >= 1 samples from lo, starting at t_from (s):
    columns sum dt df (3, m/s), sum dt |df| (m/s), sum dt |omega - omega_0| (rad), sum dt |f| (m/s, for the
    band). Blocks of windows padded to the longest (padding has dt = 0), one array per axis (contiguous)."""
    out = np.zeros((len(lo), 6))
    b_omega, b_f = (
        np.ascontiguousarray(imu.b_omega.T),
        np.ascontiguousarray(imu.b_f.T),
    )  # (3, samples)
    per_block = max(1, _BULK_MAX_SAMPLES // int(cnt.max()))
    for start in range(0, len(lo), per_block):
        stop = min(start + per_block, len(lo))
        lo_b, cnt_b = lo[start:stop], cnt[start:stop]
        col = np.arange(int(cnt_b.max()))[None, :]
        inside = col < cnt_b[:, None]
        i = np.where(inside, lo_b[:, None] + col, lo_b[:, None])  # (windows, width)
        tw = imu.t[i]
        dt = np.empty(tw.shape)
        dt[:, 0] = tw[:, 0] - t_from[start:stop]
        dt[:, 1:] = tw[:, 1:] - tw[:, :-1]
        dt[~inside] = 0.0
        w, f = b_omega[:, i], b_f[:, i]  # (3, windows, width)
        # df = f - exp(theta)^T f_0 (_turned_back), theta the gyro's angle since the window's start
        theta = np.cumsum(w * dt, axis=2)
        angle = np.sqrt(theta[0] * theta[0] + theta[1] * theta[1] + theta[2] * theta[2])
        k = theta / np.where(angle < 1e-12, 1.0, angle)
        c, s = np.cos(angle), np.sin(angle)
        v = f[:, :, :1]
        k_v = k[0] * v[0] + k[1] * v[1] + k[2] * v[2]
        k_x_v = np.stack(
            [k[1] * v[2] - k[2] * v[1], k[2] * v[0] - k[0] * v[2], k[0] * v[1] - k[1] * v[0]]
        )
        df = f - (v * c - k_x_v * s + k * (k_v * (1.0 - c)))
        dw = w - w[:, :, :1]
        out[start:stop, :3] = np.sum(df * dt, axis=2).T
        out[start:stop, 3] = np.sum(
            np.sqrt(df[0] * df[0] + df[1] * df[1] + df[2] * df[2]) * dt, axis=1
        )
        out[start:stop, 4] = np.sum(
            np.sqrt(dw[0] * dw[0] + dw[1] * dw[1] + dw[2] * dw[2]) * dt, axis=1
        )
        out[start:stop, 5] = np.sum(np.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) * dt, axis=1)
    return out


def _bulk_screen(
    t: np.ndarray, y: np.ndarray, imu: ImuData, cfg: DvlConfig, repeats_need_motion: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """(code, sure) of each ping n >= 1 (ping 0: USABLE, sure) with screened values y (M, K) under the assumption
    that ping n - 1 is the reference and ping n - 2 was its reference (last_rate from the two; 0 for ping 1 and
    with dvl.use_beams): PingScreen's rules on the samples in (t[n-1], t[n]]. sure: the assumption's code is
    PingScreen's (no capped window, every value finite and clear of the thresholds by _BAND)."""
    # PingScreen's beam rules (even on a 3-D velocity when the log has no beams)
    beams = cfg.use_beams
    m = len(t)
    code = np.zeros(m, dtype=np.int8)
    sure = np.ones(m, dtype=bool)
    if m < 2:
        return code, sure
    t_prev, t_now, y_prev, y_now = t[:-1], t[1:], y[:-1], y[1:]
    span = t_now - t_prev  # t - last_t
    with np.errstate(all="ignore"):
        prev_speed, rate = _reference_speed_and_rate(t, y, beams)
        windowed, has, sums = _window_evidence(imu, t_prev, t_now)
        s_df, s_adf, s_dw, s_af = (
            np.linalg.norm(sums[:, :3], axis=1),
            sums[:, 3],
            sums[:, 4],
            sums[:, 5],
        )
        dv_low = np.abs(s_df - rate * span) - s_dw * prev_speed
        motion = has & (dv_low > cfg.motion_dv_m_s)
        dv_imu = np.where(has, s_adf + s_dw * prev_speed, 0.0)
        scale = s_adf + s_af + rate * span + s_dw * prev_speed
        clear = ~has | (np.abs(dv_low - cfg.motion_dv_m_s) > _BAND * (scale + cfg.motion_dv_m_s))
        clear &= np.abs(prev_speed - cfg.moving_speed_m_s) > _BAND * cfg.moving_speed_m_s
        zero, repeated = _zero_and_repeated(y_prev, y_now, motion, prev_speed, cfg)
        if repeats_need_motion:
            repeated &= motion
        ok = windowed & (span >= 0) & np.isfinite(prev_speed) & np.isfinite(rate)
        ok &= np.isfinite(sums).all(axis=1)
        implausible = np.zeros(m - 1, dtype=bool)
        if not beams:
            implausible, jump_clear, jump_finite = _implausible_jumps(
                y_prev, y_now, span, dv_imu, prev_speed, scale, cfg
            )
            clear &= jump_clear
            ok &= jump_finite
    code[1:] = np.where(
        zero,
        ZERO_WHILE_MOVING,
        np.where(repeated, REPEATED, np.where(implausible, IMPLAUSIBLE_ACCEL, USABLE)),
    )
    sure[1:] = ok & clear
    return code, sure


def _reference_speed_and_rate(
    t: np.ndarray, y: np.ndarray, beams: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Of each ping n >= 1 under _bulk_screen's assumption: the reference's speed (m/s; with beams the largest
    beam velocity, NaN without a beam) and last_rate (m/s^2, the velocity change from ping n - 2 to n - 1; 0
    for ping 1 and with beams)."""
    m = len(t)
    y_prev = y[:-1]
    if beams:
        beam_prev = ~np.isnan(y_prev)
        prev_speed = np.max(np.where(beam_prev, np.abs(y_prev), -np.inf), axis=1)  # nanmax
        prev_speed[~beam_prev.any(axis=1)] = np.nan  # nanmax of no beam: NaN (left to PingScreen)
        rate = np.zeros(m - 1)
    else:
        prev_speed = np.linalg.norm(y_prev, axis=1)
        rate = np.zeros(m - 1)
        rate[1:] = np.linalg.norm(y[1:-1] - y[:-2], axis=1) / (t[1:-1] - t[:-2])
    return prev_speed, rate


def _window_evidence(
    imu: ImuData, t_prev: np.ndarray, t_now: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The IMU window (t_prev, t_now] of each ping: whether the bulk handles it (not capped at SCREEN_WINDOW_S,
    not far longer than the typical one), whether it also holds a sample, and its sums (_window_sums; 0 where
    none)."""
    lo = np.searchsorted(imu.t, t_prev, side="right")
    cnt = np.searchsorted(imu.t, t_now, side="right") - lo
    uncapped = t_now - SCREEN_WINDOW_S <= t_prev  # t_from = last_t
    # a window far longer than the typical one (after a dropout) is left to PingScreen: it would widen the
    # padding of its block
    short = cnt <= 8 * int(np.median(cnt)) + 64
    has = uncapped & short & (cnt >= 1)
    sums = np.zeros((len(t_prev), 6))
    if has.any():
        sums[has] = _window_sums(imu, t_prev[has], lo[has], cnt[has])
    return uncapped & short, has, sums


def _zero_and_repeated(
    y_prev: np.ndarray,
    y_now: np.ndarray,
    motion: np.ndarray,
    prev_speed: np.ndarray,
    cfg: DvlConfig,
) -> tuple[np.ndarray, np.ndarray]:
    """The pings that read zero while the vehicle moves (ZERO_WHILE_MOVING) and those that repeat the previous
    ping's values bit for bit (REPEATED)."""
    finite_now = np.isfinite(y_now)
    all_zero = finite_now.any(axis=1) & np.where(finite_now, y_now == 0.0, True).all(axis=1)
    zero = all_zero & (motion | (prev_speed > cfg.moving_speed_m_s))
    repeated = finite_now.any(axis=1) & ~all_zero
    repeated &= ((y_now == y_prev) | (np.isnan(y_now) & np.isnan(y_prev))).all(axis=1)
    return zero, repeated


def _implausible_jumps(
    y_prev: np.ndarray,
    y_now: np.ndarray,
    span: np.ndarray,
    dv_imu: np.ndarray,
    prev_speed: np.ndarray,
    scale: np.ndarray,
    cfg: DvlConfig,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 3-D velocity's jump from the reference against what the time and the IMU allow: the implausible ones
    (IMPLAUSIBLE_ACCEL), those clear of the limit by _BAND, those with every value finite."""
    jump = np.linalg.norm(y_now - y_prev, axis=1)
    allowed = cfg.max_accel_m_s2 * span + cfg.accel_imu_factor * dv_imu + cfg.jump_margin_m_s
    band = _BAND * (
        jump + allowed + np.linalg.norm(y_now, axis=1) + prev_speed + cfg.accel_imu_factor * scale
    )
    finite = np.isfinite(y_now).all(axis=1) & np.isfinite(jump) & np.isfinite(allowed)
    return jump > allowed, np.abs(jump - allowed) > band, finite


def frozen_runs(dvl: DvlData) -> list[tuple[float, float, int]]:
    """The stretches where the DVL's 3-D velocity repeats bit for bit (valid, finite, not zero): per run of
    consecutive pings equal to the one before them, (first repeat's t, last repeat's t, repeats), s. What the
    screen drops as frozen output (REPEATED), found on the log alone, for the report; none for a noise-free
    simulation, whose repeats are its model's."""
    if dvl.noise_free or len(dvl) < 2:
        return []
    v = np.asarray(dvl.d_v, dtype=float)
    ok = np.asarray(dvl.valid, dtype=bool) & np.isfinite(v).all(axis=1) & (v != 0.0).any(axis=1)
    rep = np.zeros(len(dvl), dtype=bool)
    rep[1:] = ok[1:] & ok[:-1] & (v[1:] == v[:-1]).all(axis=1)
    edges = np.flatnonzero(np.diff(np.r_[0, rep.astype(np.int8), 0]))
    t = np.asarray(dvl.t, dtype=float)
    return [
        (float(t[a]), float(t[b - 1]), int(b - a))
        for a, b in zip(edges[::2], edges[1::2], strict=True)
    ]
