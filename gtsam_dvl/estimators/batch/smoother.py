"""Batch smoother: the whole log in one factor graph, solved by Gauss-Newton with QR."""

from __future__ import annotations

import time
from typing import Any

import gtsam
import numpy as np
from scipy.stats import chi2

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.states import calibration_info
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.pieces import long_gaps, smooth_pieces
from gtsam_dvl.estimators.batch.solve import (  # noqa: F401  (re-exported: the solve's names of old)
    RECENTRE_FRACTION,
    SolvedLog,
    extract_result,
    solve_centred,
    solve_graph,
    solve_log,
)
from gtsam_dvl.estimators.batch.timeline import filtering_timeline
from gtsam_dvl.estimators.graph.bulk import BulkGraph
from gtsam_dvl.estimators.graph.solver import SolveReport
from gtsam_dvl.estimators.inputs.gaps import screened_losses
from gtsam_dvl.estimators.inputs.prepare import prepare
from gtsam_dvl.estimators.models import weak_hold
from gtsam_dvl.estimators.models.constant_error import consider_constant_error
from gtsam_dvl.estimators.models.noise_levels import NoiseReport


def _result_with_hold(
    solved: SolvedLog, estimator: str, calibration: VehicleCalibration | None
) -> tuple[BulkGraph, gtsam.Values, NavResult]:
    """The solution's result with its marginals, then (without a calibration file) the nominal calibration's check
    and the weakly determined directions held (weak_hold.py): the graph of the result's covariance, its values and
    the result."""
    result = solved.result(estimator)
    if calibration is not None or result.calib_joint_cov is None:
        return solved.graph, solved.values, result
    builder = solved.builder
    hold = weak_hold.plan(
        builder.config, builder.log.mounting, result.calib_joint_cov, len(builder.epochs) - 1
    )
    if hold is None:
        return solved.graph, solved.values, result
    return _hold_calibration(solved, hold, estimator, result)


def _solver_info(report: SolveReport, dof: int, passes: Any) -> dict[str, Any]:
    """NavResult.info["solver"]: the last solve's iterations, convergence, errors, degrees of freedom, the noise
    loop's passes and the solver's timings."""
    return {
        "iterations": report.iterations,
        "converged": report.converged,
        "initial_error": report.initial_error,
        "final_error": report.final_error,
        "dof": dof,
        "passes": passes,
        **{f"{k}_s": v for k, v in report.timing_s.items()},
    }


def smooth_batch(
    log: LogData,
    config: EstimatorConfig | None = None,
    progress: ProgressFn | None = None,
    timeline: bool = False,
    estimator: str = "batch",
    calibration: VehicleCalibration | None = None,
) -> NavResult:
    """Estimate trajectory, IMU biases, DVL scale factor and misalignment from a whole log. timeline: also
    the filtering sigma timeline over the same linearisation (how the log's information accrued; one more
    pass over the states). estimator: the name the result carries (the planner's is "plan"). calibration: a
    vehicle's calibration, already inflated for its age, as the joint prior of the states it holds
    (core/states.py calibration_prior; recorded in info["calibration_prior"])."""
    # the configuration checked, [current] water_track resolved, the combinations no estimator does refused,
    # the IMU screened when the reader did not (inputs/prepare.py)
    prepared = prepare(log, config, "batch", calibration)
    log, config = prepared.log, prepared.config
    # what result.config records: water_track as resolved (noise_levels.py: the levels used are in info["noise"])
    stated = config
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    noise = NoiseReport()
    # IMU gaps longer than imu.max_gap_s: the log smoothed as pieces
    if gaps := long_gaps(log, config):
        pieces = smooth_pieces(log, stated, gaps, progress, estimator, calibration)
        consider_constant_error(pieces, config, calibration is not None)
        return pieces
    solved = solve_log(log, config, noise, timing, calibration, progress, t0)
    builder = solved.builder
    config = builder.config  # (at the levels taken from the data)

    t3 = time.perf_counter()
    graph, values, result = _result_with_hold(solved, estimator, calibration)
    consider_constant_error(result, config, calibration is not None)  # (constant_error.py)
    timing["marginals"] = time.perf_counter() - t3
    if timeline and config.imu.bias_model == "constant":
        t4 = time.perf_counter()
        result.timeline = filtering_timeline(builder, graph, values)
        timing["timeline"] = time.perf_counter() - t4
    timing["total"] = time.perf_counter() - t0
    result.timing_s = timing
    result.info["noise"] = noise.as_dict()
    # what the screen of an in-memory log found (gaps.py)
    if (screened := screened_losses(log)) is not None:
        result.info["screened_losses"] = screened
    result.config = stated.to_dict()
    if calibration is not None:
        result.info["calibration_prior"] = calibration_info(config, calibration)
    if builder.offset_centring:  # the time offset's windows against the solution (solve_centred)
        result.info["time_offset_centring"] = builder.offset_centring
    result.info["solver"] = _solver_info(solved.report, solved.dof, solved.passes)
    if progress:
        progress(1.0)
    return result


