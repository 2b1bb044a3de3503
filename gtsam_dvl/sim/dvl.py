"""DVL measurements (docs/conventions.md): y = k d_R_b (n_R_b^T n_v + b_omega x b_l) + noise, in dvl_link.

b_R_d = R_c b_R_d0 is the true mounting (the nominal one corrected by the misalignment R_c in body axes),
b_omega the body rate relative to the Earth, b_l the lever arm. Janus geometry: four beams at
beam_angle from the face axis a (in dvl_link, towards the bottom) at azimuths 45/135/225/315 deg,
d_u_j = cos(beam) a + sin(beam) (cos(az_j) e1 + sin(az_j) e2), e1 the dvl x axis made perpendicular to a
and e2 = e1 x a. Beam j measures y_j = d_u_j . y; its slant range reaches a flat seafloor at a constant
height. The output is instantaneous at the stamp.

Water track (a scenario with [seafloor], sim/current.py): while the DVL's altitude (seafloor depth minus its
depth) exceeds its bottom-track range, the ping measures the vehicle's velocity relative to the water, seen
through the same scale, misalignment and lever arm: y = k d_R_b (n_R_b^T (n_v - n_c) + b_omega x b_l), n_c the
current at base_link's depth. Such a ping has its own white noise (water_track_noise_m_s, from its own random
stream) instead of noise_m_s, the correlated error, dropouts and outliers as a bottom-track ping, no beam ranges
and no altitude; DvlData marks it water_track and not valid (valid means usable as
velocity over ground), its velocity and beam velocities kept.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from gtsam_dvl.core.rotations import matrix_to_rpy_deg, rpy_deg_to_matrix, so3_exp
from gtsam_dvl.core.types import BeamData, DvlData
from gtsam_dvl.sim.local_level import imu_truth
from gtsam_dvl.sim.motion import MotionProfile
from gtsam_dvl.sim.position import PositionTrack

if TYPE_CHECKING:
    from gtsam_dvl.core.earth import LocalFrame
    from gtsam_dvl.sim.current import CurrentSpec, SeafloorSpec
    from gtsam_dvl.sim.scenario import DvlSpec, Scenario

AZIMUTHS_DEG = (45.0, 135.0, 225.0, 315.0)


def janus_beams(beam_angle_deg: float, face_axis: np.ndarray) -> np.ndarray:
    """Unit beam vectors (4, 3) in dvl_link."""
    a = np.asarray(face_axis, dtype=float)
    a = a / np.linalg.norm(a)
    x = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = x - a * (a @ x)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e1, a)
    az = np.radians(AZIMUTHS_DEG)[:, None]
    b = np.radians(beam_angle_deg)
    return np.cos(b) * a + np.sin(b) * (np.cos(az) * e1 + np.sin(az) * e2)


@dataclass(frozen=True)
class Water:
    """What a DVL with water track needs of the scenario: the map frame (the current is given in it), the current
    (None: still water) and the seafloor."""

    frame: LocalFrame
    current: CurrentSpec | None
    seafloor: SeafloorSpec


@dataclass
class WaterPings:
    """dvl_true's water-track part: water_track (M,) the pings out of bottom-track range and altitude (M,) m,
    the DVL's altitude above the seafloor (NaN out of range)."""

    water_track: np.ndarray
    altitude: np.ndarray


def dvl_true(
    spec: DvlSpec,
    b_R_d0: np.ndarray,
    b_l: np.ndarray,
    motion: MotionProfile,
    track: PositionTrack,
    t: np.ndarray,
    floor_h: float,
    water: Water | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, WaterPings | None]:
    """Error-free y (M, 3) m/s, beam unit vectors d_u (4, 3), slant ranges (M, 4) m (inf: no bottom) and, with
    water (floor_h then ignored: the seafloor is water.seafloor), the water-track pings: their y is relative to
    the water and their ranges inf."""
    m = motion.evaluate(t)
    lat, lon, h = track.at(t)
    _, _, l_R_b, b_omega_eb = imu_truth(m, lat, h)
    b_lever_v = np.cross(b_omega_eb, b_l)
    b_v = np.einsum("kji,kj->ki", l_R_b, m.l_v()) + b_lever_v
    b_R_d = rpy_deg_to_matrix(spec.misalignment_deg) @ b_R_d0
    y = spec.scale * b_v @ b_R_d  # rows: (d_R_b b_v)^T = b_v^T b_R_d
    d_u = janus_beams(spec.beam_angle_deg, np.asarray(spec.face_axis))
    l_u = np.einsum("kij,bj->kbi", l_R_b, d_u @ b_R_d.T)  # beams in the local level
    h_dvl = h + (l_R_b @ b_l)[:, 2]
    if water is not None:
        floor_h = -water.seafloor.depth_m
    down = -l_u[..., 2]
    with np.errstate(divide="ignore"):
        rng = np.where(down > 1e-9, (h_dvl - floor_h)[:, None] / down, np.inf)
    rng = np.where(rng > 0, rng, np.inf)  # a DVL above its seafloor only
    if water is None:
        return y, d_u, rng, None
    altitude = h_dvl - floor_h
    out = altitude > spec.bottom_range_m
    l_v_water = m.l_v()
    if water.current is not None:  # the current at base_link's depth, from map into the local level
        n_c = water.current.at(-h, t)
        l_v_water = l_v_water - np.einsum("kji,kj->ki", water.frame.n_R_l(lat, lon), n_c)
    y_water = spec.scale * (np.einsum("kji,kj->ki", l_R_b, l_v_water) + b_lever_v) @ b_R_d
    y = np.where(out[:, None], y_water, y)
    rng = np.where(out[:, None], np.inf, rng)
    return y, d_u, rng, WaterPings(water_track=out, altitude=np.where(out, np.nan, altitude))


