"""Safe outputs of `gtsam-dvl smooth`: an output that is an input is refused before any work, every output
location is checked first, the outputs are written all or none, SIGTERM leaves no stray temporary file,
files are group-readable like the MCAP, errors name the user's path; health and --strict; no traceback on a
log that never moves."""

from __future__ import annotations

import copy
import errno
import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from gtsam_dvl.app.cli import app
from gtsam_dvl.app.commands import smooth_file
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.io import atomic
from gtsam_dvl.io.atomic import OutputSet
from gtsam_dvl.io.storage.sources import open_source
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

CLI = [sys.executable, "-m", "gtsam_dvl.app.cli"]


def _scenario_log(path: Path, segments: list[dict[str, Any]], name: str) -> Path:
    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = segments
    write_log(path, simulate(scenario_from_dict(raw, name), 5))
    return path


@pytest.fixture(scope="module")
def short_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """paper-2d cut to 300 s: 100 s static, speed-up, two surges (a fraction of a second per batch run)."""
    segments = copy.deepcopy(load_scenario("paper-2d").raw["segments"][:4])
    segments[0]["duration_s"] = 100.0
    return _scenario_log(tmp_path_factory.mktemp("safe") / "short.mcap", segments, "paper-2d-short")


@pytest.fixture(scope="module")
def static_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _scenario_log(
        tmp_path_factory.mktemp("static") / "static.mcap",
        [{"kind": "static", "duration_s": 60.0}],
        "static",
    )


def cli(*args: str | Path) -> Any:
    return CliRunner().invoke(app, [str(a) for a in args])


