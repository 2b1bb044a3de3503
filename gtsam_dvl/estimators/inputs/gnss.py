"""GNSS fixes for the factor graph: which fixes aid, which are held out, and their position in map.

A fix (LogData.gnss, sensor_msgs/msg/NavSatFix) is the antenna's geodetic position at the surface. Here it
becomes the antenna's position in map, z = LocalFrame.geodetic_to_map(lat, lon, h), with its covariance
rotated from the ENU axes at the fix into map axes ([gnss] noise_m if > 0, else the message's, else
default_noise_m; times [gnss] noise_multiplier squared, the variance component the batch smoother fits: [noise]
fit_gnss). Each fix gets a role:

- "rejected_status": not a fix (status < 0, or a non-finite latitude, longitude or height);
- "rejected_depth": the depth sensor (if the log has one) says deeper than [gnss] max_depth_m at its time;
- "used": a position factor on the antenna of the nearest state (factors/gnss.py), the time between them
  bridged by the state's velocity;
- "held_out": a good fix that does not aid, kept for the evaluation (analysis/surfacing.py: the surfacing
  error, the real-data accuracy figure);
- "too_far": no state within [gnss] max_time_to_state_s, so neither used nor evaluated.

Good fixes less than [gnss] surface_gap_s apart form one surface interval. [gnss] use says which good fixes
are used: "origin" the origin fix only (the first good fix, when the map origin came from it, i.e. the log
records none: io/reader.py), "start" the first surface interval when it comes before the first dive (no depth
sample deeper than max_depth_m before it), "all" every good fix.

The first state: when the map origin is the first fix, the log does not say where the vehicle started; the
first state's position prior is then loose (LOOSE_POSITION_SIGMA_M: the fixes place it) and its initial guess
is the first fix minus the antenna's offset. When no fix aids, the prior is the origin fix's covariance.
When the log records its own origin (the simulator's), the first state stays pinned at it ([priors]).
The batch smoother; the online estimator decides the same roles as the fixes come (estimators/online/gnss_queue.py);
the EKF takes the origin only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.types import GnssData, LogData
from gtsam_dvl.estimators.inputs.depth import depth_samples, nearest_states

LOOSE_POSITION_SIGMA_M = 100.0  # first state's position prior when the fixes place it (m, per axis)
# the log's origin is the first fix when they agree this closely (and 1e-6 m in height)
ORIGIN_TOL_DEG = 1e-9
ROLES = ("used", "held_out", "rejected_status", "rejected_depth", "too_far")


@dataclass(frozen=True)
class GnssFixes:
    """Every message of a log's GNSS data with its role (module doc), in map."""

    t: np.ndarray  # (K,) s
    n_p: np.ndarray  # (K, 3) antenna position in map, m (NaN for messages that are not fixes)
    cov: np.ndarray  # (K, 3, 3) m^2, map axes
    role: np.ndarray  # (K,) str, one of ROLES
    interval: np.ndarray  # (K,) surface interval of a good fix (0, 1, ...), -1 for the others
    state: np.ndarray  # (K,) nearest state, -1 if none within max_time_to_state_s
    dt: np.ndarray  # (K,) s, fix time minus its state's time
    b_p_antenna: np.ndarray  # (3,) the antenna in base_link, m
    origin_from_gnss: bool  # the map origin is the first fix (the log records none)
    origin_index: int  # index of the first good fix, -1 without one

    def mask(self, role: str) -> np.ndarray:
        return np.asarray(self.role == role)

    @property
    def n_intervals(self) -> int:
        return int(self.interval.max()) + 1 if len(self.interval) else 0

    def counters(self) -> dict[str, int]:
        """gnss_used, gnss_held_out, gnss_rejected (status, depth gate, too far) and each reason, and the
        number of surface intervals."""
        n = {r: int(self.mask(r).sum()) for r in ROLES}
        return {
            "gnss_used": n["used"],
            "gnss_held_out": n["held_out"],
            "gnss_rejected": n["rejected_status"] + n["rejected_depth"] + n["too_far"],
            "gnss_rejected_status": n["rejected_status"],
            "gnss_rejected_depth": n["rejected_depth"],
            "gnss_too_far": n["too_far"],
            "gnss_surface_intervals": self.n_intervals,
        }