def dvl_measure(
    spec: DvlSpec,
    t: np.ndarray,
    y_true: np.ndarray,
    d_u: np.ndarray,
    ranges: np.ndarray,
    noise_rng: np.random.Generator | None,
    event_rng: np.random.Generator | None,
    water: WaterPings | None = None,
    water_rng: np.random.Generator | None = None,
) -> DvlData:
    """Add noise, dropouts and outliers (None generators: none of them) and build DvlData. The event
    generator's draws come in the order event_blocks gives (sim/stream.py positions a generator at each).
    water (dvl_true's): the water-track pings get their noise from water_rng (drawn for every ping, so that the
    stream advances ping by ping whatever the mode) and are marked; every beam of a bottom-track ping with a
    range is valid (bottom lock is decided on the altitude, not beam by beam), every beam of a water-track ping
    measures."""
    M, B = ranges.shape
    wt = None if water is None else np.asarray(water.water_track, dtype=bool)
    beam_ok: np.ndarray = (
        np.asarray(ranges <= spec.max_range_m) if wt is None else np.isfinite(ranges) | wt[:, None]
    )
    if event_rng is not None:
        ping_lost: np.ndarray = event_rng.random((M,)) < spec.dropout_ping_prob
        beam_lost: np.ndarray = event_rng.random((M, B)) < spec.dropout_beam_prob
        beam_ok &= ~ping_lost[:, None] & ~beam_lost
    draws = _Draws(noise_rng, event_rng, water_rng)
    if spec.noise_model == "velocity":
        y, v_beam, cov = _velocity_noise(spec, y_true, d_u, wt, draws)
    else:
        y, v_beam, cov = _beam_noise(spec, y_true, d_u, beam_ok, wt, draws)
    return _dvl_data(t, y, cov, v_beam, beam_ok, d_u, ranges, wt, water)


class _Draws(NamedTuple):
    """The generators of one dvl_measure call (None: none of those draws): the white noise, the events
    (outliers), the water-track noise."""

    noise: np.random.Generator | None
    event: np.random.Generator | None
    water: np.random.Generator | None


