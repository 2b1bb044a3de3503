"""Water track and altitude through a log file: the message's velocity_mode, altitude and per-beam validity written
and decoded as simulated, a separate water-track twist topic (--dvl-water-topic) merged back in stamp order, the
simulated current read back into the truth."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.reader import read_log, read_topic
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import water_dive_raw


@pytest.fixture(scope="module")
def water_log() -> LogData:
    """The water dive with the per-beam noise model and beam dropouts (some water-track pings lose a beam)."""
    raw = water_dive_raw("beam", noise_m_s=0.02, dropout_beam_prob=0.1)
    return simulate(scenario_from_dict(raw, "water"), 4)


@pytest.fixture(scope="module")
def written(water_log: LogData, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("water") / "water.mcap"
    write_log(path, water_log)
    return path


def test_velocity_mode_altitude_and_beams_round_trip(water_log: LogData, written: Path) -> None:
    sim, back = water_log.dvl, read_log(written).dvl
    assert sim.water_track is not None and sim.altitude is not None and sim.beams is not None
    wt = sim.water_track
    # beams lost in both modes
    assert 20 < wt.sum() < len(wt) - 20 and (~sim.beams.valid[~wt]).any()
    msgs = [m for _, m in read_topic(written, "/dvl/data")]
    assert [m.velocity_mode for m in msgs] == [2 if w else 1 for w in wt]
    # a water-track ping's velocity is written (relative to the water), its measuring beams reported good
    water_beams = np.array([m.beam_quality for m in msgs])[wt] > 0
    assert np.array_equal(water_beams, np.isfinite(sim.beams.v[wt]))
    assert all(np.isnan(m.speed_gnd) for m, w in zip(msgs, wt, strict=True) if w)  # not over ground
    assert back.water_track is not None and back.altitude is not None and back.beams is not None
    assert np.array_equal(back.water_track, wt) and np.array_equal(back.valid, sim.valid)
    assert np.array_equal(back.d_v, sim.d_v, equal_nan=True)
    # a water-track velocity wherever three beams measured
    assert np.array_equal(
        np.isfinite(back.d_v[wt]).all(axis=1), np.isfinite(sim.beams.v[wt]).sum(axis=1) >= 3
    )
    assert (
        np.array_equal(back.altitude, sim.altitude, equal_nan=True)
        and np.isnan(back.altitude[wt]).all()
    )
    # valid over ground: none of a water-track ping's
    assert np.array_equal(back.beams.valid, sim.beams.valid)
    # float32 in the message
    assert np.allclose(back.beams.v, sim.beams.v, rtol=0, atol=1e-6, equal_nan=True)
    assert np.allclose(back.d_cov, sim.d_cov, rtol=1e-9, atol=1e-15, equal_nan=True)


def test_current_truth_read_back(water_log: LogData, written: Path) -> None:
    truth, back = water_log.truth, read_log(written).truth
    assert truth is not None and back is not None and truth.n_c is not None and back.n_c is not None
    # from the metadata's [current] at the truth's depth
    assert np.abs(back.n_c - truth.n_c).max() < 1e-9


def test_altitude_not_positive_is_unknown(water_log: LogData, tmp_path: Path) -> None:
    altitude = np.full(len(water_log.dvl), 12.5)
    altitude[:4] = [0.0, -1.0, np.nan, 3.0]
    path = tmp_path / "alt.mcap"
    write_log(
        path,
        dataclasses.replace(water_log, dvl=dataclasses.replace(water_log.dvl, altitude=altitude)),
    )
    back = read_log(path).dvl.altitude
    assert back is not None
    assert np.array_equal(back[:5], [np.nan, np.nan, np.nan, 3.0, 12.5], equal_nan=True)


def test_separate_water_topic_is_merged(water_log: LogData, tmp_path: Path) -> None:
    sim = water_log.dvl
    assert sim.water_track is not None and sim.altitude is not None
    wt = sim.water_track
    path = tmp_path / "split.mcap"
    write_log(path, water_log, dvl_water_topic="/dvl/water")
    bottom_only = read_log(path).dvl
    assert len(bottom_only) == (~wt).sum() and bottom_only.water_track is None
    back = read_log(path, dvl_water_topic="/dvl/water").dvl
    assert back.water_track is not None and back.altitude is not None and back.beams is not None
    assert np.array_equal(back.t, sim.t) and np.array_equal(back.water_track, wt)
    assert np.array_equal(back.valid, sim.valid) and np.array_equal(
        back.d_v, sim.d_v, equal_nan=True
    )
    # the twist's
    assert np.allclose(back.d_cov[wt], sim.d_cov[wt], rtol=1e-9, atol=1e-15, equal_nan=True)
    assert np.array_equal(back.altitude, sim.altitude, equal_nan=True)
    # the twist has no beams
    assert not back.beams.valid[wt].any() and np.isnan(back.beams.v[wt]).all()
    for topic, message in (
        ("/dvl/none", "--dvl-water-topic"),
        ("/imu/data_raw", "water-track topics must be"),
    ):
        with pytest.raises(GtsamDvlError, match=message) as exc:
            read_log(path, dvl_water_topic=topic)
        assert "\n" not in str(exc.value)


def test_cli_reads_the_water_topic(water_log: LogData, tmp_path: Path) -> None:
    from gtsam_dvl.app.cli import app

    path = tmp_path / "split.mcap"
    write_log(path, water_log, dvl_water_topic="/dvl/water")
    wt = water_log.dvl.water_track
    assert wt is not None
    out = CliRunner().invoke(app, ["info", str(path), "--dvl-water-topic", "/dvl/water"])
    assert out.exit_code == 0, out.output
    assert (
        f"DVL {len(wt)} msgs" in out.output
        and f"water track (velocity relative to the water): {wt.sum()}" in out.output
    )
    assert "DVL altitude" in out.output
