"""Every estimator on every kind of log, through the command line (issue 39): the cells a new user would try.

Factors: the estimator (batch, online, online-full, ekf; io-dvlc on the log it applies to), the configuration
(the defaults, `-c paper`, datasheet-like priors, a sensor preset) and the kind of log (a static start, an underway
start with the attitude given and turns and the DVL stamped 1 s early, an underway start with GNSS at the surface
and nothing else, a straight run where the nominal check holds, a foreign-topic rosbag2 folder, water track). The
full product is 4 x 4 x 6 = 96 runs; every (log, estimator) pair runs once with a configuration chosen so that
every (estimator, configuration) and (log, configuration) pair also appears (a Latin square), 24 cells plus
io-dvlc's 4 on the static start and 2 as real subprocesses.

Each cell runs `smooth` through the console script's own entry point (app/cli.py _run_app, in process) and
asserts what a user relies on: exit 0, or exit 1 with one line on stderr; never a traceback; the summary JSON
written; health not "failed" on these clean logs; and, where the truth is known, either the calibration and the
final position inside 3 sigma of it, or a health that is not "ok" (never silently wrong).
"""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

pytestmark = pytest.mark.slow

MODES = ("batch", "online", "online-full", "ekf")
CONFIGS: dict[str, str | None] = {
    "default": None,
    "paper": "paper",
    # a user who knows the DVL's datasheet: scale to 0.4 %, the mounting to 0.5 deg
    "datasheet": "[priors]\nscale_sigma = 0.004\nmounting_tolerance_deg = 0.5\n",
    "preset": '[imu]\nmodel = "kvh-1750"\n\n[dvl]\nmodel = "teledyne-pathfinder"\n',
}
SEED = 4
SIGMAS = 3.0
# online-full (iSAM2 over the whole history, its DVL factors Python CustomFactors, each of which GTSAM hands a copy
# of all the Values per call) costs quadratically in the states: on field-survey's 200 s at 5 Hz (1000 states) it
# ran more than 15 minutes on a loaded 2-core machine (2026-12-07). A known limit (issue 41, long missions), not
# hidden: the cell is left out and named here; online-full meets 5 Hz pings on the foreign log's 150 s.
TOO_SLOW = {("gnss", "online-full")}
# Known defects the matrix found, each failing as expected until it is fixed (strict: a fix makes it fail loudly, so
# that its entry goes). The EKF with -c paper (no time offset estimated) on field-survey, whose DVL stamps are 0.3 s
# early, ends 5 sigma off in calibration; the residual time offset shows it, but for a filter that is a note
# (analysis/dvl_misfit.py: a filter's lag reads the same way), so the health stays "ok" (issue 39, items 5-6).
KNOWN_DEFECTS = {
    ("gnss", "ekf", "paper"): "EKF -c paper on a 0.3 s DVL offset: 5 sigma off, health ok"
}


def cut(raw: dict[str, Any], seconds: float) -> dict[str, Any]:
    """A scenario's TOML dict with its segments cut to about seconds in all (the last one shortened)."""
    raw = copy.deepcopy(raw)
    out, total = [], 0.0
    for seg in raw["segments"]:
        if total >= seconds:
            break
        if "duration_s" in seg:
            seg["duration_s"] = min(seg["duration_s"], seconds - total)
            total += seg["duration_s"]
        else:  # a square: its legs
            total += seg.get("sides", 4) * (seg["leg_duration_s"] + seg["turn_duration_s"])
        out.append(seg)
    raw["segments"] = out
    return raw


def builtin(name: str, seconds: float) -> LogData:
    return simulate(scenario_from_dict(cut(load_scenario(name).raw, seconds), name=name), SEED)


def static_start() -> LogData:
    """paper-3d-short's static start (120 s) and first manoeuvres, 240 s."""
    return builtin("paper-3d-short", 240.0)


def underway_turns() -> LogData:
    """realistic-turns: underway from the first sample, the attitude given, 30-35 deg/s turns, stamps 1 s early."""
    return builtin("realistic-turns", 180.0)


def underway_gnss() -> LogData:
    """field-survey: underway at the surface, the origin from the first GNSS fix, nothing else given."""
    return builtin("field-survey", 200.0)


def straight() -> LogData:
    """realistic-straight: one straight line, where the nominal check holds the calibration."""
    return builtin("realistic-straight", 150.0)


def water_track() -> LogData:
    """deep-descent: a descent without bottom lock, water-track pings on the DVL topic."""
    return builtin("deep-descent", 200.0)


LOGS: dict[str, Callable[[], LogData]] = {
    "static": static_start,
    "turns": underway_turns,
    "gnss": underway_gnss,
    "straight": straight,
    "water": water_track,
}


