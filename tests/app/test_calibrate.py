"""`gtsam-dvl calibrate` (app/campaign/calibrate.py): one calibration file from several dives, a dive that fails
left out with its error, the per-dive table naming a dive whose scale moved; the same answer on Dask."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from gtsam_dvl.app.campaign.calibrate import calibrate_logs
from gtsam_dvl.app.campaign.cluster import DaskEngine
from gtsam_dvl.app.cli import app
from gtsam_dvl.app.commands import simulate_to_file
from gtsam_dvl.io.calibration_file import read_calibration
from tests.support.campaign import SCENARIO


@pytest.fixture(scope="module")
def dives(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Two small dives (mc-tiny), the second's DVL scale 2 % larger, and a file that is not a log."""
    d = tmp_path_factory.mktemp("calibrate")
    same, moved = d / "same.toml", d / "moved.toml"
    same.write_text(SCENARIO)
    moved.write_text(SCENARIO.replace("scale = 0.9998", "scale = 1.0198"))
    logs = [d / "dive1.mcap", d / "dive2.mcap"]
    simulate_to_file(same, logs[0], seed=1, show_progress=False)
    simulate_to_file(moved, logs[1], seed=2, show_progress=False)
    bad = d / "broken.mcap"
    bad.write_bytes(b"not a log")
    return {"dir": d, "logs": logs, "bad": bad}


def test_calibrate_writes_the_file_reports_the_bad_dive_and_the_moved_scale(
    dives: dict[str, Any],
) -> None:
    d = dives["dir"]
    out = d / "calib.toml"
    res = CliRunner().invoke(
        app,
        [
            "calibrate",
            str(dives["logs"][0]),
            str(dives["bad"]),
            str(dives["logs"][1]),
            "-o",
            str(out),
            "--out-dir",
            str(d / "fleet"),
            "--workers",
            "1",
            "-q",
            "--vehicle",
            "auv-7",
        ],
    )
    assert res.exit_code == 3, res.output  # one dive left out
    assert "1 of 3 dives left out" in res.output
    assert "broken.mcap: neither an MCAP nor a rosbag2" in res.output
    cal = read_calibration(out)
    assert (
        cal.method == "calibrate"
        and cal.vehicle == "auv-7"
        and cal.states == ("scale", "misalignment")
    )
    assert [Path(s.path).name for s in cal.sources] == ["dive1.mcap", "dive2.mcap"]
    assert all(len(s.sha256) == 64 for s in cal.sources)
    # the hash of the configuration as smooth records it (so that `smooth --calibration` recognises it)
    from gtsam_dvl.core.calibration import config_hash
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.estimators.models.current import resolve_water_track
    from gtsam_dvl.io.reader import read_log

    log = read_log(dives["logs"][0])
    stated = resolve_water_track(EstimatorConfig.for_log(log.metadata).validate(), log)
    assert cal.config_hash == config_hash(stated.to_dict())
    # the joint scale between the dives' (0.9998 and 1.0198), its sigma about 1/sqrt(2) of one dive's
    fleet = json.loads((d / "fleet" / "calibration-fleet.json").read_text())
    rows = {Path(r["log"]).name: r for r in fleet["dives"]}
    assert rows["dive1.mcap"]["scale"] < cal.values["scale"][0] < rows["dive2.mcap"]["scale"]
    assert cal.sigma("scale")[0] == pytest.approx(rows["joint"]["scale_sigma"], rel=1e-9)
    assert cal.sigma("scale")[0] < 0.8 * rows["dive1.mcap"]["scale_sigma"]
    # two dives 2 % apart (10 sigma of one): each the other's only reference, both moved in scale alone
    for name in ("dive1.mcap", "dive2.mcap"):
        assert rows[name]["moved_states"] == ["scale"]
        assert rows[name]["vs_joint"]["scale"]["n_sigma"] > 3
    assert fleet["failures"][0]["log"].endswith("broken.mcap")
    table = (d / "fleet" / "calibration-fleet.md").read_text()
    assert (
        "MOVED: scale" in table
        and "**joint (2 dives)**" in table
        and "| broken.mcap | error |" in table
    )
    assert (d / "fleet" / "calibration-fleet.png").stat().st_size > 10_000
    dives["in_process"] = cal


def test_calibrate_on_dask_gives_the_same_calibration(dives: dict[str, Any]) -> None:
    pytest.importorskip("distributed")
    from dask.distributed import Client

    with Client(
        processes=False, n_workers=2, threads_per_worker=1, dashboard_address=None
    ) as client:
        outcome = calibrate_logs(dives["logs"] + [dives["bad"]], show_progress=False, client=client)
    assert [Path(f.log).name for f in outcome.failures] == ["broken.mcap"]
    assert (
        outcome.calibration is not None
        and outcome.solution is not None
        and outcome.solution.converged
    )
    here = (
        dives.get("in_process")
        or calibrate_logs(
            dives["logs"], engine=DaskEngine(workers=1), show_progress=False
        ).calibration
    )
    assert here is not None
    np.testing.assert_allclose(
        outcome.calibration.values["scale"], here.values["scale"], rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(
        outcome.calibration.values["misalignment"], here.values["misalignment"], atol=1e-12
    )
    np.testing.assert_allclose(outcome.calibration.cov, here.cov, rtol=1e-9)
