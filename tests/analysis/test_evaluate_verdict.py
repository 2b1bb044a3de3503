"""`evaluate` checks that the log it is given is the result's source (content hash, stamps, origin) and prints a
verdict like `plan`'s: a Yes/No headline, advice, every estimated state with the time it was determined, the errors
against the truth where the truth has them, and no NaN or empty field."""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from gtsam_dvl.analysis.evaluate import origin_distance_m, source_mismatch, truth_error_lines
from gtsam_dvl.analysis.observability import (
    LEVER_ARM_NOTE,
    ObservabilityReport,
    StateVerdict,
    calibration_answer,
    determined_at,
)
from gtsam_dvl.app.cli import app
from gtsam_dvl.app.commands import SmoothOutcome, evaluate_to_dir, smooth_file
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import StoredResult, Timeline
from gtsam_dvl.core.types import GeoOrigin
from gtsam_dvl.io.result_reader import read_result
from gtsam_dvl.io.result_writer import file_sha256
from gtsam_dvl.io.writer import write_log
from tests.support.scenarios import simulate_variant
from tests.support.synthetic_log import make_log

# ----- the source check ------------------------------------------------------------------------------------


def test_file_sha256_of_a_file_and_a_folder(tmp_path: Path) -> None:
    f = tmp_path / "a.mcap"
    f.write_bytes(b"abc" * 1000)
    assert file_sha256(f) == hashlib.sha256(b"abc" * 1000).hexdigest()
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "x.db3").write_bytes(b"1")
    (bag / "metadata.yaml").write_bytes(b"2")
    before = file_sha256(bag)
    assert before and before != file_sha256(f)
    (bag / "x.db3").write_bytes(b"3")
    assert file_sha256(bag) != before  # a changed file of the folder changes its hash
    assert file_sha256(tmp_path / "missing.mcap") == ""


def stored_for(log: Any, sha: str = "", origin: GeoOrigin | None = None) -> StoredResult:
    """A StoredResult whose result spans the log's stamps (source_mismatch reads only t and t0_ns)."""
    result: Any = SimpleNamespace(t=np.asarray(log.imu.t), t0_ns=log.t0_ns)
    return StoredResult(
        result,
        {},
        "r.mcap",
        "/data/dive.mcap",
        "dive.mcap",
        {},
        sha,
        origin.as_dict() if origin is not None else None,
    )


def test_origin_distance() -> None:
    a = GeoOrigin(30.0, 114.0, -100.0)
    # a degree of latitude is 111.2 km on the mean sphere; a degree of longitude at 30 deg cos(30) of it
    assert origin_distance_m(a, GeoOrigin(31.0, 114.0, -100.0)) == pytest.approx(111_195, rel=1e-4)
    assert origin_distance_m(a, GeoOrigin(30.0, 115.0, 0.0)) == pytest.approx(
        111_195 * np.cos(np.radians(30)), rel=1e-3
    )


def test_source_mismatch_reasons() -> None:
    log = make_log(20.0)
    assert log.origin is not None
    # the same content is the source, whatever else
    assert (
        source_mismatch(stored_for(log, "ab" * 32, GeoOrigin(10.0, 0.0, 0.0)), log, "ab" * 32) == ""
    )
    # content differs
    why = source_mismatch(stored_for(log, "ab" * 32, log.origin), log, "cd" * 32)
    assert "content differs" in why and "/data/dive.mcap" in why
    # a result that recorded no hash: judged on stamps and origin
    near = GeoOrigin(log.origin.lat_deg + 0.005, log.origin.lon_deg, 0.0)  # 556 m north
    assert source_mismatch(stored_for(log, "", near), log, "cd" * 32) == ""
    far = GeoOrigin(log.origin.lat_deg + 13.0, log.origin.lon_deg, 0.0)
    why = source_mismatch(stored_for(log, "", far), log, "cd" * 32)
    assert "map origin is 1445.5 km from the source's" in why and "stamps" not in why
    other_day = dataclasses.replace(log, t0_ns=log.t0_ns + 86_400 * 10**9)
    why = source_mismatch(stored_for(log), other_day, "cd" * 32)
    assert "do not overlap" in why and "2023-11-15" in why and "2023-11-14" in why


