"""Simulated GNSS fixes at the surface (the scenario's [gnss] table, GnssSpec), and the map frame a log without
a recorded origin gets from them.

A fix is the antenna's geodetic position, the antenna at b_p_a in base_link: in ECEF
e_p_a = e_p(lat, lon, h) + e_R_l (l_R_b b_p_a), plus white noise drawn in the ENU axes at the vehicle
(horizontal_sigma_m on east and north, vertical_sigma_m up), converted back to latitude, longitude and
ellipsoidal height. Fixes come at k / rate_hz while base_link's depth below the water surface (ellipsoidal
height 0, as the depth sensor's) is under max_depth_m, within [start_s, end_s]; none while submerged. Status 0,
covariance diag(h^2, h^2, v^2) in ENU. The noise is drawn at every candidate stamp, surfaced or not, from
SeedSequence(seed)'s sixth child: the other five streams, and so every other sensor's bytes, are those of a
scenario without [gnss], and the same seed gives the same fixes.

origin_in_log = false (reframe_truth): the log records no origin, so a reader takes the first fix as the map
origin (io/reader.py); the truth is then expressed in the ENU frame at that fix, the frame such a log's
estimates are in. Both map frames are Earth-fixed: positions move by the offset (metres), attitudes and
velocities turn by n'_R_n (micro-radians), body rates relative to the map are unchanged.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from gtsam_dvl.core.earth import LocalFrame, e_R_l, ecef_to_geodetic, geodetic_to_ecef
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, quat_xyzw_to_matrix
from gtsam_dvl.core.types import GnssData, TruthData
from gtsam_dvl.sim.local_level import imu_truth

if TYPE_CHECKING:
    from gtsam_dvl.sim.motion import MotionProfile
    from gtsam_dvl.sim.position import PositionTrack
    from gtsam_dvl.sim.scenario import GnssSpec

GNSS_STREAM = 5  # index of the GNSS child of SeedSequence(seed)


def simulate_gnss(
    spec: GnssSpec,
    motion: MotionProfile,
    track: PositionTrack,
    imu_hz: float,
    n: int,
    seed: int,
    white_noise: bool,
) -> GnssData:
    """The fixes of GnssSpec over IMU samples 0..n-1 (module doc)."""
    k = np.arange(0, n, int(round(imu_hz / spec.rate_hz)))
    return gnss_fixes(spec, motion, track, k, gnss_rng(seed) if white_noise else None)


def gnss_rng(seed: int) -> np.random.Generator:
    """The GNSS noise generator: SeedSequence(seed)'s sixth child, one (3,) draw per candidate stamp."""
    return np.random.Generator(
        np.random.PCG64(np.random.SeedSequence(seed).spawn(GNSS_STREAM + 1)[GNSS_STREAM])
    )


def gnss_fixes(
    spec: GnssSpec,
    motion: MotionProfile,
    track: PositionTrack,
    k: np.ndarray,
    rng: np.random.Generator | None,
) -> GnssData:
    """The fixes among the candidate stamps k / rate (IMU sample indices), noise from rng (None: none)."""
    t = k / track.rate
    lat, lon, h = track.at_samples(k)
    _, _, l_R_b, _ = imu_truth(motion.evaluate(t), lat, h)
    lever = np.asarray(spec.antenna_lever_arm_m, dtype=float)
    R_el = e_R_l(lat, lon)
    e_p = geodetic_to_ecef(lat, lon, h) + np.einsum("kij,kj->ki", R_el, l_R_b @ lever)
    sig = np.array([spec.horizontal_sigma_m, spec.horizontal_sigma_m, spec.vertical_sigma_m])
    if rng is not None:
        noise = rng.standard_normal((len(t), 3)) * sig
        e_p = e_p + np.einsum("kij,kj->ki", R_el, noise)
    keep = -h < spec.max_depth_m
    if spec.start_s is not None:
        keep &= t >= spec.start_s - 1e-9
    if spec.end_s is not None:
        keep &= t <= spec.end_s + 1e-9
    lat_f, lon_f, h_f = ecef_to_geodetic(e_p[keep])
    m = int(keep.sum())
    return GnssData(
        t=t[keep],
        lat_deg=np.degrees(lat_f),
        lon_deg=np.degrees(lon_f),
        height_m=np.asarray(h_f),
        cov_enu_m2=np.broadcast_to(np.diag(sig**2), (m, 3, 3)).copy(),
        status=np.zeros(m, dtype=int),
        b_p_antenna=lever.copy(),
    )


def first_fix_frame(gnss: GnssData) -> LocalFrame | None:
    """The map frame a reader gives a log without an origin: ENU at the first fix (None without fixes)."""
    if not len(gnss):
        return None
    return LocalFrame(float(gnss.lat_deg[0]), float(gnss.lon_deg[0]), float(gnss.height_m[0]))


def reframe_truth(truth: TruthData, frame: LocalFrame, new: LocalFrame) -> TruthData:
    """The truth expressed in another Earth-fixed ENU frame (module doc)."""
    m_R_n = new.e_R_n.T @ frame.e_R_n
    lat, lon, h = frame.map_to_geodetic(truth.n_p)
    n_R_b = quat_xyzw_to_matrix(truth.n_q_b)
    return TruthData(
        t=truth.t.copy(),
        n_p=new.geodetic_to_map(lat, lon, h),
        n_q_b=matrix_to_quat_xyzw(m_R_n @ n_R_b),
        n_v=truth.n_v @ m_R_n.T,
        b_omega=truth.b_omega.copy(),
        n_c=None if truth.n_c is None else truth.n_c @ m_R_n.T,
    )
