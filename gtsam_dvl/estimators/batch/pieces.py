"""A log cut at its long IMU gaps: the pieces smoothed with one shared calibration, one result with marked breaks.

An IMU gap longer than [imu] max_gap_s cannot be crossed by holding the last sample (estimators/inputs/gaps.py): over a
30 s gap in a turn that motion model is wrong, not just uncertain. The batch smoother then cuts the log at each such
gap into pieces (cut_log: the IMU samples, pings, depth, GNSS and truth of each piece's time span; what falls in a
gap is left out) and smooths them as the dives of one vehicle (estimators/batch/multi_dive.py): each piece has its own
trajectory, IMU biases and time offset, and the pieces share the DVL calibration (scale, misalignment, lever arm
when estimated), solved jointly. Each piece after the first starts in motion: it is aligned in motion
(estimators/inputs/alignment.py, the DVL-aided alignment) and its position, which no measurement ties to the piece
before, is placed by dead reckoning across the gap (across_gap: a constant-rate turn between the velocities on
either side) with its first position's prior sigma DEAD_RECKONING_M plus DEAD_RECKONING_FRACTION of the distance
crossed: a marked break, not a measurement.

The result is one NavResult: the pieces' states in time order, info["pieces"] (each piece's first state index in
the result, its time span, its IMU biases and time offset, alone) and info["breaks"] (the gaps), the shared states
the joint calibration's marginals, each piece's trajectory covariances conditioned on every piece's information
about the shared states (the other pieces' reduced information enters each piece's graph as a linear factor on the
shared keys).
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import gtsam
import numpy as np

from gtsam_dvl.core.calibration import VehicleCalibration
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.progress import ProgressFn
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.multi_dive import (
    DiveState,
    JointSolution,
    Reduction,
    Rows,
    calibrate_in_process,
    prepare_dive,
    state_keys,
    state_slices,
)
from gtsam_dvl.estimators.batch.solve import extract_result
from gtsam_dvl.estimators.graph.bulk import BulkGraph
from gtsam_dvl.estimators.inputs.gaps import find_gaps

# the first position of a piece after a gap: its prior sigma (m), a floor plus a fraction of the distance crossed
# (the path across the gap is a constant-rate turn between the velocities on either side: across_gap; a vehicle
# that changes its turn or speed in the gap leaves it, which this sigma is meant to cover)
DEAD_RECKONING_M = 1.0
DEAD_RECKONING_FRACTION = 0.05


def across_gap(n_v0: np.ndarray, n_v1: np.ndarray, dt: float) -> np.ndarray:
    """The displacement (m, map) across a gap of dt seconds between the velocities n_v0 before and n_v1 after it,
    as a horizontal arc at constant speed and turn rate (the chord: the mean velocity times dt, lengthened by
    (sin(a) / a) / cos(a) for the half heading change a; a straight line when the heading does not change), the
    vertical at the mean vertical velocity."""
    n_v0, n_v1 = np.asarray(n_v0, dtype=float), np.asarray(n_v1, dtype=float)
    mean = 0.5 * (n_v0 + n_v1) * dt
    h0, h1 = np.arctan2(n_v0[1], n_v0[0]), np.arctan2(n_v1[1], n_v1[0])
    a = 0.5 * float(np.angle(np.exp(1j * (h1 - h0))))
    if (
        abs(a) > 1e-6
        and np.hypot(*n_v0[:2]) > 0.1
        and np.hypot(*n_v1[:2]) > 0.1
        and abs(a) < 0.45 * np.pi
    ):
        mean[:2] *= np.sin(a) / a / np.cos(a)
    return mean


def long_gaps(log: LogData, config: EstimatorConfig) -> list[tuple[float, float]]:
    """The IMU gaps longer than [imu] max_gap_s between the first and last valid DVL pings: (start, end) in s,
    start the last sample before the gap, end the first after it."""
    imu = log.imu
    if len(imu) < 3 or not len(log.dvl):
        return []
    gaps = find_gaps(imu.t, config.imu.gap_samples)
    valid = log.dvl.t[log.dvl.valid] if log.dvl.valid.any() else log.dvl.t
    t0, t1 = float(valid[0]), float(valid[-1])
    out = []
    for j in range(len(gaps)):
        k = int(gaps.index[j])
        start, end = float(imu.t[k]), float(imu.t[k + 1])
        if gaps.end[j] - gaps.start[j] > config.imu.max_gap_s and end > t0 and start < t1:
            out.append((start, end))
    return out


def _length(obj: Any) -> int | None:
    """The leading length of a dataclass's first array field (its messages), None without one."""
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1:
            return int(v.shape[0])
    return None


