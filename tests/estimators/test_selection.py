"""One rule for which pings become epochs and how IMU samples are split (estimators/selection.py), shared by
the batch smoother, the online estimator and the EKF: the same log with dropouts gives all three the same
epochs and the same counts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gtsam_dvl.core.config import DvlConfig, EstimatorConfig
from gtsam_dvl.core.types import DvlData, LogData
from gtsam_dvl.estimators.batch import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.estimators.selection import (
    TOO_FAST,
    UNUSABLE,
    USABLE,
    classify_pings,
    imu_pieces,
    sample_starts,
    select_epochs,
)


def _with_dropouts(log: LogData, t_end: float = 800.0) -> tuple[LogData, np.ndarray]:
    """The first t_end seconds of a log with bottom-lock losses: a 30 s block in the motion, every 7th ping
    invalid, one NaN velocity flagged valid and one 15 m/s outlier. Returns the log and the indices of the
    pings that must become epochs."""
    imu_keep = log.imu.t <= t_end
    dvl_keep = log.dvl.t <= t_end
    imu = dataclasses.replace(log.imu, t=log.imu.t[imu_keep], b_omega=log.imu.b_omega[imu_keep],
                              b_f=log.imu.b_f[imu_keep])
    d = log.dvl
    t = d.t[dvl_keep]
    d_v, valid = d.d_v[dvl_keep].copy(), d.valid[dvl_keep].copy()
    block = (t > 640.0) & (t < 670.0)
    every7 = (np.arange(len(t)) % 7 == 3) & (t > 100.0)
    valid[block | every7] = False
    d_v[~valid] = np.nan
    nan_ping, fast_ping = int(np.searchsorted(t, t_end - 40.5)), int(np.searchsorted(t, t_end - 20.5))
    valid[nan_ping] = valid[fast_ping] = True
    d_v[nan_ping] = np.nan
    d_v[fast_ping] = [15.0, 0.0, 0.0]
    dvl = DvlData(t, d_v, d.d_cov[dvl_keep], valid, None)
    expected = np.flatnonzero(valid & np.isfinite(d_v).all(axis=1) & (np.linalg.norm(np.nan_to_num(d_v), axis=1) < 10)
                              & (t > imu.t[0]))
    return dataclasses.replace(log, imu=imu, dvl=dvl, truth=None), expected


def test_batch_online_and_ekf_use_the_same_epochs(sim_paper3d_clean: LogData) -> None:
    log, expected = _with_dropouts(sim_paper3d_clean)
    cfg = EstimatorConfig()
    batch = smooth_batch(log, cfg)
    online = smooth_online(log, cfg)
    ekf = run_ekf(log, cfg)
    t_expected = log.dvl.t[expected]
    print(f"{len(log.dvl)} pings, {len(expected)} epochs; counters batch {batch.info['counters']}, "
          f"online {online.info['counters']}, ekf {ekf.info['counters']}")
    np.testing.assert_array_equal(batch.t, t_expected)
    np.testing.assert_array_equal(online.t, t_expected)
    np.testing.assert_array_equal(ekf.t, t_expected)
    # invalid, the NaN ping flagged valid, and the ping at the first IMU stamp (nothing to propagate from)
    n_unusable = int((~log.dvl.valid).sum()) + 1 + int((log.dvl.t <= log.imu.t[0]).sum())
    assert n_unusable + 1 + len(expected) == len(log.dvl)
    for res in (batch, online, ekf):
        assert res.info["counters"].get("dvl_too_fast", 0) == 1
        assert res.info["counters"].get("dvl_unusable", 0) == n_unusable


def test_keyframe_thinning_is_the_same_online_and_in_batch(sim_paper3d_clean: LogData) -> None:
    log, _ = _with_dropouts(sim_paper3d_clean, t_end=700.0)
    cfg = EstimatorConfig()
    cfg.solver.keyframe_interval_s = 2.5
    counters: dict[str, int] = {}
    idx = select_epochs(log.dvl, log.imu.t, cfg.dvl, 2.5, counters)
    assert np.all(np.diff(log.dvl.t[idx]) >= 2.5) and counters["dvl_not_keyframe"] > 0
    batch = smooth_batch(log, cfg)
    online = smooth_online(log, cfg)
    np.testing.assert_array_equal(batch.t, log.dvl.t[idx])
    np.testing.assert_array_equal(online.t, log.dvl.t[idx])
    assert batch.info["counters"]["dvl_not_keyframe"] == online.info["counters"]["dvl_not_keyframe"]


def test_classify_pings_reasons() -> None:
    t = np.array([0.5, 1.5, 2.5, 3.5, 4.5, 9.5])
    d_v = np.array([[1.0, 0, 0], [np.nan, 0, 0], [20.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0]])
    valid = np.array([True, True, True, False, True, True])
    code = classify_pings(t, d_v, valid, None, None, DvlConfig(), t_imu_first=1.0, t_imu_last=9.0)
    # before the first IMU sample; NaN; too fast; flagged invalid; usable; after the last IMU sample
    assert code.tolist() == [UNUSABLE, UNUSABLE, TOO_FAST, UNUSABLE, USABLE, UNUSABLE]
    beams_ok = np.array([[True, False], [False, False], [True, True], [False, True], [True, True], [True, True]])
    finite = np.array([True, True, True, True, False, True])
    code = classify_pings(t, d_v, valid, beams_ok, finite, DvlConfig(use_beams=True), 1.0, 10.0)
    # with beams: any valid finite beam counts, the 3-D flag and speed do not
    assert code.tolist() == [UNUSABLE, UNUSABLE, USABLE, USABLE, UNUSABLE, USABLE]


@pytest.mark.parametrize("a,b", [(0.0, 1.0), (0.013, 0.987), (0.5, 0.5 + 1e-9), (0.9999, 3.0)])
def test_imu_pieces_split_samples_exactly(a: float, b: float) -> None:
    """The pieces of (a, b] cover it exactly once: their durations add up to b - a (inside the IMU's span)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.006, 1000))  # jittered 200 Hz stamps
    starts = sample_starts(t)
    np.testing.assert_array_equal(starts[1:], t[:-1])
    idx, dt = imu_pieces(t, starts, a + t[0], b + t[0])
    assert np.all(dt > 0) and np.all(np.diff(idx) == 1)
    assert abs(dt.sum() - (b - a)) < 1e-12
