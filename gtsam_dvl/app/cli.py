"""The `gtsam-dvl` command line: each command parses, calls one library function, prints.

Imports of the heavy modules (gtsam, matplotlib, the simulator) happen inside the commands so that
`--help` is instant.
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from gtsam_dvl.app.cli_options import (
    ENGINE,
    EXIT_SIGTERM,
    EXIT_UNHEALTHY,
    READING,
    UNHEALTHY,
    ConfigOpt,
    Debug,
    LogArg,
    Quiet,
    ReadOpts,
    ScenarioArg,
    Terminated,
    _builtin_scenarios,
    _on_sigterm,
    _state,
    _user_errors,
    app,
    option_groups,
)
from gtsam_dvl.core.errors import GtsamDvlError

if TYPE_CHECKING:
    from gtsam_dvl.app.campaign.cluster import DaskEngine
    from gtsam_dvl.app.commands import SmoothOutcome
    from gtsam_dvl.io.read_options import ReadOptions


def _print_version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            typer.echo(f"gtsam-dvl {version('gtsam-dvl')}")
        except PackageNotFoundError:  # run from a source tree that was never installed
            typer.echo("gtsam-dvl (version unknown: not installed)")
        raise typer.Exit(0)


@app.callback()
def _root(
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
    version: Annotated[
        bool,
        typer.Option(
            "--version", help="Print the version and exit.", is_eager=True, callback=_print_version
        ),
    ] = False,
) -> None:
    _state["debug"] = debug


@app.command()
@_user_errors
def simulate(
    scenario: Annotated[
        str,
        typer.Argument(help=f"Built-in name ({', '.join(_builtin_scenarios())}) or a TOML file."),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="MCAP file to write.")],
    seed: Annotated[int, typer.Option(help="Random seed: same seed, same bytes.")] = 7,
    no_noise: Annotated[
        bool,
        typer.Option(
            "--no-noise",
            help="No white noise, correlated DVL error, dropouts or "
            "outliers (biases, quantisation and calibration kept).",
        ),
    ] = False,
    quiet: Quiet = False,
    debug: Debug = False,
) -> None:
    """Simulate a scenario and write it as a ROS 2 MCAP log with truth."""
    from gtsam_dvl.app.commands import simulate_to_file
    from gtsam_dvl.app.outputs import check_folders, check_outputs

    check_folders({"-o": output})
    check_outputs(
        {"the scenario": Path(scenario) if Path(scenario).exists() else None}, {"-o": output}
    )

    result = simulate_to_file(
        scenario, output, seed=seed, white_noise=not no_noise, show_progress=not quiet
    )
    typer.echo(result.describe())


@app.command("plot-log")
@_user_errors
@option_groups
def plot_log(
    log: LogArg,
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder for the PNG figures.")],
    *,
    read_options: ReadOpts,
    debug: Debug = False,
) -> None:
    """Write the paper's Figures 1-3 (trajectory, DVL output, IMU output) for a log."""
    from gtsam_dvl.app.commands import plot_log_to_dir
    from gtsam_dvl.app.outputs import check_folders

    check_folders({}, {"-o": output})
    for path in plot_log_to_dir(
        log,
        output,
        read_options,
    ):
        typer.echo(str(path))


@app.command()
@_user_errors
@option_groups
def info(
    log: LogArg,
    *,
    read_options: ReadOpts,
    debug: Debug = False,
) -> None:
    """Summarise a log: duration, message counts, rates, mounting, truth calibration; of a result of `smooth -o`,
    its estimator, source log, calibration and health."""
    from gtsam_dvl.app.info import describe_log, describe_result

    as_result = describe_result(log) if log.is_file() else None
    if as_result is not None:
        typer.echo(as_result)
        return
    typer.echo(
        describe_log(
            log,
            read_options,
        )
    )


