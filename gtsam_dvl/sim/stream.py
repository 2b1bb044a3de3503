"""simulate() in time chunks with bounded memory, written to an MCAP as it goes (a 24 h, 200 Hz survey is 17.3 M
IMU samples, too many to hold whole with their truth).

ChunkedSimulation cuts the IMU samples 0..n-1 into chunks of chunk_s and yields each chunk's part of the log
(IMU samples, truth, pings, depth and fixes) as a LogData; io/writer.py's write_log_stream writes the parts as
they come (``write_log_stream(path, ChunkedSimulation(scenario, seed))``: the file write_log writes of
simulate(scenario, seed), byte for byte). Memory holds one chunk whatever the length, where simulate() and
write_log hold the whole mission (the peak RSS: bench/bench_long.py, docs/results.md "Speed").

The parts are simulate()'s log, bit for bit, for the same scenario and seed (tests/sim/test_stream.py):

* physics: the same functions on the same sample times. The position quadrature (sim/position.py) is a running
  sum; each chunk continues it from the previous chunk's sums (one per latitude pass), which are the very
  floats the whole-mission np.cumsum reaches there (it adds in order), so every grid value is the same. The
  true IMU increments are computed in true_imu's blocks (imu.true_imu_range). numpy gives a row the same
  bits in any array of two or more rows, not in an array of one (a one-row matrix product is a dot product;
  MotionProfile.evaluate takes another path for one time): a single stamp of a chunk (one truth sample, ping,
  depth sample or candidate fix) is computed doubled and the copy dropped, and a last chunk of one IMU sample
  joins the one before.
* random streams: the children of SeedSequence(seed) as in simulate(), each drawn in order, a chunk continuing
  where the previous one stopped (numpy's Generator draws the same numbers in parts as at once). A stream that
  holds several blocks one after the other gets a generator per block, positioned at the block's start: the
  IMU white noise (all gyro draws, then all accelerometer draws) and the bias walks are positioned by drawing
  and dropping the earlier blocks once at the start (normal draws take a variable count of raw numbers); the
  DVL event stream's blocks (dvl.event_blocks) are uniform draws before the last, one raw number each, so
  PCG64.advance positions them.
* two things simulate() knows only at the end are found first: the bias series of walking biases (metadata)
  by a pass over the bias streams, and, with GNSS, whether the log has fixes and the first fix (the map frame
  of gnss.origin_in_log = false, in which the truth is written) by a pass of the position quadrature up to
  that fix.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import (
    BeamData,
    DepthData,
    DvlData,
    GeoOrigin,
    GnssData,
    ImuData,
    LogData,
    TruthData,
)
from gtsam_dvl.sim import dvl as sim_dvl
from gtsam_dvl.sim import record
from gtsam_dvl.sim.dvl import (
    GaussMarkov,
    correlated_error,
    dvl_measure,
    dvl_true,
    event_blocks,
    janus_beams,
)
from gtsam_dvl.sim.gnss import first_fix_frame, gnss_fixes, gnss_rng, reframe_truth
from gtsam_dvl.sim.imu import (
    initial_biases,
    quantise,
    saturate,
    true_imu_range,
    walk_step_sigmas,
    white_noise_sigmas,
)
from gtsam_dvl.sim.motion import MotionProfile
from gtsam_dvl.sim.position import PositionStream, TrackWindow
from gtsam_dvl.sim.simulate import depth_at, depth_rng, dvl_stamps, truth_at, with_drawn_calibration

if TYPE_CHECKING:
    from gtsam_dvl.core.earth import LocalFrame
    from gtsam_dvl.sim.scenario import GnssSpec, Scenario

DEFAULT_CHUNK_S = 600.0
_SKIP_BLOCK = 1 << 20  # normal draws per call when dropping a block


# ----- random streams -----------------------------------------------------------------------------------
def _generator(state: Any) -> np.random.Generator:
    """A PCG64 generator in a saved bit_generator.state."""
    bg = np.random.PCG64()
    bg.state = copy.deepcopy(state)
    return np.random.Generator(bg)


def _skip_normals(rng: np.random.Generator, count: int) -> None:
    while count > 0:
        m = min(count, _SKIP_BLOCK)
        rng.standard_normal(m)
        count -= m


class _BiasWalk:
    """draw_biases' walk() of one triad, sample by sample range: b0 + cumsum of N(0, sigma) steps, the first 0."""

    def __init__(self, b0: np.ndarray, sigma: float, rng: np.random.Generator) -> None:
        self.b0, self.sigma, self.rng = b0, sigma, rng
        self.s = np.zeros(3)
        self.next = 0

    def take(self, a: int, b: int) -> np.ndarray:
        assert a == self.next
        self.next = b
        if self.sigma == 0.0:
            return np.broadcast_to(self.b0, (b - a, 3))
        steps = self.rng.normal(0.0, self.sigma, (b - a, 3))
        if a == 0:
            steps[0] = 0.0  # the first sample has the initial bias
        cum = np.cumsum(np.concatenate([self.s[None], steps]), axis=0)
        self.s = cum[-1].copy()
        return self.b0 + cum[1:]


