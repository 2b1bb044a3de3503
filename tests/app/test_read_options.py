"""Reading options on every log-reading command, and the source log a result remembers: `evaluate result.mcap`
finds the log relative to the result file from any working directory, reads it with the options smooth used
(here --repair, which the log needs), and says so when the log is gone instead of dropping the truth silently."""

from __future__ import annotations

import copy
import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

CLI = [sys.executable, "-m", "gtsam_dvl.app.cli"]
NOT_FOUND = "not found: errors against the truth not computed; give --truth LOG"


def run(*args: str, cwd: Path, check: bool = True) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600, cwd=cwd)
    if check and proc.returncode != 0:
        raise AssertionError(f"{args} failed: {proc.stderr}")
    return proc


@pytest.fixture(scope="module")
def moved(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short paper-2d log with one duplicated IMU stamp (readable only with --repair) in base/logs/, smoothed
    with --repair into base/results/ from base's parent, then base moved elsewhere: the recorded absolute path
    is stale, the relative one is right. Returns the moved base folder."""
    from gtsam_dvl.io.writer import write_log
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = raw["segments"][:4]
    raw["segments"][0]["duration_s"] = 150.0
    log = simulate(scenario_from_dict(raw, "paper-2d-short"), 5)
    t = log.imu.t.copy()
    t[len(t) // 3 + 1] = t[len(t) // 3]
    log = dataclasses.replace(log, imu=dataclasses.replace(log.imu, t=t))
    root = tmp_path_factory.mktemp("read_options")
    (root / "base" / "logs").mkdir(parents=True)
    (root / "base" / "results").mkdir()  # (outputs never create folders)
    write_log(root / "base" / "logs" / "short.mcap", log)
    no_repair = run("info", "base/logs/short.mcap", cwd=root, check=False)
    assert no_repair.returncode == 1 and "--repair" in no_repair.stderr  # the log needs --repair
    run(
        "smooth",
        "base/logs/short.mcap",
        "--repair",
        "-o",
        "base/results/result.mcap",
        "-q",
        "--no-timeline",
        cwd=root,
    )
    shutil.move(root / "base", root / "moved")
    return root / "moved"


def test_result_records_source_log_and_read_options(moved: Path) -> None:
    from gtsam_dvl.io.result_reader import read_result

    stored = read_result(moved / "results" / "result.mcap")
    assert stored.source_log_relative == str(Path("..") / "logs" / "short.mcap")
    # base was moved
    assert Path(stored.source_log).is_absolute() and not Path(stored.source_log).exists()
    assert stored.source_log == str((moved.parent / "base" / "logs" / "short.mcap").resolve())
    assert stored.read_options == {
        "imu_topic": "/imu/data_raw",
        "dvl_topic": None,
        "salvage": False,
        "repair": True,
    }


def test_evaluate_finds_moved_log_from_any_directory_and_reuses_repair(
    moved: Path, tmp_path: Path
) -> None:
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    result, out = moved / "results" / "result.mcap", tmp_path / "eval"
    # no --repair given: the recorded one
    proc = run("evaluate", str(result), "-o", str(out), cwd=elsewhere)
    assert NOT_FOUND not in proc.stdout
    metrics = json.loads((out / "metrics.json").read_text())
    assert "truth" in metrics and metrics["truth"]["calibration_errors"]
    assert Path(metrics["truth_log"]).resolve() == (moved / "logs" / "short.mcap").resolve()
    assert metrics["truth_log_read_options"]["repair"] is True
    assert metrics["truth_log_losses"]["repair"]  # the duplicated stamp dropped again, and counted
    # an option given to evaluate overrides the recorded one: without repair the log cannot be read
    proc = run(
        "evaluate",
        str(result),
        "-o",
        str(tmp_path / "eval2"),
        "--no-repair",
        cwd=elsewhere,
        check=False,
    )
    assert proc.returncode == 1 and "--repair" in proc.stderr


def test_evaluate_says_when_source_log_is_gone(moved: Path, tmp_path: Path) -> None:
    gone = tmp_path / "gone"
    shutil.copytree(moved, gone)
    (gone / "logs" / "short.mcap").unlink()
    out = tmp_path / "eval"
    proc = run("evaluate", str(gone / "results" / "result.mcap"), "-o", str(out), cwd=tmp_path)
    lines = [line for line in proc.stdout.splitlines() if NOT_FOUND in line]
    assert lines == [
        f"source log {(moved.parent / 'base' / 'logs' / 'short.mcap').resolve()} {NOT_FOUND}"
    ]
    metrics = json.loads((out / "metrics.json").read_text())
    assert "truth" not in metrics and metrics["truth_log"] is None
    assert metrics["verdict"]  # the rest of the evaluation is still there
