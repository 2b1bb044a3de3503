"""What a new user meets around the commands: Dask missing or out of reach (one line, nothing written), progress
on stderr and results on stdout, output folders refused rather than created as trees, --version, -h, shell
completion, `config` printing a TOML that loads back, `info` on a result file, the time offset's sign in words,
fleet folder names and the plan figure's target lines."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
import pytest
from typer.testing import CliRunner

from gtsam_dvl.analysis.observability import time_offset_words
from gtsam_dvl.app.cli import app
from gtsam_dvl.core.config import EstimatorConfig
from tests.support.campaign import SCENARIO

matplotlib.use("Agg")


def invoke(*args: str | Path) -> Any:
    """The CLI in this process (click's runner: stdout and stderr apart)."""
    return CliRunner().invoke(app, [str(a) for a in args])


def one_error_line(res: Any) -> str:
    assert res.exit_code == 1, (res.exit_code, res.stdout, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("gtsam-dvl: error: "), res.stderr
    assert "Traceback" not in res.stderr and res.stdout == ""
    return str(lines[0])


@pytest.fixture
def scenario_file(tmp_path: Path) -> Path:
    path = tmp_path / "mc-tiny.toml"
    path.write_text(SCENARIO)
    return path


# ----- Dask optional ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["montecarlo", "fleet"])
def test_without_dask_one_line_exit_1_and_nothing_written(
    command: str, scenario_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for name in (
        "dask",
        "dask.distributed",
        "distributed",
    ):  # None in sys.modules: `import` raises ImportError
        monkeypatch.setitem(sys.modules, name, None)
    out = tmp_path / "out"
    if command == "montecarlo":
        res = invoke("montecarlo", scenario_file, "-o", out, "--runs", "2", "-q")
    else:
        logs = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
        for log in logs:
            log.write_bytes(b"never read: Dask is checked first")
        res = invoke("smooth", *logs, "--out-dir", out, "-q")
    line = one_error_line(res)
    assert "pip install 'gtsam-dvl[distributed]'" in line
    assert not out.exists()  # no campaign.json, no folder


def test_unreachable_scheduler_one_line_after_the_timeout_nothing_written(
    scenario_file: Path, tmp_path: Path
) -> None:
    pytest.importorskip("distributed")
    out = tmp_path / "campaign"
    res = invoke(
        "montecarlo",
        scenario_file,
        "-o",
        out,
        "--runs",
        "1",
        "--scheduler",
        "tcp://127.0.0.1:1",
        "--scheduler-timeout",
        "0.3",
        "-q",
    )
    line = one_error_line(res)
    assert "tcp://127.0.0.1:1: cannot reach the Dask scheduler" in line and "after 0.3 s" in line
    assert not out.exists()


# ----- streams, output folders, errors ----------------------------------------------------------------------------
def test_progress_bar_goes_to_stderr(capsys: pytest.CaptureFixture[str]) -> None:
    from gtsam_dvl.app.progress import progress_bar

    with progress_bar("reading dive.mcap") as progress:
        progress(0.5)
    out, err = capsys.readouterr()
    assert out == "" and "reading dive.mcap" in err and "100%" in err


def test_missing_output_folder_and_file_as_folder_are_refused(tmp_path: Path) -> None:
    missing = tmp_path / "nonexistent" / "dir"
    line = one_error_line(invoke("simulate", "paper-2d", "-o", missing / "out.mcap"))
    assert line == (
        f"gtsam-dvl: error: {missing / 'out.mcap'}: no folder {missing} for -o; create it first "
        "(outputs never create folder trees)"
    )
    line = one_error_line(invoke("smooth", tmp_path / "log.mcap", "--summary", missing / "s.json"))
    assert f"no folder {missing} for --summary" in line
    line = one_error_line(invoke("plan", "paper-2d", "-o", missing))
    assert f"{missing}: no folder {missing.parent} to create it in for -o" in line
    existing = tmp_path / "figure.png"
    existing.write_bytes(b"png")
    line = one_error_line(invoke("plot-log", tmp_path / "log.mcap", "-o", existing))
    assert (
        line
        == f"gtsam-dvl: error: {existing}: is a file, and -o takes a folder; choose another path"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.png"]  # nothing created


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["smooth", "--foo"],
            "gtsam-dvl: error: No such option: --foo; `gtsam-dvl smooth -h` lists the options",
        ),
        (
            ["smooth"],
            "gtsam-dvl: error: Missing argument 'LOG...'; `gtsam-dvl smooth -h` lists the options",
        ),
        (["bogus"], "gtsam-dvl: error: No such command 'bogus'; `gtsam-dvl -h` lists the options"),
    ],
)
def test_usage_errors_are_one_line_in_the_same_style(
    args: list[str],
    expected: str,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from gtsam_dvl.app import cli

    monkeypatch.setattr(sys, "argv", ["gtsam-dvl", *args])
    assert cli._run_app() == 2
    out, err = capsys.readouterr()
    assert out == "" and err.splitlines() == [expected]


def test_an_os_error_is_one_line_in_the_same_style(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """An OSError from deep inside (here a folder in the way) reads "PATH: what", not "[Errno 17] ..."."""
    import errno

    from gtsam_dvl.app import commands

    def in_the_way(*args: Any, **kwargs: Any) -> list[Path]:
        raise FileExistsError(errno.EEXIST, "File exists", str(tmp_path / "figs" / "fig01.png"))

    monkeypatch.setattr(commands, "plot_log_to_dir", in_the_way)
    line = one_error_line(invoke("plot-log", tmp_path / "log.mcap", "-o", tmp_path / "figs"))
    assert line == f"gtsam-dvl: error: {tmp_path / 'figs' / 'fig01.png'}: file exists"


# ----- --version, -h, completion, config --------------------------------------------------------------------------
def test_version_and_h_on_every_command() -> None:
    from importlib.metadata import version

    res = invoke("--version")
    assert res.exit_code == 0 and res.stdout.strip() == f"gtsam-dvl {version('gtsam-dvl')}"
    names = [c.name or c.callback.__name__.replace("_", "-") for c in app.registered_commands]  # type: ignore[union-attr]
    assert {"smooth", "config", "plan", "montecarlo"} <= set(names)
    for name in names:
        res = invoke(name, "-h")
        assert res.exit_code == 0 and res.stdout.startswith(f"Usage: root {name} "), (
            name,
            res.stdout[:200],
        )


def test_shell_completion_completes_commands_and_options(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The completion script's protocol (what bash calls on TAB: the words so far in COMP_WORDS) answers from the
    command line's own commands and options."""

    def complete(words: str) -> list[str]:
        monkeypatch.setenv("_GTSAM_DVL_COMPLETE", "complete_bash")
        monkeypatch.setenv("COMP_WORDS", words)
        monkeypatch.setenv("COMP_CWORD", str(len(words.split()) - 1))
        with pytest.raises(SystemExit) as done:
            app(prog_name="gtsam-dvl", args=[])
        assert done.value.code == 0
        return capsys.readouterr().out.split()

    assert complete("gtsam-dvl smo") == ["smooth"]
    assert complete("gtsam-dvl conf") == ["config"]
    assert set(complete("gtsam-dvl smooth --sched")) == {"--scheduler", "--scheduler-timeout"}


@pytest.mark.parametrize("given", ["--default", "paper", "partial"])
def test_config_prints_a_toml_that_loads_back_to_the_same_configuration(
    given: str, tmp_path: Path
) -> None:
    if given == "--default":
        args, expected = ["--default"], EstimatorConfig.named("default")
    elif given == "paper":
        args, expected = ["-c", "paper"], EstimatorConfig.named("paper")
    else:
        partial = tmp_path / "partial.toml"
        partial.write_text('[priors]\nscale_sigma = 0.02\n[dvl]\nmodel = "teledyne-pathfinder"\n')
        args, expected = ["-c", str(partial)], EstimatorConfig.load(partial)
        assert expected.priors.scale_sigma == 0.02 and expected != EstimatorConfig.named("default")
    res = invoke("config", *args)
    assert res.exit_code == 0, res.stderr
    printed = tmp_path / "printed.toml"
    printed.write_text(res.stdout)
    assert EstimatorConfig.load(printed) == expected
    # the printed file prints itself (every key was written)
    again = invoke("config", "-c", printed)
    assert again.stdout.splitlines()[1:] == res.stdout.splitlines()[1:]
    assert "gtsam-dvl: error: give --default or -c FILE, not both" == one_error_line(
        invoke("config", "--default", "-c", printed)
    )


# ----- the time offset's sign -------------------------------------------------------------------------------------
def test_time_offset_words_say_early_or_late() -> None:
    assert time_offset_words(1.0) == (
        "dt_d = +1.000 s: the DVL's stamps are 1.000 s early (each ping measures the "
        "velocity 1.000 s after its stamp)"
    )
    assert time_offset_words(-0.3) == (
        "dt_d = -0.300 s: the DVL's stamps are 0.300 s late (each ping measures the "
        "velocity 0.300 s before its stamp)"
    )
    assert "on time" in time_offset_words(0.0)


@pytest.fixture(scope="module")
def lagged_result(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Any, Any]:
    """A 210 s dive whose DVL stamps are 0.4 s late (dt_d = -0.4 s, a transport delay), simulated and smoothed
    by the EKF with the default configuration (time offset estimated) through the command line."""
    folder = tmp_path_factory.mktemp("lag")
    scenario = folder / "lag.toml"
    scenario.write_text(
        SCENARIO.replace('estimator_config = "paper"', 'estimator_config = "default"')
        .replace("dvl_hz = 1.0\n", "dvl_hz = 1.0\ndvl_time_offset_s = -0.4\n")
        .replace(
            'duration_s = 60.0\n[[segments]]\nkind = "level"',
            'duration_s = 30.0\n[[segments]]\nkind = "level"',
            1,
        )
    )
    log, result = folder / "lag.mcap", folder / "result.mcap"
    sim = invoke("simulate", scenario, "-o", log, "--seed", "3")
    assert sim.exit_code == 0, sim.stderr
    smooth = invoke("smooth", log, "--mode", "ekf", "-o", result, "--no-timeline")
    assert smooth.exit_code == 0, smooth.stderr
    return log, result, sim, smooth


@pytest.mark.slow
def test_known_lag_is_printed_as_stamps_late_with_results_on_stdout(
    lagged_result: tuple[Path, Path, Any, Any],
) -> None:
    _, _, sim, smooth = lagged_result
    # progress bars on stderr, the results alone on stdout
    assert "simulating" in sim.stderr and "━" not in sim.stdout and sim.stdout.count("\n") == 1
    assert "ekf on lag.mcap" in smooth.stderr and "━" not in smooth.stdout
    line = next(x for x in smooth.stdout.splitlines() if "DVL time offset" in x)
    print(line)
    value_ms, sigma_ms = (
        float(v) for v in line.split("DVL time offset ")[1].split(" ms")[0].split(" +- ")
    )
    assert abs(value_ms + 400.0) < 3 * sigma_ms  # the simulated -0.4 s, within 3 sigma
    words = re.search(
        r"dt_d = -(\d\.\d{3}) s: the DVL's stamps are (\d\.\d{3}) s late \(each ping measures the "
        r"velocity (\d\.\d{3}) s before its stamp\)$",
        line,
    )
    assert words is not None, line
    assert len(set(words.groups())) == 1 and abs(float(words.group(1)) + value_ms / 1e3) < 6e-4


@pytest.mark.slow
def test_info_recognises_a_result_file(lagged_result: tuple[Path, Path, Any, Any]) -> None:
    log, result, _, smooth = lagged_result
    res = invoke("info", result)
    assert res.exit_code == 0, res.stderr
    lines = res.stdout.splitlines()
    print(res.stdout)
    assert lines[0].startswith(f"{result}: a gtsam_dvl result (ekf)")
    assert lines[1].startswith(f"  source log: {log}")
    # the calibration and health as smooth printed them
    for key in ("  scale ", "  DVL time offset ", "  health: "):
        assert next(x for x in lines if x.startswith(key)) == next(
            x for x in smooth.stdout.splitlines() if x.startswith(key)
        )
    assert "/gtsam_dvl/odometry" not in res.stdout and "wrote" not in res.stdout


# ----- fleet names and table --------------------------------------------------------------------------------------
def test_fleet_run_names_are_unique_and_readable() -> None:
    from gtsam_dvl.app.campaign.fleet import run_names

    assert run_names(
        [Path("a/dive1/dive.mcap"), Path("b/dive2/dive.mcap"), Path("x/other.mcap")]
    ) == ["dive1_dive", "dive2_dive", "other"]
    assert run_names([Path("a/d/dive.mcap"), Path("b/d/dive.mcap")]) == ["d_dive", "d_dive_2"]


def test_fleet_table_says_which_surfacing_figure() -> None:
    from gtsam_dvl.app.campaign.fleet import fleet_table

    surf = {"horizontal_error_m": 1.5, "horizontal_error_pct": 0.05, "distance_m": 3000.0}
    row = {
        "log": "/x/dive1/dive.mcap",
        "dir": "/out/dive1_dive",
        "status": "ok",
        "scale": {"value": 1.0, "sigma": 1e-3},
        "misalignment_deg": {"value": [0, 0, 0], "sigma": [0.1] * 3},
        "time_offset_s": {"value": 0.3, "sigma": 0.01},
        "surfacing_error": surf,
        "surfacing_figure": "mean of 4 fixes",
    }
    header, _, line = fleet_table([row])
    assert "time offset (ms, + = stamps early)" in header
    assert (
        line.startswith("| dive1_dive | ok |")
        and "| 1.50 m (0.050 % of 3000 m), mean of 4 fixes |" in line
    )


# ----- plan's figure ----------------------------------------------------------------------------------------------
def test_normalised_sigma_figure_draws_the_targets(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from gtsam_dvl.app.plots import timeline_plots
    from gtsam_dvl.app.plots.timeline_plots import priors_for_plots, targets_for_plots
    from gtsam_dvl.core.result import Timeline

    n = 5
    ones, ones3 = np.ones(n), np.ones((n, 3))
    tl = Timeline(
        t=np.arange(n, dtype=float),
        scale=ones,
        scale_sigma=0.01 * ones,
        misalignment_deg=0 * ones3,
        misalignment_sigma_deg=ones3,
        gyro_bias_deg_per_h=0 * ones3,
        gyro_bias_sigma_deg_per_h=0.01 * ones3,
        accel_bias_ug=0 * ones3,
        accel_bias_sigma_ug=50 * ones3,
        attitude_sigma_deg=ones3,
    )
    figures: list[Any] = []
    monkeypatch.setattr(
        timeline_plots, "save_figure", lambda fig, path: figures.append(fig) or path
    )
    config = EstimatorConfig.named("default")
    config.observability.accel_bias_ug = 10.0
    priors, targets = priors_for_plots(config.to_dict()), targets_for_plots(config.to_dict())
    timeline_plots.plot_normalised_sigmas(tl, tmp_path / "f.png", priors, targets=targets)
    (fig,) = figures
    dashed = {
        ax.get_title(): sorted(
            {
                round(float(line.get_ydata()[0]), 6)
                for line in ax.get_lines()
                if line.get_linestyle() == "--"
            }
        )
        for ax in fig.axes
    }
    assert dashed["attitude (east, north, up)"] == []
    assert dashed["DVL scale and misalignment"] == sorted(
        {
            round(1000e-6 / priors["scale"], 6),
            round(0.1 / float(np.atleast_1d(priors["misalignment_deg"])[0]), 6),
        }
    )
    assert dashed["accelerometer bias"] == [round(10.0 / float(priors["accel_bias_ug"][0]), 6)]


TINY_PLAN = """
name = "tiny"
[origin]
lat_deg = 30.0
lon_deg = 114.0
[rates]
imu_hz = 20.0
dvl_hz = 1.0
[[segments]]
kind = "static"
duration_s = 10.0
[[segments]]
kind = "level"
duration_s = 20.0
speed_end_m_s = 2.0
"""


def test_plan_figure_has_the_target_lines(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`plan`'s normalised-sigma figure: one dashed line per calibration group at target / prior sigma."""
    from gtsam_dvl.app import commands
    from gtsam_dvl.app.plots import timeline_plots

    scenario = tmp_path / "tiny.toml"
    scenario.write_text(TINY_PLAN)
    figures: list[Any] = []
    monkeypatch.setattr(
        timeline_plots, "save_figure", lambda fig, path: figures.append(fig) or path
    )
    commands.plan_to_dir(scenario, tmp_path / "plan", show_progress=False)
    (fig,) = figures
    config = EstimatorConfig.named("default")  # what a scenario without estimator_config plans with
    obs, priors = config.observability, timeline_plots.priors_for_plots(config.to_dict())
    dashed = {
        ax.get_title(): [
            float(line.get_ydata()[0]) for line in ax.get_lines() if line.get_linestyle() == "--"
        ]
        for ax in fig.axes
    }
    assert dashed["DVL scale and misalignment"] == pytest.approx(
        [obs.scale_ppm * 1e-6 / priors["scale"]]
    )
    # the misalignment's target is at the same fraction of its prior: one line for the group
    assert obs.misalignment_deg / priors["misalignment_deg"][0] == pytest.approx(
        dashed["DVL scale and misalignment"][0]
    )
    assert dashed["gyro bias"] == pytest.approx(
        [obs.gyro_bias_deg_per_h / priors["gyro_bias_deg_per_h"][0]]
    )
    assert dashed["accelerometer bias"] == pytest.approx(
        [obs.accel_bias_ug / priors["accel_bias_ug"][0]]
    )
    assert "dashed: the targets" in fig.texts[0].get_text()