def _velocity_noise(
    spec: DvlSpec,
    y_true: np.ndarray,
    d_u: np.ndarray,
    wt: np.ndarray | None,
    draws: _Draws,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The velocity noise model: noise and outliers on the 3-D velocity, the beams its projections. Returns the
    velocity (M, 3), the beam velocities (M, B) and the stated covariance (M, 3, 3)."""
    M = len(y_true)
    # what the covariance says, not what the noise is
    stated = spec.stated_noise_m_s or spec.noise_m_s
    y = y_true.copy()
    if draws.noise is not None:
        y += draws.noise.normal(0.0, spec.noise_m_s, (M, 3))
    if wt is not None and draws.water is not None:
        y = np.where(
            wt[:, None], y_true + draws.water.normal(0.0, spec.water_track_noise_m_s, (M, 3)), y
        )
    if draws.event is not None:
        ping_out: np.ndarray = draws.event.random((M,)) < spec.outlier_prob
        direction = draws.event.normal(size=(M, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        y[ping_out] += spec.outlier_m_s * direction[ping_out]
    v_beam = y @ d_u.T
    cov = np.broadcast_to(stated**2 * np.eye(3), (M, 3, 3)).copy()
    if wt is not None:
        cov[wt] = spec.water_track_noise_m_s**2 * np.eye(3)
    return y, v_beam, cov


def _beam_noise(
    spec: DvlSpec,
    y_true: np.ndarray,
    d_u: np.ndarray,
    beam_ok: np.ndarray,
    wt: np.ndarray | None,
    draws: _Draws,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The beam noise model: noise and outliers on each beam, the velocity their least-squares solution over the
    valid beams. Returns the velocity (M, 3), the beam velocities (M, B) and the stated covariance (M, 3, 3);
    a ping of fewer than 3 valid beams gets placeholders (NaN in _dvl_data)."""
    M, B = beam_ok.shape
    # what the covariance says, not what the noise is
    stated = spec.stated_noise_m_s or spec.noise_m_s
    v_beam = y_true @ d_u.T
    if draws.noise is not None:
        v_beam += draws.noise.normal(0.0, spec.noise_m_s, (M, B))
    if wt is not None and draws.water is not None:
        v_water = y_true @ d_u.T + draws.water.normal(0.0, spec.water_track_noise_m_s, (M, B))
        v_beam = np.where(wt[:, None], v_water, v_beam)
    if draws.event is not None:
        beam_out: np.ndarray = draws.event.random((M, B)) < spec.outlier_prob
        v_beam += np.where(
            beam_out, spec.outlier_m_s * np.sign(draws.event.random((M, B)) - 0.5), 0.0
        )
    w = beam_ok.astype(float)
    normal = np.einsum("kb,bi,bj->kij", w, d_u, d_u)
    rhs = np.einsum("kb,bi,kb->ki", w, d_u, np.where(beam_ok, v_beam, 0.0))
    enough = beam_ok.sum(axis=1) >= 3
    normal[~enough] = np.eye(3)  # placeholder, overwritten with NaN below
    y = np.linalg.solve(normal, rhs[..., None])[..., 0]
    inv_normal = np.linalg.inv(normal)
    cov = stated**2 * inv_normal
    if wt is not None:
        cov[wt] = spec.water_track_noise_m_s**2 * inv_normal[wt]
    return y, v_beam, cov


def _dvl_data(
    t: np.ndarray,
    y: np.ndarray,
    cov: np.ndarray,
    v_beam: np.ndarray,
    beam_ok: np.ndarray,
    d_u: np.ndarray,
    ranges: np.ndarray,
    wt: np.ndarray | None,
    water: WaterPings | None,
) -> DvlData:
    """The DvlData of the pings: a ping of fewer than 3 valid beams NaN; a water-track ping not valid as a
    velocity over ground, its altitude kept."""
    M, B = beam_ok.shape
    valid = beam_ok.sum(axis=1) >= 3
    y[~valid] = np.nan
    cov[~valid] = np.nan
    beams = BeamData(
        d_u=np.broadcast_to(d_u, (M, B, 3)).copy(),
        v=np.where(beam_ok, v_beam, np.nan),
        range=np.where(beam_ok & np.isfinite(ranges), ranges, np.nan),  # no bottom lock, no range
        valid=beam_ok,
    )
    if wt is None:
        return DvlData(t=t, d_v=y, d_cov=cov, valid=valid, beams=beams)
    beams.valid = beam_ok & ~wt[:, None]  # valid: usable as velocity over ground (core/types.py)
    return DvlData(
        t=t,
        d_v=y,
        d_cov=cov,
        valid=valid & ~wt,
        beams=beams,
        water_track=wt.copy(),
        altitude=np.asarray(water.altitude, dtype=float).copy(),  # type: ignore[union-attr]
    )


def event_blocks(spec: DvlSpec, n_pings: int, n_beams: int) -> list[tuple[str, int]]:
    """The draws dvl_measure takes from its event generator for n_pings pings, in order, as blocks
    ("uniform" | "normal", count): ping and beam dropouts, then the outliers (velocity model: which pings, then
    their directions; beam model: which beams, then their signs). Each call continues a block in ping order,
    so a run cut into parts draws the same numbers from generators positioned at each block's start."""
    m, b = n_pings, n_beams
    if spec.noise_model == "velocity":
        return [("uniform", m), ("uniform", m * b), ("uniform", m), ("normal", 3 * m)]
    return [("uniform", m), ("uniform", m * b), ("uniform", m * b), ("uniform", m * b)]


WATER_STREAM = 7  # index of the water-track noise's child of SeedSequence(seed) (sim/simulate.py)


def water_noise_rng(seed: int) -> np.random.Generator:
    """The water-track noise generator of a run: its own child of SeedSequence(seed), drawn only by a scenario with
    a [seafloor], so that every other stream's numbers are those of a scenario without it."""
    return np.random.Generator(
        np.random.PCG64(np.random.SeedSequence(seed).spawn(WATER_STREAM + 1)[WATER_STREAM])
    )


def water_model(scenario: Scenario) -> Water | None:
    """The scenario's Water (None without a [seafloor]: bottom lock always, the older model)."""
    if scenario.seafloor is None:
        return None
    return Water(scenario.local_frame(), scenario.current, scenario.seafloor)


# index of the correlated error's child of SeedSequence(seed) (sim/simulate.py)
CORRELATED_STREAM = 6


def correlated_error(spec: DvlSpec, dvl_hz: float, seed: int) -> GaussMarkov | None:
    """The DVL's Gauss-Markov error process of a run (None when correlated_sigma_m_s is 0): its own child of
    SeedSequence(seed), so the other streams, and so every other number of the log, are those of a scenario
    without it."""
    if spec.correlated_sigma_m_s <= 0:
        return None
    ss = np.random.SeedSequence(seed).spawn(CORRELATED_STREAM + 1)[CORRELATED_STREAM]
    return GaussMarkov(
        spec.correlated_sigma_m_s,
        spec.correlated_tau_s,
        1.0 / dvl_hz,
        np.random.Generator(np.random.PCG64(ss)),
    )


class GaussMarkov:
    """A first-order Gauss-Markov error per DVL axis, drawn ping by ping across calls (sim/stream.py continues it
    chunk by chunk: the same numbers as one call). Exact discretisation of dx = -x / tau dt + noise over the
    ping interval dt: x_{k+1} = phi x_k + sigma sqrt(1 - phi^2) w_k, phi = exp(-dt / tau), w_k ~ N(0, I); the
    first ping's x_0 = sigma w_0 (the stationary distribution), so the std is sigma at every ping and the
    correlation at lag L is exp(-L / tau)."""

    def __init__(
        self, sigma_m_s: float, tau_s: float, dt_s: float, rng: np.random.Generator
    ) -> None:
        self.sigma, self.rng = sigma_m_s, rng
        self.phi = float(np.exp(-dt_s / tau_s))
        self.drive = sigma_m_s * float(np.sqrt(1.0 - self.phi**2))
        self.x: np.ndarray | None = None  # the last ping's error

    def take(self, n_pings: int) -> np.ndarray:
        """The errors (n_pings, 3) m/s of the next n_pings pings."""
        w = self.rng.standard_normal((n_pings, 3))
        out = np.empty((n_pings, 3))
        x = self.x
        for k in range(n_pings):
            x = self.sigma * w[k] if x is None else self.phi * x + self.drive * w[k]
            out[k] = x
        self.x = x
        return out


# index of the drawn calibration's child of SeedSequence(seed) (sim/simulate.py)
CALIBRATION_STREAM = 8
CONSTANT_STREAM = 9  # index of the per-run constant error's child


def _child_rng(seed: int, index: int) -> np.random.Generator:
    return np.random.Generator(
        np.random.PCG64(np.random.SeedSequence(seed).spawn(index + 1)[index])
    )


def draw_calibration(spec: DvlSpec) -> bool:
    """Whether the scenario draws its truth calibration per seed (DvlSpec.draw_scale_sigma and
    draw_misalignment_sigma_deg)."""
    return bool(
        spec.draw_scale_sigma > 0 or np.any(np.asarray(spec.draw_misalignment_sigma_deg) > 0)
    )


def drawn_calibration(spec: DvlSpec, seed: int) -> DvlSpec:
    """spec with the truth scale and misalignment of this seed: k = scale + draw_scale_sigma z_0 and
    R_c = Exp(r) Rz Ry Rx(misalignment_deg), r = radians(draw_misalignment_sigma_deg) * z_1..3 in body axes (the
    estimators' prior on b_R_d, core/states.py: sigmas about body axes, R_c on the left), z ~ N(0, I_4) from its own
    child of SeedSequence(seed); spec itself when nothing is drawn. Four numbers are always drawn, so a sigma set to
    0 leaves the other draws as they were."""
    if not draw_calibration(spec):
        return spec
    z = _child_rng(seed, CALIBRATION_STREAM).standard_normal(4)
    r_rad = (
        np.radians(np.broadcast_to(np.asarray(spec.draw_misalignment_sigma_deg, dtype=float), (3,)))
        * z[1:]
    )
    R_c = so3_exp(r_rad) @ rpy_deg_to_matrix(spec.misalignment_deg)
    rpy = matrix_to_rpy_deg(R_c)
    return dataclasses.replace(
        spec,
        scale=float(spec.scale + spec.draw_scale_sigma * z[0]),
        misalignment_deg=(float(rpy[0]), float(rpy[1]), float(rpy[2])),
    )


def constant_error(spec: DvlSpec, seed: int) -> np.ndarray | None:
    """The run's constant velocity error (3,) m/s in dvl_link, constant_error_sigma_m_s per axis from its own child
    of SeedSequence(seed) (None when the sigma is 0)."""
    if spec.constant_error_sigma_m_s <= 0:
        return None
    return spec.constant_error_sigma_m_s * _child_rng(seed, CONSTANT_STREAM).standard_normal(3)
