"""Monte Carlo campaigns on Dask (campaign/runner.py, campaign/montecarlo.py): a small campaign on a LocalCluster,
the same campaign against a scheduler and two workers started here as separate processes (identical numbers), a
task that fails reported with its seed and error, and a campaign resumed without redoing finished seeds."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.app.campaign.cluster import DaskEngine
from gtsam_dvl.app.campaign.montecarlo import nees_band, run_seed
from gtsam_dvl.app.campaign.runner import FAIL_SEED_ENV, run_campaign
from gtsam_dvl.sim.scenario import load_scenario
from tests.support.campaign import SCENARIO

pytest.importorskip("distributed")
# Dask clusters and worker processes: make test runs them, make check does not
pytestmark = pytest.mark.slow

RUNS, FAIL_SEED = 6, 4
ESTIMATORS = ["batch", "ekf"]


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("mc") / "mc-tiny.toml"
    path.write_text(SCENARIO)
    return path


def _seed_files(out: Path) -> dict[int, dict]:
    return {
        int(p.stem.split("_")[1]): json.loads(p.read_text())
        for p in sorted((out / "runs").glob("seed_*.json"))
    }


@pytest.fixture(scope="module")
def local_campaign(scenario_file: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The campaign on a LocalCluster of 2 workers, the run of FAIL_SEED failing on every try."""
    out = tmp_path_factory.mktemp("mc") / "local"
    os.environ[FAIL_SEED_ENV] = str(FAIL_SEED)  # the workers are spawned now and inherit it
    try:
        res = run_campaign(
            scenario_file, RUNS, ESTIMATORS, out, engine=DaskEngine(workers=2), show_progress=False
        )
    finally:
        del os.environ[FAIL_SEED_ENV]
    assert res.runs_done == RUNS - 1 and [f["seed"] for f in res.failures] == [FAIL_SEED]
    return out


def test_campaign_reports_failures_and_statistics(
    local_campaign: Path, scenario_file: Path
) -> None:
    out = local_campaign
    failures = json.loads((out / "failures.json").read_text())
    assert failures == [
        {
            "seed": FAIL_SEED,
            "error": f"RuntimeError: {FAIL_SEED_ENV}={FAIL_SEED}: this run fails on purpose",
        }
    ]
    stats = json.loads((out / "montecarlo.json").read_text())
    assert stats["runs"] == RUNS - 1 and stats["seeds"] == [
        s for s in range(1, RUNS + 1) if s != FAIL_SEED
    ]
    report = (out / "report.md").read_text()
    assert (
        f"seed {FAIL_SEED}: RuntimeError" in report and "## batch" in report and "## ekf" in report
    )
    assert (out / "figures" / "z_histograms_batch.png").exists() and (
        out / "figures" / "nees_time_ekf.png"
    ).exists()
    # the statistics are those of the runs' files: recompute one number independently
    runs = _seed_files(out)
    z = np.array(
        [
            np.array(r["estimators"]["batch"]["error"][0]) / r["estimators"]["batch"]["sigma"][0]
            for r in runs.values()
        ]
    )
    assert stats["estimators"]["batch"]["states"]["scale"]["z_std"] == pytest.approx(
        np.std(z, ddof=1), rel=1e-12
    )
    lo, hi = nees_band(RUNS - 1)
    assert stats["estimators"]["ekf"]["nees_block"]["band_95"] == pytest.approx([lo, hi])
    # a worker's run is the same as one here: seeds decide everything
    here = run_seed(load_scenario(scenario_file).raw, 2, ESTIMATORS, None, "mc-tiny")
    for name in ESTIMATORS:
        assert here["estimators"][name]["error"] == runs[2]["estimators"][name]["error"]
        assert here["estimators"][name]["sigma"] == runs[2]["estimators"][name]["sigma"]
    print(
        "\nbatch z std:",
        {k: round(v["z_std"], 2) for k, v in stats["estimators"]["batch"]["states"].items()},
    )


def test_campaign_resumes_without_redoing_finished_seeds(
    local_campaign: Path, scenario_file: Path, tmp_path: Path
) -> None:
    out = tmp_path / "resumed"
    shutil.copytree(local_campaign, out)
    (out / "runs" / "seed_000002.json").unlink()  # as if interrupted before seed 2 was written
    before = _seed_files(out)
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("seed_*.json")}
    res = run_campaign(
        scenario_file, RUNS, ESTIMATORS, out, engine=DaskEngine(workers=1), show_progress=False
    )
    assert res.runs_new == 2 and res.runs_done == RUNS and not res.failures  # seeds 2 and FAIL_SEED
    assert {
        p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("seed_*.json") if p.name in stamps
    } == stamps
    after = _seed_files(out)
    assert all(after[s] == before[s] for s in before)
    # another campaign's settings in the same folder are refused
    from gtsam_dvl.core.errors import GtsamDvlError

    with pytest.raises(GtsamDvlError, match="holds a campaign with other settings"):
        run_campaign(
            scenario_file, RUNS, ["batch"], out, engine=DaskEngine(workers=1), show_progress=False
        )


def test_campaign_on_a_scheduler_and_two_worker_processes_gives_identical_numbers(
    local_campaign: Path, scenario_file: Path, tmp_path: Path
) -> None:
    sched_file = tmp_path / "scheduler.json"
    env = {k: v for k, v in os.environ.items() if k != FAIL_SEED_ENV}
    procs = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "distributed.cli.dask_scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(sched_file),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
        )
    ]
    try:
        # the scheduler creates its file, then writes it: wait until it reads as JSON with the address
        deadline, address = time.monotonic() + 60, None
        while address is None and time.monotonic() < deadline:
            try:
                address = json.loads(sched_file.read_text())["address"]
            except (FileNotFoundError, json.JSONDecodeError, KeyError):
                time.sleep(0.2)
        assert address is not None, "the Dask scheduler wrote no address within 60 s"
        for _ in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "distributed.cli.dask_worker",
                        address,
                        "--nthreads",
                        "1",
                        "--no-dashboard",
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    env=env,
                )
            )
        from dask.distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        out = tmp_path / "remote"
        res = run_campaign(
            scenario_file, RUNS, ESTIMATORS, out, engine=DaskEngine(address), show_progress=False
        )
    finally:
        for p in procs[::-1]:
            p.terminate()
        for p in procs:
            p.wait(timeout=30)
    assert res.runs_done == RUNS and not res.failures
    local, remote = _seed_files(local_campaign), _seed_files(out)
    for seed, run in local.items():
        for name in ESTIMATORS:
            assert remote[seed]["estimators"][name]["error"] == run["estimators"][name]["error"]
            assert remote[seed]["estimators"][name]["sigma"] == run["estimators"][name]["sigma"]
    assert json.loads((out / "cramer_rao.json").read_text()) == json.loads(
        (local_campaign / "cramer_rao.json").read_text()
    )
