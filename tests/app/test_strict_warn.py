"""`smooth --strict` on an honest result with weak geometry (health "warn", analysis/geometry.py): exit code 0,
the finding on the console and in the summary; only "degraded" and "failed" make exit code 3."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from gtsam_dvl.app.cli import app
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import scenario_raw


def test_weak_geometry_warns_without_failing_strict(tmp_path: Path) -> None:
    # 200 s straight at 1.9 m/s from the start, the default configuration with the initial attitude given
    raw = scenario_raw(
        initial={"speed_m_s": 1.9}, segments=[{"kind": "straight", "duration_s": 200.0}]
    )
    raw.pop("estimator_config", None)
    log = tmp_path / "straight.mcap"
    write_log(log, simulate(scenario_from_dict(raw, name="straight"), 4))
    config = tmp_path / "c.toml"
    config.write_text("[alignment]\ninitial_attitude_deg = [3.0, 0.0, 10.0]\n")
    result = CliRunner().invoke(
        app,
        [
            "smooth",
            str(log),
            "-c",
            str(config),
            "--summary",
            str(tmp_path / "s.json"),
            "-q",
            "--strict",
        ],
    )
    print(result.stdout, result.stderr)
    assert result.exit_code == 0, result.stderr
    assert "  health: warn" in result.stdout and "  motion: straight, level" in result.stdout
    assert (
        "warning: misalignment yaw leans on its prior on a straight track; a turn separates it"
        in result.stdout
    )
    summ = json.loads((tmp_path / "s.json").read_text())
    assert summ["health"]["status"] == "warn" and summ["geometry"]["motion"]["kind"] == "straight"
    yaw = [f for f in summ["geometry"]["findings"] if f["column"] == "misalignment yaw"]
    assert len(yaw) == 1 and yaw[0]["severity"] == "warn" and yaw[0]["ratio"] > 0.9