def _take(obj: Any, keep: np.ndarray) -> Any:
    """A dataclass of per-message arrays (and nested ones, e.g. DvlData.beams) restricted to keep (bool)."""
    n = len(keep)
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == n:
            changes[f.name] = v[keep]
        elif dataclasses.is_dataclass(v) and not isinstance(v, type) and _length(v) == n:
            changes[f.name] = _take(v, keep)
    return dataclasses.replace(obj, **changes)


def cut_log(log: LogData, gaps: list[tuple[float, float]]) -> list[LogData]:
    """The log's pieces between the gaps: piece k spans [after gap k-1, before gap k] (the IMU samples at its
    ends included); every stream's messages in that span."""
    edges = [-np.inf] + [x for g in gaps for x in g] + [np.inf]
    out = []
    for k in range(len(gaps) + 1):
        lo, hi = edges[2 * k], edges[2 * k + 1]
        streams: dict[str, Any] = {}
        for f in dataclasses.fields(log):  # every stream: a field with per-message stamps t
            data: Any = getattr(log, f.name)
            t = getattr(data, "t", None)
            if dataclasses.is_dataclass(data) and isinstance(t, np.ndarray):
                streams[f.name] = _take(data, (t >= lo) & (t <= hi))
        out.append(
            dataclasses.replace(log, **streams, source=f"{log.source or 'log'} (piece {k + 1})")
        )
    return out


def _piece_config(config: EstimatorConfig, sigma_m: float) -> EstimatorConfig:
    """A later piece's configuration: aligned in motion, its first position's prior widened to sigma_m."""
    d = config.to_dict()
    d.setdefault("alignment", {})["method"] = "in_motion"
    d["alignment"]["initial_attitude_deg"] = None
    d.setdefault("priors", {})["position_sigma_m"] = max(
        float(config.priors.position_sigma_m), sigma_m
    )
    return EstimatorConfig.from_dict(d)


def _linear_prior(parts: list[Reduction], names: list[str]) -> gtsam.NonlinearFactor:
    """The stacked square-root rows [R | d] on the shared keys as a factor whose linearisation they are (the other
    pieces' and the priors' information, for one piece's marginals at its values; GTSAM's Python JacobianFactor
    takes at most three keys, the shared states may be four)."""
    R = np.vstack([p.R for p in parts])
    d = np.concatenate([p.d for p in parts])
    sl = state_slices(names)
    return gtsam.CustomFactor(
        gtsam.noiseModel.Unit.Create(R.shape[0]),
        state_keys(names),
        Rows([R[:, sl[n]] for n in names], d),
    )


def _piece_result(dive: DiveState, others: list[Reduction]) -> NavResult:
    graph = gtsam.NonlinearFactorGraph()
    graph.push_back(dive.graph.graph)
    graph.add(_linear_prior(others, dive.states))
    full = BulkGraph(graph, dive.graph.bulk, dive.graph.imu)
    result = extract_result(dive.builder, full, dive.values, dive.builder.elimination_ordering())
    result.info["noise"] = dive.alone.info.get("noise")
    return result