def _hold_calibration(
    solved: SolvedLog, hold: dict[str, Any], estimator: str, free: NavResult
) -> tuple[BulkGraph, gtsam.Values, NavResult]:
    """The nominal-calibration check and the weak-direction hold (estimators/models/weak_hold.py): the log solved again
    with the scale and misalignment pinned at the prior's mean (the nominal); when the free estimate does not lower
    the chi^2 by more than NOMINAL_LEVEL's quantile of chi^2(4), the calibration is held at the nominal with the
    consider covariance (its prior's sigma) and the result says so; else the weak directions alone are held (when
    any). Returns the graph of the result's covariance (for the timeline), its values and the result."""
    if not solved.builder.config.priors.nominal_check:
        return _hold_weak(solved, hold, estimator, free, None)
    everything = {**hold, "weak": np.ones_like(hold["weak"])}
    nominal_values, gain, nominal_graph = _pinned(solved, everything)
    limit = float(chi2.ppf(weak_hold.NOMINAL_LEVEL, len(hold["weak"])))
    check = {
        "chi2_gain": gain,
        "chi2_limit": limit,
        "level": weak_hold.NOMINAL_LEVEL,
        "pays": bool(gain > limit),
    }
    if not check["pays"]:
        result = extract_result(
            solved.builder, nominal_graph, nominal_values, solved.ordering, estimator=estimator
        )
        result.info["calibration_hold"] = weak_hold.report(
            {**everything, "nominal": check},
            gain,
            why=(
                f"held at the nominal calibration: estimating the DVL scale and misalignment lowers chi^2 by "
                f"{gain:.1f}, not more than {limit:.1f} ({weak_hold.NOMINAL_LEVEL:.0%} of chi^2 with 4 dof): "
                "it does not pay for its four states; the nominal's sigmas are its prior's"
            ),
        )
        return nominal_graph, nominal_values, result
    return _hold_weak(solved, hold, estimator, free, check)


def _hold_weak(
    solved: SolvedLog,
    hold: dict[str, Any],
    estimator: str,
    free: NavResult,
    check: dict[str, Any] | None,
) -> tuple[BulkGraph, gtsam.Values, NavResult]:
    """The weak directions held (weak_hold.py) when any, the result with its consider covariance; the free one when
    pinning costs more chi^2 than its 99 % limit. check: the nominal calibration's, reported beside."""
    plan = hold if check is None else {**hold, "nominal": check}
    if not hold["weak"].any():
        free.info["calibration_hold"] = weak_hold.report(plan, 0.0)
        return solved.graph, solved.values, free
    held, increase, cov_graph = _pinned(solved, hold)
    info = weak_hold.report(plan, increase)
    if not info["consistent"]:
        free.info["calibration_hold"] = weak_hold.report(
            plan,
            increase,
            released=True,
            why=(
                f"not held: pinning cost chi^2 {info['chi2_increase']:.1f} > {info['chi2_limit_99']:.1f} (99 %): the "
                "data disagree with the prior along directions they inform little"
            ),
        )
        return solved.graph, solved.values, free
    result = extract_result(solved.builder, cov_graph, held, solved.ordering, estimator=estimator)
    result.info["calibration_hold"] = info
    return cov_graph, held, result


def _pinned(solved: SolvedLog, hold: dict[str, Any]) -> tuple[gtsam.Values, float, BulkGraph]:
    """The estimate with hold's weak directions pinned at the prior's mean (the rest solved again, the offset's
    windows re-centred), its chi^2 increase over values', and the graph of its consider covariance (the prior's
    precision taken off along the pinned directions: estimators/models/weak_hold.py)."""
    graph, values = solved.graph, solved.values
    pinned, consider = gtsam.NonlinearFactorGraph(), gtsam.NonlinearFactorGraph()
    slots = set(weak_hold.prior_slots(graph.graph))
    for j in range(graph.graph.size()):
        pinned.add(graph.graph.at(j))
        if j not in slots:
            consider.add(graph.graph.at(j))
    pinned.add(weak_hold.hold_factor(hold))
    consider.add(weak_hold.consider_prior(hold))
    free_error = graph.error(values)
    _, held, _ = solve_centred(
        solved.builder, BulkGraph(pinned, graph.bulk, graph.imu), values, solved.ordering, []
    )
    increase = 2.0 * (graph.error(held) - free_error)
    return held, increase, BulkGraph(consider, graph.bulk, graph.imu)