SMOOTH_HELP = (
    "Estimate trajectory, IMU biases, DVL scale and misalignment from a log.\n\n"
    "After every run a self-diagnosis (solver convergence, chi^2 per degree of freedom, DVL residuals per 30 s "
    "window, rejected pings, what --salvage and --repair lost) gives a health status, ok, warn, degraded or failed, "
    "printed with one line per warning and written into the summary and the result MCAP.\n\n"
    "Exit codes: 0 done (whatever the health, unless --strict); 1 bad input (one line on stderr, nothing "
    "written); 2 a usage error (an unknown option, a missing argument; one line); 3 with --strict when the health "
    "is degraded or failed (the outputs are still written); 143 "
    "terminated by SIGTERM (no partial output left behind).\n\n"
    "An output path that is an input, that cannot be written or whose folder does not exist (no folder tree is "
    "created) is refused before any work; the outputs are "
    "written all together or not at all."
)


# smooth's arguments and options whose help runs over a line (the command's parameter list stays readable)
SmoothLogs = Annotated[
    list[Path],
    typer.Argument(
        help="MCAP log (or rosbag2 directory); several with --out-dir.", metavar="LOG..."
    ),
]
SmoothMode = Annotated[
    str,
    typer.Option(help="Estimator: batch, online (iSAM2 fixed lag), online-full, ekf, io-dvlc."),
]
Strict = Annotated[
    bool,
    typer.Option(
        "--strict",
        help="Exit with code 3 when the run's health is degraded or "
        "failed (the outputs are still written).",
    ),
]
FleetDir = Annotated[
    Path | None,
    typer.Option(
        "--out-dir",
        help="Fleet processing: smooth every LOG in parallel "
        "(Dask) into DIR/<log name>/, with a table of all "
        "runs in DIR/fleet.md.",
    ),
]
# with --out-dir, where the logs are smoothed
FleetEngine = Annotated[
    "DaskEngine",
    ENGINE.helped(
        scheduler="With --out-dir: a running Dask scheduler (default: a LocalCluster here).",
        workers="With --out-dir: LocalCluster processes.",
    ),
]
CalibrationPrior = Annotated[
    Path | None,
    typer.Option(
        help="A vehicle's calibration file as the prior of its states "
        "(inflated by [calibration] inflation_per_day for its age)."
    ),
]
ResultOutput = Annotated[Path | None, typer.Option("-o", "--output", help="Result MCAP to write.")]
TumOutput = Annotated[
    Path | None, typer.Option(help="TUM trajectory file to write (opens in evo).")
]
Timeline = Annotated[
    bool, typer.Option(help="Sigma timeline of the calibration (batch: ~1 s more).")
]
TimelineNpz = Annotated[
    Path | None, typer.Option(help="Timeline arrays file (default <output>.timeline.npz).")
]
CalibrationOut = Annotated[
    Path | None, typer.Option(help="Write this run's calibration file (TOML).")
]
Vehicle = Annotated[
    str | None,
    typer.Option(help="Vehicle name (default: --calibration's, else the log's folder name)."),
]


@app.command(help=SMOOTH_HELP)
@_user_errors
@option_groups
def smooth(
    logs: SmoothLogs,
    output: ResultOutput = None,
    mode: SmoothMode = "batch",
    summary: Annotated[Path | None, typer.Option(help="Summary JSON to write.")] = None,
    tum: TumOutput = None,
    config: ConfigOpt = None,
    *,
    read_options: ReadOpts,
    timeline: Timeline = True,
    timeline_npz: TimelineNpz = None,
    quiet: Quiet = False,
    strict: Strict = False,
    out_dir: FleetDir = None,
    engine: FleetEngine,
    calibration: CalibrationPrior = None,
    calibration_out: CalibrationOut = None,
    vehicle: Vehicle = None,
    debug: Debug = False,
) -> None:
    """Estimate trajectory, IMU biases, DVL scale and misalignment from a log (help: SMOOTH_HELP)."""
    from gtsam_dvl.app.commands import smooth_file

    one_log = _check_smooth_folders(output, summary, tum, timeline_npz, calibration_out, out_dir)
    if out_dir is not None or len(logs) > 1:
        _smooth_fleet(
            logs,
            out_dir,
            [*one_log, calibration],
            mode,
            config,
            read_options,
            engine,
            quiet,
            strict,
        )
        return
    outcome = smooth_file(
        logs[0],
        output,
        mode=mode,
        summary_path=summary,
        tum_path=tum,
        config_path=config,
        show_progress=not quiet,
        read_options=read_options,
        timeline=timeline,
        timeline_path=timeline_npz,
        calibration_path=calibration,
        calibration_out=calibration_out,
        vehicle=vehicle,
    )
    _echo_outcome(outcome, strict)