class _Draws:
    """Stands in for a generator in dvl_measure: the i-th draw of a call comes from gens[i] (the event stream: one
    generator per block of dvl.event_blocks; the noise stream: one), each continuing from call to call.
    doubled: the call's pings are one ping and its copy (_padded); only the real ping's numbers are drawn."""

    def __init__(self, gens: list[np.random.Generator]) -> None:
        self.gens = gens
        self.i = 0
        self.doubled = False

    def start(self, doubled: bool) -> _Draws:
        self.i, self.doubled = 0, doubled
        return self

    def _draw(self, fn: Callable[[Any], np.ndarray], size: Any) -> np.ndarray:
        if not self.doubled:
            return fn(size)
        shape = (size,) if isinstance(size, int) else tuple(size)
        x = fn((1, *shape[1:]))
        return np.concatenate([x, x])

    def random(self, size: Any = None) -> np.ndarray:
        g = self.gens[min(self.i, len(self.gens) - 1)]
        self.i += 1
        return self._draw(g.random, size)

    def normal(self, loc: float = 0.0, scale: float = 1.0, size: Any = None) -> np.ndarray:
        g = self.gens[min(self.i, len(self.gens) - 1)]
        self.i += 1
        return self._draw(lambda sz: g.normal(loc, scale, sz), size)


def _padded(k: np.ndarray) -> np.ndarray:
    """k (one or more stamps) with a single element doubled (module doc): one row takes other numpy paths than
    simulate()'s arrays (a dot product for a matrix product; MotionProfile.evaluate's unsorted path, which at
    a segment's start time picks the other piece: equal in value, not in every bit)."""
    return np.concatenate([k, k]) if len(k) == 1 else k


_NOT_ROWS = ("frame_id", "b_p_sensor", "b_p_antenna")


def _rows(obj: Any, m: int) -> Any:
    """A copy of the data class obj (TruthData, DvlData, DepthData, GnssData) with the first m rows of its
    arrays."""
    kw: dict[str, Any] = {}
    for f in obj.__dataclass_fields__:
        v = getattr(obj, f)
        if isinstance(v, np.ndarray) and f not in _NOT_ROWS:
            kw[f] = v[:m]
        elif dataclasses.is_dataclass(v):
            kw[f] = _rows(v, m)
    return dataclasses.replace(obj, **kw)


class _Fixed:
    """A generator stand-in that returns given standard normal draws (the padded copy's are the real one's)."""

    def __init__(self, values: np.ndarray) -> None:
        self.values = values

    def standard_normal(self, size: Any = None) -> np.ndarray:
        return np.concatenate([self.values, self.values]).reshape(size)


