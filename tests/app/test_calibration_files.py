"""`smooth --calibration-out` writes a vehicle's calibration file, `smooth --calibration` reads it as the prior of
the next dive, inflated for the days between them, and the verdict is in the summary; a missing folder, another
vehicle's file and io-dvlc are one-line errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from typer.testing import CliRunner

from gtsam_dvl.app.cli import app
from gtsam_dvl.core.calibration import iso_date
from gtsam_dvl.io.calibration_file import read_calibration
from gtsam_dvl.io.result_writer import file_sha256
from gtsam_dvl.io.writer import write_log
from tests.support.calibration import MOVING
from tests.support.scenarios import simulate_variant

T0_S = 1_790_000_000  # 2026-09-21
DAY_S = 86400


@pytest.fixture(scope="module")
def dives(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two dives of one vehicle (a folder auv-3), ten days apart, the same truth calibration."""
    folder = tmp_path_factory.mktemp("fleet") / "auv-3"
    folder.mkdir()
    paths = (folder / "dive1.mcap", folder / "dive2.mcap")
    for k, path in enumerate(paths):
        write_log(path, simulate_variant(3 + k, segments=MOVING, t0_s=T0_S + 10 * DAY_S * k))
    return paths


def cli(*args: str | Path) -> Any:
    return CliRunner().invoke(app, [str(a) for a in args])


def test_round_trip_out_then_in(dives: tuple[Path, Path], tmp_path: Path) -> None:
    first, second = dives
    cal1 = tmp_path / "auv.toml"
    out = cli("smooth", first, "--mode", "ekf", "--calibration-out", cal1, "-q")
    assert out.exit_code == 0, out.stderr
    assert f"wrote {cal1}" in out.stdout
    c1 = read_calibration(cal1)
    assert c1.vehicle == "auv-3" and c1.method == "smooth" and c1.date == iso_date(T0_S * 10**9)
    assert [(s.path, s.sha256) for s in c1.sources] == [(str(first), file_sha256(first))]
    assert set(c1.states) == {
        "scale",
        "misalignment",
    }  # the log's configuration ("paper") has no time offset

    # the second dive with the first's calibration as its prior, written back in place (read first, then replaced)
    summary = tmp_path / "s.json"
    out = cli(
        "smooth",
        second,
        "--mode",
        "ekf",
        "--calibration",
        cal1,
        "--calibration-out",
        cal1,
        "--summary",
        summary,
        "-q",
    )
    assert out.exit_code == 0, out.stderr
    assert "prior of scale, misalignment: auv-3's calibration of 2026-09-21" in out.stdout
    s = json.loads(summary.read_text())
    infl = s["info"]["calibration_prior"]["inflation"]
    assert infl["days"] == pytest.approx(10.0, abs=0.01)
    # the default inflation_per_day
    assert infl["variance_factor"] == pytest.approx(1.0 + 0.01 * infl["days"])
    np.testing.assert_allclose(
        s["info"]["calibration_prior"]["cov"],
        c1.block(["scale", "misalignment"]) * infl["variance_factor"],
        rtol=1e-12,
    )
    check = s["calibration_check"]
    assert check["moved"] is False and check["verdict"].startswith(
        "consistent with auv-3's calibration"
    )
    # both dives: the log's "paper"
    assert not any("another configuration" in n for n in s["health"]["notes"])
    c2 = read_calibration(cal1)
    assert [src.path for src in c2.sources] == [str(first), str(second)]
    assert c2.date == iso_date((T0_S + 10 * DAY_S) * 10**9)
    for name in (
        "scale",
        "misalignment",
    ):  # two dives know more than one, even after ten days' inflation
        assert np.all(c2.sigma(name) < c1.sigma(name)), name


def test_refused_in_one_line(dives: tuple[Path, Path], tmp_path: Path) -> None:
    first, _ = dives
    out = cli("smooth", first, "--calibration-out", tmp_path / "missing" / "auv.toml")
    assert (
        out.exit_code == 1
        and "no folder" in out.stderr
        and len(out.stderr.strip().splitlines()) == 1
    )
    other = tmp_path / "other.toml"
    assert (
        cli(
            "smooth", first, "--mode", "ekf", "--calibration-out", other, "--vehicle", "auv-9", "-q"
        ).exit_code
        == 0
    )
    out = cli("smooth", first, "--calibration", other, "--vehicle", "auv-3", "-q")
    assert out.exit_code == 1 and "a calibration of vehicle 'auv-9', not of 'auv-3'" in out.stderr
    out = cli("smooth", first, "--mode", "io-dvlc", "--calibration", other, "-q")
    assert out.exit_code == 1 and "io-dvlc takes no --calibration" in out.stderr
    out = cli("smooth", first, "--calibration", tmp_path / "nothing.toml", "-q")
    assert out.exit_code == 1 and "no such calibration file" in out.stderr


def test_live_takes_the_calibration(dives: tuple[Path, Path], tmp_path: Path) -> None:
    """`live --calibration`: the online estimator's prior, the verdict in the health it prints."""
    from gtsam_dvl.io.calibration_file import write_calibration
    from gtsam_dvl.io.reader import read_log
    from tests.support.calibration import calibration_at_truth

    first, _ = dives
    path = write_calibration(tmp_path / "auv.toml", calibration_at_truth(read_log(first)))
    out = cli(
        "live", first, "--speed", "max", "--port", "0", "--exit-when-done", "--calibration", path
    )
    assert out.exit_code == 0, out.output
    assert "consistent with auv-7's calibration of 2023-11-01" in out.output


def test_montecarlo_run_takes_the_calibration(tmp_path: Path) -> None:
    """A Monte Carlo run (campaign/montecarlo.run_seed, a worker's task) with a calibration file's data: on a log
    at rest every estimator ends at the file's sigma, inflated for the days to the simulated log's date."""
    from gtsam_dvl.app.calibration_files import calibration_data
    from gtsam_dvl.app.campaign.montecarlo import run_seed
    from gtsam_dvl.io.calibration_file import write_calibration
    from tests.support.calibration import STATIC, calibration_at_truth
    from tests.support.scenarios import scenario_raw

    raw = scenario_raw(segments=STATIC, t0_s=T0_S)
    log = simulate_variant(1, segments=STATIC, t0_s=T0_S)
    cal = calibration_at_truth(log)  # dated 2023-11-01, 1055 days before the log: variances x 11.55
    data = calibration_data(write_calibration(tmp_path / "auv.toml", cal))
    out = run_seed(raw, 1, ["ekf"], None, "static", data)
    sigma_ppm = out["estimators"]["ekf"]["sigma"][0]
    factor = 1.0 + 0.01 * cal.days_before(iso_date(T0_S * 10**9))
    assert sigma_ppm == pytest.approx(cal.sigma("scale")[0] * 1e6 * np.sqrt(factor), rel=0.01)
