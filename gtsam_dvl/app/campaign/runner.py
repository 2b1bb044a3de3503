"""Monte Carlo campaigns on Dask distributed: `gtsam-dvl montecarlo SCENARIO --runs N ...`.

A task is one seed (campaign/montecarlo.run_seed) on the client of campaign/cluster.py: it ships the scenario's
tables, the seed, the estimator names and the configuration as plain data, so a worker needs no file and no
object of the client's, and the result is the same on any machine.

The campaign folder DIR holds campaign.json (what the campaign is: scenario, estimators, configuration; a
rerun with other settings is refused), runs/seed_NNNNNN.json (one file per finished seed, written atomically as
it completes: an interrupted campaign resumes without redoing them), failures.json (seeds whose task failed
twice, with their error: Dask retries a task once), montecarlo.json (the statistics) and report.md with the
figures under figures/ (campaign/report.py).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gtsam_dvl.app.calibration_files import calibration_data
from gtsam_dvl.app.campaign.cluster import LOCAL_CLUSTER, DaskEngine, finished, require_dask
from gtsam_dvl.app.campaign.montecarlo import (
    ESTIMATORS,
    campaign_statistics,
    cramer_rao_sigmas,
    run_seed,
)
from gtsam_dvl.app.campaign.report import write_report
from gtsam_dvl.core.errors import GtsamDvlError

if TYPE_CHECKING:
    from gtsam_dvl.sim.scenario import Scenario

# for tests of the engine only: the run of this seed raises (a task that fails on every try)
FAIL_SEED_ENV = "GTSAM_DVL_MONTECARLO_FAIL_SEED"


def _run_task(
    scenario: dict[str, Any],
    seed: int,
    estimators: list[str],
    config: dict[str, Any] | None,
    name: str,
    calibration: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The worker's task: one seed (campaign/montecarlo.run_seed)."""
    if os.environ.get(FAIL_SEED_ENV) == str(seed):
        raise RuntimeError(f"{FAIL_SEED_ENV}={seed}: this run fails on purpose")
    return run_seed(scenario, seed, estimators, config, name, calibration)


@dataclass
class CampaignResult:
    out_dir: Path
    statistics: dict[str, Any]
    runs_done: int
    runs_new: int
    failures: list[dict[str, Any]] = field(default_factory=list)
    written: list[Path] = field(default_factory=list)


def _campaign_record(
    scenario_name: str,
    scenario: dict[str, Any],
    estimators: list[str],
    config: dict[str, Any] | None,
) -> dict[str, Any]:
    return {
        "scenario_name": scenario_name,
        "scenario": scenario,
        "estimators": list(estimators),
        "config": config,
    }


def _check_request(estimators: list[str], runs: int) -> None:
    """The estimators known and at least one run, else a one-line GtsamDvlError before any work."""
    unknown = [e for e in estimators if e not in ESTIMATORS + ("online-full",)]
    if unknown or not estimators:
        raise GtsamDvlError(
            f"unknown estimator(s) {', '.join(unknown) or '(none given)'} "
            f"(known: {', '.join(ESTIMATORS)}, online-full)"
        )
    if runs < 1:
        raise GtsamDvlError(f"--runs must be at least 1, got {runs}")


def _campaign_setup(
    scenario: str | Path,
    estimators: list[str],
    config_path: Path | None,
    calibration_path: Path | None,
) -> tuple[Scenario, dict[str, Any] | None, dict[str, Any] | None, dict[str, Any]]:
    """The campaign's scenario, configuration (None: the scenario's own), calibration prior (None: none) and its
    record as campaign.json holds it (plain JSON data)."""
    from gtsam_dvl.core.config import EstimatorConfig
    from gtsam_dvl.sim.scenario import load_scenario

    sc = load_scenario(scenario)
    # -c: the scenario's [estimator] table below it (None: the scenario's own configuration, in run_seed)
    config = (
        EstimatorConfig.load(config_path, under=sc.estimator).to_dict() if config_path else None
    )
    calibration = calibration_data(calibration_path) if calibration_path else None
    record = json.loads(
        json.dumps(_campaign_record(sc.name, sc.raw, estimators, config), default=str)
    )
    if calibration is not None:  # only then: the records of campaigns without one stay as they were
        record["calibration"] = json.loads(json.dumps(calibration, default=str))
    return sc, config, calibration, record


def _check_same_campaign(meta_path: Path, record: dict[str, Any], out_dir: Path) -> None:
    """A folder that holds a campaign with other settings is refused (a rerun resumes only the same one)."""
    if meta_path.exists():
        old = json.loads(meta_path.read_text())
        if old != record:
            raise GtsamDvlError(
                f"{out_dir}: holds a campaign with other settings (scenario, estimators or "
                "configuration); choose another folder"
            )