@pytest.fixture(scope="module")
def tiny_dive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """A 65 s dive (static, accelerate, descent) smoothed; another seed's log of the same plan (same stamps and
    origin, other data)."""
    d = tmp_path_factory.mktemp("tiny")
    segments = [
        {"kind": "static", "duration_s": 20.0},
        {"kind": "level", "duration_s": 15.0, "speed_end_m_s": 2.0},
        {"kind": "descent", "duration_s": 30.0, "peak_vertical_speed_m_s": 0.8},
    ]
    source, other, result = d / "dive.mcap", d / "other.mcap", d / "result.mcap"
    write_log(source, simulate_variant(5, segments=segments))
    write_log(other, simulate_variant(6, segments=segments))
    smooth_file(source, result, show_progress=False, timeline=False)
    return source, other, result


def test_result_records_source_hash_and_origin(tiny_dive: tuple[Path, Path, Path]) -> None:
    source, _, result = tiny_dive
    stored = read_result(result)
    assert stored.source_sha256 == hashlib.sha256(source.read_bytes()).hexdigest()
    assert stored.source_origin == {
        "lat_deg": 30.0,
        "lon_deg": 114.0,
        "height_m": -100.0,
    }  # paper-3d-short's


def test_evaluate_refuses_another_dive_unless_forced(
    tiny_dive: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    source, other, result = tiny_dive
    with pytest.raises(
        GtsamDvlError,
        match=r"other\.mcap is not the source of .*result\.mcap: its content "
        r"differs from that of the source .*dive\.mcap .*--force",
    ):
        evaluate_to_dir(result, tmp_path / "refused", truth_path=other)
    assert not (tmp_path / "refused").exists()  # nothing written
    cli = CliRunner().invoke(
        app, ["evaluate", str(result), "-o", str(tmp_path / "cli"), "--truth", str(other)]
    )
    assert cli.exit_code == 1 and not (tmp_path / "cli").exists()
    assert "is not the source of" in cli.output and len(cli.output.strip().splitlines()) == 1


def test_evaluate_forced_says_so_then_the_verdict(
    tiny_dive: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    _, other, result = tiny_dive
    lines, _ = evaluate_to_dir(result, tmp_path / "forced", truth_path=other, force=True)
    print("\n".join(lines))
    assert lines[0].startswith(
        f"--force: judged against {other}, which is not the result's source: its content"
    )
    # then the verdict, as plan words it, and the errors against (this) truth, with no unknown field
    assert lines[1].startswith("No: this log leaves ") and "descent or ascent" in lines[2]
    assert sum(line.startswith("vs truth: ") for line in lines) == 2
    assert not any("nan" in line.lower() or "  deg" in line for line in lines)


# ----- the verdict --------------------------------------------------------------------------------------------


def verdict(key: str, description: str, verdict: str, unit: str = "deg") -> StateVerdict:
    ratio = {"determined": 0.05, "weakly determined": 0.6, "not determined": 1.0}[verdict]
    return StateVerdict(key, description, unit, 1.0, ratio, ratio, verdict)


def report(
    roll: str = "determined", offset: str | None = None, lever: str | None = None
) -> ObservabilityReport:
    states = [
        verdict("accel_bias_x", "accelerometer bias along body x", "not determined", "micro-g"),
        verdict("scale", "DVL scale factor", "determined", "ppm"),
        verdict("misalignment_roll", "DVL misalignment about body x, the thrust axis (roll)", roll),
        verdict("misalignment_pitch", "DVL misalignment about body y (pitch)", "determined"),
        verdict("misalignment_yaw", "DVL misalignment about body z (yaw)", "determined"),
    ]
    return ObservabilityReport(
        states,
        [],
        600.0,
        lever_arm=[
            verdict(f"lever_arm_{a}", f"DVL lever arm along body {a}", lever, "m") for a in "xyz"
        ]
        if lever
        else [],
        time_offset=[verdict("time_offset", "DVL-IMU time offset", offset, "ms")] if offset else [],
    )


def test_headline_yes_names_every_estimated_dvl_state_and_when() -> None:
    rep = report(offset="determined")
    when = {
        "scale": 100.0,
        "misalignment_roll": 250.0,
        "misalignment_pitch": 120.0,
        "misalignment_yaw": 130.0,
        "time_offset": 310.0,
    }
    lines = calibration_answer(rep, when, "log")
    assert lines[0] == (
        "Yes: this log calibrated the DVL (scale, all three misalignment angles and the time offset); "
        "the last of them was determined 310 s into the log."
    )
    assert any(
        line.startswith("  DVL-IMU time offset: determined")
        and line.endswith("determined at 310 s")
        for line in lines
    )
    assert any(
        line.startswith("  accelerometer bias along body x: not determined") for line in lines
    )
    # without a filtering timeline: no time, no empty field
    assert calibration_answer(rep, {}, "log")[0] == (
        "Yes: this log calibrated the DVL (scale, all three "
        "misalignment angles and the time offset)."
    )
    # the planner's words are unchanged
    plan = calibration_answer(report(), when, "plan")[0]
    assert plan == (
        "Yes: this plan calibrates the DVL (scale and all three misalignment angles); the last of them "
        "is determined 250 s into the mission."
    )


def test_headline_no_with_advice() -> None:
    lines = calibration_answer(
        report(roll="weakly determined", offset="not determined", lever="not determined"), {}, "log"
    )
    assert lines[0] == (
        "No: this log leaves DVL-IMU time offset; DVL lever arm along body x; DVL lever arm along "
        "body y; DVL lever arm along body z not determined, and DVL misalignment about body x, the "
        "thrust axis (roll) weakly determined."
    )
    assert "descent or ascent" in lines[1] and "turns or speed changes" in lines[2]
    assert lines[3] == f"  {LEVER_ARM_NOTE[0].upper()}{LEVER_ARM_NOTE[1:]}."


def _offset_timeline(
    t: np.ndarray, scale_sigma: float, offset_s: np.ndarray, offset_sigma_s: np.ndarray
) -> Timeline:
    """A timeline at times t (s) with the time offset estimated (its values and sigmas in s), the scale 1 with a
    constant sigma, the misalignment and the biases zero with unit sigmas, unit attitude sigmas."""
    n = len(t)
    zeros3, ones3 = np.zeros((n, 3)), np.ones((n, 3))
    return Timeline(
        t,
        np.ones(n),
        np.full(n, scale_sigma),
        zeros3,
        ones3,
        zeros3,
        ones3,
        zeros3,
        ones3,
        ones3,
        time_offset_s=offset_s,
        time_offset_sigma_s=offset_sigma_s,
    )


def test_determined_at_reads_the_time_offset_timeline() -> None:
    tl = _offset_timeline(
        np.arange(5) * 100.0, 1e-2, np.zeros(5), np.array([0.1, 0.05, 0.02, 0.009, 0.004])
    )
    rep = ObservabilityReport(
        [],
        [],
        400.0,
        time_offset=[
            StateVerdict("time_offset", "DVL-IMU time offset", "ms", 100.0, 4.0, 0.04, "determined")
        ],
    )
    # "determined" below a tenth of the 100 ms prior: first at 9 ms, t = 300 s
    assert determined_at(rep, tl) == {"time_offset": 300.0}


# ----- errors against the truth: only those the truth gives ----------------------------------------------------


def test_truth_error_lines_leave_out_what_the_truth_lacks() -> None:
    trajectory = {
        "final_horizontal_position_m": 2.5,
        "final_horizontal_position_pct_distance": 0.1,
        "position_rmse_m": 1.25,
        "attitude_rmse_deg": [0.01, 0.02, 0.05],
    }
    assert truth_error_lines(trajectory) == [
        "vs truth: final horizontal position error 2.50 m (0.100 % of distance), position rms 1.25 m, attitude rms "
        "about east/north/up 0.01, 0.02, 0.05 deg"
    ]
    full = {
        **trajectory,
        "scale_ppm": 12.4,
        "scale_nsigma": 0.81,
        "misalignment_deg": [0.01, -0.02, 0.03],
        "misalignment_nsigma": [0.1, -0.2, 0.3],
        "dvl_time_offset_s": 0.0012,
        "dvl_time_offset_nsigma": 0.4,
        "gyro_bias_deg_per_h": [float("nan")] * 3,
        "final_horizontal_position_pct_distance": None,
    }
    lines = truth_error_lines(full)
    assert lines[0].startswith("vs truth: final horizontal position error 2.50 m, position rms")
    assert lines[1] == (
        "vs truth: scale +12 ppm (+0.8 sigma); misalignment roll/pitch/yaw +0.010, -0.020, +0.030 deg "
        "(+0.1, -0.2, +0.3 sigma); time offset +1.2 ms (+0.4 sigma)"
    )
    assert truth_error_lines({}) == []


def test_smooth_vs_truth_without_true_calibration_has_no_nan() -> None:
    s = {
        "estimator": "batch",
        "states": 10,
        "duration_s": 9.0,
        "timing_s": {"total": 1.0},
        "scale": {"value": 1.0, "sigma": 0.001},
        "misalignment_deg": {"value": [0.0] * 3, "sigma": [0.1] * 3},
        "gyro_bias_deg_per_h": {"value": [0.0] * 3},
        "accel_bias_ug": {"value": [0.0] * 3},
        "distance_travelled_m": 750.0,
        "final_horizontal_position_sigma_m": 2.0,
        "errors": {
            "final_horizontal_position_m": 1.5,
            "final_horizontal_position_pct_distance": 0.2,
        },
    }
    text = SmoothOutcome(s, []).describe()
    assert "  vs truth: final horizontal position 1.50 m (0.200 % of distance)" in text.splitlines()
    assert "nan" not in text and "  deg" not in text


# ----- figures "over time" draw the timeline -------------------------------------------------------------------


def test_smoother_figures_draw_the_filtering_band_over_time(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A smoother's timeline (its value the final estimate, its sigmas the filtering ones): the figure shows the
    band over the whole timeline, not one point; the time offset in ms with its truth."""
    from matplotlib.collections import PolyCollection

    from gtsam_dvl.app.plots import timeline_plots

    figures: list[Any] = []
    monkeypatch.setattr(
        timeline_plots, "save_figure", lambda fig, path: figures.append(fig) or path
    )
    n = 50
    t = np.linspace(0.0, 490.0, n)
    shrinking = np.linspace(0.5, 0.02, n)  # s
    tl = _offset_timeline(t, 1e-3, np.full(n, 0.3), shrinking)
    timeline_plots.plot_estimates(
        [("batch", tl)], tmp_path / "time_offset.png", "time_offset", truth=0.31
    )
    (fig,) = figures
    ax = fig.axes[0]
    bands = [c for c in ax.collections if isinstance(c, PolyCollection)]
    x = np.concatenate([p.vertices[:, 0] for band in bands for p in band.get_paths()])
    y = np.concatenate([p.vertices[:, 1] for band in bands for p in band.get_paths()])
    assert x.min() == pytest.approx(0.0) and x.max() == pytest.approx(490.0)  # the whole timeline
    # ms: the prior's band at the start about the final estimate
    assert y.max() == pytest.approx(300.0 + 3 * 500.0)
    assert [line.get_ydata()[0] for line in ax.get_lines() if line.get_linestyle() == "--"][
        -1
    ] == pytest.approx(310.0)
    assert "filtering 3-sigma band over time" in fig._suptitle.get_text()


def test_a_result_without_source_hash_says_what_the_check_rests_on(
    tiny_dive: tuple[Path, Path, Path],
) -> None:
    from gtsam_dvl.analysis.evaluate import evaluate_result
    from gtsam_dvl.io.reader import read_log

    source, _, result = tiny_dive
    stored = dataclasses.replace(read_result(result), source_sha256="")
    notes = evaluate_result(stored, read_log(source)).notes
    assert notes == [
        f"the result records no content hash of its source log (written by an older gtsam_dvl): "
        f"{source} is taken as its source on its stamps and origin alone"
    ]
    assert evaluate_result(read_result(result), read_log(source)).notes == []
