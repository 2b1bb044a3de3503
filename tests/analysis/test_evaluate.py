"""`evaluate` on stored results: with truth (errors inside their sigmas, segments credited) and on a
log without truth (segments classified from the IMU)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from gtsam_dvl.app.commands import evaluate_to_dir, smooth_file
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def smoothed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("eval")
    log = d / "run.mcap"
    write_log(log, simulate(load_scenario("paper-3d"), 21))
    result = d / "result.mcap"
    smooth_file(log, result, show_progress=False)
    return log, result


def test_evaluate_with_truth(smoothed: tuple[Path, Path], tmp_path: Path) -> None:
    log, result = smoothed
    lines, written = evaluate_to_dir(result, tmp_path, truth_path=log)
    m = json.loads((tmp_path / "metrics.json").read_text())
    truth = m["truth"]
    print(
        json.dumps(
            {
                k: truth[k]
                for k in (
                    "attitude_within_3_sigma",
                    "position_within_3_sigma",
                    "velocity_within_3_sigma",
                    "final_horizontal_position_pct_distance",
                )
            }
        )
    )
    # a consistent smoother keeps its errors inside 3 sigma nearly all the time
    assert (
        min(truth["attitude_within_3_sigma"]) > 0.9 and min(truth["position_within_3_sigma"]) > 0.9
    )
    assert min(truth["velocity_within_3_sigma"]) > 0.9
    obs = {s["key"]: s for s in m["observability"]}
    assert any(
        c.startswith("descent 660-720") for c in obs["misalignment_roll"]["credited_segments"]
    )
    assert any(c.startswith("square") for c in obs["accel_bias_x"]["credited_segments"])
    names = {p.name for p in written}
    assert {
        "attitude_error.png",
        "position_error.png",
        "scale.png",
        "misalignment.png",
        "normalised_sigmas.png",
        "metrics.json",
        "observability.txt",
    } <= names


def test_evaluate_log_without_truth(smoothed: tuple[Path, Path], tmp_path: Path) -> None:
    """A 'real' log: same data without truth or segment metadata; the segments come from the IMU."""
    log_path, _ = smoothed
    from gtsam_dvl.io.reader import read_log

    log = read_log(log_path)
    meta = {k: v for k, v in log.metadata.items() if k not in ("truth",)}
    real = dataclasses.replace(
        log, truth=None, metadata=meta, true_calibration=None, true_imu_bias=None, segments=[]
    )
    real_path = tmp_path / "real.mcap"
    write_log(real_path, real)
    result = tmp_path / "real-result.mcap"
    smooth_file(real_path, result, show_progress=False)
    lines, written = evaluate_to_dir(result, tmp_path / "out", truth_path=real_path)
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert "truth" not in m and m["segments_from"] == "classified from IMU"
    roll = next(s for s in m["observability"] if s["key"] == "misalignment_roll")
    print(roll)
    # informed, not to 0.1 deg
    assert roll["verdict"] == "weakly determined" and roll["ratio"] < 0.5
    # the descent, found from the IMU
    assert any("along body z" in c for c in roll["credited_segments"])