def smooth_pieces(
    log: LogData,
    config: EstimatorConfig,
    gaps: list[tuple[float, float]],
    progress: ProgressFn | None = None,
    estimator: str = "batch",
    calibration: VehicleCalibration | None = None,
) -> NavResult:
    """Smooth a log cut at its long IMU gaps (module doc). calibration: a vehicle's calibration as the joint prior
    of the states it holds (batch.smooth_batch's), which the pieces then share."""
    t0 = time.perf_counter()
    pieces = cut_log(log, gaps)
    dives: list[DiveState] = []
    kept: list[int] = []
    left_out: list[dict[str, Any]] = []
    for k, piece in enumerate(pieces):
        cfg = config
        if dives:
            prev = dives[-1].alone
            distance = (
                float(np.linalg.norm(prev.n_v[-1])) * float(piece.imu.t[0] - prev.t[-1])
                if len(piece.imu)
                else 0.0
            )
            cfg = _piece_config(config, DEAD_RECKONING_M + DEAD_RECKONING_FRACTION * distance)
        try:
            dives.append(prepare_dive(piece, cfg, name=piece.source, calibration=calibration))
            kept.append(k)
        except GtsamDvlError as exc:
            # the piece that holds the log's start (its map origin and alignment): no result without it
            if k == 0:
                raise GtsamDvlError(
                    f"{log.source or 'log'}: cut at {len(gaps)} IMU gap(s) longer than "
                    f"imu.max_gap_s ({gaps[0][0]:.2f}-{gaps[0][1]:.2f} s first): the first piece "
                    f"cannot be smoothed: {exc}"
                ) from None
            t = piece.imu.t
            left_out.append(
                {
                    "piece": k + 1,
                    "t_start_s": float(t[0]) if len(t) else None,
                    "t_end_s": float(t[-1]) if len(t) else None,
                    "error": str(exc),
                }
            )
        if progress:
            progress(0.6 * (k + 1) / len(pieces))
    solution = calibrate_in_process(dives)
    if progress:
        progress(0.8)
    results = []
    for k, dive in enumerate(dives):
        others = [r for j, r in enumerate(solution.reductions) if j != k] + solution.prior_rows
        result = _piece_result(dive, others)
        if result.dvl_pings is not None:  # the piece's ping indices in the log's
            result.dvl_pings = result.dvl_pings + int(
                np.searchsorted(log.dvl.t, pieces[kept[k]].dvl.t[0])
            )
        results.append(result)
    # the breaks between the pieces kept: from the last IMU sample of one to the first of the next
    breaks = [
        (float(pieces[a].imu.t[-1]), float(pieces[b].imu.t[0]))
        for a, b in zip(kept, kept[1:], strict=False)
    ]
    out = _joined(results, dives, solution, breaks, estimator)
    if calibration is not None:
        out.info["calibration_prior"] = dives[0].alone.info.get("calibration_prior")
    if left_out:
        out.info["pieces_left_out"] = left_out
    out.timing_s = {"total": time.perf_counter() - t0}
    if progress:
        progress(1.0)
    return out


def _joined(
    results: list[NavResult],
    dives: list[DiveState],
    solution: JointSolution,
    gaps: list[tuple[float, float]],
    estimator: str,
) -> NavResult:
    """The pieces' results as one, each later piece's positions placed by dead reckoning across its gap."""
    n_p = [results[0].n_p]
    for k in range(1, len(results)):
        prev, cur = results[k - 1], results[k]
        n_p.append(
            cur.n_p
            + (
                n_p[-1][-1]
                + across_gap(prev.n_v[-1], cur.n_v[0], float(cur.t[0] - prev.t[-1]))
                - cur.n_p[0]
            )
        )
    first = results[0]

    def cat(name: str) -> Any:
        parts = [getattr(r, name) for r in results]
        return None if any(p is None for p in parts) else np.concatenate(parts)

    starts = np.cumsum([0] + [len(r.t) for r in results[:-1]]).tolist()
    pieces = [
        {
            "start_index": int(s),
            "t_start_s": float(r.t[0]),
            "t_end_s": float(r.t[-1]),
            "states": len(r.t),
            "alone": {
                name: {"value": np.asarray(e.value).tolist(), "sigma": e.sigma.tolist()}
                for name, e in d.alone.calibration.items()
            },
        }
        for s, r, d in zip(starts, results, dives, strict=True)
    ]
    info = dict(first.info)
    info.update(
        epochs=int(sum(len(r.t) for r in results)),
        pieces=pieces,
        breaks=[
            {"after_index": int(s) - 1, "gap_start_s": g[0], "gap_end_s": g[1]}
            for s, g in zip(starts[1:], gaps, strict=True)
        ],
        joint={
            "iterations": solution.iterations,
            "converged": solution.converged,
            "history": solution.history,
        },
    )
    pings = [r.dvl_pings for r in results if r.dvl_pings is not None]
    return NavResult(
        estimator=estimator,
        t=cat("t"),
        n_p=np.concatenate(n_p),
        n_R_b=cat("n_R_b"),
        n_v=cat("n_v"),
        pose_cov=cat("pose_cov"),
        vel_cov=cat("vel_cov"),
        calibration=dict(first.calibration),
        b_R_d0=first.b_R_d0,
        t0_ns=first.t0_ns,
        b_omega=cat("b_omega"),
        pose_vel_cross=cat("pose_vel_cross"),
        calib_joint_cov=first.calib_joint_cov,
        shared_joint_cov=first.shared_joint_cov,
        info=info,
        water_current=first.water_current,  # (the first piece's, as its info)
        config=first.config,
        alignment_method=first.alignment_method,
        dvl_pings=np.concatenate(pings) if len(pings) == len(results) else None,
    )
