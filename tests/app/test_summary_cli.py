"""Every estimator's summary through the command line's entry point (gtsam_dvl.app.cli main, in this process), on a
short straight run where the nominal check holds: realistic-straight's first 150 s (seed 1: underway, stamps 1 s
early, the attitude given). The EKF and the batch smoother exit 0 and their console names what was held and why (issue
39: the EKF's console summary ended in a TypeError, its calibration_hold another shape than the batch smoother's);
every estimator's --summary file reads back into its model (core/summary.py) unchanged, and a result's summary too."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from gtsam_dvl.app.cli import main
from gtsam_dvl.core.summary import IoDvlcSummary, Summary, parse_summary, read_summary
from gtsam_dvl.io.result_reader import read_result
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import scenario_raw


@pytest.fixture(scope="module")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """realistic-straight cut to 150 s (one straight segment), seed 1, as a log file."""
    path = tmp_path_factory.mktemp("summary") / "straight.mcap"
    raw = scenario_raw("realistic-straight", segments=[{"kind": "straight", "duration_s": 150.0}])
    write_log(path, simulate(scenario_from_dict(raw, name="realistic-straight"), 1))
    return path


def _smooth(
    log: Path, mode: str, out: Path, capsys: pytest.CaptureFixture[str], *extra: str
) -> tuple[int, str, dict]:
    """`gtsam-dvl smooth LOG --mode MODE --summary OUT/MODE.json -q EXTRA...` through main: (exit code, stdout and
    stderr, the summary file's JSON). An exception other than SystemExit (a traceback) fails the test."""
    path = out / f"{mode}.json"
    argv = ["gtsam-dvl", "smooth", str(log), "--mode", mode, "--summary", str(path), "-q", *extra]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sys, "argv", argv)
        with pytest.raises(SystemExit) as done:
            main()
    captured = capsys.readouterr()
    code = done.value.code if isinstance(done.value.code, int) else 0
    return code, captured.out + captured.err, json.loads(path.read_text())


def _same_json(a: dict, b: dict) -> bool:
    """a and b the same JSON (NaN equal to NaN)."""
    return json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


@pytest.mark.parametrize(
    ("mode", "words"),
    [
        ("ekf", "the filtered calibration's chi^2 gain over the nominal"),
        ("batch", "estimating the DVL scale and misalignment lowers chi^2"),
    ],
)
def test_nominal_hold_is_named_on_the_console(
    straight: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], mode: str, words: str
) -> None:
    result = tmp_path / "result.mcap"
    code, text, written = _smooth(straight, mode, tmp_path, capsys, "-o", str(result))
    assert code == 0 and "Traceback" not in text, text
    summary = read_summary(written, f"{mode}.json")
    hold = summary.calibration_hold
    assert hold is not None and hold.reason == "nominal_check", hold
    # every direction held, each with the data's information along it (the EKF's too: issue 39)
    assert len(hold.held) == 4 and all(h.information is not None for h in hold.held)
    assert hold.nominal is not None and not hold.nominal.pays
    lines = text.splitlines()
    (at,) = [
        i for i, line in enumerate(lines) if line.startswith("  held at the nominal calibration")
    ]
    print(lines[at], lines[at + 1], sep="\n")
    assert all(h.label() in lines[at] for h in hold.held)
    assert lines[at + 1] == f"    why: {hold.why}" and words in hold.why
    assert _same_json(summary.to_json_dict(), written)  # read back, nothing lost
    assert read_result(result).summary.calibration_hold == hold  # the result's summary, typed


@pytest.mark.parametrize("mode", ["online", "online-full", "io-dvlc"])
def test_every_estimators_summary_fits_the_model(
    straight: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], mode: str
) -> None:
    """The other estimators' summaries (batch and EKF: above). io-dvlc finds no Type-I segment on a straight run:
    no scale, health "failed", exit 0 and its own model."""
    code, text, written = _smooth(straight, mode, tmp_path, capsys)
    assert code == 0 and "Traceback" not in text, text
    summary = parse_summary(written, f"{mode}.json")
    assert _same_json(summary.to_json_dict(), written)
    if mode == "io-dvlc":
        assert isinstance(summary, IoDvlcSummary)
        assert summary.health is not None and summary.health.status == "failed"
        return
    assert isinstance(summary, Summary)
    hold = summary.calibration_hold
    assert hold is not None and hold.reason == "nominal_check" and len(hold.held) == 4
    assert "held at the nominal calibration" in text and f"why: {hold.why}" in text