def cells() -> list[tuple[str, str, str]]:
    """(log, mode, config): every (log, mode) pair, the configuration cycled so that every pair of factors meets."""
    names = [*LOGS, "foreign"]
    configs = list(CONFIGS)
    # a cell too slow to run (TOO_SLOW) keeps its configuration on the batch smoother
    out = [
        (log, "batch" if (log, mode) in TOO_SLOW else mode, configs[(i + j) % len(configs)])
        for i, log in enumerate(names)
        for j, mode in enumerate(MODES)
    ]
    out += [("static", "io-dvlc", c) for c in configs]  # io-dvlc needs the paper's Type-I segments
    return out


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, LogData, list[str]]]:
    """Each kind of log as a file, with the reading options it needs."""
    folder = tmp_path_factory.mktemp("matrix")
    out: dict[str, tuple[Path, LogData, list[str]]] = {}
    for name, make in LOGS.items():
        log = make()
        path = folder / f"{name}.mcap"
        write_log(path, log)
        out[name] = (path, log, [])
    from tests.app.test_field_bag import _scenario_raw, _write_bag

    raw = _scenario_raw()
    raw["segments"][0]["duration_s"] = 60.0
    log = simulate(scenario_from_dict(cut(raw, 150.0), name="field-bag"), SEED)
    bag = folder / "foreign"
    _write_bag(bag, log, np.random.default_rng(SEED))
    topics = ["--imu-topic", "/vectornav/imu_uncompensated", "--dvl-topic", "/nortek/dvl/twist"]
    topics += ["--depth-topic", "/bar30/pressure", "--gnss-topic", "/ublox/fix"]
    out["foreign"] = (bag, log, topics)
    return out


def config_args(name: str, folder: Path) -> list[str]:
    value = CONFIGS[name]
    if value is None:
        return []
    if "\n" not in value:
        return ["-c", value]
    path = folder / f"{name}.toml"
    path.write_text(value)
    return ["-c", str(path)]


def smooth_in_process(
    args: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> tuple[int, str, str]:
    """`gtsam-dvl ARGS` through the console script's entry point, in this process: (exit code, stdout, stderr).
    An exception escaping it is a traceback a user would see: the test fails with it."""
    from gtsam_dvl.app.cli import _run_app

    monkeypatch.setattr(sys, "argv", ["gtsam-dvl", *args])
    code = _run_app()
    captured = capsys.readouterr()
    return (code if isinstance(code, int) else 0), captured.out, captured.err


def judge(
    cell: tuple[str, str, str], code: int, out: str, err: str, summary_path: Path, log: LogData
) -> None:
    """What every cell must show (module doc)."""
    assert "Traceback" not in out + err, (cell, err[-3000:])
    if code != 0:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert code == 1 and len(lines) == 1 and lines[0].startswith("gtsam-dvl: error:"), (
            cell,
            code,
            err,
        )
        return
    summary = json.loads(summary_path.read_text())
    health = summary["health"]
    assert health["status"] != "failed", (cell, health["warnings"])
    errors = summary.get("errors")
    if errors is None or cell[1] == "io-dvlc" or log.truth is None:
        return
    off = [abs(errors["scale_nsigma"]), *map(abs, errors["misalignment_nsigma"])]
    position = errors["final_horizontal_position_m"]
    sigma = summary["final_horizontal_position_sigma_m"]
    inside = max(off) <= SIGMAS and position <= SIGMAS * sigma + 0.05
    # never silently wrong: outside its sigmas, the health must say so
    assert inside or health["status"] != "ok", (
        cell,
        f"calibration {max(off):.1f} sigma, position {position:.2f} m against sigma {sigma:.2f} m, health ok",
    )


@pytest.mark.parametrize("cell", cells(), ids=lambda c: "-".join(c))
def test_cell(
    cell: tuple[str, str, str],
    logs: dict[str, tuple[Path, LogData, list[str]]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    request: pytest.FixtureRequest,
) -> None:
    name, mode, config = cell
    if cell in KNOWN_DEFECTS:
        request.node.add_marker(pytest.mark.xfail(strict=True, reason=KNOWN_DEFECTS[cell]))
    path, log, options = logs[name]
    summary = tmp_path / "summary.json"
    args = ["smooth", str(path), "--mode", mode, "-q", "--summary", str(summary)]
    args += options + config_args(config, tmp_path)
    code, out, err = smooth_in_process(args, capsys, monkeypatch)
    judge(cell, code, out, err, summary, log)


@pytest.mark.parametrize("cell", [("turns", "ekf", "default"), ("foreign", "online", "datasheet")])
def test_cell_as_subprocess(
    cell: tuple[str, str, str], logs: dict[str, tuple[Path, LogData, list[str]]], tmp_path: Path
) -> None:
    """Two cells as a user runs them: the console script's module in its own process."""
    name, mode, config = cell
    path, log, options = logs[name]
    summary = tmp_path / "summary.json"
    cmd = [sys.executable, "-m", "gtsam_dvl.app.cli", "smooth", str(path), "--mode", mode, "-q"]
    cmd += ["--summary", str(summary), *options, *config_args(config, tmp_path)]
    proc = subprocess.run(
        cmd, capture_output=True, text=True, timeout=600, stdin=subprocess.DEVNULL
    )
    judge(cell, proc.returncode, proc.stdout, proc.stderr, summary, log)


def test_cells_cover_every_pair() -> None:
    """The design's promise: every pair of factor levels meets in some cell."""
    got = cells()
    logs_, modes, configs = {c[0] for c in got}, set(MODES), set(CONFIGS)
    for log in logs_:
        assert {c[1] for c in got if c[0] == log} >= modes - {m for g, m in TOO_SLOW if g == log}
        assert {c[2] for c in got if c[0] == log} == configs
    for (
        mode
    ) in modes:  # less the configuration of a cell too slow to run, which the batch smoother takes
        dropped = sum(1 for _, m in TOO_SLOW if m == mode)
        assert len({c[2] for c in got if c[1] == mode}) >= len(configs) - dropped
