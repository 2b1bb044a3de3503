"""Real-log faults through the reader and every estimator (batch, online, EKF) on paper-3d-short's first 460 s
(two turns): an IMU clock step undone with --repair, a gyro saturating in the turns, a DVL frozen in a turn and
water-track pings. Each is counted and said in the health report, and the estimate stays within 3 sigma of the
truth."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.health import assess_health
from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.estimators.ekf import run_ekf
from gtsam_dvl.estimators.inputs.gaps import screened_in_memory
from gtsam_dvl.estimators.online import smooth_online
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.logs import cut_log

pytestmark = pytest.mark.slow

MODES: dict[str, Callable[[LogData, EstimatorConfig], NavResult]] = {
    "batch": smooth_batch,
    "online": smooth_online,
    "ekf": run_ekf,
}


# paper-3d-short up to the end of its second turn: static, the Type-I segments, two turns
END_S = 460.0


def _through_file(log: LogData, tmp: Path, **read: bool) -> LogData:
    """The log's first END_S seconds written and read back."""
    assert log.truth is not None
    log = cut_log(log, END_S, beams=False)
    path = tmp / "log.mcap"
    write_log(path, log)
    return read_log(path, **read)


def _worst_nsigma(result: NavResult, log: LogData) -> tuple[float, float]:
    """The largest |error / sigma| of the scale, misalignment and time offset, and the final horizontal position's."""
    s = summary(result, log)
    e = s["errors"]
    calib = [e["scale_nsigma"], *e["misalignment_nsigma"]] + [
        e.get("dvl_time_offset_nsigma") or 0.0
    ]
    return float(np.max(np.abs(calib))), e["final_horizontal_position_m"] / s[
        "final_horizontal_position_sigma_m"
    ]


@pytest.fixture(scope="module")
def clock_step_log(sim_paper3d_short: LogData, tmp_path_factory: pytest.TempPathFactory) -> LogData:
    """The IMU's stamps 5 s ahead from 285 s on (entering the first turn), read with --repair."""
    log = sim_paper3d_short
    t = log.imu.t.copy()
    t[int(np.searchsorted(t, 285.0)) :] += 5.0
    return _through_file(
        dataclasses.replace(log, imu=dataclasses.replace(log.imu, t=t)),
        tmp_path_factory.mktemp("clock"),
        repair=True,
    )


@pytest.mark.parametrize("mode", MODES)
def test_clock_step_undone_in_every_mode(clock_step_log: LogData, mode: str) -> None:
    """With the default configuration (time offset estimated): read as a gap, the step put the time offset 15
    sigma off on the whole 840 s log (measured); undone, every mode is within its sigmas and the health says
    what was done."""
    res = MODES[mode](clock_step_log, EstimatorConfig())
    worst, final = _worst_nsigma(res, clock_step_log)
    health = assess_health(res, clock_step_log)
    print(
        f"{mode}: health {health.status}, worst calibration |err/sigma| {worst:.2f}, final position {final:.2f}"
    )
    assert worst < 3.0 and final < 3.0
    assert any("clock step at 284.990 s" in n and "back by 5.000 s" in n for n in health.notes)


@pytest.fixture(scope="module")
def saturated_log(sim_paper3d_short: LogData, tmp_path_factory: pytest.TempPathFactory) -> LogData:
    """paper-3d-short's gyro clipped at 0.055 rad/s: the peak of each turn (0.0576 rad/s) for about 5 s."""
    raw = copy.deepcopy(sim_paper3d_short.metadata["scenario"])
    raw.setdefault("imu", {})["saturation_gyro_rad_s"] = 0.055
    return _through_file(simulate(scenario_from_dict(raw), 11), tmp_path_factory.mktemp("sat"))


@pytest.mark.parametrize("mode", MODES)
def test_saturated_gyro_crossed_as_gaps_in_every_mode(saturated_log: LogData, mode: str) -> None:
    """Integrating the clipped rate instead gave health "ok" with the misalignment 6.3 sigma off (batch,
    measured)."""
    res = MODES[mode](saturated_log, EstimatorConfig.paper())
    worst, final = _worst_nsigma(res, saturated_log)
    health = assess_health(res, saturated_log)
    print(
        f"{mode}: health {health.status}, worst calibration |err/sigma| {worst:.2f}, final position {final:.2f}"
    )
    assert worst < 3.0 and final < 3.0
    assert health.status == "degraded"
    assert any(
        "the IMU saturated (gyro z at +0.055 rad/s)" in w and "2 stretch(es)" in w
        for w in health.warnings
    )
    # no gap in the log: the sensor's range
    assert not any("check the IMU driver" in w for w in health.warnings)


