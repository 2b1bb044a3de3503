"""The batch smoother's solve: the log's graph in bulk, Gauss-Newton with QR and the time offset's windows
re-centred on the estimate (solve_centred), the noise levels from the data, and the result read from the solution
(extract_result). batch.py (smooth_batch) and the pieces and dives of multi_dive.py and pieces.py build on it."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.keys import T_OFFSET, S, V, W, X
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.states import (
    correlated_error,
    enabled,
    read_estimates,
    read_values,
    shared_keys,
    water_current,
)
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.graph.bulk import BulkGraph, graph_rows
from gtsam_dvl.estimators.graph.log_graph import LogGraph
from gtsam_dvl.estimators.graph.solver import (
    ChunkedOrdering,
    CompactBayesNet,
    SolveReport,
    bayes_net_marginals,
    eliminate,
    gauss_newton_qr,
    tail_covariance,
)
from gtsam_dvl.estimators.inputs.depth import depth_samples
from gtsam_dvl.estimators.models import correlated_fit, current
from gtsam_dvl.estimators.models.epoch_states import graph_estimates, reports
from gtsam_dvl.estimators.models.noise_levels import (
    SCREEN_K,
    SENSOR_GROUPS,
    LongLevel,
    NoiseReport,
    chi2_ratio,
    dvl_fit_enabled,
    dvl_fit_report,
    fitted_multiplier,
    honest_multiplier,
    imu_levels,
    long_level,
    median_ping_sigma,
    multiplier_bounds,
    robust_inside,
    sensor_fit_enabled,
    sensor_fit_report,
    sensor_multiplier,
    sensor_not_fitted,
    with_levels,
    with_sensor_multiplier,
)


@dataclass
class SolvedLog:
    """solve_log's solution: the LogGraph, its bulk graph, the estimate and the elimination ordering, with the last
    pass's report, each pass's figures and the final chi^2's degrees of freedom."""

    builder: LogGraph
    graph: BulkGraph
    values: gtsam.Values
    ordering: ChunkedOrdering
    report: SolveReport
    passes: list[dict[str, float]]
    dof: int

    def result(self, estimator: str = "batch") -> NavResult:
        """Its estimates and marginals (extract_result), from the converged iteration's Bayes net when the last
        step was tiny (every GN iteration's stop rule makes the last step change the error by < 0.01, i.e. far
        below one sigma)."""
        return extract_result(
            self.builder,
            self.graph,
            self.values,
            self.ordering,
            estimator=estimator,
            bayes_net=self.report.bayes_net if self.report.converged else None,
        )


