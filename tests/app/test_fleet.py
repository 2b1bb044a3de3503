"""Fleet processing (`gtsam-dvl smooth LOG... --out-dir DIR`, campaign/fleet.py smooth_fleet): several logs
smoothed in parallel on Dask with one configuration, one result set per log and a table of all runs; a bad log
gets its error line in the table and the others finish."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from gtsam_dvl.app.commands import simulate_to_file
from tests.support.campaign import SCENARIO

pytest.importorskip("distributed")


# whole command-line runs on several logs: make test runs them, make check does not
pytestmark = pytest.mark.slow


def _smooth(*args: str | Path, timeout_s: float) -> subprocess.CompletedProcess[str]:
    """`gtsam-dvl smooth ARGS` in another interpreter, its output captured as text."""
    return subprocess.run(
        [sys.executable, "-m", "gtsam_dvl.app.cli", "smooth", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def test_fleet_smooths_every_log_and_reports_the_bad_one(tmp_path: Path) -> None:
    scenario = tmp_path / "mc-tiny.toml"
    scenario.write_text(SCENARIO)
    logs = []
    for seed in (1, 2):  # two logs of one name in two folders: DIR/dive1_dive/, DIR/dive2_dive/
        (tmp_path / f"dive{seed}").mkdir()
        logs.append(tmp_path / f"dive{seed}" / "dive.mcap")
        simulate_to_file(scenario, logs[-1], seed=seed, show_progress=False)
    bad = tmp_path / "broken.mcap"
    bad.write_bytes(b"not a log")
    out = tmp_path / "fleet"
    proc = _smooth(logs[0], bad, logs[1], "--out-dir", out, "--workers", "2", "-q", timeout_s=600)
    print(proc.stdout)
    assert proc.returncode == 3, proc.stderr  # one log failed
    assert "gtsam-dvl: error: 1 of 3 logs failed" in proc.stderr
    # where it runs, with the dashboard's address when bokeh is there to serve it
    dashboard = (
        "dashboard http://" if importlib.util.find_spec("bokeh") is not None else "no dashboard"
    )
    assert f"Dask LocalCluster: 2 worker processes, {dashboard}" in proc.stderr
    rows = json.loads((out / "fleet.json").read_text())
    assert [Path(r["log"]).resolve() for r in rows] == [
        p.resolve() for p in (logs[0], bad, logs[1])
    ]  # as given
    assert [Path(r["dir"]).name for r in rows] == ["dive1_dive", "broken", "dive2_dive"]
    assert [r["status"] for r in rows] == ["ok", "error", "ok"]
    assert "neither an MCAP nor a rosbag2" in rows[1]["error"]
    for r, seed in ((rows[0], 1), (rows[2], 2)):
        summ = json.loads((out / f"dive{seed}_dive" / "summary.json").read_text())
        assert summ["scale"] == r["scale"] and (out / f"dive{seed}_dive" / "result.mcap").exists()
        assert abs(summ["errors"]["scale_nsigma"]) < 3
    table = (out / "fleet.md").read_text()
    assert "| broken | error |" in table and table.count("| ok |") == 2
    assert "| dive1_dive | ok |" in table and "| dive2_dive | ok |" in table
    # several logs need --out-dir; -o is for one log
    proc = _smooth(logs[0], logs[1], "-o", tmp_path / "r.mcap", timeout_s=60)
    assert proc.returncode == 1 and "several logs are smoothed with --out-dir" in proc.stderr