def _run_on_dask(
    record: dict[str, Any],
    name: str,
    todo: list[int],
    estimators: list[str],
    config: dict[str, Any] | None,
    calibration: dict[str, Any] | None,
    out_dir: Path,
    failures: list[dict[str, Any]],
    engine: DaskEngine,
    show_progress: bool,
) -> None:
    """The seeds still to run and the Cramer-Rao bound (when not written yet) on Dask: campaign.json first once
    the client is up, each seed's result written as it completes, a failed task's error appended to failures."""
    from gtsam_dvl.app.progress import progress_bar
    from gtsam_dvl.io.atomic import atomic_write_json

    runs_dir = out_dir / "runs"
    meta_path = out_dir / "campaign.json"
    crb_path = out_dir / "cramer_rao.json"
    with engine.client() as client:
        if not meta_path.exists():  # the client is up: the campaign starts, its record first
            atomic_write_json(meta_path, record)
        futures = {
            client.submit(
                _run_task,
                record["scenario"],
                s,
                list(estimators),
                config,
                name,
                calibration,
                key=f"gtsam-dvl-seed-{name}-{s}",
                pure=False,
                retries=1,
            ): s
            for s in todo
        }
        crb_future = (
            client.submit(cramer_rao_sigmas, record["scenario"], config, name, pure=False)
            if not crb_path.exists()
            else None
        )
        with progress_bar(
            f"montecarlo {name}: {len(todo)} runs", enabled=show_progress
        ) as progress:
            for seed, fut, exc in finished(futures, progress):
                if exc is not None:
                    failures.append({"seed": seed, "error": f"{type(exc).__name__}: {exc}"})
                else:
                    atomic_write_json(runs_dir / f"seed_{seed:06d}.json", fut.result())
        if crb_future is not None:
            try:
                atomic_write_json(crb_path, crb_future.result())
            except Exception as exc:  # noqa: BLE001 - the bound is optional: say why it is missing
                failures.append(
                    {"seed": None, "error": f"Cramer-Rao bound: {type(exc).__name__}: {exc}"}
                )


def run_campaign(
    scenario: str | Path,
    runs: int,
    estimators: list[str],
    out_dir: Path,
    seed_start: int = 1,
    engine: DaskEngine = LOCAL_CLUSTER,
    config_path: Path | None = None,
    show_progress: bool = True,
    calibration_path: Path | None = None,
) -> CampaignResult:
    """Run (or resume) a campaign of seeds seed_start .. seed_start + runs - 1 (module doc). Nothing is written
    before the Dask client is up: without Dask, or with a scheduler out of reach, a one-line GtsamDvlError and an
    untouched folder. calibration_path: a vehicle's calibration file, the prior of every run (shipped as data,
    recorded in campaign.json)."""
    from gtsam_dvl.io.atomic import atomic_write_json

    _check_request(estimators, runs)
    require_dask()
    sc, config, calibration, record = _campaign_setup(
        scenario, estimators, config_path, calibration_path
    )
    out_dir = Path(out_dir)
    runs_dir = out_dir / "runs"
    meta_path = out_dir / "campaign.json"
    _check_same_campaign(meta_path, record, out_dir)
    seeds = list(range(seed_start, seed_start + runs))
    done = {s for s in seeds if (runs_dir / f"seed_{s:06d}.json").exists()}
    todo = [s for s in seeds if s not in done]
    failures: list[dict[str, Any]] = []
    crb = None
    crb_path = out_dir / "cramer_rao.json"
    if todo or not crb_path.exists():
        _run_on_dask(
            record,
            sc.name,
            todo,
            estimators,
            config,
            calibration,
            out_dir,
            failures,
            engine,
            show_progress,
        )
    if crb_path.exists():
        crb = json.loads(crb_path.read_text())
    results = [
        json.loads((runs_dir / f"seed_{s:06d}.json").read_text())
        for s in seeds
        if (runs_dir / f"seed_{s:06d}.json").exists()
    ]
    atomic_write_json(out_dir / "failures.json", failures)
    if not results:
        raise GtsamDvlError(
            f"{out_dir}: every run failed; see failures.json (first: {failures[0]['error']})"
            if failures
            else f"{out_dir}: no runs"
        )
    stats = campaign_statistics(results, crb)
    stats.update(scenario=sc.name, seeds=[r["seed"] for r in results], failures=failures)
    written = [atomic_write_json(out_dir / "montecarlo.json", stats)]
    written += write_report(out_dir, stats)
    return CampaignResult(
        out_dir, stats, len(results), len(todo) - len(failures), failures, written
    )