def solve_log(
    log: LogData,
    config: EstimatorConfig,
    noise: NoiseReport,
    timing: dict[str, float],
    calibration: VehicleCalibration | None = None,
    progress: ProgressFn | None = None,
    t0: float | None = None,
) -> SolvedLog:
    """The batch smoother's solve of a screened log (config with "auto" resolved): the IMU levels from the data,
    the graph in bulk, Gauss-Newton (both passes with the time offset) and the DVL noise fit (SolvedLog); noise
    records the levels used, timing the phases' seconds (t0: when the run began)."""
    t0 = time.perf_counter() if t0 is None else t0
    # the IMU's white noise from the data ([noise], noise_levels.py)
    config = imu_levels(log, config, noise)
    builder = LogGraph(
        log,
        config,
        progress=(lambda f: progress(0.15 * f)) if progress else None,
        calibration=calibration,
    )
    timing["preintegrate"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    # the DVL and IMU factors evaluated in bulk (estimators/graph/bulk.py: the same objective as builder.build())
    bulk, values = builder.build_bulk()
    ordering = builder.elimination_ordering()
    # degrees of freedom of the final chi^2 (= 2 x final_error): measurement rows minus variable dimensions
    dof = graph_rows(bulk) - values.dim()
    # the offset's first guess (estimators/inputs/offset_guess.py)
    if enabled(builder.config, "time_offset"):
        guess = builder.offset_guess()
        builder.offset_centring = {"guess": guess.as_dict()}
        if guess.used:
            values.update(T_OFFSET, np.array([guess.guess_s]))
            builder.recentre_time_offset(bulk, guess.guess_s)
    timing["build"] = time.perf_counter() - t1
    if progress:
        progress(0.2)

    t2 = time.perf_counter()
    graph, values, report, passes = solve_graph(
        builder,
        bulk,
        values,
        ordering,
        progress=(lambda f: progress(0.2 + 0.6 * f)) if progress else None,
    )
    if not isinstance(graph, BulkGraph):  # (solve_graph keeps a BulkGraph a BulkGraph)
        raise GtsamDvlError("solve_log: the batch smoother's bulk graph expected")
    if (
        dvl_fit_enabled(builder.config)
        or fitted_sensors(builder)
        or correlated_fit.fit_enabled(builder.config)
    ):
        values, report = fit_dvl_noise(builder, graph, values, ordering, report, passes, noise)
    timing["solve"] = time.perf_counter() - t2
    return SolvedLog(builder, graph, values, ordering, report, passes, dof)


# A first pass that the time offset's re-centring follows stops once an iteration lowers the error by less than
# this (half a chi^2 unit: the step is within one sigma, Mahalanobis, of the first pass's solution), whatever the
# configured tolerances: its solution only centres the offset's windows, and the passes after it converge to the
# configured tolerances.
FIRST_PASS_TOL = 0.5
# The time offset's IMU windows are consistent with a solution when their centre is within this fraction of the
# offset's sigma of its estimate, and the accelerometer bias taken off their samples differs from the estimate's
# by less than RECENTRE_BIAS_M_S over the offset (a phantom velocity of 0.1 mm/s, 50 ppm of scale at 2 m/s: far
# below what a DVL's slow error of a few mm/s lets the calibration resolve).
RECENTRE_FRACTION = 0.1
RECENTRE_BIAS_M_S = 1e-4
# Re-centrings at the most in one solve_centred call; each is one more Gauss-Newton pass. The offset's first-order
# model converges in two or three from a guess within its window (docs/results.md): more says the model is off.
MAX_RECENTRES = 6


def solve_graph(
    builder: LogGraph,
    graph: gtsam.NonlinearFactorGraph | BulkGraph,
    values: gtsam.Values,
    ordering: gtsam.Ordering | ChunkedOrdering,
    progress: ProgressFn | None = None,
) -> tuple[
    gtsam.NonlinearFactorGraph | BulkGraph, gtsam.Values, SolveReport, list[dict[str, float]]
]:
    """Gauss-Newton (QR) on a LogGraph's graph, with [dvl] estimate_time_offset the offset's windows re-centred
    until they agree with the solution (solve_centred). Returns the graph (the recentred one), the solution, the
    last pass's report (its Bayes net serves the marginals) and each pass's iterations and seconds."""
    passes: list[dict[str, float]] = []
    graph, values, report = solve_centred(
        builder, graph, values, ordering, passes, progress=progress, first=True
    )
    return graph, values, report, passes


def solve_centred(
    builder: LogGraph,
    graph: gtsam.NonlinearFactorGraph | BulkGraph,
    values: gtsam.Values,
    ordering: gtsam.Ordering | ChunkedOrdering,
    passes: list[dict[str, float]],
    progress: ProgressFn | None = None,
    first: bool = False,
) -> tuple[gtsam.NonlinearFactorGraph | BulkGraph, gtsam.Values, SolveReport]:
    """Gauss-Newton, and with the time offset: while the offset's IMU windows disagree with the solution (their
    centre more than RECENTRE_FRACTION of the offset's sigma from its estimate, or the accelerometer bias taken off
    their samples more than RECENTRE_BIAS_M_S / |dt| from the estimate's), the windows re-centred on the solution
    (LogGraph.recentre_time_offset: the offset's velocity rate averaged over [t, t + dt_hat], a secant, with the
    biases and the ping's attitude of the solution) and solved again. A linearisation point fixed after one early
    pass converges to the wrong answer (0.90 s centred, 1.02 s estimated: the scale 2 % off); re-centred until
    consistent, the final centre is the final offset. Every solve of the batch smoother goes through here (the first,
    the noise fit's, the weak hold's). first: the log's first solve, whose first pass stops at FIRST_PASS_TOL (a
    re-solve starts near its solution). builder.offset_centring records the last check; each pass is appended to
    passes."""
    kw = _solver_options(builder)
    offset = enabled(builder.config, "time_offset")
    loose = offset and first
    values, report = gauss_newton_qr(
        graph,
        values,
        ordering,
        progress=progress,  # type: ignore[arg-type]
        **({**kw, "absolute_tol": max(kw["absolute_tol"], FIRST_PASS_TOL)} if loose else kw),
    )
    passes.append({"iterations": report.iterations, **report.timing_s})
    recentres = 0
    while offset:
        check = offset_check(builder, values, report)
        builder.offset_centring = {**builder.offset_centring, **check, "recentred": recentres}
        if check["consistent"] and not loose:
            break
        if not check["consistent"]:
            if recentres >= MAX_RECENTRES:
                break  # reported: offset_centring["consistent"] is False
            graph = builder.recentre_time_offset(graph, check["estimate_s"], values)
            recentres += 1
        values, report = gauss_newton_qr(graph, values, ordering, **kw)  # type: ignore[arg-type]
        passes.append({"iterations": report.iterations, **report.timing_s})
        loose = False
    return graph, values, report


def offset_check(builder: LogGraph, values: gtsam.Values, report: SolveReport) -> dict[str, Any]:
    """Whether the time offset's windows agree with the solution values (solve_centred): the estimate, its sigma
    (from the last Bayes net's tail: core/states.py puts the shared keys last), the windows' centre and bias."""
    dt_hat = float(read_values(values, builder.config)["time_offset"][0])
    sigma = math.nan
    if report.bayes_net is not None:
        sigma = float(math.sqrt(tail_covariance(report.bayes_net, [T_OFFSET])[0, 0]))
    bias_now, _ = builder.offset_state(builder.offset_rows, values, attitude=False)
    assert bias_now is not None
    step = np.abs(builder.offset_accel_bias - bias_now[0])
    bias_step = float(step.max()) * abs(dt_hat) if step.size else 0.0
    centre_ok = abs(dt_hat - builder.offset_centre) <= RECENTRE_FRACTION * sigma
    return {
        "estimate_s": dt_hat,
        "sigma_s": sigma,
        "centre_s": builder.offset_centre,
        "bias_step_m_s": bias_step,
        "consistent": bool(centre_ok and bias_step <= RECENTRE_BIAS_M_S),
    }


def _solver_options(builder: LogGraph) -> dict[str, Any]:
    """gauss_newton_qr's options from the [solver] section, gravity following the positions."""
    s = builder.config.solver
    return dict(
        max_iterations=s.max_iterations,
        relative_tol=s.relative_error_tol,
        absolute_tol=s.absolute_error_tol,
        before_iteration=builder.refresh_gravity,
    )


def fitted_sensors(builder: LogGraph) -> list[str]:
    """The sensor groups besides the DVL whose noise factor the batch fit takes (SENSOR_GROUPS): fitting
    enabled ([noise] fit_depth, fit_gnss) and factors in the graph."""
    return [
        s
        for s in SENSOR_GROUPS
        if sensor_fit_enabled(builder.config, s) and len(builder.factor_slots.get(s, ()))
    ]


def _long_level(
    builder: LogGraph,
    graph: BulkGraph,
    sensor: str,
    values: gtsam.Values,
    t_rows: np.ndarray,
    ew: np.ndarray,
    robust_k: float,
) -> LongLevel | None:
    """The long-window level (noise_levels.long_level) of sensor's rows within the robust screen: the DVL's
    bottom-track rows with the estimated correlated error E added back (correlated_fit.residual_series: what the
    DVL's slow error is, not what E left of it), whitened at the current level."""
    if sensor == "dvl" and correlated_error(builder.config) and graph.bulk.pings.dim == 3:
        t, r = correlated_fit.residual_series(graph.bulk, values)
        ok = np.isfinite(r).all(axis=1)
        return long_level(t[ok], np.einsum("nij,nj->ni", graph.bulk.whiten[ok], r[ok]))
    inside = robust_inside(np.einsum("ni,ni->n", ew, ew), ew.shape[1], robust_k)
    if sensor == "dvl" and graph.bulk.water is not None:  # the slow error is the bottom track's
        inside &= ~graph.bulk.water
    return long_level(t_rows[inside], ew[inside])


def _fit_rows(
    builder: LogGraph, graph: BulkGraph, sensor: str, values: gtsam.Values
) -> tuple[np.ndarray, np.ndarray]:
    """The times (N,) s and whitened errors (N, m) at values of sensor's rows that its noise fit takes: the DVL's
    bulk rows (before the robust kernel), or the (non-robust) depth or GNSS factors at their slots (each at its
    state's time)."""
    if sensor == "dvl":
        return graph.bulk.t_ping, graph.bulk.whitened_errors(values)
    t_states = np.array([ep.t for ep in builder.epochs])
    factors = [graph.graph.at(i) for i in builder.factor_slots[sensor]]
    dim = 3 if sensor == "gnss" else 1
    ew = np.array(
        [
            np.asarray(f.whitenedError(values))  # type: ignore[attr-defined,type-var]
            for f in factors
        ],
        dtype=float,
    ).reshape(-1, dim)
    t = np.array([t_states[gtsam.Symbol(f.keys()[0]).index()] for f in factors], dtype=float)
    return t, ew


def _sensor_sigma(builder: LogGraph, sensor: str) -> float:
    """The median sigma of sensor's factors at builder.config's factor (m; a fix's per axis)."""
    if sensor == "depth":
        assert builder.log.depth is not None
        sigma = depth_samples(builder.log.depth, builder.config.depth, builder.frame).sigma
    else:
        plan = builder.gnss_plan()
        assert plan is not None
        cov = plan.cov[plan.mask("used")]
        sigma = np.sqrt(np.trace(cov, axis1=1, axis2=2) / 3.0)
    return float(np.median(sigma)) if len(sigma) else math.nan


def _replace_sensor_factors(builder: LogGraph, graph: BulkGraph, sensor: str) -> None:
    """sensor's factors in graph made again at builder.config's noise factor, in their slots."""
    factors = builder.depth_factors() if sensor == "depth" else builder.gnss_factors()
    slots = builder.factor_slots[sensor]
    if len(factors) != len(slots):
        raise GtsamDvlError(
            f"fit_dvl_noise: {len(factors)} {sensor} factors made again for {len(slots)} slots"
        )
    for i, f in zip(slots, factors, strict=True):
        graph.graph.replace(i, f)


@dataclass
class _NoiseFit:
    """The state of fit_dvl_noise's loop: the sensors still fitted, the multiplier each factor uses, the levels
    given (configured, preset, message covariances: the honest level's floor), each fit's rows and (multiplier, at
    its bound), the white fit and long-window level behind it; the correlated error's slots and last fit."""

    sensors: list[str]
    used: dict[str, float]
    configured: dict[str, tuple[float, float]]
    stated: dict[str, float]
    configured0: EstimatorConfig  # builder.config when the fit started (the fits' bounds, [noise])
    gm_slots: range
    t_states: np.ndarray
    rows: dict[str, int] = field(default_factory=dict)
    fits: dict[str, tuple[float, bool]] = field(default_factory=dict)
    levels: dict[str, dict[str, Any]] = field(default_factory=dict)
    gm_fit: correlated_fit.LevelFit | None = None

    @classmethod
    def start(cls, builder: LogGraph) -> _NoiseFit:
        cfg = builder.config
        sensors = (["dvl"] if dvl_fit_enabled(cfg) else []) + fitted_sensors(builder)
        used = {s: sensor_multiplier(cfg, s) for s in sensors}
        return cls(
            sensors,
            used,
            {s: (used[s], _sensor_sigma(builder, s)) for s in sensors if s != "dvl"},
            dict(used),
            builder.config,
            builder.factor_slots.get("dvl_error", range(0))
            if correlated_fit.fit_enabled(cfg)
            else range(0),
            np.array([ep.t for ep in builder.epochs]),
        )

    def fit_sensors(
        self, builder: LogGraph, graph: BulkGraph, values: gtsam.Values, noise: NoiseReport
    ) -> None:
        """Each sensor's variance component on the solution values; a sensor with fewer than [noise] min_rows rows
        leaves the fit (it keeps the factor it has)."""
        cfg, n = self.configured0, self.configured0.noise
        for s in list(self.sensors):
            t_rows, ew = _fit_rows(builder, graph, s, values)
            dim = ew.shape[1]
            k = graph.bulk.robust_k if s == "dvl" else SCREEN_K
            ratio, used_rows = chi2_ratio(np.einsum("ni,ni->n", ew, ew), dim, k)
            self.rows[s] = used_rows * dim
            if self.rows[s] < n.min_rows or not np.isfinite(ratio):
                self._not_fitted(s, used_rows, n.min_rows, noise)
                continue
            white, at_bound = fitted_multiplier(self.used[s], ratio, cfg, s)
            long = _long_level(builder, graph, s, values, t_rows, ew, k)
            # only GNSS fixes observe the DVL's slow error (the IMU cannot, at 30-60 s); nothing in these logs
            # observes the depth sensor's or the fixes' own
            can_lower = s == "dvl" and len(builder.factor_slots.get("gnss", ())) > 0
            honest, why = honest_multiplier(
                white, self.used[s], self.stated[s], long, multiplier_bounds(cfg, s), can_lower
            )
            self.fits[s] = honest, at_bound and honest == white
            self.levels[s] = {
                "white_multiplier": white,
                "stated_multiplier": self.stated[s],
                "honest_why": why,
                "long": None if long is None else long.as_dict(self.used[s]),
            }

    def _not_fitted(self, s: str, used_rows: int, min_rows: int, noise: NoiseReport) -> None:
        self.sensors.remove(s)  # keeps the factor it has
        self.fits.pop(s, None)
        if s == "dvl":
            noise.dvl = {
                "multiplier": self.used[s],
                "rows": used_rows,
                "why": f"DVL noise not fitted: "
                f"{used_rows} usable residual rows, fewer than [noise] min_rows = {min_rows}",
            }
        else:
            setattr(noise, s, sensor_not_fitted(s, self.used[s], self.rows[s], min_rows))

    def moving(self, builder: LogGraph, graph: BulkGraph, values: gtsam.Values) -> list[str]:
        """The fits that moved beyond their tolerance ("dvl_correlated": the correlated error's level and time
        constant, correlated_fit.py)."""
        n = self.configured0.noise
        out = [
            s for s in self.sensors if abs(self.fits[s][0] / self.used[s] - 1.0) > n.fit_tolerance
        ]
        if self.gm_slots:
            d = builder.config.dvl
            self.gm_fit = correlated_fit.fit_level(
                *correlated_fit.residual_series(graph.bulk, values), builder.config
            )
            if self.gm_fit.moves(
                d.correlated_sigma_m_s, d.correlated_tau_s, n.correlated_tolerance
            ):
                out.append("dvl_correlated")
        return out

    def apply(self, builder: LogGraph, graph: BulkGraph, moving: list[str]) -> None:
        """The moved fits into the graph's factors (the DVL's whitening, the depth and GNSS factors made again,
        the correlated error's prior and links made again)."""
        bulk = graph.bulk
        for s in moving:
            if s == "dvl_correlated":
                assert self.gm_fit is not None
                sigma, tau = self.gm_fit.sigma_m_s, self.gm_fit.tau_s
                builder.config = correlated_fit.with_level(builder.config, sigma, tau)
                bulk.config = correlated_fit.with_level(bulk.config, sigma, tau)
                correlated_fit.replace_factors(
                    graph.graph, self.gm_slots, builder.config, self.t_states
                )
                continue
            new = self.fits[s][0]
            if s == "dvl":
                bulk.whiten *= self.used[s] / new  # W ~ 1 / sigma
            else:
                builder.config = with_sensor_multiplier(builder.config, s, new)
                _replace_sensor_factors(builder, graph, s)
            self.used[s] = new

    def report(self, builder: LogGraph, noise: NoiseReport, solves: int, settled: bool) -> None:
        """builder.config at the levels used, and noise's reports of each fit."""
        n = self.configured0.noise
        if self.gm_fit is not None:
            d = builder.config.dvl
            how = f"{solves} solve" + ("s" if solves > 1 else "")
            if self.gm_fit.moves(
                d.correlated_sigma_m_s, d.correlated_tau_s, n.correlated_tolerance
            ):
                how += (
                    f", not settled: the last fit asked for {self.gm_fit.sigma_m_s * 1e3:.3g} mm/s over "
                    f"{self.gm_fit.tau_s:.3g} s"
                )
            noise.dvl_correlated = correlated_fit.fit_report(
                self.configured0, builder.config, self.gm_fit, solves, how
            )
        for s in self.sensors:
            used = self.used[s]
            builder.config = with_sensor_multiplier(builder.config, s, used)
            how = f"{solves} solve" + ("s" if solves > 1 else "")
            new, at_bound = self.fits[s]
            if not settled and abs(new / used - 1.0) > n.fit_tolerance:
                how += f", not settled: the last fit asked for x {new / used:.3g}"
            if s == "dvl":
                noise.dvl = dvl_fit_report(
                    builder.config,
                    used,
                    self.rows[s],
                    solves,
                    at_bound,
                    median_ping_sigma(builder.config, builder.log.dvl.d_cov[builder.usable]),
                    how,
                )
            else:
                setattr(
                    noise,
                    s,
                    sensor_fit_report(
                        builder.config,
                        s,
                        *self.configured[s],
                        used,
                        self.rows[s],
                        solves,
                        at_bound,
                        how,
                    ),
                )
            with_levels(getattr(noise, s), self.levels[s], used)


def fit_dvl_noise(
    builder: LogGraph,
    graph: BulkGraph,
    values: gtsam.Values,
    ordering: ChunkedOrdering,
    report: SolveReport,
    passes: list[dict[str, float]],
    noise: NoiseReport,
) -> tuple[gtsam.Values, SolveReport]:
    """The variance components (estimators/models/noise_levels.py) of the DVL and of the depth and GNSS factors
    (fitted_sensors), each fitted on the solution from its own whitened residuals, and re-solved with until none
    changes by more than [noise] fit_tolerance, in at most fit_passes solves (the first included). A factor is
    applied only with a re-solve, so the solution and its Bayes net are always at the weights reported; a
    sensor with fewer than min_rows rows keeps its configured factor. With [noise] fit_correlated, the DVL's
    correlated error's level and time constant too (estimators/models/correlated_fit.py; settled within
    correlated_tolerance). builder.config takes the factors used ([dvl], [depth], [gnss] noise_multiplier, [dvl]
    correlated_sigma_m_s and correlated_tau_s), noise.dvl, noise.depth, noise.gnss and noise.dvl_correlated say
    how they came."""
    fit = _NoiseFit.start(builder)
    settled, solves = False, 1
    while True:
        fit.fit_sensors(builder, graph, values, noise)
        moving = fit.moving(builder, graph, values)
        if not moving:
            settled = True
            break
        if solves >= fit.configured0.noise.fit_passes:
            break
        fit.apply(builder, graph, moving)
        graph_c, values, report = solve_centred(builder, graph, values, ordering, passes)
        assert isinstance(graph_c, BulkGraph)
        solves += 1
    fit.report(builder, noise, solves, settled)
    return values, report


def _marginal_groups(
    cfg: EstimatorConfig, n: int
) -> tuple[list[tuple[int, ...]], tuple[int, ...], tuple[int, ...]]:
    """The joint marginals a result needs (extract_result): each state's (X, V), the calibration block's keys, each
    other shared key at the last state alone, and every shared state jointly (NavResult.shared_joint_cov,
    states.joint_states); with the calibration block's and the shared group."""
    last = shared_keys(cfg, n - 1)
    calib_group = tuple(shared_keys(cfg, n - 1, block=True))
    groups: list[tuple[int, ...]] = [(X(i), V(i)) for i in range(n)] + [calib_group]
    groups += [(k,) for k in last if k not in calib_group]
    shared_group = tuple(last)
    if shared_group != calib_group:
        groups.append(shared_group)
    return groups, calib_group, shared_group


def extract_result(
    builder: LogGraph,
    graph: gtsam.NonlinearFactorGraph | BulkGraph,
    values: gtsam.Values,
    ordering: gtsam.Ordering | ChunkedOrdering,
    estimator: str = "batch",
    bayes_net: gtsam.GaussianBayesNet | CompactBayesNet | None = None,
) -> NavResult:
    """Estimates and marginal covariances at `values` (QR elimination, backward pass); bayes_net: reuse
    the solver's last elimination instead of linearising again. The shared states (core/states.py) at the last
    state: the calibration block's keys jointly (calib_joint_cov), each other state's key on its own, and all of
    them jointly (shared_joint_cov)."""
    cfg = builder.config
    n = len(builder.epochs)
    groups, calib_group, shared_group = _marginal_groups(cfg, n)
    bn = bayes_net or eliminate(graph.linearize(values), ordering)
    marg = bayes_net_marginals(bn, groups)

    poses = [values.atPose3(X(i)) for i in range(n)]
    n_p = np.array([p.translation() for p in poses])
    n_R_b = np.array([p.rotation().matrix() for p in poses])
    n_v = np.array([values.atVector(V(i)) for i in range(n)])
    joints = [marg.joints[(X(i), V(i))] for i in range(n)]
    pose_cov = np.array([j[:6, :6] for j in joints])
    vel_cov = np.array([j[6:, 6:] for j in joints])
    pose_vel_cross = np.array([j[:6, 6:] for j in joints])
    calibration = read_estimates(values, marg.covariances, cfg, n - 1)
    # epochs' body rates already exclude Earth rate; remove the estimated gyro bias too
    b_omega = np.array([e.b_omega for e in builder.epochs]) - calibration["gyro_bias"].value
    info: dict[str, Any] = {
        "alignment": builder.maker.alignment_info(),
        "counters": dict(builder.counters),
        "epochs": n,
        "imu_gaps": builder.gaps.summary(),
    }
    t = np.array([e.t for e in builder.epochs])
    # (epoch_states.py)
    info.update(reports(cfg, graph_estimates(cfg, values, marg.covariances, t)))
    profile = None
    # the water current per state with its marginal sigmas (estimators/models/current.py)
    if water_current(cfg):
        profile = current.profile(
            np.array([e.t for e in builder.epochs]),
            n_p[:, 2],
            np.array([values.atVector(W(i)) for i in range(n)]),
            np.array([marg.covariances[W(i)] for i in range(n)]),
            cfg,
            current.epochs_with_water(builder),
            {b: (values.atVector(S(b)), marg.covariances[S(b)]) for b in builder.shear},
        )
    return NavResult(
        estimator=estimator,
        t=np.array([e.t for e in builder.epochs]),
        n_p=n_p,
        n_R_b=n_R_b,
        n_v=n_v,
        pose_cov=pose_cov,
        vel_cov=vel_cov,
        calibration=calibration,
        b_R_d0=builder.log.mounting.b_R_d0,
        t0_ns=builder.log.t0_ns,
        b_omega=b_omega,
        pose_vel_cross=pose_vel_cross,
        calib_joint_cov=marg.joints[calib_group],
        shared_joint_cov=marg.joints[shared_group],
        info=info,
        water_current=profile,
        config=cfg.to_dict(),
        alignment_method=builder.alignment.method,
        dvl_pings=builder.usable,
    )
