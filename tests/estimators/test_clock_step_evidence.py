"""An IMU clock step told from a gap by the DVL's timing across it (estimators/inputs/clock_evidence.py), in the
screen batch, online and EKF share (estimators/inputs/gaps.py screened_in_memory). The step is put in a straight
leg (300 s, in the middle of 120 s at constant speed), where the IMU's samples alone cannot tell a clock step from
a gap (core/imu_faults.py clock_steps finds nothing there); the log is paper-3d-short's start (alignment, surge,
descent), the straight leg and its end (surge, ascent), 450 s. Read as a gap (before), on the whole paper-3d-short
with the step in its straight leg at 350 s: a +2 s step put the time offset 6.4 (batch), 11.4 (online), 8.5 (EKF)
sigma off and the final position 2.6, 3.6, 3.4 sigma, health "degraded" for a 2 s IMU gap; a -1 s step 3.4 and
4.2 sigma off with health "ok" (batch, EKF) and stopped the online estimator (a repeated stamp)."""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.health import assess_health
from gtsam_dvl.analysis.health_losses import loss_findings
from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.imu_faults import clock_steps
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

AT_S = 300.0  # in the straight leg
MODES: dict[str, Callable[[LogData, EstimatorConfig], NavResult]] = {
    "batch": smooth_batch,
    "online": smooth_online,
    "ekf": run_ekf,
}


@pytest.fixture(scope="module")
def straight_leg(sim_paper3d_short: LogData) -> LogData:
    """paper-3d-short's alignment, surge and descent, 120 s straight at 2 m/s, its last surge and ascent."""
    raw = copy.deepcopy(sim_paper3d_short.metadata["scenario"])
    raw["name"] = "straight-leg-step"
    raw["segments"] = [
        *raw["segments"][:4],
        {"kind": "straight", "duration_s": 120.0},
        *raw["segments"][-2:],
    ]
    return simulate(scenario_from_dict(raw), 11)


def _faulty(log: LogData, case: str) -> LogData:
    """The IMU's stamps 2 s ahead ("+2") or 1 s behind ("-1") from AT_S on, the samples running on; or 2 s of
    samples missing from AT_S ("gap")."""
    t = log.imu.t.copy()
    k = int(np.searchsorted(t, AT_S))
    if case == "gap":
        keep = (t < AT_S) | (t >= AT_S + 2.0)
        imu = dataclasses.replace(
            log.imu, t=t[keep], b_omega=log.imu.b_omega[keep], b_f=log.imu.b_f[keep]
        )
    else:
        t[k:] += float(case)
        imu = dataclasses.replace(log.imu, t=t)
    return dataclasses.replace(log, imu=imu)


@pytest.mark.parametrize(
    ("case", "decision"), [("+2", "clock step"), ("-1", "clock step"), ("gap", "gap")]
)
def test_the_dvl_tells_a_clock_step_from_a_gap(
    straight_leg: LogData, case: str, decision: str
) -> None:
    """The offset after the step differs from the one before by the step (a clock step) or by nothing (a gap);
    the IMU's samples alone found no clock step there."""
    log = _faulty(straight_leg, case)
    assert clock_steps(log.imu.t, log.imu.b_omega, log.imu.b_f) == []
    screened = screened_in_memory(log)
    kind = "clock_steps" if decision == "clock step" else "imu_stamp_steps"
    (record,) = screened.metadata["reader_losses"][kind]["IMU"]
    assert record["decision"] == decision and not record["by_imu"]
    assert record["step_s"] == pytest.approx(2.0 if case == "gap" else float(case), abs=1e-6)
    assert record["difference_sigma_s"] < 0.2
    if decision == "clock step":  # the stamps after it put back on the IMU's clock
        assert np.allclose(screened.imu.t, straight_leg.imu.t, atol=1e-9)
    else:
        assert np.array_equal(screened.imu.t, log.imu.t)


def test_a_step_too_small_to_time_is_undecided_and_said(straight_leg: LogData) -> None:
    """+0.1 s: the two offsets' sigma (0.12 s) cannot tell it from 0; left as it is and "degraded" in the health."""
    screened = screened_in_memory(_faulty(straight_leg, "+0.1"))
    losses = screened.metadata["reader_losses"]
    assert "clock_steps" not in losses
    (record,) = losses["imu_stamp_steps"]["IMU"]
    assert record["decision"] == "undecided"
    (finding,) = [f for f in loss_findings(losses) if "undecided" in f[1]]
    assert finding[0] == "degraded" and "a gap or a clock step of +0.100 s" in finding[1]


@pytest.mark.slow
@pytest.mark.parametrize("case", ["+2", "-1", "gap"])
@pytest.mark.parametrize("mode", MODES)
def test_clock_step_and_gap_in_every_mode(straight_leg: LogData, mode: str, case: str) -> None:
    """Each mode: the time offset and the final position within 3 sigma; the health names the clock step with
    its size and the DVL's offsets, or the gap as a gap."""
    log = _faulty(straight_leg, case)
    res = MODES[mode](log, EstimatorConfig())
    s = summary(res, log)
    offset = abs(s["errors"]["dvl_time_offset_nsigma"])
    final = s["errors"]["final_horizontal_position_m"] / s["final_horizontal_position_sigma_m"]
    health = assess_health(res, log)
    print(
        f"{mode} {case}: offset {offset:.2f} sigma, final position {final:.2f} sigma, {health.status}"
    )
    assert offset < 3.0 and final < 3.0
    if case == "gap":
        assert any("299.990 s: samples missing, not a clock step" in n for n in health.notes)
        assert health.status == "degraded"  # the 2 s hole itself
    else:
        shift = "back by 2.000 s" if case == "+2" else "forward by 1.000 s"
        assert any(
            "clock step at 299.990 s" in n and "shown by the DVL's timing" in n and shift in n
            for n in health.notes
        ), health.notes
        assert health.status == "ok", health.warnings


@pytest.mark.slow
@pytest.mark.parametrize("case", ["+2", "gap"])
def test_a_log_read_from_a_file(straight_leg: LogData, case: str, tmp_path: Path) -> None:
    """Read from a file, the reader's rule from the IMU's samples leaves the step as a 2 s gap (no error, no
    --repair needed); the estimators' screen then asks the DVL as for a log built in memory."""
    path = tmp_path / "log.mcap"
    write_log(path, cut_log(_faulty(straight_leg, case), 450.0, beams=False))
    log = read_log(path)
    assert "clock_steps" not in log.metadata["reader_losses"]
    res = smooth_batch(log, EstimatorConfig())
    s = summary(res, log)
    final = s["errors"]["final_horizontal_position_m"] / s["final_horizontal_position_sigma_m"]
    health = assess_health(res, log)
    print(
        f"file {case}: offset {s['errors']['dvl_time_offset_nsigma']:.2f} sigma, final {final:.2f}, {health.status}"
    )
    assert abs(s["errors"]["dvl_time_offset_nsigma"]) < 3.0 and final < 3.0
    if case == "gap":
        assert health.status == "degraded"
        assert any("299.990 s: samples missing, not a clock step" in n for n in health.notes)
    else:
        assert health.status == "ok", health.warnings
        assert any("clock step at 299.990 s" in n and "back by 2.000 s" in n for n in health.notes)
