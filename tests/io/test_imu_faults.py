"""IMU faults the reader finds in the samples (core/imu_faults.py): a clipped axis is saturation and nothing else
is; a clock step is told from a gap where the motion changes; the reader drops the saturated samples, names a
clock step or undoes it with --repair, and records both."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.health import assess_log_health
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.imu_faults import clock_steps, saturated_mask, saturated_runs, undo_clock_steps
from gtsam_dvl.core.types import ImuData, LogData
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log

HZ = 100.0


def _turning_imu(
    seconds: float, seed: int = 1, gyro_sigma: float = 1e-3, accel_sigma: float = 2e-3
) -> ImuData:
    """A noisy IMU turning back and forth (yaw rate 0.1 sin(2 pi t / 20) rad/s) with a surge (2 cos(2 pi t / 15)
    m/s^2):
    outputs that change all the time, as in a manoeuvre."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, int(seconds * HZ) + 1) / HZ
    w = np.zeros((len(t), 3))
    w[:, 2] = 0.1 * np.sin(2 * np.pi * t / 20.0)
    f = np.zeros((len(t), 3))
    f[:, 0] = 2.0 * np.cos(2 * np.pi * t / 15.0)
    f[:, 2] = 9.81
    return ImuData(
        t, w + rng.normal(0.0, gyro_sigma, w.shape), f + rng.normal(0.0, accel_sigma, f.shape)
    )


def test_a_clipped_axis_is_saturation_and_nothing_else_is() -> None:
    imu = _turning_imu(60.0)
    # noisy manoeuvres: never a run at the extreme
    assert saturated_runs(imu.b_omega, imu.b_f) == []
    clipped = np.clip(imu.b_omega, -0.08, 0.08)
    runs = saturated_runs(clipped, imu.b_f)
    hit = np.abs(imu.b_omega[:, 2]) >= 0.08
    assert {(r.sensor, r.axis, abs(r.value)) for r in runs} == {("gyro", 2, 0.08)}
    assert len(runs) == 6  # three turns each way in 60 s
    # every sample dropped is at the limit, and the ones at the limit left are the edges of the stretches,
    # where the noise takes the true value in and out of the range (within 0.5 s of a stretch dropped)
    mask = saturated_mask(len(imu), runs)
    assert np.all(hit[mask]) and mask.sum() > 0.95 * hit.sum()
    dropped = np.flatnonzero(mask)
    left = np.flatnonzero(hit & ~mask)
    assert np.all(np.min(np.abs(left[:, None] - dropped[None, :]), axis=1) <= 50)
    # a steady noisy turn is no saturation (its extreme is a noise peak), nor are a noise-free stream and a
    # quantised one, whose values repeat everywhere; a dead axis (all zeros) neither
    steady = imu.b_omega.copy()
    steady[:, 2] = 0.05 + np.random.default_rng(2).normal(0.0, 1e-3, len(imu))
    assert saturated_runs(steady, imu.b_f) == []
    smooth = np.zeros_like(imu.b_omega)
    smooth[:, 2] = 0.1 * np.sin(2 * np.pi * imu.t / 20.0)
    assert saturated_runs(smooth, np.tile([0.0, 0.0, 9.81], (len(imu), 1))) == []
    assert saturated_runs(np.round(smooth / 1e-3) * 1e-3, imu.b_f) == []
    # an accelerometer clipped at its range
    f = imu.b_f.copy()
    f[:, 0] = np.minimum(f[:, 0], 1.5)
    assert {(r.sensor, r.axis, r.value) for r in saturated_runs(imu.b_omega, f)} == {
        ("accel", 0, 1.5)
    }


@pytest.mark.parametrize("at_s", [12.0, 31.5, 47.0])
def test_a_clock_step_is_told_from_a_gap(at_s: float) -> None:
    imu = _turning_imu(60.0, seed=int(at_s))
    k = int(np.searchsorted(imu.t, at_s))
    stepped = imu.t.copy()
    stepped[k:] += 3.0
    found = clock_steps(stepped, imu.b_omega, imu.b_f)
    assert len(found) == 1 and found[0].index == k
    assert found[0].step_s == pytest.approx(3.0, abs=1e-9) and found[0].t_before == pytest.approx(
        imu.t[k - 1]
    )
    keep = (imu.t <= at_s) | (imu.t > at_s + 3.0)  # 3 s of samples missing: a gap
    assert clock_steps(imu.t[keep], imu.b_omega[keep], imu.b_f[keep]) == []
    # the clock stepping back by 3 s, the samples running on
    back = imu.t.copy()
    back[k:] -= 3.0
    found = clock_steps(back, imu.b_omega, imu.b_f)
    assert (
        len(found) == 1 and found[0].index == k and found[0].step_s == pytest.approx(-3.0, abs=1e-9)
    )
    # samples logged late (1 s of older samples again after the newest): no clock step
    late = np.r_[np.arange(k), np.arange(k - 100, len(imu))]
    assert clock_steps(imu.t[late], imu.b_omega[late], imu.b_f[late]) == []
    # one sample's stamp wrong (back by 0.1 s): no window on its side, no clock step
    one = imu.t.copy()
    one[k] = one[k - 10]
    assert clock_steps(one, imu.b_omega, imu.b_f) == []
    # steady motion: a step and a gap look alike, so it stays a gap
    flat = _turning_imu(60.0, seed=3)
    flat.b_omega[:, 2] -= 0.1 * np.sin(2 * np.pi * flat.t / 20.0)
    flat.b_f[:, 0] -= 2.0 * np.cos(2 * np.pi * flat.t / 15.0)
    assert clock_steps(stepped, flat.b_omega, flat.b_f) == []


