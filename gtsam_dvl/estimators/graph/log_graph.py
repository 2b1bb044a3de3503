"""The whole-log graph: the batch smoother's and the planner's factor graph over every epoch of a log.

States (pose X_i = n_T_b, velocity V_i = n_v) at the DVL epochs chosen by estimators/inputs/selection.py (every
usable ping, or with [solver] keyframe_spacing_s the keyframes) and at DVL-dropout fillers; preintegrated IMU
factors between consecutive states, integrated exactly to the DVL stamps; DVL velocity (or beam) factors on
(X_i, V_i, scale K, misalignment C = b_R_d); the pings between keyframes as DVL factors on the state before
them through the IMU motion up to the ping (estimators/graph/keyframes.py, factors/dvl.py with a PingMotion, also on the
bias); IMU bias B (one random constant, or B_i as a random walk). Every factor comes from the FactorMaker
(estimators/graph/factor_maker.py: the Earth model and why it
is exact), which the online estimator shares; this module owns the epochs, their preintegrations and the
initial guess of the whole trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import V, X, key_dim
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.states import enabled, shared_keys, water_current
from gtsam_dvl.core.states import initial_values as initial_shared_values
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.graph.bulk import BulkGraph, bulk_dvl
from gtsam_dvl.estimators.graph.bulk_imu import BulkImu, GravityRefs
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.graph.keyframes import interval_with_snapshots
from gtsam_dvl.estimators.graph.solver import ChunkedOrdering
from gtsam_dvl.estimators.inputs.alignment import Alignment, align_log
from gtsam_dvl.estimators.inputs.depth import depth_samples, nearest_states
from gtsam_dvl.estimators.inputs.gaps import (
    Gaps,
    Holds,
    ImuPieces,
    check_gaps,
    check_spacing,
    find_gaps,
    gaps_within,
    sample_starts_with_gaps,
    with_fillers,
)
from gtsam_dvl.estimators.inputs.gnss import (
    GnssFixes,
    first_position,
    first_position_cov,
    plan_fixes,
)
from gtsam_dvl.estimators.inputs.mounting import log_in_base_link
from gtsam_dvl.estimators.inputs.offset_guess import OffsetGuess, guess_offset
from gtsam_dvl.estimators.inputs.selection import covering_sample, decide_epochs
from gtsam_dvl.estimators.models import current
from gtsam_dvl.estimators.models.epoch_states import StatePath, enabled_epoch_states, state_keys
from gtsam_dvl.factors import EarthImuFactor
from gtsam_dvl.factors.imu_bulk import ImuArrays, bias_jacobians, gravity_maps
from gtsam_dvl.factors.imu_earth import REFRESH_M
from gtsam_dvl.factors.ping_motion import PingMotion

CHUNK_STATES = 1000  # states eliminated at once (solver.eliminate_chunked)


@dataclass
class BetweenPing:
    """A usable ping between keyframes ([solver] keyframe_spacing_s): a DVL factor on the state before it."""

    t: float
    dvl_index: int
    b_omega: np.ndarray  # body rate relative to map at t (for the lever arm), rad/s
    rate_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # as Epoch.rate_input, at t
    # its IMU motion from the state before: row of LogGraph.snapshots (LogGraph.ping_snapshot)
    snap: int = -1


@dataclass
class Epoch:
    """One state of the graph: a DVL ping used as keyframe."""

    t: float
    dvl_index: int  # -1: a state without a ping (a DVL dropout: estimators/inputs/gaps.py)
    b_omega: np.ndarray  # body rate relative to map at t (for the lever arm), rad/s
    # with dvl.estimate_time_offset: (mean specific force, mean body rate) around t (FactorMaker.velocity_rate_input)
    rate_input: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    # the pings up to the next state (keyframes)
    between: list[BetweenPing] = field(default_factory=list)


@dataclass
class LogGraph:
    """A log turned into epochs, factors and an initial guess. Solvers take what they need from it."""

    log: LogData
    config: EstimatorConfig
    # the fraction of the preintegration done, 20 times (the longest stage on a long log: docs/results.md)
    progress: ProgressFn | None = field(default=None, repr=False, compare=False)
    # a vehicle's calibration as the prior of the states it holds (FactorMaker.calibration); None: the configuration's
    calibration: VehicleCalibration | None = field(default=None, repr=False, compare=False)
    maker: FactorMaker = field(init=False)
    epochs: list[Epoch] = field(init=False)
    pims: list[gtsam.PreintegratedImuMeasurements] = field(init=False)
    imu_params: list[gtsam.PreintegrationParams] = field(init=False)
    imu_held: list[Holds] = field(init=False)  # what each IMU interval held across IMU gaps
    # (imu_factors)
    _imu_factors: list[EarthImuFactor] | None = field(default=None, init=False, repr=False)
    # the IMU factors' gravity references, shared by the EarthImuFactors' copies and the bulk IMU factors
    gravity_refs: GravityRefs = field(init=False, repr=False)
    gaps: Gaps = field(init=False)
    counters: dict[str, int] = field(default_factory=dict)
    # map positions (N, 3) of the states at which the keyframe factors' gravity is referenced (initial_values)
    gravity_positions: np.ndarray | None = field(default=None, init=False, repr=False)
    _keyframe_gravity: tuple[np.ndarray | None, np.ndarray, np.ndarray] | None = field(
        default=None, init=False, repr=False
    )
    # the IMU motion to each ping between keyframes (BetweenPing.snap: its row); None once build_bulk let it go
    snapshots: PingMotion | None = field(default=None, init=False, repr=False)
    # the usable pings' indices in log.dvl (NavResult.dvl_pings)
    usable: np.ndarray = field(init=False, repr=False)
    water: np.ndarray = field(init=False, repr=False)  # (M,) bool: log.dvl's water-track pings
    # the states' stamps and heights as the per-epoch states' processes see them (initial_values), and the variables
    # of those processes beside the per-state ones (the water current's layer boundaries S(b) the states cross):
    # estimators/models/epoch_states.py
    path: StatePath | None = field(default=None, init=False, repr=False)
    extra_keys: list[int] = field(default_factory=list, init=False, repr=False)
    # where each per-epoch state's factors (by its registry name: "dvl_error" the correlated error's), the depth and
    # GNSS factors sit in the graph of _factors_but_dvl (the batch smoother's noise fit makes them again in place)
    factor_slots: dict[str, range] = field(default_factory=dict, init=False, repr=False)
    # the time offset's IMU windows as last set (set_time_offset_window, recentre_time_offset): the offset (s) they
    # are centred on and the accelerometer bias (m/s^2, per ping row of the bulk or (3,)) taken off their samples
    offset_centre: float = field(default=0.0, init=False, repr=False)
    offset_rows: np.ndarray = field(
        default_factory=lambda: np.zeros(0, dtype=int), init=False, repr=False
    )
    offset_accel_bias: np.ndarray = field(
        default_factory=lambda: np.zeros((0, 3)), init=False, repr=False
    )
    # the batch smoother's last check of the windows against its solution (batch.solve_centred)
    offset_centring: dict[str, Any] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        # IMU samples in base_link (estimators/inputs/mounting.py)
        self.log = log_in_base_link(self.log)
        cfg, log = self.config, self.log
        frame, alignment = align_log(log, cfg)
        self.maker = FactorMaker(
            cfg, frame, alignment, log.mounting, log.source, calibration=self.calibration
        )
        if enabled(cfg, "time_offset") and cfg.dvl.use_beams:
            raise GtsamDvlError(
                "[dvl] estimate_time_offset works with the 3-D velocity only, not with use_beams"
            )
        if len(log.imu) < 2:
            raise GtsamDvlError(f"{log.source or 'log'}: fewer than two IMU samples")
        check_spacing(cfg.solver)
        self.gaps = find_gaps(log.imu.t, cfg.imu.gap_samples)
        self.epochs = self._select_epochs()
        if sum(e.dvl_index >= 0 for e in self.epochs) < 2:
            raise GtsamDvlError(f"{log.source or 'log'}: fewer than two usable DVL pings")
        # the given attitude and map origin are at the log's first IMU stamp (an attitude sensor's at its own
        # time): carry them to the first state (alignment.first_state)
        j0 = self.epochs[0].dvl_index
        # (M,) the water-track pings (used when water_current(cfg))
        self.water = current.water_pings(log)
        d_y0 = log.dvl.d_v[j0] if log.dvl.valid[j0] and not self.water[j0] else None
        self.maker.carry_to_first(log.imu, self.epochs[0].t, d_y0, log.dvl.d_cov[j0])
        # the gaps the states cross
        self.gaps = gaps_within(self.gaps, self.epochs[0].t, self.epochs[-1].t)
        self.counters["imu_gaps"] = len(self.gaps)
        check_gaps(self.gaps, cfg.imu, log.source)
        # the samples' intervals and rotation-compensated specific force, made once for both integrations (each
        # an array over every IMU sample of the log)
        imu = log.imu
        starts = sample_starts_with_gaps(imu.t, self.gaps)
        b_f = self.maker.compensate_rotation(imu.b_f, imu.b_omega, imu.t - starts)
        self.imu_held = self._preintegrate(ImuPieces(imu.t, starts, b_f, imu.b_omega, self.gaps))
        del starts, b_f
        n_f = len(self.pims)
        self.gravity_refs = GravityRefs(
            np.full((n_f, 3), np.nan),
            np.array([p.n_gravity for p in self.imu_params], dtype=float).reshape(n_f, 3),
            np.zeros((n_f, 3, 3)),
            None if cfg.solver.earth_model == "flat" else self.maker.gravity_model,
        )
        self._per_factor_built = False

    @property
    def imu_factors(self) -> list[EarthImuFactor]:
        """The per-factor graph's IMU factors (EarthImuFactor), made on first use with the gravity references set so far
        (the bulk IMU factors of build_bulk need none, which saves an EarthImuFactor's time and memory per interval:
        docs/results.md, Speed); empty once build_bulk let the preintegrations go."""
        if self._imu_factors is None:
            if len(self.pims) + 1 != len(self.epochs):
                raise GtsamDvlError(
                    "the IMU factors: build_bulk let the preintegrations go; make a new LogGraph"
                )
            self._imu_factors = [
                self.maker.new_imu_factor(
                    i, pim, params, self.epochs[i + 1].t - self.epochs[i].t, h
                )
                for i, (pim, params, h) in enumerate(
                    zip(self.pims, self.imu_params, self.imu_held, strict=True)
                )
            ]
            refs = self.gravity_refs
            for i in np.flatnonzero(~np.isnan(refs.n_p[:, 0])).tolist():
                f = self._imu_factors[i]
                f.set_reference(refs.n_p[i], refs.n_g[i], refs.G[i])
                f.set_gravity(refs.n_p[i])
        return self._imu_factors

    @property
    def frame(self) -> LocalFrame:
        return self.maker.frame

    @property
    def alignment(self) -> Alignment:
        return self.maker.alignment

    # ----- epochs and preintegration -------------------------------------------------------------
    def _select_epochs(self) -> list[Epoch]:
        """States at the keyframes among the usable (and decimated) pings and at the dropout fillers; the other
        pings go to the state before them (Epoch.between)."""
        dvl, imu, cfg = self.log.dvl, self.log.imu, self.config
        spacing = cfg.solver.keyframe_spacing_s
        if spacing > cfg.solver.max_state_spacing_s:
            raise GtsamDvlError(
                f"solver.keyframe_spacing_s = {spacing:g} s needs solver.max_state_spacing_s >= "
                f"{spacing:g} s: states without a ping would take the places of the keyframes"
            )
        self.usable, all_idx, key = decide_epochs(
            dvl,
            imu,
            cfg.dvl,
            cfg.solver.keyframe_interval_s,
            spacing,
            self.counters,
            water_current(cfg),
        )
        # the last ping too: every other ping lies between two states (and the gaps they cross)
        key[-1:] = True
        idx = all_idx[key]
        times, is_filler = with_fillers(
            dvl.t[idx], float(imu.t[-1]), cfg.solver.max_state_spacing_s
        )
        self.counters["states_without_ping"] = int(is_filler.sum())
        self.counters["keyframes"] = int(key.sum())
        self.counters["pings_between_keyframes"] = int((~key).sum())
        dvl_index = np.full(len(times), -1)
        dvl_index[~is_filler] = idx
        gyro = covering_sample(imu.t, times)
        epochs = [
            Epoch(float(t), int(j), self.maker.body_rate(imu.b_omega[g]))
            for t, j, g in zip(times.tolist(), dvl_index.tolist(), gyro.tolist(), strict=True)
        ]
        rest = all_idx[~key]
        if len(rest):
            # the latest state before each ping
            state = np.searchsorted(times, dvl.t[rest], side="left") - 1
            gyro_p = covering_sample(imu.t, dvl.t[rest])
            for j, i, g in zip(rest.tolist(), state.tolist(), gyro_p.tolist(), strict=True):
                epochs[i].between.append(
                    BetweenPing(float(dvl.t[j]), int(j), self.maker.body_rate(imu.b_omega[g]))
                )
        if enabled(cfg, "time_offset"):
            self.set_time_offset_window(cfg.dvl.time_offset_prior_s, epochs)
        return epochs

    def set_time_offset_window(
        self, dt: float, epochs: list[Epoch] | None = None, values: gtsam.Values | None = None
    ) -> None:
        """The epochs' IMU constants of the time-offset model, averaged around t + dt / 2 (dt: the current
        estimate of the offset; FactorMaker.velocity_rate_input). Factors built afterwards use them. values: the
        current estimate, whose IMU biases are taken off the samples and whose attitudes remove the Earth rate
        (offset_state); None: no bias, the alignment's attitude."""
        imu = self.log.imu
        owners: list[Epoch | BetweenPing] = []
        state: list[int] = []
        for i, ep in enumerate(self.epochs if epochs is None else epochs):
            if ep.dvl_index >= 0:
                owners.append(ep)
                state.append(i)
            owners += ep.between
            state += [i] * len(ep.between)
        if not owners:
            return
        bias, n_R_b = self.offset_state(np.array(state), values)
        b_a, w_mean, G = self.maker.velocity_rate_inputs(
            np.array([o.t for o in owners]), imu.t, imu.b_f, imu.b_omega, dt, bias=bias, n_R_b=n_R_b
        )
        for o, a, m, g in zip(owners, b_a, w_mean, G, strict=True):
            o.rate_input = (a, m, g)
        self._windows_set(dt, np.array(state), bias)

    def _windows_set(
        self, dt: float, state: np.ndarray, bias: tuple[np.ndarray, np.ndarray] | None
    ) -> None:
        """Records what the time offset's windows were last set at: their centre, states and accelerometer bias."""
        self.offset_centre = float(dt)
        self.offset_rows = np.asarray(state, dtype=int)
        self.offset_accel_bias = np.zeros((len(state), 3)) if bias is None else np.asarray(bias[0])

    def offset_guess(self) -> OffsetGuess:
        """The time offset's first guess from the data (estimators/inputs/offset_guess.py) on the usable bottom-track
        pings, from the alignment's attitude."""
        log, cfg = self.log, self.config
        idx = self.usable[~self.water[self.usable]] if len(self.water) else self.usable
        t_ref = float(log.imu.t[0]) if self.alignment.t_ref is None else float(self.alignment.t_ref)
        return guess_offset(
            np.asarray(log.imu.t, dtype=float),
            np.asarray(log.imu.b_omega, dtype=float),
            np.asarray(log.imu.b_f, dtype=float),
            self.alignment.n_R_b,
            t_ref,
            np.asarray(log.dvl.t, dtype=float)[idx],
            np.asarray(log.dvl.d_v, dtype=float)[idx],
            log.mounting.b_R_d0,
            self.maker.offset_gravity(),
            self.maker.n_omega_ie(),
            cfg.dvl.time_offset_prior_s,
        )

    def offset_state(
        self, state: np.ndarray, values: gtsam.Values | None, attitude: bool = True
    ) -> tuple[tuple[np.ndarray, np.ndarray] | None, np.ndarray | None]:
        """The IMU biases (accelerometer m/s^2, gyro rad/s; each (P, 3)) and, with attitude, the attitudes n_R_b
        (P, 3, 3) of the states `state` (indices) in values, for the time offset's IMU windows; (None, None) without
        values."""
        if values is None:
            return None, None
        state = np.asarray(state, dtype=int)
        ks = [self.maker.bias_key(int(i)) for i in state]
        biases = {k: values.atConstantBias(k) for k in set(ks)}
        acc = np.array([biases[k].accelerometer() for k in ks]).reshape(-1, 3)
        gyro = np.array([biases[k].gyroscope() for k in ks]).reshape(-1, 3)
        if not attitude:
            return (acc, gyro), None
        rot = {int(i): values.atPose3(X(int(i))).rotation().matrix() for i in np.unique(state)}
        return (acc, gyro), np.array([rot[int(i)] for i in state]).reshape(-1, 3, 3)

    def ping_snapshot(self, p: BetweenPing) -> PingMotion:
        """The IMU motion from the state before a ping between keyframes up to it (estimators/graph/keyframes.py)."""
        if self.snapshots is None or p.snap < 0:
            raise GtsamDvlError(
                "between_factors: build_bulk let the pings' IMU snapshots go; build the per-factor "
                "graph first, or make a new LogGraph"
            )
        return self.snapshots.get(p.snap)

    def _preintegrate(self, imu: ImuPieces) -> list[Holds]:
        """The IMU intervals between the epochs (imu: the log's samples as ImuPieces), each integrated once, the
        IMU motion to each ping between keyframes taken on the way (keyframes.interval_with_snapshots); returns
        what each interval held across IMU gaps."""
        self.pims, self.imu_params = [], []
        self.snapshots = PingMotion.empty(sum(len(ep.between) for ep in self.epochs))
        held: list[Holds] = []
        q = 0
        n = len(self.epochs) - 1
        every = max(1, n // 20)
        for i, (a, b) in enumerate(zip(self.epochs[:-1], self.epochs[1:], strict=True)):
            if self.progress is not None and i % every == 0:
                self.progress(i / n)
            if a.between:
                params = self.maker.make_params()
                pim, h, snaps = interval_with_snapshots(
                    a.t, b.t, [p.t for p in a.between], params, imu, self.config.imu
                )
                for p, snap in zip(a.between, snaps, strict=True):
                    self.snapshots.put(q, snap)
                    p.snap = q
                    q += 1
            else:
                pim, params, h = self.maker.preintegrate_interval(a.t, b.t, imu)
            self.pims.append(pim)
            self.imu_params.append(params)
            held.append(h)
        return held

    # ----- gravity -------------------------------------------------------------------------------
    def set_gravity_from_positions(self, n_p: np.ndarray, only_stale: bool = False) -> int:
        """Reference gravity of the IMU factors at the mid positions of states n_p (N+1, 3), evaluated
        for all factors in one vectorised call, not a normal-gravity evaluation per factor. only_stale: just
        the factors whose mid position left their reference's range. Returns how many were updated."""
        if self.config.solver.earth_model == "flat":
            return 0
        mid = 0.5 * (n_p[:-1] + n_p[1:])
        refs = self.gravity_refs
        if only_stale:  # (EarthImuFactor.needs_reference, on the shared arrays)
            stale = np.isnan(refs.n_p[:, 0]) | (np.abs(mid - refs.n_p).max(axis=1) > REFRESH_M)
            idx = np.flatnonzero(stale)
        else:
            idx = np.arange(len(mid))
        if len(idx):
            g, G = self.maker.gravity_model(mid[idx])
            refs.n_p[idx], refs.n_g[idx], refs.G[idx] = mid[idx], g, G
            if self._imu_factors:
                for k, i in enumerate(idx.tolist()):
                    self._imu_factors[i].set_reference(mid[i], g[k], G[k])
                    self._imu_factors[i].set_gravity(mid[i])
            # what EarthImuFactor.set_gravity writes: the gravity pim.predict uses
            elif self.imu_params:
                for k, i in enumerate(idx.tolist()):
                    self.imu_params[i].n_gravity = g[k]
        return len(idx)

    def refresh_gravity(self, values: gtsam.Values) -> bool:
        """Between solver iterations: re-reference the factors that moved far (see factors/imu_earth.py).
        The objective changes by less than 1e-8 m/s^2 of gravity, so this reports no change."""
        # every Pose3 in key order: the states X(0..n-1)
        poses = gtsam.utilities.extractPose3(values)
        if poses.shape[0] == len(self.epochs):
            n_p = poses[:, 9:]
        else:
            n_p = np.array([values.atPose3(X(i)).translation() for i in range(len(self.epochs))])
        self.set_gravity_from_positions(n_p, only_stale=True)
        return False

    # ----- factors -------------------------------------------------------------------------------
    def imu_factor(self, i: int) -> gtsam.NonlinearFactor:
        """IMU factor between states i and i+1, gravity following position."""
        return self.imu_factors[i].factor

    def bias_factors(self, i: int) -> list[gtsam.NonlinearFactor]:
        """The links between states i and i + 1 of the per-epoch states that sit beside the IMU factor (the bias
        random walk: estimators/models/epoch_states.py)."""
        dt = self.epochs[i + 1].t - self.epochs[i].t
        out: list[gtsam.NonlinearFactor] = []
        for s in enabled_epoch_states(self.config):
            if s.beside_imu:
                out += s.link_factors(self.config, i, i + 1, dt)
        return out

    def dvl_factors(self, i: int) -> list[gtsam.NonlinearFactor]:
        """DVL factors of state i: the 3-D velocity, or one per valid beam."""
        dvl, ep = self.log.dvl, self.epochs[i]
        j = ep.dvl_index
        if j < 0:
            return []
        beams = (
            None if dvl.beams is None else (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
        )
        return self.maker.dvl_factors_for(
            i, dvl.d_v[j], dvl.d_cov[j], ep.b_omega, beams, ep.rate_input, bool(self.water[j])
        )

    def between_factors(self, i: int) -> list[gtsam.NonlinearFactor]:
        """DVL factors of the pings between state i and the next (keyframes, factors/dvl.py with a PingMotion), with
        gravity referenced at state i's position in gravity_positions (the initial guess; the map origin if
        unset). Normal gravity's gradient, 1.5e-6 s^-2, is in the factor: over 1 s it moves the predicted
        velocity by 1.5e-6 m/s per metre of position change."""
        ep = self.epochs[i]
        if not ep.between:
            return []
        dvl = self.log.dvl
        n_p0 = np.zeros(3) if self.gravity_positions is None else self.gravity_positions[i]
        if (
            self._keyframe_gravity is None
            or self._keyframe_gravity[0] is not self.gravity_positions
        ):
            # every state's at once, in one vectorised call
            n_p = (
                np.zeros((len(self.epochs), 3))
                if self.gravity_positions is None
                else self.gravity_positions
            )
            self._keyframe_gravity = (self.gravity_positions, *self.maker.keyframe_gravity(n_p))
        g, G = self._keyframe_gravity[1][i : i + 1], self._keyframe_gravity[2][i : i + 1]
        w = self.maker.n_omega_ie()
        out: list[gtsam.NonlinearFactor] = []
        for p in ep.between:
            s, j = self.ping_snapshot(p), p.dvl_index
            motion = s.motion(w, g[0], n_p0, G[0])
            beams = (
                None
                if dvl.beams is None
                else (dvl.beams.d_u[j], dvl.beams.v[j], dvl.beams.valid[j])
            )
            out += self.maker.dvl_keyframe_factors_for(
                i,
                dvl.d_v[j],
                dvl.d_cov[j],
                p.b_omega,
                motion,
                s.cov,
                beams,
                p.rate_input,
                bool(self.water[j]),
            )
        return out

    def layer_heights(self, z_guess: np.ndarray) -> np.ndarray:
        """The states' heights (m above the map origin) that place them in the water current's depth layers
        (estimators/models/current.py, "Layers"): the depth sensor's, interpolated at the states' stamps, when the log
        has one in use (the initial guess's height drifts with the misalignment's error: 1.7 cm/s at 2 m/s and
        0.5 deg), else the initial guess's z_guess."""
        depth = self.log.depth
        if depth is None or not self.config.depth.use or not len(depth):
            return z_guess
        samples = depth_samples(depth, self.config.depth, self.frame)
        if not len(samples.t):
            return z_guess
        return np.interp(np.array([ep.t for ep in self.epochs]), samples.t, samples.z_meas)

    def depth_factors(self) -> list[gtsam.NonlinearFactor]:
        """Depth factors of the log's depth samples (estimators/inputs/depth.py), each on its nearest state; none
        without depth data or with [depth] use = false. Counts "depth_used" and "depth_too_far"."""
        depth = self.log.depth
        if depth is None or not self.config.depth.use or not len(depth):
            return []
        samples = depth_samples(depth, self.config.depth, self.frame, self.counters)
        t_states = np.array([ep.t for ep in self.epochs])
        near, dt = nearest_states(t_states, samples.t, self.config.depth.max_time_to_state_s)
        self.counters["depth_used"] = int((near >= 0).sum())
        self.counters["depth_too_far"] = int((near < 0).sum())
        out: list[gtsam.NonlinearFactor] = []
        for k in np.flatnonzero(near >= 0).tolist():
            out += self.maker.depth_factors_for(
                int(near[k]),
                float(samples.z_meas[k]),
                float(samples.sigma[k]),
                samples.b_p_sensor,
                float(dt[k]),
            )
        return out

    def gnss_plan(self) -> GnssFixes | None:
        """The role of every GNSS message (estimators/inputs/gnss.py: used, held out, rejected); None without fixes."""
        return plan_fixes(self.log, self.config, self.frame, np.array([ep.t for ep in self.epochs]))

    def gnss_factors(self, plan: GnssFixes | None = None) -> list[gtsam.NonlinearFactor]:
        """GNSS factors of the fixes that aid ([gnss] use), each on its nearest state's antenna position; none
        without fixes. Counts "gnss_used", "gnss_held_out" and "gnss_rejected" (with its reasons)."""
        plan = self.gnss_plan() if plan is None else plan
        if plan is None:
            return []
        self.counters.update(plan.counters())
        out: list[gtsam.NonlinearFactor] = []
        for k in np.flatnonzero(plan.mask("used")).tolist():
            out += self.maker.gnss_factors_for(
                int(plan.state[k]), plan.n_p[k], plan.cov[k], plan.b_p_antenna, float(plan.dt[k])
            )
        return out

    # ----- initial guess -------------------------------------------------------------------------
    def initial_values(self) -> gtsam.Values:
        """Dead reckoning: attitude from the gyros (from the alignment), velocity from the DVL at the
        initial scale and nominal mounting, position by integrating that velocity."""
        if len(self.pims) + 1 != len(self.epochs):
            raise GtsamDvlError(
                "initial_values: build_bulk let the preintegrations go; make a new LogGraph"
            )
        # at their priors
        values = initial_shared_values(self.config, self.maker.mounting, self.calibration)
        dvl = self.log.dvl
        zero_bias = gtsam.imuBias.ConstantBias()
        n_p_all = np.zeros((len(self.epochs), 3))
        self.set_gravity_from_positions(n_p_all)
        n_R_b = gtsam.Rot3(self.alignment.n_R_b)
        # the origin carried to the first state
        n_p0 = None if self.maker.first is None else self.maker.first.n_p
        n_p, n_v = (
            first_position(self.gnss_plan(), n_R_b.matrix(), n_p0),
            np.zeros(3),
        )  # that unless GNSS
        for i, ep in enumerate(self.epochs):
            if i > 0:
                state = self.pims[i - 1].predict(gtsam.NavState(n_R_b, n_p, n_v), zero_bias)
                n_R_b = state.attitude()
            j = ep.dvl_index
            # (water track: relative to the water, W = 0)
            usable = j >= 0 and (dvl.valid[j] or self.water[j])
            n_v_ping = self.maker.velocity_from_ping(n_R_b.matrix(), dvl.d_v[j] if usable else None)
            n_v_new = n_v if n_v_ping is None else n_v_ping
            if i > 0:
                n_p = n_p + 0.5 * (n_v + n_v_new) * (ep.t - self.epochs[i - 1].t)
            n_v = n_v_new
            n_p_all[i] = n_p
            values.insert(X(i), gtsam.Pose3(n_R_b, n_p))
            values.insert(V(i), n_v)
        self._epoch_initial_values(values, n_p_all[:, 2])
        self.set_gravity_from_positions(n_p_all)
        self.gravity_positions = n_p_all
        return values

    def _epoch_initial_values(self, values: gtsam.Values, z: np.ndarray) -> None:
        """The per-epoch states' variables at their priors' means (estimators/models/epoch_states.py; state 0's of
        the bias random walk is the shared state's), and their extra variables (the water current's layer
        boundaries) at zero; z (N,) m: the states' heights in the initial guess."""
        t = np.array([ep.t for ep in self.epochs])
        self.path = StatePath(t, z, self.layer_heights(z), self.frame.height_m)
        self.extra_keys = []
        for s in enabled_epoch_states(self.config):
            for i in range(1 if s.first_shared else 0, len(self.epochs)):
                s.insert(values, s.key(i), s.initial(self.config))
            extra = s.extra_keys(self.config, self.path)
            for k in extra:
                values.insert(k, np.zeros(key_dim(k)))
            self.extra_keys += extra

    @property
    def shear(self) -> list[int]:
        """The water current's layer boundaries b the states cross (their keys S(b) among extra_keys)."""
        return [
            gtsam.Symbol(k).index() for k in self.extra_keys if chr(gtsam.Symbol(k).chr()) == "s"
        ]

    def build(self) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
        """The whole graph and its initial guess (batch smoothing, covariance analysis)."""
        if self._imu_factors == []:
            raise GtsamDvlError(
                "build: build_bulk let the IMU factors go (their numbers are in the bulk graph); "
                "make a new LogGraph"
            )
        values = self.initial_values()
        graph = self._factors_but_dvl(values)
        # its IMU factors follow the gravity references too (build_bulk keeps them)
        self._per_factor_built = True
        for i in range(len(self.epochs)):
            for f in self.dvl_factors(i) + self.between_factors(i):
                graph.add(f)
        return graph, values

    def _factors_but_dvl(
        self, values: gtsam.Values, imu: bool = True
    ) -> gtsam.NonlinearFactorGraph:
        """The priors, IMU (imu=False: not them) and bias-link factors, depth and GNSS factors: all but the
        DVL's."""
        graph = gtsam.NonlinearFactorGraph()
        self.factor_slots = {}

        # (their slots: factor_slots[name])
        def add(name: str, factors: list[gtsam.NonlinearFactor]) -> None:
            start = graph.size()
            for f in factors:
                graph.add(f)
            self.factor_slots[name] = range(start, graph.size())

        gnss = self.gnss_plan()
        for f in self.maker.prior_factors(values, first_position_cov(gnss)):
            graph.add(f)
        for i in range(len(self.epochs) - 1):
            if imu:
                graph.add(self.imu_factor(i))
            for f in self.bias_factors(i):
                graph.add(f)
        if self.path is None:
            raise GtsamDvlError("the graph's factors need its initial guess first (initial_values)")
        # each per-epoch state's prior and links (epoch_states.py)
        for s in enabled_epoch_states(self.config):
            add(s.name, s.graph_factors(self.config, self.path))
        add("depth", self.depth_factors())
        add("gnss", self.gnss_factors(gnss))
        return graph

    def build_bulk(self, values: gtsam.Values | None = None) -> tuple[BulkGraph, gtsam.Values]:
        """build() with the DVL velocity factors evaluated in bulk (estimators/graph/bulk.py): the same objective and
        linear systems, several times faster to evaluate. values: an initial guess already made (a second
        build after set_time_offset_window keeps the first's gravity references)."""
        if self.snapshots is None:
            raise GtsamDvlError(
                "build_bulk: the pings' IMU snapshots were let go by an earlier build_bulk (1 kB a "
                "ping); make a new LogGraph for another graph"
            )
        values = self.initial_values() if values is None else values
        graph = self._factors_but_dvl(values, imu=False)
        bulk = BulkGraph(graph, bulk_dvl(self), self.bulk_imu())
        # the bulk factors hold the snapshots', time-offset windows' and IMU factors' numbers: let the LogGraph's
        # copies go unless a per-factor graph holds the IMU factors, and the preintegrations
        self.snapshots = None
        for ep in self.epochs:
            ep.rate_input = None
            for p in ep.between:
                p.rate_input = None
        self.pims, self.imu_params = [], []
        if not self._per_factor_built:
            self._imu_factors = []
        return bulk, values

    def bulk_imu(self) -> BulkImu:
        """The IMU factors as arrays (estimators/graph/bulk_imu.py): each interval's preintegration, bias Jacobian,
        gravity
        map and whitening (GTSAM's, of the covariance the EarthImuFactor gets: FactorMaker.new_imu_factor), with
        the gravity references this LogGraph keeps."""
        if len(self.pims) + 1 != len(self.epochs):
            raise GtsamDvlError(
                "bulk_imu: build_bulk let the preintegrations go; make a new LogGraph"
            )
        n_omega = np.asarray(self.maker.n_omega_ie(), dtype=float)
        x, H, dt = bias_jacobians(self.pims, n_omega)
        arrays = ImuArrays(x=x, H=H, dt=dt, n_omega=n_omega, M=gravity_maps(n_omega, dt))
        whiten = np.empty((len(self.pims), 9, 9))
        keys: list[tuple[int, int, int, int, int]] = []
        for i, (pim, h) in enumerate(zip(self.pims, self.imu_held, strict=True)):
            cov = pim.preintMeasCov()
            extra = self.maker.imu_hold_cov(h, self.epochs[i + 1].t - self.epochs[i].t)
            if extra is not None:
                cov = cov + extra
            # the noise model's own square root information (a Gaussian's R), so that the rows are GTSAM's
            whiten[i] = gtsam.noiseModel.Gaussian.Covariance(cov).R()  # type: ignore[attr-defined]
            keys.append(self.maker.imu_keys(i))
        state_bias_keys = [self.maker.bias_key(i) for i in range(len(self.epochs))]
        return BulkImu(arrays, whiten, keys, self.gravity_refs, state_bias_keys)

    def recentre_time_offset(
        self,
        graph: gtsam.NonlinearFactorGraph | BulkGraph,
        dt: float,
        values: gtsam.Values | None = None,
    ) -> gtsam.NonlinearFactorGraph | BulkGraph:
        """The graph with the time-offset windows centred on the offset estimate dt (set_time_offset_window),
        the IMU biases of values taken off their samples and each ping's attitude in values removing the Earth
        rate: a BulkGraph is updated in place (only the pings' IMU constants change), a per-factor graph built
        again."""
        # straight into the bulk factors (the epochs' own let go by build_bulk)
        if isinstance(graph, BulkGraph):
            imu = self.log.imu
            bias, n_R_b = self.offset_state(graph.bulk.pings.state, values)
            b_a, w_mean, G = self.maker.velocity_rate_inputs(
                graph.bulk.t_ping, imu.t, imu.b_f, imu.b_omega, dt, bias=bias, n_R_b=n_R_b
            )
            graph.bulk.set_offset_inputs(w_mean, b_a, G, self.maker.mounting.b_l)
            self._windows_set(dt, graph.bulk.pings.state, bias)
            return graph
        self.set_time_offset_window(dt, values=values)
        return self.build()[0]

    def elimination_ordering(self, chunk_states: int = CHUNK_STATES) -> ChunkedOrdering:
        """States in time order, the shared states' keys last (core/states.py): the Bayes net is a chain
        whose root holds the calibration block, and marginals follow by one backward pass. Given in chunks of
        chunk_states states, which the solver eliminates one at a time when there are more than
        solver.CHUNKED_FROM_STATES states (solver.eliminate: the same Bayes net, in time linear in the mission);
        .ordering() is the plain gtsam.Ordering."""
        keys: list[int] = []
        chunks: list[list[int]] = []
        for i in range(len(self.epochs)):
            keys += state_keys(self.config, i)
            if (i + 1) % chunk_states == 0 or i + 1 == len(self.epochs):
                chunks.append(keys)
                keys = []
        # (the per-epoch states' extra variables with the shared states: every state may reach them)
        return ChunkedOrdering(chunks, shared_keys(self.config, per_state=False) + self.extra_keys)