def _check_smooth_folders(
    output: Path | None,
    summary: Path | None,
    tum: Path | None,
    timeline_npz: Path | None,
    calibration_out: Path | None,
    out_dir: Path | None,
) -> list[Path | None]:
    """smooth's output paths checked before any work (outputs.check_folders: an output file's folder must
    exist, --out-dir's parent too). Returns the output files of one log's run (None: not given)."""
    from gtsam_dvl.app.outputs import check_folders

    one_log = {
        "-o": output,
        "--summary": summary,
        "--tum": tum,
        "--timeline-npz": timeline_npz,
        "--calibration-out": calibration_out,
    }
    check_folders(one_log, {"--out-dir": out_dir})
    return list(one_log.values())


def _echo_outcome(outcome: SmoothOutcome, strict: bool) -> None:
    """One log's run printed (commands.SmoothOutcome.describe); with --strict, exit code 3 when unhealthy."""
    typer.echo(outcome.describe())
    if strict and outcome.status in UNHEALTHY:
        typer.echo(
            f"gtsam-dvl: error: health {outcome.status} (--strict): exit code {EXIT_UNHEALTHY}",
            err=True,
        )
        raise typer.Exit(EXIT_UNHEALTHY)


def _smooth_fleet(
    logs: list[Path],
    out_dir: Path | None,
    one_log: list[Path | None],
    mode: str,
    config: Path | None,
    read_options: ReadOptions,
    engine: DaskEngine,
    quiet: bool,
    strict: bool,
) -> None:
    """`smooth LOG... --out-dir DIR`: the fleet smoothed (app/campaign/fleet.py), its table printed, the logs that
    failed counted on stderr; exit code 3 when one failed (or, with --strict, is unhealthy). one_log: the options
    that take one log (-o, --summary, --tum, --timeline-npz, --calibration-out, --calibration), refused here."""
    from gtsam_dvl.app.campaign.fleet import fleet_table, smooth_fleet

    if out_dir is None or any(p is not None for p in one_log):
        raise GtsamDvlError(
            "several logs are smoothed with --out-dir DIR (each into DIR/<log name>/); -o, "
            "--summary, --tum, --timeline-npz, --calibration and --calibration-out take one log"
        )

    rows, written = smooth_fleet(
        logs,
        out_dir,
        mode=mode,
        config_path=config,
        read_options=read_options,
        engine=engine,
        show_progress=not quiet,
    )
    typer.echo("\n".join(fleet_table(rows)))
    for path in written:
        typer.echo(f"wrote {path}")
    bad = [r for r in rows if r["status"] == "error" or (strict and r["status"] in UNHEALTHY)]
    if any(r["status"] == "error" for r in rows):
        typer.echo(
            f"gtsam-dvl: error: {sum(r['status'] == 'error' for r in rows)} of {len(rows)} logs failed; "
            "their errors are in the table",
            err=True,
        )
    if bad:
        raise typer.Exit(EXIT_UNHEALTHY)


CHARACTERISE_HELP = (
    "What the log says about its sensors, and the [imu] / [dvl] settings it recommends.\n\n"
    "Per sensor (IMU, DVL, depth, GNSS) the rate, the stamp jitter and the gaps; the quantisation step of every "
    "IMU axis and the white noise it adds, q/sqrt(12 f), against the configured density; the Allan deviation of "
    "every IMU axis on the longest static stretch (else the whole log, with a warning); the DVL noise fitted by "
    "the batch smoother, chi^2/dof, and the DVL residuals' autocorrelation and Gauss-Markov fit.\n\n"
    "Writes DIR/characterise.json, DIR/allan.png and DIR/recommended.toml (use it with `gtsam-dvl smooth LOG -c "
    "DIR/recommended.toml`), all together or none. A DIR that exists and is not empty is refused unless --force."
)


