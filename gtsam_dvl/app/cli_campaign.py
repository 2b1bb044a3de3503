"""The campaign commands of the command line (app/cli.py's `app`): `montecarlo` (consistency over many seeds) and
`calibrate` (one calibration from several dives), both on Dask. Imported by app/cli.py, which registers them."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from gtsam_dvl.app.cli_options import (
    ENGINE,
    EXIT_UNHEALTHY,
    READING,
    ConfigOpt,
    Debug,
    Quiet,
    ScenarioArg,
    _user_errors,
    app,
    option_groups,
)
from gtsam_dvl.core.errors import GtsamDvlError

if TYPE_CHECKING:
    from gtsam_dvl.app.campaign.cluster import DaskEngine
    from gtsam_dvl.io.read_options import ReadOptions

MONTECARLO_HELP = (
    "Monte Carlo consistency of the estimators on a scenario, on Dask distributed.\n\n"
    "Each task simulates one seed and runs the chosen estimators on it; the statistics per estimator and state "
    "(error/sigma mean and spread, NEES with its 95 % band, RMSE against the reported sigma and the Cramer-Rao "
    "bound) go to DIR/montecarlo.json and DIR/report.md with figures. A failed task is retried once, then listed "
    "with its seed and error (exit code 3). Rerun with the same DIR to resume: finished seeds are kept.\n\n"
    "Engine: a LocalCluster of --workers processes (default: the cores), or a running scheduler: "
    "`dask scheduler` and `dask worker tcp://HOST:8786` on the machines, then --scheduler tcp://HOST:8786."
)


CampaignEngine = Annotated[
    "DaskEngine",
    ENGINE.helped(
        scheduler="Address of a running Dask scheduler (default: a LocalCluster here).",
        workers="LocalCluster processes (default: the cores).",
    ),
]


@app.command(help=MONTECARLO_HELP)
@_user_errors
@option_groups
def montecarlo(
    scenario: ScenarioArg,
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Campaign folder (created; reused to resume).")
    ],
    runs: Annotated[int, typer.Option("--runs", help="Number of seeds.")] = 20,
    estimators: Annotated[
        str, typer.Option("--estimators", help="Comma-separated: batch, online, ekf, online-full.")
    ] = "batch,online,ekf",
    seed_start: Annotated[int, typer.Option("--seed-start", help="First seed.")] = 1,
    *,
    engine: CampaignEngine,
    config: ConfigOpt = None,
    quiet: Quiet = False,
    calibration: Annotated[
        Path | None, typer.Option(help="A vehicle's calibration file as every run's prior.")
    ] = None,
    debug: Debug = False,
) -> None:
    """Monte Carlo consistency of the estimators on a scenario (help: MONTECARLO_HELP)."""
    from gtsam_dvl.app.campaign.runner import run_campaign
    from gtsam_dvl.app.outputs import check_folders

    check_folders({}, {"-o": output})
    res = run_campaign(
        scenario,
        runs,
        [e.strip() for e in estimators.split(",") if e.strip()],
        output,
        seed_start=seed_start,
        engine=engine,
        config_path=config,
        show_progress=not quiet,
        calibration_path=calibration,
    )
    for name, est in res.statistics["estimators"].items():
        z = ", ".join(
            f"{k} {v['z_std']:.2f}" for k, v in est["states"].items() if not k.startswith("final")
        )
        nb = est["nees_block"]
        typer.echo(
            f"{name}: error/sigma std {z}; block NEES {nb['mean']:.2f} (95 % band "
            f"{nb['band_95'][0]:.2f}-{nb['band_95'][1]:.2f}, {'inside' if nb['inside_band'] else 'OUTSIDE'})"
        )
    typer.echo(f"{res.runs_done} runs ({res.runs_new} new) in {res.out_dir}")
    for f in res.failures:
        typer.echo(
            f"gtsam-dvl: error: seed {f['seed']} failed: {f['error']}"
            if f["seed"] is not None
            else f"gtsam-dvl: error: {f['error']}",
            err=True,
        )
    for path in res.written[:2]:
        typer.echo(f"wrote {path}")
    if res.failures:
        raise typer.Exit(EXIT_UNHEALTHY)


# calibrate reads the IMU, DVL, depth and GNSS (no attitude, truth or water-track topic)
DiveReadOpts = Annotated[
    "ReadOptions",
    READING.only("imu_topic", "dvl_topic", "salvage", "repair", "depth_topic", "gnss_topic"),
]


# calibrate runs in this process with --workers 1
DiveEngine = Annotated[
    "DaskEngine",
    ENGINE.helped(
        scheduler="A running Dask scheduler (default: a LocalCluster here).",
        workers="LocalCluster processes (default: the cores; 1: in this process).",
    ),
]


CALIBRATE_HELP = (
    "One DVL calibration (scale, misalignment; the lever arm when estimated) from several dives of one vehicle, "
    "on Dask.\n\n"
    "Each dive is smoothed alone, then the dives are solved jointly: each dive (a Dask task on the worker that "
    "holds it) linearises its graph and eliminates its own states; the client sums their information on the "
    "shared calibration, solves, and sends the step back, until it settles (docs/calibration-across-dives.md). "
    "IMU biases and time offsets stay per dive. Writes the calibration file (-o, TOML: `smooth --calibration`) "
    "and, with --out-dir, the per-dive table and figure (each dive alone against the joint; which moved beyond 3 "
    "sigma). A dive that fails is reported with its error and left out (exit code 3); the others finish.\n\n"
    "Engine: a LocalCluster of --workers processes (default: the cores), a running scheduler (--scheduler), or "
    "this process with --workers 1 (also when Dask is not installed)."
)


@app.command(help=CALIBRATE_HELP)
@_user_errors
@option_groups
def calibrate(
    logs: Annotated[
        list[Path],
        typer.Argument(help="The dives' logs (MCAP or rosbag2 directories).", metavar="LOG..."),
    ],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Calibration file to write (TOML).")
    ],
    out_dir: Annotated[
        Path | None,
        typer.Option("--out-dir", help="Folder for calibration-fleet.md, .json and .png."),
    ] = None,
    vehicle: Annotated[
        str, typer.Option("--vehicle", help="The vehicle's name in the file.")
    ] = "vehicle",
    config: ConfigOpt = None,
    *,
    read_options: DiveReadOpts,
    engine: DiveEngine,
    quiet: Quiet = False,
    debug: Debug = False,
) -> None:
    """One calibration from several dives (help: CALIBRATE_HELP)."""
    from gtsam_dvl.app.campaign.calibrate import calibrate_logs
    from gtsam_dvl.app.outputs import check_folders

    check_folders({"-o": output}, {"--out-dir": out_dir})
    outcome = calibrate_logs(
        logs,
        output,
        config_path=config,
        read_options=read_options,
        engine=engine,
        vehicle=vehicle,
        out_dir=out_dir,
        show_progress=not quiet,
    )
    typer.echo(outcome.describe())
    if outcome.calibration is None:
        raise GtsamDvlError("calibrate: no dive could be smoothed; their errors are above")
    if outcome.failures:
        typer.echo(
            f"gtsam-dvl: error: {len(outcome.failures)} of {len(logs)} dives left out; their errors are "
            "above",
            err=True,
        )
        raise typer.Exit(EXIT_UNHEALTHY)
