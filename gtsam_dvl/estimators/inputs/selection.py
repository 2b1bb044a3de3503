"""Which measurements an estimator uses, and how IMU samples are split between epochs: the one copy of these
rules, shared by the batch smoother (estimators/graph/log_graph.py), the online estimator (estimators/online/) and the
EKF (estimators/ekf/), so that all three see the same epochs on the same log.

Pings. A DVL ping is usable when it lies after the first IMU sample (nothing before it can be propagated) and
not after the last one (counted apart: "dvl_before_imu", "dvl_after_imu", where sensors that did not start or
stop together leave pings), it is not a water-track ping ("dvl_water_track": velocity relative to the water),
it has a valid velocity (or, with `dvl.use_beams`, at least one valid beam with finite values), it is not
faster than `dvl.max_speed_m_s` (a bottom-track outlier) (classify_pings), and when it is not bogus
(estimators/inputs/ping_screen.py, with `dvl.screen`): an exact zero velocity while moving, a velocity repeated bit
for bit (a frozen output), or a velocity change the IMU cannot explain. Every rejection is counted by reason.

Epochs. One causal rule, KeyframeRule, decides which of the usable pings become epochs: keyframe thinning
(`solver.keyframe_interval_s`) keeps pings at least that far apart (the others are dropped); of those, the
keyframes `solver.keyframe_spacing_s` apart become states and the pings between them go on the keyframe before
(no ping is dropped). The whole-log estimators run it over the log (decide_epochs); the online
estimator feeds EpochScheduler (classification, screen and KeyframeRule) ping by ping and gets the same decisions.

IMU samples. Sample i is the average over (starts[i], t[i]] (ImuData's convention); an interval (a, b] between
two epochs takes each sample's overlap with it, so a sample straddling a ping is split exactly.
"""

from __future__ import annotations

from array import array
from collections import deque
from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.types import DvlData, ImuData
from gtsam_dvl.estimators.inputs.ping_screen import AFTER_IMU as AFTER_IMU
from gtsam_dvl.estimators.inputs.ping_screen import BEFORE_IMU as BEFORE_IMU
from gtsam_dvl.estimators.inputs.ping_screen import IMPLAUSIBLE_ACCEL as IMPLAUSIBLE_ACCEL
from gtsam_dvl.estimators.inputs.ping_screen import REASONS as REASONS
from gtsam_dvl.estimators.inputs.ping_screen import REPEATED as REPEATED
from gtsam_dvl.estimators.inputs.ping_screen import SCREEN_WINDOW_S as SCREEN_WINDOW_S
from gtsam_dvl.estimators.inputs.ping_screen import TOO_FAST as TOO_FAST
from gtsam_dvl.estimators.inputs.ping_screen import UNUSABLE as UNUSABLE
from gtsam_dvl.estimators.inputs.ping_screen import USABLE as USABLE
from gtsam_dvl.estimators.inputs.ping_screen import WATER_TRACK as WATER_TRACK
from gtsam_dvl.estimators.inputs.ping_screen import ZERO_WHILE_MOVING as ZERO_WHILE_MOVING
from gtsam_dvl.estimators.inputs.ping_screen import PingScreen as PingScreen
from gtsam_dvl.estimators.inputs.ping_screen import screen_pings as screen_pings
from gtsam_dvl.estimators.inputs.ping_screen import screened_value as screened_value


def ping_covariance(cfg: DvlConfig, d_cov: np.ndarray) -> np.ndarray:
    """The covariance a ping's 3-D velocity is given (m^2/s^2), for (..., 3, 3) message covariances: the
    configured sigma (dvl.noise_m_s > 0), else the message's own if finite and positive definite, else
    dvl.default_noise_m_s; every one times dvl.noise_multiplier^2 (the fitted variance component). The one rule
    for the factor graphs, the EKF and the health check."""
    cov = np.array(d_cov, dtype=float)
    m2 = cfg.noise_multiplier**2
    if cfg.noise_m_s > 0:
        return np.broadcast_to(np.eye(3) * (m2 * cfg.noise_m_s**2), cov.shape).copy()
    flat = cov.reshape(-1, 3, 3)
    ok = np.isfinite(flat).all(axis=(1, 2))
    if ok.any():
        sym = 0.5 * (flat[ok] + np.transpose(flat[ok], (0, 2, 1)))
        ok[ok] = np.linalg.eigvalsh(sym).min(axis=1) > 0
    flat[~ok] = np.eye(3) * cfg.default_noise_m_s**2
    return (flat if m2 == 1.0 else m2 * flat).reshape(cov.shape)