@app.command(help=CHARACTERISE_HELP)
@_user_errors
@option_groups
def characterise(
    log: LogArg,
    output: Annotated[
        Path,
        typer.Option(
            "-o", "--output", help="Folder for characterise.json, allan.png and recommended.toml."
        ),
    ],
    config: ConfigOpt = None,
    force: Annotated[
        bool,
        typer.Option(
            "--force", help="Write into a folder that is not empty (the three files are replaced)."
        ),
    ] = False,
    *,
    read_options: ReadOpts,
    quiet: Quiet = False,
    debug: Debug = False,
) -> None:
    """Sensor rates, jitter, quantisation, Allan deviation, DVL noise; a recommended configuration (help:
    CHARACTERISE_HELP)."""
    from gtsam_dvl.app.characterise import characterise_to_dir
    from gtsam_dvl.app.outputs import check_folders

    check_folders({}, {"-o": output})
    ch = characterise_to_dir(
        log,
        output,
        config_path=config,
        force=force,
        show_progress=not quiet,
        read_options=read_options,
    )
    typer.echo(ch.describe())


# evaluate's reading options: the ones not given are as smooth read the source log (its result records them)
EvaluateReadOpts = Annotated[
    "ReadOptions",
    READING.not_given_by_default(
        imu_topic=Annotated[
            str | None,
            typer.Option(
                "--imu-topic",
                help="IMU topic (default: as smooth read the source log, else /imu/data_raw).",
            ),
        ],
        salvage=Annotated[
            bool | None,
            typer.Option(
                "--salvage/--no-salvage",
                help="Recover the intact chunks of a "
                "damaged log (default: as smooth read the source log).",
            ),
        ],
        repair=Annotated[
            bool | None,
            typer.Option(
                "--repair/--no-repair",
                help="Drop (and count) NaN, duplicate or "
                "backwards messages (default: as smooth read the source log).",
            ),
        ],
    ),
]


@app.command()
@_user_errors
@option_groups
def evaluate(
    result: Annotated[Path, typer.Argument(help="Result MCAP written by `gtsam-dvl smooth -o`.")],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Folder for metrics.json and figures.")
    ],
    truth: Annotated[
        Path | None,
        typer.Option(
            help="Log with truth (default: the result's source log, found "
            "relative to the result file, else at its absolute path)."
        ),
    ] = None,
    *,
    read_options: EvaluateReadOpts,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="Judge the result against a --truth log that is not its "
            "source (another content, stamps or origin).",
        ),
    ] = False,
    debug: Debug = False,
) -> None:
    """Errors against the truth over time, observability verdict and the segments that made it; the run's health
    as smooth recorded it, and what reading the truth log lost. Without --truth the source log is read with the
    options smooth recorded (the options given here override them); if it is not found, a line says so and the
    errors against the truth are left out."""
    from gtsam_dvl.app.commands import evaluate_to_dir
    from gtsam_dvl.app.outputs import check_folders

    check_folders({}, {"-o": output})
    lines, written = evaluate_to_dir(
        result,
        output,
        truth_path=truth,
        read_options=read_options,
        force=force,
    )
    typer.echo("\n".join(lines))
    for path in written:
        typer.echo(f"wrote {path}")


@app.command()
@_user_errors
def plan(
    scenario: ScenarioArg,
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Folder for plan.json, plan.md and figures.")
    ],
    config: ConfigOpt = None,
    quiet: Quiet = False,
    debug: Debug = False,
) -> None:
    """Will this mission calibrate the DVL, and when? Covariance analysis of a scenario (no noise)."""
    from gtsam_dvl.app.commands import plan_to_dir
    from gtsam_dvl.app.outputs import check_folders

    check_folders({}, {"-o": output})
    answer, written = plan_to_dir(scenario, output, config_path=config, show_progress=not quiet)
    typer.echo(answer)
    for path in written:
        typer.echo(f"wrote {path}")


# montecarlo and calibrate (app/cli_campaign.py), registered here, in this place of the command list
from gtsam_dvl.app import cli_campaign as _cli_campaign  # noqa: E402, F401


