"""What the `gtsam-dvl` commands share: the Typer app, the exit codes, the one-line error handling and the option
groups (the reading options, the Dask engine's). Its own module so that the modules of the commands (app/cli.py,
app/cli_campaign.py, app/cli_live.py) import it and not each other (no import cycle, tests/test_architecture.py)."""

from __future__ import annotations

import copy
import functools
import inspect
import signal
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar, get_args

import typer

from gtsam_dvl.core.errors import GtsamDvlError

if TYPE_CHECKING:
    from gtsam_dvl.app.campaign.cluster import DaskEngine
    from gtsam_dvl.io.read_options import ReadOptions

# rich_markup_mode=None: click's plain help, where a boolean flag reads as a flag ("--salvage"); typer 0.29's
# rich help prints "<bool>" after every flag, as if it took a value
# add_completion: typer's --install-completion / --show-completion (bash, zsh, fish, PowerShell); -h as well as
# --help on every command (click passes help_option_names down to the subcommands)
app = typer.Typer(
    add_completion=True,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Self-calibrating IMU + DVL navigation on GTSAM.",
)
_state = {"debug": False}
F = TypeVar("F", bound=Callable[..., Any])
EXIT_UNHEALTHY = 3  # smooth --strict: the run's health is "degraded" or "failed"
UNHEALTHY = (
    "degraded",
    "failed",
)  # --strict fails on these; "warn" (weak geometry) is an honest result
EXIT_SIGTERM = 128 + signal.SIGTERM  # the shell's convention for a process ended by SIGTERM


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every atomic writer removes its temporary files (a
    BaseException, like KeyboardInterrupt, so that no `except Exception` swallows it)."""


def _on_sigterm(signum: int, frame: object) -> None:
    from gtsam_dvl.io import atomic

    if atomic.deferring():  # outputs being renamed into place: finish the set first, then stop
        atomic.defer(signum)
        return
    raise Terminated(signum)


def _error_text(exc: Exception) -> str:
    """An error's line in the style of the others: an OSError as "PATH: what went wrong" rather than Python's
    "[Errno 17] File exists: 'PATH'"."""
    if isinstance(exc, OSError) and exc.strerror:
        what = exc.strerror[:1].lower() + exc.strerror[1:]
        return f"{exc.filename}: {what}" if exc.filename is not None else what
    return str(exc)


def _user_errors(func: F) -> F:
    """Turn a GtsamDvlError (or a bad-input OSError) into one line on stderr and exit code 1."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if kwargs.get("debug"):  # --debug after the command name (before it: the callback _root)
            _state["debug"] = True
        try:
            return func(*args, **kwargs)
        except BrokenPipeError:  # output piped into `head` and closed: not an error of ours
            raise typer.Exit(0) from None
        except (GtsamDvlError, OSError) as exc:
            if _state["debug"]:
                raise
            typer.echo(f"gtsam-dvl: error: {_error_text(exc)}", err=True)
            raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]


ImuTopic = Annotated[str, typer.Option("--imu-topic", help="IMU topic (sensor_msgs/msg/Imu).")]
Debug = Annotated[
    bool, typer.Option("--debug", help="Show tracebacks (also accepted before the command).")
]
Quiet = Annotated[bool, typer.Option("-q", "--quiet", help="No progress bars.")]
DvlTopic = Annotated[
    str | None, typer.Option("--dvl-topic", help="DVL topic (default /dvl/data, else /dvl/twist).")
]
Salvage = Annotated[
    bool, typer.Option("--salvage", help="Recover the intact chunks of a damaged log.")
]
Repair = Annotated[
    bool,
    typer.Option(
        "--repair",
        help="Drop (and count) NaN, duplicate or backwards messages; "
        "shift the IMU stamps back across a clock step.",
    ),
]
SchedulerTimeout = Annotated[
    float,
    typer.Option(
        "--scheduler-timeout",
        metavar="SECONDS",
        help="How long to try to reach --scheduler before giving up.",
    ),
]


DepthTopic = Annotated[
    str | None,
    typer.Option(
        "--depth-topic",
        help="Depth topic: sensor_msgs/msg/FluidPressure, or a PoseWithCovarianceStamped / Odometry "
        "whose z is -depth (default /depth/pressure if the log has it; 'none': no depth).",
    ),
]


GnssTopic = Annotated[
    str | None,
    typer.Option(
        "--gnss-topic",
        help="GNSS topic (sensor_msgs/msg/NavSatFix; default /gnss/fix if the log has it; 'none': no "
        "GNSS). The first good fix gives the map origin when the log has none.",
    ),
]
AttitudeTopic = Annotated[
    str | None,
    typer.Option(
        "--attitude-topic",
        help="Attitude topic for the initial attitude (sensor_msgs/msg/Imu, nav_msgs/msg/Odometry "
        "or PoseWithCovarianceStamped; default: the IMU topic's orientation when its covariance is valid; 'none').",
    ),
]
DvlWaterTopic = Annotated[
    str | None,
    typer.Option(
        "--dvl-water-topic",
        help="A separate water-track topic (TwistWithCovarianceStamped or TwistStamped: velocity "
        "relative to the water), merged with the DVL's pings in stamp order.",
    ),
]
TruthTopic = Annotated[
    str | None,
    typer.Option(
        "--truth-topic",
        help="Ground-truth odometry topic (nav_msgs/msg/Odometry; default /ground_truth/odometry).",
    ),
]


def _read_options(**given: str | bool | None) -> ReadOptions:
    """The reading options given on the command line (io/read_options.py; None: not given, the option's default,
    and not in the result's model_fields_set: `evaluate` takes the recorded one)."""
    from gtsam_dvl.io.read_options import ReadOptions

    return ReadOptions(**{k: v for k, v in given.items() if v is not None})


