"""A log with an IMU gap longer than imu.max_gap_s (estimators/batch/pieces.py): smoothed as pieces that share the DVL
calibration, one result with the breaks marked, the calibration within 3 sigma of the truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_log
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.pieces import _take, across_gap, cut_log, long_gaps
from gtsam_dvl.estimators.batch.smoother import smooth_batch

GAP = (285.0, 315.0)  # 30 s in paper-3d-short's first turn (270-330 s)


def _with_gap(log: LogData, a: float, b: float) -> LogData:
    keep = (log.imu.t <= a) | (log.imu.t > b)
    return dataclasses.replace(log, imu=_take(log.imu, keep))


def test_cut_log_keeps_every_message_outside_the_gaps(sim_paper3d_short: LogData) -> None:
    log = _with_gap(sim_paper3d_short, *GAP)
    gaps = long_gaps(log, EstimatorConfig.for_log(log.metadata))
    assert (
        len(gaps) == 1
        and gaps[0][0] == pytest.approx(GAP[0])
        and gaps[0][1] == pytest.approx(GAP[1], abs=0.02)
    )
    pieces = cut_log(log, gaps)
    assert len(pieces) == 2
    assert sum(len(p.imu) for p in pieces) == len(log.imu)  # the IMU has no sample in the gap
    in_gap = (log.dvl.t > gaps[0][0]) & (log.dvl.t < gaps[0][1])
    assert sum(len(p.dvl) for p in pieces) == len(log.dvl) - int(in_gap.sum())
    assert pieces[0].dvl.t[-1] <= gaps[0][0] < gaps[0][1] <= pieces[1].dvl.t[0]
    assert pieces[1].dvl.beams is not None and pieces[1].dvl.beams.v.shape[0] == len(pieces[1].dvl)
    assert pieces[1].truth is not None and pieces[1].truth.t[0] >= gaps[0][1]


def test_a_30s_imu_gap_in_a_turn_smooths_as_two_pieces(
    sim_paper3d_short: LogData, tmp_path: Path
) -> None:
    log = _with_gap(sim_paper3d_short, *GAP)
    result = smooth_batch(log)
    pieces, breaks = result.info["pieces"], result.info["breaks"]
    assert len(pieces) == 2 and len(breaks) == 1
    k = pieces[1]["start_index"]
    assert result.t[k - 1] <= GAP[0] < GAP[1] <= result.t[k] and np.all(np.diff(result.t) > 0)
    assert breaks[0]["after_index"] == k - 1 and result.info["joint"]["converged"]
    assert len(result.t) == pieces[0]["states"] + pieces[1]["states"] == result.info["epochs"]
    assert result.dvl_pings is not None and np.all(np.diff(result.dvl_pings) > 0)
    # the ping indices are the log's
    assert np.allclose(log.dvl.t[result.dvl_pings[k]], result.t[k])
    # the calibration within 3 sigma of the truth
    truth = log.true_calibration
    assert truth is not None
    assert abs(result.scale - truth.scale) < 3 * result.scale_sigma
    b_R_d = rpy_deg_to_matrix(truth.misalignment_deg) @ log.mounting.b_R_d0
    mis = result.calibration["misalignment"]
    assert np.all(np.abs(so3_log(b_R_d.T @ mis.value)) < 3 * mis.sigma)
    # the joint is tighter than either piece alone
    assert all(result.scale_sigma < p["alone"]["scale"]["sigma"][0] for p in pieces)
    # the trajectory across the break: dead reckoning, within 3 of its own sigmas of the truth at the last state
    assert log.truth is not None
    j = np.searchsorted(log.truth.t, result.t[-1])
    err = np.linalg.norm(result.n_p[-1, :2] - log.truth.n_p[j, :2])
    assert err < 3 * np.hypot(*result.position_sigma_m[-1, :2])
    # the result MCAP: a Path message per piece (no line across the break), the health names the break
    from mcap.reader import make_reader

    from gtsam_dvl.analysis.metrics import summary
    from gtsam_dvl.io.result_writer import write_result_log

    s = summary(result, log)
    assert s["health"]["status"] == "degraded" and any(
        "smoothed as 2 pieces" in w for w in s["health"]["warnings"]
    )
    path = write_result_log(tmp_path / "result.mcap", result, log, s)
    with path.open("rb") as f:
        stamps = [
            m.log_time for _, ch, m in make_reader(f).iter_messages(topics=["/gtsam_dvl/path"])
        ]
    assert len(stamps) == 2
    assert stamps[0] == result.t0_ns + round(result.t[k - 1] * 1e9)
    # with a vehicle's calibration as the prior (smooth --calibration): held once by the joint, not once per piece
    from gtsam_dvl.core.calibration import VehicleCalibration

    cov = np.diag([8e-4**2, *np.radians([0.3, 0.1, 0.1]) ** 2])
    cal = VehicleCalibration(
        "auv",
        "2026-11-02T00:00:00Z",
        ("scale", "misalignment"),
        {"scale": np.array([truth.scale]), "misalignment": b_R_d},
        cov,
    )
    with_file = smooth_batch(log, calibration=cal)
    assert with_file.info["calibration_prior"] and len(with_file.info["pieces"]) == 2
    # the scale's information: the file's plus the pieces' (the paper's prior, 0.5, adds nothing)
    expected = 1 / np.sqrt(1 / 8e-4**2 + 1 / result.scale_sigma**2)
    assert with_file.scale_sigma == pytest.approx(expected, rel=0.05)


def test_across_gap_is_the_chord_of_a_constant_rate_turn() -> None:
    speed, rate, dt = 2.0, np.radians(1.5), 30.0  # a 45 deg turn
    h0 = 0.3
    n_v0 = speed * np.array([np.cos(h0), np.sin(h0), 0.1])
    n_v1 = speed * np.array([np.cos(h0 + rate * dt), np.sin(h0 + rate * dt), 0.1])
    radius = speed / rate
    chord = radius * np.array(
        [np.sin(h0 + rate * dt) - np.sin(h0), np.cos(h0) - np.cos(h0 + rate * dt)]
    )
    d = across_gap(n_v0, n_v1, dt)
    np.testing.assert_allclose(d[:2], chord, atol=1e-9)
    assert d[2] == pytest.approx(0.2 * dt)
    np.testing.assert_allclose(across_gap(n_v0, n_v0, dt), n_v0 * dt)  # straight on
