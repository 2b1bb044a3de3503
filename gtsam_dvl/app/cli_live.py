"""The real-time commands of the command line (app/cli.py's `app`): `live` (a log replayed through the online
estimator into Foxglove), `node` (the online estimator as a ROS 2 node) and `play` (a recorded log published on its
ROS 2 topics). Imported by app/cli.py, which registers them."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from gtsam_dvl.app.cli_options import ConfigOpt, Debug, ReadOpts, _user_errors, app, option_groups
from gtsam_dvl.core.errors import GtsamDvlError

LIVE_HELP = (
    "Replay a log through the online estimator and show it live in Foxglove (needs pip install "
    "'gtsam-dvl[live]').\n\n"
    "Serves a Foxglove WebSocket on --host:--port and publishes, as they are computed: the estimated pose (/tf "
    "map -> base_link, /gtsam_dvl/odometry with covariance), the path, DVL scale, misalignment, time offset and "
    "IMU biases with their sigmas, the estimator's counters and the health warnings, the raw IMU / DVL / depth "
    "messages and the truth when the log has it. In Foxglove: Open connection > Foxglove WebSocket > "
    "ws://localhost:8765, then Layouts > Import from file > the layout that `gtsam-dvl live --layout "
    "gtsam_dvl_live.json` writes (docs/live-view.md)."
)


@app.command(help=LIVE_HELP)
@_user_errors
@option_groups
def live(
    log: Annotated[
        Path | None, typer.Argument(metavar="LOG", help="MCAP log (or rosbag2 directory).")
    ] = None,
    layout: Annotated[
        Path | None,
        typer.Option(
            "--layout",
            help="Write the Foxglove layout of the live view to "
            "this file (not overwritten; its folder must exist); without a "
            "LOG, only that.",
        ),
    ] = None,
    speed: Annotated[
        str, typer.Option(help="Times real time (e.g. 1, 10); 0 or 'max': as fast as possible.")
    ] = "1",
    port: Annotated[int, typer.Option(help="WebSocket port (0: any free port, printed).")] = 8765,
    host: Annotated[
        str,
        typer.Option(
            help="Address to serve on (127.0.0.1: this machine only; 0.0.0.0: every interface)."
        ),
    ] = "127.0.0.1",
    config: ConfigOpt = None,
    wait: Annotated[
        bool, typer.Option("--wait", help="Start the replay only once a client subscribes.")
    ] = False,
    exit_when_done: Annotated[
        bool,
        typer.Option(
            "--exit-when-done",
            help="Stop serving when the replay ends (default: serve until Ctrl-C).",
        ),
    ] = False,
    *,
    read_options: ReadOpts,
    calibration: Annotated[
        Path | None, typer.Option(help="A vehicle's calibration file as the prior.")
    ] = None,
    debug: Debug = False,
) -> None:
    """Replay a log through the online estimator and show it live in Foxglove (help: LIVE_HELP)."""
    from gtsam_dvl.app.live import serve_log

    _write_live_layout(layout, log)
    if log is None:  # --layout alone
        return
    serve_log(
        log,
        speed=speed,
        port=port,
        host=host,
        config_path=config,
        wait=wait,
        linger=not exit_when_done,
        layout_path=layout,
        calibration_path=calibration,
        read_options=read_options,
        echo=typer.echo,
    )


def _write_live_layout(layout: Path | None, log: Path | None) -> None:
    """live's --layout: the Foxglove layout written when asked; neither a LOG nor --layout: a one-line error."""
    from gtsam_dvl.app.live import copy_layout

    if layout is not None:
        typer.echo(f"wrote {copy_layout(layout)}: in Foxglove, Layouts > Import from file")
    if log is None and layout is None:
        raise GtsamDvlError(
            "live: give a LOG to replay (or --layout PATH to write the Foxglove layout)"
        )


NODE_HELP = (
    "Run the online estimator as a ROS 2 node on live topics (needs pip install 'gtsam-dvl[ros2]').\n\n"
    "Subscribes the IMU (sensor_msgs/Imu), the DVL (TwistWithCovarianceStamped, TwistStamped or "
    "marine_acoustic_msgs/Dvl), pressure (FluidPressure) and GNSS (NavSatFix, the map origin); publishes "
    "nav_msgs/Odometry (map -> base_link with covariances), the calibration with sigmas (Float64MultiArray), "
    "diagnostics and the path; the service ~/save_calibration writes the vehicle's calibration file. Settings and "
    "the estimator configuration: -c TOML ([node] table) and/or --params YAML (docs/ros2.md). Arguments after "
    "--ros-args go to ROS (remappings, -p name:=value)."
)


@app.command(
    help=NODE_HELP, context_settings={"allow_extra_args": True, "ignore_unknown_options": True}
)
@_user_errors
def node(
    ctx: typer.Context,
    config: Annotated[
        Path | None,
        typer.Option(
            "-c",
            "--config",
            help="Estimator configuration (TOML, with an "
            "optional [node] table of the node's settings) or its name.",
        ),
    ] = None,
    params: Annotated[
        Path | None,
        typer.Option(
            "--params",
            help="ROS parameter file (YAML) with the node's "
            "settings and estimator.* configuration keys.",
        ),
    ] = None,
    calibration: Annotated[
        Path | None, typer.Option(help="A vehicle's calibration file as the prior.")
    ] = None,
    name: Annotated[str | None, typer.Option(help="The node's name (default gtsam_dvl).")] = None,
    debug: Debug = False,
) -> None:
    """Run the online estimator as a ROS 2 node (help: NODE_HELP)."""
    from gtsam_dvl.app.node.run import run_node

    run_node(config, params, ctx.args, calibration=calibration, name=name, echo=typer.echo)


@app.command()
@_user_errors
def play(
    log: Annotated[Path, typer.Argument(metavar="LOG", help="MCAP log (or rosbag2 directory).")],
    rate: Annotated[
        str, typer.Option(help="Times real time (e.g. 1, 10); 'max': as fast as possible.")
    ] = "1",
    topic: Annotated[
        list[str] | None,
        typer.Option("--topic", help="A topic to play (repeat; default: every sensor topic)."),
    ] = None,
    wait: Annotated[
        float, typer.Option(help="Wait up to this long (s) for a subscriber on every topic.")
    ] = 0.0,
    debug: Debug = False,
) -> None:
    """Publish a recorded log's messages on their ROS 2 topics, as recorded (needs the ros2 extra)."""
    from gtsam_dvl.app.live.replay import parse_speed
    from gtsam_dvl.app.node.player import play_log

    outcome = play_log(
        log, rate=parse_speed(rate), topics=topic or None, wait_for_subscribers_s=wait
    )
    typer.echo(outcome.describe())