def valid_fixes(gnss: GnssData) -> np.ndarray:
    """Mask of the messages that are fixes: status >= 0 and finite coordinates (io/gnss.py good_fixes: the same
    rule, which this layer cannot import)."""
    return np.asarray(
        (gnss.status >= 0)
        & np.isfinite(gnss.lat_deg)
        & np.isfinite(gnss.lon_deg)
        & np.isfinite(gnss.height_m)
    )


def origin_is_first_fix(log: LogData, config: EstimatorConfig) -> bool:
    """True when the map origin is the log's first good fix: the configuration gives none and the log's origin
    is that fix (the reader sets it so when the log records no origin)."""
    gnss, o = log.gnss, log.origin
    if config.alignment.origin_lat_deg is not None or gnss is None or o is None:
        return False
    good = np.flatnonzero(valid_fixes(gnss))
    if not len(good):
        return False
    i = int(good[0])
    return bool(
        abs(gnss.lat_deg[i] - o.lat_deg) < ORIGIN_TOL_DEG
        and abs(gnss.lon_deg[i] - o.lon_deg) < ORIGIN_TOL_DEG
        and abs(gnss.height_m[i] - o.height_m) < 1e-6
    )


def origin_fix_time(log: LogData, config: EstimatorConfig) -> float | None:
    """The time (s) the map origin refers to when it is the log's first good fix (origin_is_first_fix), else
    None (the origin is the position at the first IMU stamp): for alignment.first_state."""
    if not origin_is_first_fix(log, config):
        return None
    assert log.gnss is not None
    return float(log.gnss.t[int(np.flatnonzero(valid_fixes(log.gnss))[0])])


def antenna_lever(gnss: GnssData, config: EstimatorConfig) -> np.ndarray:
    """The antenna in base_link (m): [gnss] lever_arm_m, else /tf_static's, else zero."""
    if config.gnss.lever_arm_m is not None:
        return np.asarray(config.gnss.lever_arm_m, dtype=float)
    if gnss.b_p_antenna is not None:
        return np.asarray(gnss.b_p_antenna, dtype=float)
    return np.zeros(3)


def fix_covariances(gnss: GnssData, config: EstimatorConfig, frame: LocalFrame) -> np.ndarray:
    """(K, 3, 3) covariances of the fixes in map axes (m^2): noise_m, else the message's ENU covariance at the
    fix if it is finite and positive definite, else default_noise_m; rotated by n_R_l at the fix; times
    [gnss] noise_multiplier squared."""
    cfg = config.gnss
    k = len(gnss)
    if cfg.noise_m > 0:
        return np.broadcast_to(
            np.eye(3) * (cfg.noise_m * cfg.noise_multiplier) ** 2, (k, 3, 3)
        ).copy()
    cov = np.asarray(gnss.cov_enu_m2, dtype=float).copy()
    ok = np.isfinite(cov).all(axis=(1, 2))
    for i in np.flatnonzero(ok).tolist():
        sym = 0.5 * (cov[i] + cov[i].T)
        ok[i] = bool(np.all(np.linalg.eigvalsh(sym) > 0))
        cov[i] = sym
    cov[~ok] = np.eye(3) * cfg.default_noise_m**2
    lat = np.radians(np.where(np.isfinite(gnss.lat_deg), gnss.lat_deg, frame.lat_deg))
    lon = np.radians(np.where(np.isfinite(gnss.lon_deg), gnss.lon_deg, frame.lon_deg))
    n_R_l = frame.n_R_l(lat, lon).reshape(k, 3, 3)
    return np.asarray(n_R_l @ cov @ np.transpose(n_R_l, (0, 2, 1))) * cfg.noise_multiplier**2


def fixes_in_map(gnss: GnssData, frame: LocalFrame) -> np.ndarray:
    """(K, 3) antenna positions in map, m (NaN where the message is not a fix)."""
    good = valid_fixes(gnss)
    out = np.full((len(gnss), 3), np.nan)
    if good.any():
        out[good] = frame.geodetic_to_map(
            np.radians(gnss.lat_deg[good]), np.radians(gnss.lon_deg[good]), gnss.height_m[good]
        ).reshape(-1, 3)
    return out


