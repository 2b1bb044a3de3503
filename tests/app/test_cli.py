"""The command line end to end: simulate, info, smooth, plot-log; bad input gives one line and exit 1."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.io.reader import read_odometry

CLI = [sys.executable, "-m", "gtsam_dvl.app.cli"]


def run(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=600)
    if check and proc.returncode != 0:
        raise AssertionError(f"{args} failed: {proc.stderr}")
    return proc


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "run.mcap"
    run("simulate", "paper-2d", "-o", str(path), "--seed", "11", "-q")
    return path


@pytest.mark.slow
def test_simulate_is_deterministic_byte_for_byte(sim_log: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.mcap"
    run("simulate", "paper-2d", "-o", str(again), "--seed", "11", "-q")
    other = tmp_path / "other.mcap"
    run("simulate", "paper-2d", "-o", str(other), "--seed", "12", "-q")
    assert again.read_bytes() == sim_log.read_bytes()
    assert other.read_bytes() != sim_log.read_bytes()


@pytest.mark.slow
def test_smooth_writes_result_summary_and_tum(sim_log: Path, tmp_path: Path) -> None:
    out, summ, tum = tmp_path / "result.mcap", tmp_path / "summary.json", tmp_path / "traj.tum"
    proc = run(
        "smooth",
        str(sim_log),
        "-o",
        str(out),
        "--mode",
        "batch",
        "--summary",
        str(summ),
        "--tum",
        str(tum),
        "-q",
    )
    assert "scale" in proc.stdout
    s = json.loads(summ.read_text())
    assert s["estimator"] == "batch"
    for key in (
        "scale",
        "misalignment_deg",
        "gyro_bias_deg_per_h",
        "accel_bias_ug",
        "distance_travelled_m",
        "timing_s",
        "errors",
    ):
        assert key in s
    assert len(s["misalignment_deg"]["value"]) == 3 and len(s["misalignment_deg"]["sigma"]) == 3
    # the result log decodes to the estimates: the last odometry position equals the TUM file's last row
    t, n_p, n_q, _, _, pose_cov, _ = read_odometry(out, "/gtsam_dvl/odometry")
    rows = np.loadtxt(tum)
    assert rows.shape == (len(t), 8)
    np.testing.assert_allclose(rows[-1, 1:4], n_p[-1], atol=1e-6)
    np.testing.assert_allclose(np.abs(rows[-1, 4:]), np.abs(n_q[-1]), atol=1e-6)
    assert np.all(np.linalg.eigvalsh(pose_cov[-1]) > 0)  # a real covariance, not zeros
    # summary numbers are those of a real estimate against the truth, inside 3 sigma
    assert abs(s["errors"]["scale_nsigma"]) < 3


@pytest.mark.slow
def test_info_and_plot_log(sim_log: Path, tmp_path: Path) -> None:
    proc = run("info", str(sim_log))
    assert "IMU" in proc.stdout and "truth: scale 0.9998" in proc.stdout
    run("plot-log", str(sim_log), "-o", str(tmp_path / "figs"))
    pngs = sorted(p.name for p in (tmp_path / "figs").glob("*.png"))
    assert pngs == ["fig01_trajectory.png", "fig02_dvl_output.png", "fig03_imu_output.png"]


@pytest.mark.parametrize("case", ["truncated", "missing", "not_mcap", "bad_topic", "bad_config"])
def test_bad_input_gives_one_line_and_exit_1(case: str, sim_log: Path, tmp_path: Path) -> None:
    args: list[str]
    if case == "truncated":
        bad = tmp_path / "cut.mcap"
        bad.write_bytes(sim_log.read_bytes()[: sim_log.stat().st_size // 2])
        args = ["smooth", str(bad), "-q"]
    elif case == "missing":
        args = ["smooth", str(tmp_path / "nope.mcap"), "-q"]
    elif case == "not_mcap":
        bad = tmp_path / "text.mcap"
        bad.write_text("hello\n")
        args = ["info", str(bad)]
    elif case == "bad_topic":
        args = ["info", str(sim_log), "--imu-topic", "/nope"]
    else:
        cfg = tmp_path / "cfg.toml"
        cfg.write_text("[priors]\nscale_sigmaa = 1.0\n")
        args = ["smooth", str(sim_log), "-c", str(cfg), "-q"]
    proc = run(*args, check=False)
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("gtsam-dvl: error:") and "Traceback" not in proc.stderr
    print(lines[0])


@pytest.mark.parametrize("fraction", [0.5, 0.6])
def test_truncated_log_salvage_recovers(fraction: float, sim_log: Path, tmp_path: Path) -> None:
    """info --salvage on a file cut short says so, with the time up to which data was read (also when
    the cut falls between a chunk and its message indexes: not "lost 0 chunk(s)")."""
    bad = tmp_path / "cut.mcap"
    size = int(sim_log.stat().st_size * fraction)
    bad.write_bytes(sim_log.read_bytes()[:size])
    proc = run("info", str(bad), "--salvage")
    print(proc.stdout)
    assert (
        "salvage" in proc.stdout
        and "lost 0 chunk" not in proc.stdout
        and "nothing lost" not in proc.stdout
    )
    assert (
        f"the file is cut short at byte {size} (no footer): nothing after log time" in proc.stdout
    )


@pytest.mark.slow
def test_smooth_and_evaluate_report_losses(sim_log: Path, tmp_path: Path) -> None:
    """What --salvage dropped appears in smooth's and evaluate's console output, the summary and the result."""
    from gtsam_dvl.io.storage.sources import open_source

    bad = tmp_path / "cut.mcap"
    bad.write_bytes(sim_log.read_bytes()[: sim_log.stat().st_size // 2])
    out, summ = tmp_path / "r.mcap", tmp_path / "s.json"
    proc = run(
        "smooth",
        str(bad),
        "--salvage",
        "-o",
        str(out),
        "--summary",
        str(summ),
        "-q",
        "--no-timeline",
    )
    assert (
        "  health: degraded" in proc.stdout
        and "warning: the log file is cut short at byte" in proc.stdout
    )
    s = json.loads(summ.read_text())
    assert (
        s["health"]["status"] == "degraded"
        and s["losses"]["salvage"]["truncated"][0]["at_byte"] == bad.stat().st_size
    )
    assert json.loads(open_source(out).metadata["gtsam_dvl_health"]["losses"]) == s["losses"]
    strict = run(
        "smooth",
        str(bad),
        "--salvage",
        "--summary",
        str(tmp_path / "s2.json"),
        "-q",
        "--no-timeline",
        "--strict",
        check=False,
    )
    assert strict.returncode == 3
    proc = run("evaluate", str(out), "-o", str(tmp_path / "eval"), "--truth", str(bad), "--salvage")
    assert "result health: degraded" in proc.stdout
    assert f"reading {bad}: the log file is cut short" in proc.stdout
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert (
        metrics["health"]["status"] == "degraded"
        and metrics["truth_log_losses"]["salvage"]["truncated"]
    )


# ----- configuration checked by value, the effective configuration read back with -c ------------------


@pytest.mark.parametrize(
    ("name", "text", "expected"),
    [
        (
            "cfg.toml",
            '[imu]\nbias_model = "walk"\n',
            "[imu] bias_model = 'walk' is not one of 'constant', 'random_walk'",
        ),
        (
            "cfg.toml",
            '[dvl]\nnoise_m_s = "abc"\n',
            "[dvl] noise_m_s must be a number >= 0, got 'abc'",
        ),
        (
            "cfg.toml",
            "[online]\nwindow_s = -5.0\n",
            "[online] window_s must be a number > 0, got -5.0",
        ),
        (
            "cfg.toml",
            '[ekf]\nmin_calibration_speed_m_s = "fast"\n',
            "[ekf] min_calibration_speed_m_s must be a number >= 0, got 'fast'",
        ),
        (
            "cfg.json",
            '{"estimator": "batch", "config": {"solver": {"earth_model": "round"}}}',
            "[solver] earth_model = 'round' is not one of 'wgs84', 'flat'",
        ),
    ],
)
def test_bad_config_value_gives_one_line_and_exit_1(
    name: str, text: str, expected: str, sim_log: Path, tmp_path: Path
) -> None:
    cfg = tmp_path / name
    cfg.write_text(text)
    proc = run("smooth", str(sim_log), "-c", str(cfg), "-q", check=False)
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert lines == [f"gtsam-dvl: error: {cfg}: {expected}"], proc.stderr
    print(lines[0])


@pytest.fixture(scope="module")
def short_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """paper-2d cut to 350 s (150 s static, speed-up, two surges): a few seconds per estimator."""
    import copy

    from gtsam_dvl.io.writer import write_log
    from gtsam_dvl.sim import simulate
    from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict

    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = raw["segments"][:4]
    raw["segments"][0]["duration_s"] = 150.0
    path = tmp_path_factory.mktemp("cli_short") / "short.mcap"
    write_log(path, simulate(scenario_from_dict(raw, "paper-2d-short"), 5))
    return path


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["ekf", "online"])
def test_effective_config_reads_back_with_c(mode: str, short_log: Path, tmp_path: Path) -> None:
    """Smooth with a non-default TOML, read back the config.json written with the result with -c: the same
    configuration and the same estimates."""
    from gtsam_dvl.io.storage.sources import open_source

    toml = tmp_path / "cfg.toml"
    toml.write_text(
        '[dvl]\nmodel = "teledyne-pathfinder"\nrobust = "huber"\nhuber_k = 2.0\n'
        "[priors]\nscale_sigma = 0.3\nmounting_tolerance_deg = 0.8\n"
        "[online]\nwindow_s = 8.0\n[online.relinearization]\nscale = 0.01\n"
        "[ekf]\nmin_calibration_speed_m_s = 0.3\ncalibration_speed_sigmas = 4.0\n"
    )

    def smooth_with(config: Path, name: str) -> Path:
        """The log smoothed in this mode with the configuration file config: the result name.mcap (returned)
        and the summary name.json in tmp_path."""
        result = tmp_path / f"{name}.mcap"
        summary = tmp_path / f"{name}.json"
        run(
            "smooth",
            str(short_log),
            "--mode",
            mode,
            "-c",
            str(config),
            "-o",
            str(result),
            "--summary",
            str(summary),
            "-q",
        )
        return result

    first = smooth_with(toml, "first")
    effective = tmp_path / "config.json"
    effective.write_bytes(open_source(first).attachments["config.json"][1])
    written = json.loads(effective.read_text())
    assert (
        written["config"]["dvl"]["huber_k"] == 2.0
        and written["config"]["ekf"]["calibration_speed_sigmas"] == 4.0
    )
    assert written["config"]["online"]["window_s"] == 8.0
    assert written["config"]["online"]["relinearization"]["scale"] == 0.01
    # null in JSON, read back as None
    assert written["config"]["alignment"]["initial_attitude_deg"] is None
    # the DVL preset's values, the explicit scale sigma over its scale accuracy, the mounting tolerance
    assert written["config"]["dvl"]["model"] == "teledyne-pathfinder"
    assert (
        written["config"]["dvl"]["default_noise_m_s"] == 0.008
        and written["config"]["priors"]["scale_sigma"] == 0.3
    )
    assert written["config"]["priors"]["misalignment_sigma_deg"] == [0.8, 0.8, 0.8]
    again = smooth_with(effective, "again")
    assert json.loads(open_source(again).attachments["config.json"][1]) == written
    s1, s2 = (json.loads((tmp_path / f"{n}.json").read_text()) for n in ("first", "again"))
    for key in ("scale", "misalignment_deg", "gyro_bias_deg_per_h", "accel_bias_ug"):
        assert s1[key] == s2[key], key
    np.testing.assert_array_equal(
        read_odometry(first, "/gtsam_dvl/odometry")[1],
        read_odometry(again, "/gtsam_dvl/odometry")[1],
    )
    # and the non-default values took effect: the defaults give another estimate
    run("smooth", str(short_log), "--mode", mode, "--summary", str(tmp_path / "default.json"), "-q")
    assert json.loads((tmp_path / "default.json").read_text())["scale"] != s1["scale"]


# ----- help, flags and scenario lists -----------------------------------------------------------------------------
def test_help_shows_flags_as_flags_and_lists_the_scenarios() -> None:
    from gtsam_dvl.sim.scenario import list_builtin_scenarios

    text = run("smooth", "--help").stdout
    assert "<bool>" not in text
    assert re.search(r"^\s+--salvage\s+Recover", text, re.M) and re.search(
        r"^\s+--strict\s+Exit", text, re.M
    )
    assert re.search(r"^\s+-q, --quiet\s+No progress bars", text, re.M)
    # the help wraps at hyphens ("straight-" at a line's end, "transect" on the next): joined back
    sim_help = " ".join(re.sub(r"-\n\s*", "-", run("simulate", "--help").stdout).split())
    for name in list_builtin_scenarios():
        assert name in sim_help


def test_debug_is_accepted_after_the_command(tmp_path: Path) -> None:
    plain = run("info", str(tmp_path / "missing.mcap"), check=False)
    assert plain.returncode == 1 and "Traceback" not in plain.stderr
    after = run("info", str(tmp_path / "missing.mcap"), "--debug", check=False)
    before = run("--debug", "info", str(tmp_path / "missing.mcap"), check=False)
    for proc in (after, before):
        assert (
            proc.returncode == 1
            and "Traceback" in proc.stderr
            and "no such file or directory" in proc.stderr
        )


@pytest.mark.slow
def test_io_dvlc_refuses_outputs_it_cannot_write_and_smooth_says_what_it_wrote(
    sim_log: Path, tmp_path: Path
) -> None:
    proc = run(
        "smooth", str(sim_log), "--mode", "io-dvlc", "-o", str(tmp_path / "r.mcap"), check=False
    )
    assert proc.returncode == 1 and proc.stderr.count("\n") == 1
    assert (
        "--mode io-dvlc estimates the calibration only" in proc.stderr
        and not (tmp_path / "r.mcap").exists()
    )
    out = run("smooth", str(sim_log), "--mode", "ekf", "-q").stdout
    assert "wrote nothing (give -o RESULT.mcap" in out


def test_info_prints_origin_mounting_rates_and_gaps(sim_log: Path) -> None:
    out = run("info", str(sim_log)).stdout
    assert "map origin: lat 30.0000000 deg, lon 114.0000000 deg, height -100.00 m" in out
    assert (
        "mounting (base_link <- sensor, roll/pitch/yaw deg): IMU +0.00 +0.00 +0.00, DVL +0.00 +0.00 +0.00"
        in out
    )
    assert (
        "rates: IMU 100.0 Hz, DVL 1.00 Hz" in out
        and "gaps: none" in out
        and "stamps: first DVL" in out
    )
    assert re.search(r"truth: \d\.\d{3} km travelled in 2040 s; height in map from [-+]\d", out)