@app.command()
@_user_errors
def presets(
    name: Annotated[
        str | None,
        typer.Argument(
            help="A preset's name: its values, their sources and the TOML block to use it."
        ),
    ] = None,
    debug: Debug = False,
) -> None:
    """The sensor presets ([imu] model, [dvl] model): every one in a table, or one with its sources."""
    from gtsam_dvl.core.config.presets import describe_preset, preset_table

    typer.echo(describe_preset(name) if name is not None else "\n".join(preset_table()))


@app.command("config")
@_user_errors
def config_command(
    default: Annotated[
        bool,
        typer.Option(
            "--default",
            help="The default configuration (what smooth uses when "
            "neither -c nor the log names one).",
        ),
    ] = False,
    config: Annotated[
        Path | None,
        typer.Option(
            "-c",
            "--config",
            help="A TOML file, a result's config.json or a named configuration (default, paper).",
        ),
    ] = None,
    debug: Debug = False,
) -> None:
    """Print the effective estimator configuration as TOML: every key with its value, presets filled in (save it
    and pass it back with -c for the same configuration)."""
    from gtsam_dvl.core.config import EstimatorConfig

    if default and config is not None:
        raise GtsamDvlError("give --default or -c FILE, not both")
    cfg = EstimatorConfig.load(config) if config is not None else EstimatorConfig.named("default")
    source = f"from {config}" if config is not None else "'default'"
    typer.echo(
        f"# estimator configuration {source}, every key; use it with: gtsam-dvl smooth LOG -c FILE\n\n"
        f"{cfg.to_toml()}"
    )


@app.command()
@_user_errors
def demo(
    output: Annotated[
        Path, typer.Option("-o", "--output", help="Folder for everything the demo writes.")
    ] = Path("demo-output"),
    seed: Annotated[int, typer.Option(help="Random seed of the simulated runs.")] = 7,
    debug: Debug = False,
) -> None:
    """Simulate the paper's 3-D and 2-D runs, process them and write figures into one folder."""
    from gtsam_dvl.app.demo import run_demo
    from gtsam_dvl.app.outputs import check_folders

    check_folders({}, {"-o": output})
    run_demo(output, seed=seed)


# live, node and play (app/cli_live.py), registered here, at the end of the command list
from gtsam_dvl.app import cli_live as _cli_live  # noqa: E402, F401


def _run_app() -> Any:
    """The app, with click's usage errors (an unknown option, a missing argument, a bad value) as one line in the
    style of every other error, exit code 2 as click gives them."""
    import importlib

    try:  # typer >= 0.2x carries its own copy of click; older ones use click itself
        cx: Any = importlib.import_module("typer._click.exceptions")
    except ImportError:
        cx = importlib.import_module("click.exceptions")

    no_args = getattr(cx, "NoArgsIsHelpError", ())  # click >= 8.2
    try:
        return app(prog_name="gtsam-dvl", standalone_mode=False)
    except no_args as exc:  # `gtsam-dvl` alone: the help, as click prints it
        exc.show()
        return exc.exit_code
    except cx.UsageError as exc:
        where = exc.ctx.command_path if exc.ctx is not None else "gtsam-dvl"
        sys.stderr.write(
            f"gtsam-dvl: error: {exc.format_message().rstrip('.')}; `{where} -h` lists the options\n"
        )
        return exc.exit_code
    except cx.ClickException as exc:
        sys.stderr.write(f"gtsam-dvl: error: {exc.format_message()}\n")
        return exc.exit_code
    except typer.Abort:  # Ctrl-C
        sys.stderr.write("gtsam-dvl: error: interrupted\n")
        return 130


def main() -> None:
    """Console-script entry point. SIGTERM becomes an exception (Terminated) so that the writers clean up,
    then one line on stderr and exit code 143."""
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        code = _run_app()
        sys.exit(code if isinstance(code, int) else 0)
    except Terminated:
        sys.stderr.write("gtsam-dvl: error: terminated by SIGTERM; no partial output left behind\n")
        sys.exit(EXIT_SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    main()