def surface_intervals(t: np.ndarray, good: np.ndarray, gap_s: float) -> np.ndarray:
    """(K,) interval index of each good fix (fixes less than gap_s apart share one), -1 for the others."""
    out = np.full(len(t), -1)
    idx = np.flatnonzero(good)
    if len(idx):
        out[idx] = np.concatenate([[0], np.cumsum(np.diff(t[idx]) > gap_s)])
    return out


def plan_fixes(
    log: LogData, config: EstimatorConfig, frame: LocalFrame, t_states: np.ndarray
) -> GnssFixes | None:
    """The role of every GNSS message of the log (module doc); None without GNSS data."""
    gnss = log.gnss
    if gnss is None or not len(gnss):
        return None
    cfg = config.gnss
    t = np.asarray(gnss.t, dtype=float)
    valid = valid_fixes(gnss)
    role = np.where(valid, "held_out", "rejected_status").astype("<U16")
    first_dive_s = np.inf  # time of the first depth sample deeper than the gate
    if log.depth is not None and len(log.depth):
        samples = depth_samples(log.depth, config.depth, frame)
        if len(samples.t):
            depth_m = -(samples.z_meas + frame.height_m)  # the sensor's depth below the surface
            deep = depth_m > cfg.max_depth_m
            at_fix = np.interp(t, samples.t, depth_m)
            inside = (t >= samples.t[0]) & (t <= samples.t[-1])
            role[valid & inside & (at_fix > cfg.max_depth_m)] = "rejected_depth"
            if deep.any():
                first_dive_s = float(samples.t[np.argmax(deep)])
    good = role == "held_out"
    interval = surface_intervals(t, good, cfg.surface_gap_s)
    origin_index = int(np.flatnonzero(valid)[0]) if valid.any() else -1
    from_gnss = origin_is_first_fix(log, config)
    aid = np.zeros(len(t), dtype=bool)
    if cfg.use == "all":
        aid = good.copy()
    elif cfg.use == "start":
        first = good & (interval == 0)
        if first.any() and t[first][0] < first_dive_s:
            aid = first
    elif from_gnss and origin_index >= 0 and good[origin_index]:
        aid[origin_index] = True
    state, dt = nearest_states(t_states, t, cfg.max_time_to_state_s)
    role[aid] = "used"
    role[(good | aid) & (state < 0)] = "too_far"
    return GnssFixes(
        t,
        fixes_in_map(gnss, frame),
        fix_covariances(gnss, config, frame),
        role,
        interval,
        np.asarray(state),
        np.asarray(dt),
        antenna_lever(gnss, config),
        from_gnss,
        origin_index,
    )


def first_position(
    fixes: GnssFixes | None, n_R_b: np.ndarray, n_p_origin: np.ndarray | None = None
) -> np.ndarray:
    """Initial guess of the first state's position (m, map): n_p_origin (the map origin carried to the first
    state: alignment.first_state; None: the origin), or, when the origin is the first fix, that fix minus the
    antenna's offset n_R_b b_p_antenna."""
    if fixes is None or not fixes.origin_from_gnss or fixes.origin_index < 0:
        return np.zeros(3) if n_p_origin is None else np.asarray(n_p_origin, dtype=float)
    return np.asarray(fixes.n_p[fixes.origin_index] - n_R_b @ fixes.b_p_antenna)


def first_position_cov(fixes: GnssFixes | None) -> np.ndarray | None:
    """Covariance (map axes, m^2) of the first state's position prior: None (the configured pin at the origin)
    unless the origin is the first fix; then loose when fixes aid, else the origin fix's covariance."""
    if fixes is None or not fixes.origin_from_gnss or fixes.origin_index < 0:
        return None
    if fixes.mask("used").any():
        return np.eye(3) * LOOSE_POSITION_SIGMA_M**2
    return np.asarray(fixes.cov[fixes.origin_index])