def _short_log(sim_paper3d_short: LogData, seconds: float = 330.0) -> LogData:
    """The first seconds of paper-3d-short (static, the Type-I segments, the first turn)."""
    imu, dvl = sim_paper3d_short.imu, sim_paper3d_short.dvl
    ki, kd = imu.t <= seconds, dvl.t <= seconds
    return dataclasses.replace(
        sim_paper3d_short,
        truth=None,
        imu=dataclasses.replace(imu, t=imu.t[ki], b_omega=imu.b_omega[ki], b_f=imu.b_f[ki]),
        dvl=dataclasses.replace(
            dvl, t=dvl.t[kd], d_v=dvl.d_v[kd], d_cov=dvl.d_cov[kd], valid=dvl.valid[kd], beams=None
        ),
    )


def test_reader_names_a_clock_step_or_undoes_it(sim_paper3d_short: LogData, tmp_path: Path) -> None:
    log = _short_log(sim_paper3d_short)
    t = log.imu.t.copy()
    k = int(np.searchsorted(t, 285.0))  # entering the first turn
    t[k:] += 4.0
    path = tmp_path / "step.mcap"
    write_log(path, dataclasses.replace(log, imu=dataclasses.replace(log.imu, t=t)))
    with pytest.raises(GtsamDvlError) as err:
        read_log(path)
    msg = str(err.value)
    assert "\n" not in msg and "clock step at 284.990 s" in msg and "jump by 4.010 s" in msg
    assert "--repair" in msg and "back by 4.000 s" in msg
    fixed = read_log(path, repair=True)
    # the stamps as they were before the step
    np.testing.assert_allclose(fixed.imu.t, log.imu.t, atol=1e-8)
    losses = fixed.metadata["reader_losses"]
    assert losses["clock_steps"]["/imu/data_raw"][0]["step_s"] == pytest.approx(4.0, abs=1e-6)
    assert "/imu/data_raw" not in losses["gaps"]
    notes = assess_log_health(fixed).notes
    assert any(
        "clock step at 284.990 s" in n and "shifted the later stamps back by 4.000 s" in n
        for n in notes
    )
    # the clock stepping back by 4 s (on the stamps as the reader gets them: the file's messages in the order a
    # recorder logged them, which our writer, ordering by stamp, cannot make): without the repair the stamps would
    # go back (an error), with it the samples would be dropped until the stamps pass the newest one
    ns = 1_700_000_000 * 10**9 + np.round(log.imu.t * 1e9).astype(np.int64)
    back = ns.copy()
    back[k:] -= 4_000_000_000
    with pytest.raises(
        GtsamDvlError,
        match=r"clock step at 284\.990 s: the stamps jump back by 3\.990 s .*"
        r"forward by 4\.000 s$",
    ):
        undo_clock_steps(
            back, 1_700_000_000 * 10**9, log.imu.b_omega, log.imu.b_f, "/imu", False, []
        )
    warnings: list[str] = []
    fixed_ns, found = undo_clock_steps(
        back, 1_700_000_000 * 10**9, log.imu.b_omega, log.imu.b_f, "/imu", True, warnings
    )
    np.testing.assert_array_equal(fixed_ns, ns)
    assert (
        found[0]["step_s"] == pytest.approx(-4.0, abs=1e-6) and "forward by 4.000 s" in warnings[0]
    )
    notes = assess_log_health(
        dataclasses.replace(log, metadata={"reader_losses": {"clock_steps": {"/imu": found}}})
    )
    assert any(
        "jump back by 3.990 s" in n and "shifted the later stamps forward by 4.000 s" in n
        for n in notes.notes
    )


def test_reader_drops_saturated_samples_as_gaps(sim_paper3d_short: LogData, tmp_path: Path) -> None:
    log = _short_log(sim_paper3d_short)
    limit = 0.055  # the first turn peaks at 0.0576 rad/s
    path = tmp_path / "clipped.mcap"
    write_log(
        path,
        dataclasses.replace(
            log, imu=dataclasses.replace(log.imu, b_omega=np.clip(log.imu.b_omega, -limit, limit))
        ),
    )
    read = read_log(path)
    hit = np.abs(log.imu.b_omega[:, 2]) >= limit
    report = read.metadata["reader_losses"]["saturation"]["/imu/data_raw"]
    assert report["samples"] == len(log.imu) - len(read.imu) and report["stretches"] == 1
    assert report["axes"] == [{"sensor": "gyro", "axis": "z", "limit": limit}]
    assert report["samples"] > 0.95 * hit.sum() and report["samples"] > 300
    a, b = report["spans_s"][0]
    assert 296.0 < a < 300.0 < b < 304.0
    # no data missing from the log
    assert "/imu/data_raw" not in read.metadata["reader_losses"]["gaps"]
    health = assess_log_health(read)
    assert health.status == "degraded"
    assert any(
        "the IMU saturated (gyro z at +0.055 rad/s)" in w and "crossed as IMU gaps" in w
        for w in health.warnings
    )