# ----- the chunked simulation ---------------------------------------------------------------------------
@dataclass
class _Streams:
    """The generators of one pass over the chunks."""

    gyro_walk: _BiasWalk
    accel_walk: _BiasWalk
    gyro_noise: np.random.Generator | None
    accel_noise: np.random.Generator | None
    dvl_noise: _Draws | None
    dvl_events: _Draws | None
    depth: np.random.Generator | None
    gnss: np.random.Generator | None
    dvl_correlated: GaussMarkov | None  # continued ping by ping
    dvl_water: _Draws | None  # the water-track noise (a scenario with [seafloor])


class ChunkedSimulation:
    """simulate(scenario, seed, white_noise=...) as consecutive parts of chunk_s seconds (module doc).

    head: the log's metadata, typed fields, mounting and sensors with empty arrays; parts(): (part, next_t)
    for each chunk, next_t the earliest stamp a later part can have (None after the last); t_first (the first
    stamp) and imu_stamps() (the IMU stamps in parts) what write_log takes from the whole log; gnss_fixes: the
    log has GNSS fixes. That is what io/writer.py's write_log_stream takes (its LogSource):
    ``write_log_stream(path, ChunkedSimulation(scenario, seed))`` writes write_log's file of simulate()'s log.
    n_samples, n_pings, duration_s: the log's sizes; distance_m: travelled along the truth of the parts so far."""

    def __init__(
        self,
        scenario: Scenario,
        seed: int,
        *,
        white_noise: bool = True,
        chunk_s: float = DEFAULT_CHUNK_S,
    ) -> None:
        if not np.isfinite(chunk_s) or chunk_s <= 0:
            raise GtsamDvlError(f"chunk length {chunk_s!r} s: must be a positive number of seconds")
        given_dvl = scenario.dvl
        scenario = with_drawn_calibration(scenario, seed)
        self.scenario, self.seed, self.white_noise = scenario, seed, white_noise
        self.constant = sim_dvl.constant_error(scenario.dvl, seed) if white_noise else None
        rates = scenario.rates
        self.rate = rate = rates.imu_hz
        self.n_samples = n = int(np.floor(scenario.duration_s * rate + 1e-6)) + 1  # as simulate()
        self.chunk_n = max(2, int(round(chunk_s * rate)))  # no one-sample chunk (_ranges)
        self.frame = scenario.local_frame()
        self.motion = MotionProfile.from_scenario(scenario)
        self.mounting = record.nominal_mounting(scenario)
        self.t_meas, self.t_dvl = dvl_stamps(
            rates.dvl_hz, rates.dvl_time_offset_s, float((n - 1) / rate)
        )
        self.n_pings = len(self.t_meas)
        # the grid interval each ping's time falls in (TrackWindow.grid_index_of_time): the chunk that has it
        self._ping_g = np.clip(np.floor(self.t_meas * rate + 1.0).astype(np.int64), 0, n - 1)
        self.floor_h = scenario.origin.height_m - scenario.dvl.altitude_m
        self.water = sim_dvl.water_model(scenario)
        self.truth_step = int(round(rate / rates.truth_hz))
        self.n_beams = janus_beams(
            scenario.dvl.beam_angle_deg, np.asarray(scenario.dvl.face_axis)
        ).shape[0]

        # bias, imu, dvl, event: simulate()'s children
        self._ss = np.random.SeedSequence(seed).spawn(4)
        bias_rng = np.random.Generator(np.random.PCG64(self._ss[0]))
        self.gyro_bias0, self.accel_bias0 = initial_biases(scenario.imu, bias_rng)
        self._walk_sigmas = walk_step_sigmas(scenario.imu, rate)
        self._gyro_walk_state: Any = copy.deepcopy(bias_rng.bit_generator.state)
        self._accel_walk_state: Any = None
        bias_series = self._walk_prepass()
        self._accel_noise_state: Any = None
        if white_noise:  # white_noise(): all gyro draws, then the accelerometer's
            imu_rng = np.random.Generator(np.random.PCG64(self._ss[1]))
            _skip_normals(imu_rng, 3 * n)
            self._accel_noise_state = copy.deepcopy(imu_rng.bit_generator.state)

        metadata = record.metadata(
            scenario,
            seed,
            white_noise,
            self.mounting,
            self.gyro_bias0,
            self.accel_bias0,
            bias_series,
            given_dvl,
            self.constant,
        )
        origin: GeoOrigin | None = record.map_origin(scenario)
        self.fix_frame: LocalFrame | None = None
        self.gnss_fixes = False  # the log has GNSS fixes
        if scenario.gnss is not None:
            first = self._first_fix()
            self.gnss_fixes = first is not None
            if not scenario.gnss.origin_in_log:
                self.fix_frame = record.map_from_first_fix(scenario, first, metadata)
                origin = None
        self.head = self._head(metadata, origin)
        # IMU and truth start at 0
        self.t_first = min(0.0, float(self.t_dvl[0])) if self.n_pings else 0.0
        self.duration_s = (n - 1) / rate  # the last IMU stamp
        self.distance_m = 0.0  # travelled along the truth of the parts yielded so far

    # -- set-up passes ------------------------------------------------------------------------------
    def _walk_prepass(self) -> dict[str, Any] | None:
        """Position the accelerometer walk's generator after the gyro walk's draws; the bias series once a
        second (simulate()'s metadata) when the biases walk, else None."""
        g_sigma, a_sigma = self._walk_sigmas
        rng = _generator(self._gyro_walk_state)
        if g_sigma == 0.0 and a_sigma == 0.0:
            self._accel_walk_state = self._gyro_walk_state
            return None
        step = int(round(self.rate))
        series: dict[str, list[Any]] = {"t": [], "gyro_rad_s": [], "accel_m_s2": []}
        for key, b0, sigma in (
            ("gyro_rad_s", self.gyro_bias0, g_sigma),
            ("accel_m_s2", self.accel_bias0, a_sigma),
        ):
            if key == "accel_m_s2":
                self._accel_walk_state = copy.deepcopy(rng.bit_generator.state)
            walk = _BiasWalk(b0, sigma, rng)
            for a, b in self._ranges():
                bias = walk.take(a, b)
                k = self._stamps(a, b, step)
                series[key] += bias[k - a].tolist()
                if key == "gyro_rad_s":
                    series["t"] += (k / self.rate).tolist()
        return series

    def _first_fix(self) -> LocalFrame | None:
        """The first fix's frame (None: the log has no fixes), by the position quadrature up to it."""
        spec = self.scenario.gnss
        assert spec is not None
        step = int(round(self.rate / spec.rate_hz))
        rng = gnss_rng(self.seed) if self.white_noise else None
        pos = self._position()
        for a, b in self._ranges():
            fixes = _gnss(spec, self.motion, pos.window(a, b), self._stamps(a, b, step), rng)
            if len(fixes):
                return first_fix_frame(fixes)
        return None

    def _position(self) -> PositionStream:
        f = self.frame
        return PositionStream(
            self.motion, f.lat0, f.lon0, self.scenario.origin.height_m, self.rate, self.n_samples
        )

    def _ranges(self) -> Iterator[tuple[int, int]]:
        """The chunks [a, b) of samples; a last chunk of one sample joins the one before (a product of one row
        takes another BLAS path than the same row in a larger array)."""
        n, step = self.n_samples, self.chunk_n
        a = 0
        while a < n:
            b = min(a + step, n)
            if n - b == 1:
                b = n
            yield a, b
            a = b

    def _head(self, metadata: dict[str, Any], origin: GeoOrigin | None) -> LogData:
        sc = self.scenario
        B = self.n_beams
        z3, z1 = np.zeros((0, 3)), np.zeros(0)
        water = sc.seafloor is not None
        dvl = DvlData(
            t=z1,
            d_v=z3,
            d_cov=np.zeros((0, 3, 3)),
            valid=np.zeros(0, bool),
            beams=BeamData(
                d_u=np.zeros((0, B, 3)),
                v=np.zeros((0, B)),
                range=np.zeros((0, B)),
                valid=np.zeros((0, B), bool),
            ),
            water_track=np.zeros(0, bool) if water else None,
            altitude=z1 if water else None,
        )
        truth = TruthData(
            t=z1,
            n_p=z3,
            n_q_b=np.zeros((0, 4)),
            n_v=z3,
            b_omega=z3,
            n_c=None if sc.current is None else z3,
        )
        depth = (
            None
            if sc.depth is None
            else DepthData(
                t=z1,
                depth_m=z1,
                variance_m2=z1,
                pressure_pa=z1,
                pressure_variance_pa2=z1,
                b_p_sensor=np.asarray(sc.depth.lever_arm_m, dtype=float),
            )
        )
        gnss = (
            None
            if sc.gnss is None
            else GnssData(
                t=z1,
                lat_deg=z1,
                lon_deg=z1,
                height_m=z1,
                cov_enu_m2=np.zeros((0, 3, 3)),
                status=np.zeros(0, int),
                b_p_antenna=np.asarray(sc.gnss.antenna_lever_arm_m, dtype=float),
            )
        )
        return record.log_data(
            sc,
            self.seed,
            self.gyro_bias0,
            self.accel_bias0,
            metadata,
            origin,
            imu=ImuData(t=z1, b_omega=z3, b_f=z3),
            dvl=dvl,
            mounting=self.mounting,
            truth=truth,
            depth=depth,
            gnss=gnss,
        )

    def _streams(self) -> _Streams:
        g_sigma, a_sigma = self._walk_sigmas
        white, sc = self.white_noise, self.scenario
        events = None
        if white:
            blocks = event_blocks(self.scenario.dvl, self.n_pings, self.n_beams)
            gens, offset = [], 0
            for i, (_, count) in enumerate(blocks):
                # a uniform draw is one raw 64-bit number (advance), a normal draw a variable count
                assert all(kind == "uniform" for kind, _ in blocks[:i]), (
                    "dvl.event_blocks: normals before a block"
                )
                bg = np.random.PCG64(self._ss[3])
                bg.advance(offset)
                gens.append(np.random.Generator(bg))
                offset += count
            events = _Draws(gens)
        return _Streams(
            gyro_walk=_BiasWalk(self.gyro_bias0, g_sigma, _generator(self._gyro_walk_state)),
            accel_walk=_BiasWalk(self.accel_bias0, a_sigma, _generator(self._accel_walk_state)),
            gyro_noise=np.random.Generator(np.random.PCG64(self._ss[1])) if white else None,
            accel_noise=_generator(self._accel_noise_state)
            if self._accel_noise_state is not None
            else None,
            dvl_noise=_Draws([np.random.Generator(np.random.PCG64(self._ss[2]))])
            if white
            else None,
            dvl_events=events,
            depth=depth_rng(self.seed) if white and self.scenario.depth is not None else None,
            gnss=gnss_rng(self.seed) if white and self.scenario.gnss is not None else None,
            dvl_correlated=correlated_error(sc.dvl, sc.rates.dvl_hz, self.seed) if white else None,
            dvl_water=_Draws([sim_dvl.water_noise_rng(self.seed)])
            if white and self.water is not None
            else None,
        )

    # -- the parts ----------------------------------------------------------------------------------
    def parts(
        self, progress: Callable[[float], None] | None = None
    ) -> Iterator[tuple[LogData, float | None]]:
        """(part, next_t) per chunk, in time order (class doc)."""
        sc, rate, n = self.scenario, self.rate, self.n_samples
        streams = self._streams()
        pos = self._position()
        sg, sa = white_noise_sigmas(sc.imu, rate)
        self.distance_m = 0.0
        last_p = np.zeros((0, 3))
        for a, b in self._ranges():
            win = pos.window(a, b)
            b_omega, b_f = true_imu_range(self.motion, win, a, b)
            b_omega += streams.gyro_walk.take(a, b)
            b_f += streams.accel_walk.take(a, b)
            if streams.gyro_noise is not None and streams.accel_noise is not None:
                b_omega += streams.gyro_noise.normal(0.0, sg, (b - a, 3))
                b_f += streams.accel_noise.normal(0.0, sa, (b - a, 3))
            imu = ImuData(
                t=np.arange(a, b) / rate,
                b_omega=saturate(
                    quantise(b_omega, sc.imu.quantisation_gyro_rad_s), sc.imu.saturation_gyro_rad_s
                ),
                b_f=saturate(
                    quantise(b_f, sc.imu.quantisation_accel_m_s2), sc.imu.saturation_accel_m_s2
                ),
            )

            truth = self._truth(win, self._stamps(a, b, self.truth_step))
            n_p = np.concatenate([last_p, truth.n_p])
            self.distance_m += float(np.linalg.norm(np.diff(n_p, axis=0), axis=1).sum())
            last_p = n_p[-1:]

            j0, j1 = np.searchsorted(self._ping_g, [a, b], side="left")
            dvl = self._dvl(win, int(j0), int(j1), streams)

            depth = None
            if sc.depth is not None:
                k = self._stamps(a, b, int(round(rate / sc.depth.rate_hz)))
                depth = _depth(sc, self.motion, win, self.frame, k, streams.depth, self.head)
            gnss = self.head.gnss
            if sc.gnss is not None and self.gnss_fixes:
                k = self._stamps(a, b, int(round(rate / sc.gnss.rate_hz)))
                gnss = _gnss(sc.gnss, self.motion, win, k, streams.gnss)
            part = LogData(
                imu=imu,
                dvl=dvl,
                mounting=self.mounting,
                truth=truth,
                t0_ns=sc.t0_ns,
                metadata=self.head.metadata,
                source=self.head.source,
                origin=self.head.origin,
                depth=depth,
                gnss=gnss,
            )
            next_t: float | None = None
            if b < n:
                next_t = b / rate
                if j1 < self.n_pings:
                    next_t = min(next_t, float(self.t_dvl[j1]))
            if progress is not None:
                progress(b / n)
            yield part, next_t

    def _truth(self, win: TrackWindow, k: np.ndarray) -> TruthData:
        assert self.head.truth is not None
        if not len(k):
            return _rows(self.head.truth, 0)
        truth = truth_at(self.motion, win, self.frame, _padded(k), self.scenario)
        if self.fix_frame is not None:
            truth = reframe_truth(truth, self.frame, self.fix_frame)
        return _rows(truth, len(k))  # type: ignore[no-any-return]

    def imu_stamps(self) -> Iterator[np.ndarray]:
        """The IMU stamps k / rate (s), in consecutive parts."""
        step = 1 << 20
        for a in range(0, self.n_samples, step):
            yield np.arange(a, min(a + step, self.n_samples)) / self.rate

    def _stamps(self, a: int, b: int, step: int) -> np.ndarray:
        """The sample indices in [a, b) that are multiples of step."""
        return np.arange(-(-a // step) * step, b, step)

    def _dvl(self, win: TrackWindow, j0: int, j1: int, streams: _Streams) -> DvlData:
        """The pings j0..j1-1 (one: measured doubled, _padded, its copy's numbers the real one's)."""
        sc = self.scenario
        m = j1 - j0
        water = None
        if m:
            y, d_u, ranges, water = dvl_true(
                sc.dvl,
                self.mounting.b_R_d0,
                self.mounting.b_l,
                self.motion,
                win,
                _padded(self.t_meas[j0:j1]),
                self.floor_h,
                self.water,
            )
            if streams.dvl_correlated is not None:
                e = streams.dvl_correlated.take(m)
                # the padded copy's: the real ping's
                y = y + (np.concatenate([e, e]) if m == 1 else e)
            if self.constant is not None:
                y = y + self.constant
        else:
            y, ranges = np.zeros((0, 3)), np.zeros((0, self.n_beams))
            d_u = janus_beams(sc.dvl.beam_angle_deg, np.asarray(sc.dvl.face_axis))
            if self.water is not None:
                water = sim_dvl.WaterPings(np.zeros(0, bool), np.zeros(0))
        noise, events, water_noise = (
            None if d is None else d.start(m == 1)
            for d in (streams.dvl_noise, streams.dvl_events, streams.dvl_water)
        )
        # _Draws: the draws dvl_measure takes
        dvl = dvl_measure(
            sc.dvl,
            _padded(self.t_dvl[j0:j1]),
            y,
            d_u,
            ranges,
            noise,  # type: ignore[arg-type]
            events,  # type: ignore[arg-type]
            water,
            water_noise,  # type: ignore[arg-type]
        )
        dvl.noise_free = not self.white_noise  # as simulate's (sim/record.py log_data)
        return _rows(dvl, m) if m == 1 else dvl


def _depth(
    scenario: Scenario,
    motion: MotionProfile,
    win: TrackWindow,
    frame: LocalFrame,
    k: np.ndarray,
    rng: np.random.Generator | None,
    head: LogData,
) -> DepthData:
    """depth_at for any number of stamps (one: evaluated doubled, _padded), the noise drawn as depth_at draws it."""
    spec = scenario.depth
    assert spec is not None and head.depth is not None
    if len(k) != 1:
        return depth_at(scenario, motion, win, frame, k, rng) if len(k) else _rows(head.depth, 0)
    fixed = None if rng is None or spec.noise_m <= 0 else _Fixed(rng.standard_normal(1))
    return _rows(depth_at(scenario, motion, win, frame, _padded(k), fixed), 1)  # type: ignore[arg-type]


def _gnss(
    spec: GnssSpec,
    motion: MotionProfile,
    win: TrackWindow,
    k: np.ndarray,
    rng: np.random.Generator | None,
) -> GnssData:
    """gnss_fixes for any number of candidate stamps (one: evaluated doubled, _padded)."""
    if len(k) != 1:
        return gnss_fixes(spec, motion, win, k, rng)
    fixed = None if rng is None else _Fixed(rng.standard_normal((1, 3)))
    g = gnss_fixes(spec, motion, win, _padded(k), fixed)  # type: ignore[arg-type]
    return _rows(g, len(g) // 2)  # the candidate and its copy are both fixes or neither


# ----- entry points -------------------------------------------------------------------------------------
def _concat(objs: list[Any]) -> Any:
    """Data class instances of one type (ImuData, DvlData, ...) joined row-wise; other fields from the first."""
    first = objs[0]
    kw: dict[str, Any] = {}
    for f in first.__dataclass_fields__:
        v = getattr(first, f)
        if isinstance(v, np.ndarray) and f not in _NOT_ROWS:
            kw[f] = np.concatenate([getattr(o, f) for o in objs])
        elif dataclasses.is_dataclass(v):
            kw[f] = _concat([getattr(o, f) for o in objs])
        else:
            kw[f] = v
    return dataclasses.replace(first, **kw)


def simulate_chunked(
    scenario: Scenario, seed: int, *, white_noise: bool = True, chunk_s: float = DEFAULT_CHUNK_S
) -> LogData:
    """simulate()'s LogData assembled from ChunkedSimulation's parts (the whole log in memory: for checks and
    short runs; write_log_stream(path, ChunkedSimulation(...)) is the bounded-memory path)."""
    sim = ChunkedSimulation(scenario, seed, white_noise=white_noise, chunk_s=chunk_s)
    parts = [p for p, _ in sim.parts()]
    data: dict[str, Any] = {}
    for name in ("imu", "dvl", "truth", "depth", "gnss"):
        if getattr(sim.head, name) is not None:
            data[name] = _concat([getattr(p, name) for p in parts])
    return dataclasses.replace(sim.head, **data)