@pytest.fixture(scope="module")
def frozen_log(sim_paper3d_short: LogData, tmp_path_factory: pytest.TempPathFactory) -> LogData:
    """The DVL frozen for 40 s in the second turn (401-440 s) on the ping at 400 s, and 20 pings of water track
    in the leg before it (340-359 s)."""
    d = sim_paper3d_short.dvl
    t, d_v, valid = d.t, d.d_v.copy(), d.valid.copy()
    water = (t >= 340.0) & (t < 360.0)
    valid[water] = False
    d_v[(t > 400.0) & (t <= 440.0)] = d_v[int(np.searchsorted(t, 400.0))]
    log = dataclasses.replace(
        sim_paper3d_short, dvl=dataclasses.replace(d, d_v=d_v, valid=valid, water_track=water)
    )
    return _through_file(log, tmp_path_factory.mktemp("frozen"))


@pytest.mark.parametrize("mode", MODES)
def test_frozen_dvl_and_water_track_in_every_mode(frozen_log: LogData, mode: str) -> None:
    """The frozen stretch is in a steady turn, where the IMU shows no change of the velocity: it is dropped
    anyway, counted alike by every mode and named; the water-track pings are counted as such; the ping at the
    first IMU stamp is no rejection. (Water track refused here; used, it is test_water_current.py's.)"""
    paper = EstimatorConfig.paper()
    res = MODES[mode](
        frozen_log,
        paper.model_copy(
            update={"current": paper.current.model_copy(update={"water_track": "refuse"})}
        ),
    )
    worst, final = _worst_nsigma(res, frozen_log)
    health = assess_health(res, frozen_log)
    print(
        f"{mode}: health {health.status}, worst calibration |err/sigma| {worst:.2f}, final position {final:.2f}"
    )
    assert worst < 3.0 and final < 3.0
    c = res.info["counters"]
    assert (c.get("dvl_repeated"), c.get("dvl_water_track"), c.get("dvl_before_imu")) == (40, 20, 1)
    assert c.get("dvl_unusable", 0) == 0
    assert (
        "DVL output frozen: 40 pings repeated bit for bit between 401 and 440 s, dropped; check the DVL"
        in (health.warnings)
    )
    assert any(n.startswith("20 of 461 DVL pings are water track") for n in health.notes)
    assert any(n.startswith("40 of 461 DVL pings rejected (40 repeated)") for n in health.warnings)


def test_a_log_built_in_memory_is_screened_as_the_reader_screens(
    sim_paper3d_short: LogData,
) -> None:
    """A log handed straight to an estimator (not read from a file) is screened as the reader screens one
    (estimators/inputs/gaps.py screened_in_memory): the saturated gyro samples dropped and said (before, the batch
    smoother said "ok" with a calibration state 177 sigma off, measured), a clock step undone."""
    raw = copy.deepcopy(sim_paper3d_short.metadata["scenario"])
    raw.setdefault("imu", {})["saturation_gyro_rad_s"] = 0.055
    log = simulate(scenario_from_dict(raw), 11)
    assert "reader_losses" not in log.metadata
    res = smooth_batch(log, EstimatorConfig.paper())
    worst, final = _worst_nsigma(res, log)
    health = assess_health(res, log)
    assert worst < 3.0 and final < 3.0, (worst, final)
    assert health.status == "degraded"
    assert any("the IMU saturated (gyro z at +0.055 rad/s)" in w for w in health.warnings)
    t = sim_paper3d_short.imu.t.copy()
    t[int(np.searchsorted(t, 285.0)) :] += 5.0
    stepped = dataclasses.replace(
        sim_paper3d_short, imu=dataclasses.replace(sim_paper3d_short.imu, t=t)
    )
    # the clock step the IMU's samples show (entering the first turn) is undone, the DVL's timing recorded with it
    # (tests/estimators/test_clock_step_evidence.py: a step they cannot show)
    screened = screened_in_memory(stepped)
    (record,) = screened.metadata["reader_losses"]["clock_steps"]["IMU"]
    assert record["by_imu"] and record["decision"] == "clock step", record
    assert record["step_s"] == pytest.approx(5.0, abs=1e-6)
    assert np.allclose(screened.imu.t, sim_paper3d_short.imu.t, atol=1e-9)