def water_covariance(config: EstimatorConfig, d_cov: np.ndarray) -> np.ndarray:
    """The covariance a water-track ping's 3-D velocity is given (m^2/s^2), for (..., 3, 3) message covariances:
    [current] water_track_sigma_m_s when > 0, else the message's own if finite and positive definite, else
    [current] water_track_default_sigma_m_s; times [dvl] noise_multiplier^2 (ping_covariance's rule with the
    water-track settings)."""
    cur = config.current
    dvl = config.dvl.model_copy(
        update={
            "noise_m_s": cur.water_track_sigma_m_s,
            "default_noise_m_s": cur.water_track_default_sigma_m_s,
        }
    )
    # with the current per depth layer, plus the current's spread within a layer (estimators/models/current.py,
    # "Layers")
    return ping_covariance(dvl, d_cov) + within_layer_variance(config) * np.eye(3)


def within_layer_variance(config: EstimatorConfig) -> float:
    """The variance per axis (m^2/s^2) of the current about its layer's value at a depth drawn evenly from the
    layer, for the random walk in depth of density q_z over a layer of thickness h: q_z^2 h / 6 (the mean over
    the layer of Var(B(x) - mean of B), a Brownian motion B); 0 without layers."""
    cur = config.current
    return cur.depth_rw_m_s_per_sqrt_m**2 * cur.layer_thickness_m / 6.0


def classify_pings(
    t: np.ndarray,
    d_v: np.ndarray,
    valid: np.ndarray,
    beam_valid: np.ndarray | None,
    beam_finite: np.ndarray | None,
    cfg: DvlConfig,
    t_imu_first: float,
    t_imu_last: float = np.inf,
    water_track: np.ndarray | None = None,
    water_usable: bool = False,
) -> np.ndarray:
    """Reason code per ping (USABLE, BEFORE_IMU, AFTER_IMU, WATER_TRACK, UNUSABLE, TOO_FAST, in this order of
    precedence), vectorised over M pings.

    t (M,) s; d_v (M, 3) m/s in dvl_link; valid (M,) the 3-D velocity's flag; beam_valid (M, B) and
    beam_finite (M,) (all valid beams finite) when the log has beams; water_track (M,) the water-track pings
    (None: none), usable as such when water_usable (the estimators then carry the water current,
    estimators/models/current.py) if their velocity is finite, whatever the message's bottom-track validity says.
    t_imu_last: inf for an online estimator, which waits for the IMU samples that reach a ping.
    """
    t = np.asarray(t, dtype=float)
    if cfg.use_beams and beam_valid is not None:
        usable = np.asarray(beam_valid).any(axis=1)
        if beam_finite is not None:
            usable &= np.asarray(beam_finite, dtype=bool)
        too_fast = np.zeros(len(t), dtype=bool)  # a beam sees one component: no 3-D speed check
    else:
        finite = np.isfinite(d_v).all(axis=1)
        usable = np.asarray(valid, dtype=bool) & finite
        speed = np.linalg.norm(np.where(finite[:, None], d_v, 0.0), axis=1)
        too_fast = usable & (speed > cfg.max_speed_m_s)
    code = np.full(len(t), UNUSABLE, dtype=np.int8)
    code[usable] = USABLE
    code[too_fast] = TOO_FAST
    if water_track is not None:
        water = np.asarray(water_track, dtype=bool)
        if water_usable:
            finite = np.isfinite(d_v).all(axis=1)
            code[water] = np.where(finite[water], USABLE, UNUSABLE)
            code[
                water
                & finite
                & (np.linalg.norm(np.where(finite[:, None], d_v, 0.0), axis=1) > cfg.max_speed_m_s)
            ] = TOO_FAST
        else:
            code[water] = WATER_TRACK
    code[t <= t_imu_first] = BEFORE_IMU
    code[t > t_imu_last] = AFTER_IMU
    return code