def _dask_engine(
    scheduler: str | None, workers: int | None, scheduler_timeout: float
) -> DaskEngine:
    """Where the Dask tasks run, as --scheduler, --workers and --scheduler-timeout give it."""
    from gtsam_dvl.app.campaign.cluster import DaskEngine

    return DaskEngine(scheduler, workers, scheduler_timeout)


class OptionGroup:
    """Options that make one typed value (ReadOptions, DaskEngine) for the commands that take it: each option an
    inspect.Parameter (name, typer annotation, default), in their order in the command's help, and `make`, which
    makes the value of them. Marks the command's parameter that takes the value (ReadOpts, Engine);
    @option_groups puts the options in its place."""

    def __init__(self, make: Callable[..., Any], *parameters: inspect.Parameter) -> None:
        self.make = make
        self.parameters = parameters

    def only(self, *names: str) -> OptionGroup:
        """A command that reads fewer sensors: these options alone (the others at their defaults)."""
        return OptionGroup(self.make, *(p for p in self.parameters if p.name in names))

    def not_given_by_default(self, **annotations: Any) -> OptionGroup:
        """These options declared otherwise (name=typer annotation), with the default None: not given."""
        return OptionGroup(
            self.make,
            *(
                p.replace(annotation=annotations[p.name], default=None)
                if p.name in annotations
                else p
                for p in self.parameters
            ),
        )

    def helped(self, **helps: str) -> OptionGroup:
        """These options with the command's own help (name=text)."""
        return OptionGroup(
            self.make,
            *(_with_help(p, helps[p.name]) if p.name in helps else p for p in self.parameters),
        )


def _with_help(p: inspect.Parameter, text: str) -> inspect.Parameter:
    """The option p with another help text (a copy of its typer.Option)."""
    kind, option = get_args(p.annotation)[:2]
    option = copy.copy(option)
    option.help = text
    return p.replace(annotation=Annotated[kind, option])


def _option(name: str, annotation: Any, default: Any) -> inspect.Parameter:
    return inspect.Parameter(
        name, inspect.Parameter.KEYWORD_ONLY, annotation=annotation, default=default
    )


# Every reading option, declared once for all the commands that read a log (None: not given, ReadOptions' default)
READING = OptionGroup(
    _read_options,
    _option("imu_topic", ImuTopic, "/imu/data_raw"),
    _option("dvl_topic", DvlTopic, None),
    _option("salvage", Salvage, False),
    _option("repair", Repair, False),
    _option("depth_topic", DepthTopic, None),
    _option("gnss_topic", GnssTopic, None),
    _option("attitude_topic", AttitudeTopic, None),
    _option("truth_topic", TruthTopic, None),
    _option("dvl_water_topic", DvlWaterTopic, None),
)
# a command's `read_options` parameter, which @option_groups replaces by the reading options on the command line
# ("ReadOptions" stays a forward reference: io/read_options.py is imported only when a command runs)
ReadOpts = Annotated["ReadOptions", READING]

# The Dask engine's options (app/campaign/cluster.py DaskEngine), each command with its own help for the first two
ENGINE = OptionGroup(
    _dask_engine,
    _option("scheduler", Annotated[str | None, typer.Option("--scheduler")], None),
    _option("workers", Annotated[int | None, typer.Option("--workers")], None),
    _option("scheduler_timeout", SchedulerTimeout, 10.0),
)


def option_groups(func: F) -> F:
    """A command that takes option groups: each parameter annotated with an OptionGroup (ReadOpts, an ENGINE), keyword
    only, is given on the command line as the group's options, in its place in the command's help, and passed to
    the command as the value they make (OptionGroup.make)."""
    signature = inspect.signature(func, eval_str=True)
    parameters = list(signature.parameters.values())
    groups = {
        p.name: marker
        for p in parameters
        for marker in get_args(p.annotation)[1:]
        if isinstance(marker, OptionGroup)
    }

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        for placeholder, group in groups.items():
            given = {p.name: kwargs.pop(p.name) for p in group.parameters}
            kwargs[placeholder] = group.make(**given)
        return func(*args, **kwargs)

    # what typer reads (inspect.signature, typing.get_type_hints): the options instead of the placeholders
    spliced = signature.replace(
        parameters=[
            q for p in parameters for q in (groups[p.name].parameters if p.name in groups else [p])
        ]
    )
    wrapper.__signature__ = spliced  # type: ignore[attr-defined]
    wrapper.__annotations__ = {p.name: p.annotation for p in spliced.parameters.values()}
    wrapper.__annotations__["return"] = spliced.return_annotation
    return wrapper  # type: ignore[return-value]


def _builtin_scenarios() -> list[str]:
    """The scenarios shipped with the package (listed without importing the simulator: --help stays instant)."""
    from importlib import resources

    files = resources.files("gtsam_dvl.scenarios")
    return sorted(p.name[: -len(".toml")] for p in files.iterdir() if p.name.endswith(".toml"))


CONFIG_HELP = (
    "Estimator configuration: a TOML file, a result's config.json, or a named configuration ('default': "
    "a real DVL, scale prior 1 +- 1 %; 'paper': Pan & Wu's priors, scale 0.8 +- 0.5). Default: the one "
    "the log's (or scenario's) estimator_config names, else 'default'."
)

ConfigOpt = Annotated[Path | None, typer.Option("-c", "--config", help=CONFIG_HELP)]
LogArg = Annotated[Path, typer.Argument(help="MCAP log (or rosbag2 directory).")]
ScenarioArg = Annotated[
    str,
    typer.Argument(
        help=f"Built-in name ({', '.join(_builtin_scenarios())}) or a scenario TOML file."
    ),
]