def _smooth_started(*args: str | Path) -> subprocess.Popen[str]:
    """`gtsam-dvl smooth ARGS -q` started in another process (to be signalled), its output piped as text."""
    return subprocess.Popen(
        [*CLI, "smooth", *map(str, args), "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def one_error_line(result: Any) -> str:
    lines = result.stderr.strip().splitlines()
    assert result.exit_code == 1 and len(lines) == 1, (
        result.exit_code,
        result.stderr,
        result.stdout,
    )
    assert lines[0].startswith("gtsam-dvl: error: ") and "Traceback" not in result.stderr
    return str(lines[0])


def visible_and_hidden(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


@pytest.mark.parametrize(
    "option", ["-o", "--summary", "--tum", "--timeline-npz", "link", "spelling"]
)
def test_output_that_is_the_input_is_refused(option: str, short_log: Path, tmp_path: Path) -> None:
    log = tmp_path / "log.mcap"
    log.write_bytes(short_log.read_bytes())
    before = log.read_bytes()
    args: list[str | Path]
    if option == "link":  # the input through a symlink, the output under the real name
        (tmp_path / "link.mcap").symlink_to(log)
        args = ["smooth", tmp_path / "link.mcap", "-o", log]
    elif option == "spelling":  # another spelling of the same path
        (tmp_path / "sub").mkdir()
        args = ["smooth", log, "-o", tmp_path / "sub" / ".." / "log.mcap"]
    else:
        args = ["smooth", log, "-o", tmp_path / "out.mcap"] if option != "-o" else ["smooth", log]
        args += [option, log]
    start = time.perf_counter()
    line = one_error_line(cli(*args, "-q"))
    print(line)
    assert "is the input log" in line and "choose another output path" in line
    assert time.perf_counter() - start < 5.0  # refused before reading or estimating
    assert log.read_bytes() == before
    assert visible_and_hidden(tmp_path) <= {"log.mcap", "link.mcap", "sub"}  # nothing written


def test_same_output_twice_and_config_as_output(short_log: Path, tmp_path: Path) -> None:
    line = one_error_line(
        cli("smooth", short_log, "-o", tmp_path / "a.mcap", "--summary", tmp_path / "a.mcap", "-q")
    )
    assert "given as both -o and --summary" in line
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[dvl]\nrobust = "huber"\n')
    line = one_error_line(cli("smooth", short_log, "-c", cfg, "--summary", cfg, "-q"))
    assert (
        "--summary is the configuration" in line and cfg.read_text() == '[dvl]\nrobust = "huber"\n'
    )


def test_unwritable_output_is_refused_before_the_run(short_log: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    line = one_error_line(
        cli("smooth", short_log, "-o", tmp_path / "r.mcap", "--summary", blocker / "s.json", "-q")
    )
    assert f"{blocker / 's.json'}: cannot create its folder ({blocker} is a file)" in line
    assert visible_and_hidden(tmp_path) == {"not-a-folder"}  # no MCAP left behind
    line = one_error_line(cli("smooth", short_log, "-o", tmp_path, "-q"))
    assert "is a folder" in line


def test_failing_summary_leaves_no_mcap(
    short_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A write that fails during the run (disk full on the summary) removes the outputs already staged."""
    real = OutputSet.write_json

    def full(self: OutputSet, path: Path | str, data: Any) -> Path:
        if Path(path).name == "s.json":
            raise GtsamDvlError(f"{path}: cannot write ({os.strerror(errno.ENOSPC)})")
        return real(self, path, data)

    monkeypatch.setattr(OutputSet, "write_json", full)
    with pytest.raises(GtsamDvlError, match="s.json: cannot write"):
        smooth_file(
            short_log,
            tmp_path / "r.mcap",
            summary_path=tmp_path / "s.json",
            tum_path=tmp_path / "t.tum",
            show_progress=False,
        )
    assert visible_and_hidden(tmp_path) == set()


def test_output_set_all_or_none(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError), OutputSet() as out:
        out.write_text(tmp_path / "a.txt", "a")
        with out.staged(tmp_path / "b.bin") as tmp:
            tmp.write_bytes(b"b")
        raise RuntimeError("the run fails after two outputs")
    assert visible_and_hidden(tmp_path) == set()
    # a rename that fails at commit (the target is a folder) takes back the ones already renamed
    (tmp_path / "c").mkdir()
    with pytest.raises(GtsamDvlError) as e, OutputSet() as out:
        out.write_text(tmp_path / "a.txt", "a")
        out.write_text(tmp_path / "c", "c")
    assert str(e.value).startswith(f"{tmp_path / 'c'}: cannot write")
    assert visible_and_hidden(tmp_path) == {"c"} and (tmp_path / "c").is_dir()
    # a writer's error names the user's path, not the temporary one
    with (
        pytest.raises(GtsamDvlError) as e,
        OutputSet() as out,
        out.staged(tmp_path / "r.mcap") as tmp,
    ):
        raise GtsamDvlError(f"{tmp}: cannot write (No space left on device)")
    assert str(e.value) == f"{tmp_path / 'r.mcap'}: cannot write (No space left on device)"
    assert visible_and_hidden(tmp_path) == {"c"}


def test_signal_during_commit_is_deferred(tmp_path: Path) -> None:
    """SIGTERM while the set is renamed: the renames finish first, then the signal acts."""
    seen: list[int] = []

    def handler(signum: int, frame: object) -> None:
        if atomic.deferring():
            atomic.defer(signum)
            return
        seen.append(len(list(tmp_path.iterdir())))
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    real_replace = os.replace

    def replace_and_signal(a: Any, b: Any) -> None:
        real_replace(a, b)
        if not seen:
            signal.raise_signal(signal.SIGTERM)

    try:
        out = OutputSet()
        out.write_text(tmp_path / "a.txt", "a")
        out.write_text(tmp_path / "b.txt", "b")
        os.replace = replace_and_signal  # type: ignore[assignment]
        with pytest.raises(KeyboardInterrupt):
            out.commit()
    finally:
        os.replace = real_replace
        signal.signal(signal.SIGTERM, previous)
    assert seen == [2] and visible_and_hidden(tmp_path) == {"a.txt", "b.txt"}


@pytest.mark.parametrize("umask", [0o022, 0o002])
def test_outputs_respect_the_umask(umask: int, short_log: Path, tmp_path: Path) -> None:
    old = os.umask(umask)
    try:
        outcome = smooth_file(
            short_log,
            tmp_path / "r.mcap",
            summary_path=tmp_path / "s.json",
            tum_path=tmp_path / "t.tum",
            show_progress=False,
        )
    finally:
        os.umask(old)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in outcome.written}
    assert set(modes) == {"r.mcap", "r.timeline.npz", "s.json", "t.tum"}
    assert set(modes.values()) == {0o666 & ~umask}, modes


def test_health_in_summary_console_and_result_metadata(short_log: Path, tmp_path: Path) -> None:
    result = cli(
        "smooth",
        short_log,
        "-o",
        tmp_path / "r.mcap",
        "--summary",
        tmp_path / "s.json",
        "-q",
        "--strict",
    )
    assert result.exit_code == 0, result.stderr
    assert "  health: ok" in result.stdout
    summ = json.loads((tmp_path / "s.json").read_text())
    assert summ["health"]["status"] == "ok" and summ["losses"]["repair"] == {}
    rec = open_source(tmp_path / "r.mcap").metadata["gtsam_dvl_health"]
    assert rec["status"] == "ok" and json.loads(rec["warnings"]) == []
    assert json.loads(rec["figures"])["dvl_residuals"]["whitened_rms"] == pytest.approx(
        summ["health"]["figures"]["dvl_residuals"]["whitened_rms"]
    )
    attached = json.loads(open_source(tmp_path / "r.mcap").attachments["summary.json"][1])
    assert attached["health"]["status"] == "ok"


def test_static_log_exits_cleanly_and_strict_gives_3(static_log: Path, tmp_path: Path) -> None:
    result = cli(
        "smooth", static_log, "-o", tmp_path / "r.mcap", "--summary", tmp_path / "s.json", "-q"
    )
    assert result.exit_code == 0, result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    warning = [
        ln
        for ln in result.stdout.splitlines()
        if "warning: nothing calibratable: the log never moves" in ln
    ]
    assert len(warning) == 1
    assert "no distance travelled" in result.stdout
    assert json.loads((tmp_path / "s.json").read_text())["health"]["status"] == "degraded"
    strict = cli("smooth", static_log, "--summary", tmp_path / "s2.json", "-q", "--strict")
    assert strict.exit_code == 3
    assert strict.stderr.strip().splitlines() == [
        "gtsam-dvl: error: health degraded (--strict): exit code 3"
    ]
    assert (tmp_path / "s2.json").exists()  # the outputs are still written


@pytest.mark.slow
@pytest.mark.parametrize("phase", ["first file", "mcap being written"])
def test_sigterm_leaves_no_stray_files(phase: str, short_log: Path, tmp_path: Path) -> None:
    """SIGTERM as soon as the first temporary file appears (the check that the folder is writable), or while
    the result MCAP is being written (its writer's .part file): exit 143, one line on stderr, and the outputs
    all or none, with no temporary file."""
    out = tmp_path / "out"
    out.mkdir()
    proc = _smooth_started(
        short_log, "-o", out / "r.mcap", "--summary", out / "s.json", "--tum", out / "t.tum"
    )
    deadline = time.monotonic() + 120

    def seen() -> bool:
        names = [p.name for p in out.iterdir()]
        return bool(names) if phase == "first file" else any(n.endswith(".part") for n in names)

    while proc.poll() is None and time.monotonic() < deadline and not seen():
        time.sleep(0.0005)
    caught = proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    names = visible_and_hidden(out)
    print(
        f"caught writing: {caught}, exit {proc.returncode}, left {sorted(names)}, stderr {stderr.strip()!r}"
    )
    assert not [n for n in names if n.startswith(".")], names  # no temporary file
    assert names in (set(), {"r.mcap", "r.timeline.npz", "s.json", "t.tum"})
    if caught:
        assert proc.returncode == 143
        assert stderr.strip().splitlines() == [
            "gtsam-dvl: error: terminated by SIGTERM; no partial output left behind"
        ]


@pytest.mark.slow
def test_sigterm_mid_run(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path) -> None:
    """SIGTERM while estimating: nothing written. The online estimator with the full iSAM2 history on paper-2d (14 s
    of estimation; the batch smoother's 1.4 s would be over before the signal)."""
    log = tmp_path_factory.mktemp("full") / "paper-2d.mcap"
    write_log(log, simulate(load_scenario("paper-2d"), 5))
    proc = _smooth_started(
        log, "--mode", "online-full", "-o", tmp_path / "r.mcap", "--summary", tmp_path / "s.json"
    )
    time.sleep(2.5)
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 143, stderr
    assert stderr.strip().splitlines() == [
        "gtsam-dvl: error: terminated by SIGTERM; no partial output left behind"
    ]
    assert visible_and_hidden(tmp_path) == set()