def count_reasons(code: np.ndarray, counters: dict[str, int], keep_zero: bool = True) -> None:
    """Add the rejections of classify_pings to counters (by reason name); keep_zero: also create the
    counters of reasons that did not occur."""
    for reason, name in REASONS.items():
        n = int((code == reason).sum())
        if n or keep_zero:
            counters[name] = counters.get(name, 0) + n


def beam_arrays(dvl: DvlData) -> tuple[np.ndarray | None, np.ndarray | None]:
    """(beam_valid (M, B), beam_finite (M,)) of a log's DVL data, or (None, None) without beams."""
    if dvl.beams is None:
        return None, None
    b = dvl.beams
    ok = b.valid
    finite = np.where(ok, np.isfinite(b.v), True).all(axis=1) & np.where(
        ok[..., None], np.isfinite(b.d_u), True
    ).all(axis=(1, 2))
    return np.asarray(ok), np.asarray(finite)


def usable_pings(
    dvl: DvlData,
    imu: ImuData | np.ndarray,
    cfg: DvlConfig,
    counters: dict[str, int],
    water_usable: bool = False,
) -> np.ndarray:
    """Indices of the usable pings of a whole log (module doc), counting the others. imu: the log's IMU
    samples; its stamps alone (an array) skip the screen's IMU evidence (no motion seen, no velocity change
    allowed beyond dvl.max_accel_m_s2). water_usable: water-track pings are used (classify_pings); the screen then
    compares each mode's pings among themselves (a water-track ping differs from bottom track by the current)."""
    imu_t = imu.t if isinstance(imu, ImuData) else np.asarray(imu, dtype=float)
    beam_valid, beam_finite = beam_arrays(dvl)
    t_first = float(imu_t[0]) if len(imu_t) else np.inf
    t_last = float(imu_t[-1]) if len(imu_t) else -np.inf
    code = classify_pings(
        dvl.t,
        dvl.d_v,
        dvl.valid,
        beam_valid,
        beam_finite,
        cfg,
        t_first,
        t_last,
        dvl.water_track,
        water_usable,
    )
    if cfg.screen:
        samples = (
            imu
            if isinstance(imu, ImuData)
            else ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
        )
        water = (
            np.zeros(len(code), dtype=bool)
            if dvl.water_track is None
            else np.asarray(dvl.water_track, bool)
        )
        for mode in (~water, water):
            idx = np.flatnonzero((code == USABLE) & mode)
            code[idx] = screen_pings(dvl, idx, samples, cfg)
    count_reasons(code, counters)
    return np.flatnonzero(code == USABLE)


# share of solver.keyframe_spacing_s: stamp jitter must not halve the keyframes
KEYFRAME_TOLERANCE = 0.02

# KeyframeRule's decision for a screened ping
THINNED = 0  # dropped: within solver.keyframe_interval_s of the previous kept ping (counter "dvl_not_keyframe")
BETWEEN = 1  # kept, between keyframes: a DVL factor on the state before it
KEYFRAME = 2  # kept, a keyframe: a state


class KeyframeRule:
    """The causal rule that turns the usable, screened pings (in time order) into epochs: the one definition
    the batch smoother (decide_epochs over the whole log) and the online estimator
    (EpochScheduler, ping by ping) apply; the EKF takes every usable ping.

    decide(t): a ping at t is THINNED when it lies within interval_s (solver.keyframe_interval_s) of the previous
    kept ping; a kept ping is a KEYFRAME when it is the first or lies at least spacing_s (solver.
    keyframe_spacing_s) less KEYFRAME_TOLERANCE of it after the previous keyframe (so that a DVL whose period
    equals the spacing makes a keyframe of every ping; spacing_s <= 0: every kept ping), else BETWEEN. The
    decision depends on the pings before t only. The estimators also make the last kept ping a keyframe when
    the data ends (the batch smoother's LogGraph, the online estimator's finish())."""

    def __init__(self, interval_s: float, spacing_s: float) -> None:
        self.interval_s, self.spacing_s = float(interval_s), float(spacing_s)
        self._key_interval_s = self.spacing_s * (1.0 - KEYFRAME_TOLERANCE)
        self.last_kept_t = -np.inf  # the previous kept ping's time, s
        self.last_key_t = -np.inf  # the previous keyframe's time, s

    def decide(self, t: float) -> int:
        """THINNED, BETWEEN or KEYFRAME for the next ping, at t (s, after every earlier ping decided)."""
        if t - self.last_kept_t < self.interval_s:
            return THINNED
        self.last_kept_t = t
        # never with spacing_s <= 0: the pings are in time order
        if t - self.last_key_t < self._key_interval_s:
            return BETWEEN
        self.last_key_t = t
        return KEYFRAME

    def decide_all(self, t: np.ndarray) -> np.ndarray:
        """decide() on each of the pings t (sorted, s) in turn: (M,) int8. A loop over the pings: each decision
        depends on the kept pings before it."""
        decide = self.decide
        return np.fromiter(
            (decide(x) for x in np.asarray(t, dtype=float).tolist()), dtype=np.int8, count=len(t)
        )


def decide_epochs(
    dvl: DvlData,
    imu: ImuData | np.ndarray,
    cfg: DvlConfig,
    keyframe_interval_s: float,
    keyframe_spacing_s: float,
    counters: dict[str, int],
    water_usable: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The whole log's decisions of KeyframeRule(keyframe_interval_s, keyframe_spacing_s): (usable, epochs, key):
    the usable pings' indices, those of the pings kept after thinning (counter "dvl_not_keyframe"), and which of
    those are keyframes. imu, water_usable: as in usable_pings."""
    usable = usable_pings(dvl, imu, cfg, counters, water_usable)
    decision = KeyframeRule(keyframe_interval_s, keyframe_spacing_s).decide_all(dvl.t[usable])
    kept = decision != THINNED
    if keyframe_interval_s > 0:
        counters["dvl_not_keyframe"] = counters.get("dvl_not_keyframe", 0) + int((~kept).sum())
    return usable, usable[kept], decision[kept] == KEYFRAME


def select_epochs(
    dvl: DvlData,
    imu: ImuData | np.ndarray,
    cfg: DvlConfig,
    keyframe_interval_s: float,
    counters: dict[str, int],
) -> np.ndarray:
    """Indices of the pings that become epochs: usable, then thinned to keyframe_interval_s (decide_epochs)."""
    return decide_epochs(dvl, imu, cfg, keyframe_interval_s, 0.0, counters)[1]


def keyframe_mask(t: np.ndarray, spacing_s: float) -> np.ndarray:
    """Which of the epoch pings t (sorted, s; select_epochs' pings) are keyframes under KeyframeRule with
    spacing_s: the batch smoother puts states at the keyframes and the other pings on the keyframe before them
    (estimators/graph/keyframes.py)."""
    if spacing_s <= 0 or len(t) == 0:
        return np.ones(len(t), dtype=bool)
    return KeyframeRule(0.0, spacing_s).decide_all(t) == KEYFRAME


@dataclass
class Ping:
    """One DVL ping as an estimator receives it: time t (s), velocity d_v (m/s, dvl_link) with covariance d_cov
    (3x3, m^2/s^2, NaN: the configured default), the velocity's valid flag and optionally the beams (d_u (B, 3),
    v (B,), valid (B,)). key: the scheduler's decision, a keyframe (a state) or a ping between keyframes."""

    t: float
    d_v: np.ndarray
    d_cov: np.ndarray
    valid: bool
    beams: tuple[np.ndarray, np.ndarray, np.ndarray] | None
    key: bool = True
    index: int = -1  # its place among the pings pushed (OnlineEstimator.push_dvl's calls, from 0)
    # measured relative to the water (used with the current, else counted)
    water_track: bool = False


class EpochScheduler:
    """The epoch rules fed one message at a time, for an estimator that sees the pings as they come (the online
    estimator): push_ping() classifies a ping (classify_pings, with the first IMU stamp; no last one: the
    scheduler waits for the IMU), push_imu() feeds the screen, and ready() returns the pings whose IMU evidence
    has come, screened (PingScreen) and decided by KeyframeRule, in time order, with Ping.key set. The decisions
    are the whole-log ones (usable_pings, select_epochs, keyframe_mask) ping for ping, whatever the order in
    which IMU samples and pings arrive (tests/estimators/test_scheduler.py). Rejections are counted in counters
    by reason, as the whole-log functions count them. noise_free: the pings come from a noise-free simulation
    (DvlData.noise_free: repeats are frozen output only while the IMU shows motion)."""

    def __init__(
        self,
        cfg: DvlConfig,
        keyframe_interval_s: float,
        keyframe_spacing_s: float,
        counters: dict[str, int],
        keep_usable: bool = True,
        noise_free: bool = False,
        water_usable: bool = False,
    ) -> None:
        self.cfg, self.counters = cfg, counters
        self.rule = KeyframeRule(keyframe_interval_s, keyframe_spacing_s)
        self.screen = PingScreen(cfg, repeats_need_motion=noise_free)
        # water-track pings (used when water_usable) are screened among themselves (usable_pings)
        self.water_usable = water_usable
        self.water_screen = PingScreen(cfg, repeats_need_motion=noise_free)
        self._unscreened: deque[Ping] = deque()  # usable pings waiting for the IMU to reach them
        # the indices (Ping.index) of the pings the screen passed, with keep_usable (8 bytes a ping)
        self.usable: array[int] = array("q")
        self._keep_usable = keep_usable

    def push_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> None:
        """IMU samples in time order (base_link: gyro w, rad/s, specific force f, m/s^2)."""
        self.screen.push_imu(t, w, f)
        if self.water_usable:
            self.water_screen.push_imu(t, w, f)

    def push_ping(self, p: Ping, t_imu_first: float) -> bool:
        """Classify ping p (after every earlier ping); a usable one waits for the screen. t_imu_first: the first
        IMU sample's stamp (inf before any). Returns whether p is usable."""
        beam_valid: np.ndarray | None = None
        beam_finite: np.ndarray | None = None
        if p.beams is not None:
            d_u, v, ok = p.beams
            beam_valid = ok[None, :]
            beam_finite = np.array([bool(np.isfinite(v[ok]).all() and np.isfinite(d_u[ok]).all())])
        code = classify_pings(
            np.array([p.t]),
            p.d_v[None, :],
            np.array([p.valid]),
            beam_valid,
            beam_finite,
            self.cfg,
            t_imu_first,
            water_track=np.array([p.water_track]),
            water_usable=self.water_usable,
        )
        if code[0] != USABLE:
            count_reasons(code, self.counters, keep_zero=False)
            return False
        self._unscreened.append(p)
        return True

    def ready(self) -> list[Ping]:
        """The pings the IMU now reaches, screened and decided, in time order: the kept ones (Ping.key set); the
        others are counted."""
        out: list[Ping] = []
        while self._unscreened and self.screen.reaches(self._unscreened[0].t):
            p = self._unscreened.popleft()
            screen = self.water_screen if p.water_track else self.screen
            code = screen.check_buffered(p.t, screened_value(p.d_v, p.beams, self.cfg))
            if code != USABLE:
                count_reasons(np.array([code]), self.counters, keep_zero=False)
                continue
            if self._keep_usable:
                self.usable.append(p.index)
            decision = self.rule.decide(p.t)
            if decision == THINNED:
                self.counters["dvl_not_keyframe"] = self.counters.get("dvl_not_keyframe", 0) + 1
                continue
            p.key = decision == KEYFRAME
            out.append(p)
        return out

    def drop_waiting(self) -> int:
        """Forget the pings still waiting for the IMU (at the end of the data); returns how many."""
        n = len(self._unscreened)
        self._unscreened.clear()
        return n


def sample_starts(t: np.ndarray) -> np.ndarray:
    """Start of each IMU sample's interval: the previous stamp (the first sample gets the median spacing)."""
    if len(t) == 0:
        return np.zeros(0)
    first_dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
    return np.concatenate([[t[0] - first_dt], t[:-1]])


def imu_pieces(
    t: np.ndarray, starts: np.ndarray, a: float, b: float
) -> tuple[np.ndarray, np.ndarray]:
    """Samples covering (a, b] and the part of each inside it (s): interval averages are split exactly."""
    lo = int(np.searchsorted(t, a, side="right"))  # first sample ending after a
    hi = min(int(np.searchsorted(t, b, side="left")), len(t) - 1)  # last sample that reaches b
    idx = np.arange(lo, hi + 1)
    dt = np.minimum(t[idx], b) - np.maximum(starts[idx], a)
    keep = dt > 0.0
    return idx[keep], dt[keep]


def covering_sample(t: np.ndarray, t_ping: float | np.ndarray) -> np.ndarray:
    """Index of the IMU sample whose interval contains each ping time (the last one past the end)."""
    return np.minimum(np.searchsorted(t, t_ping, side="left"), len(t) - 1)
