"""The chunked simulation (sim/stream.py) and the streaming MCAP writer (io/writer.py LogStreamWriter): the
chunked log is simulate()'s bit for bit, whatever the chunk length, and its file is write_log's byte for byte."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import LogStreamWriter, imu_rate_hz, write_log, write_log_stream
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario, scenario_from_dict
from gtsam_dvl.sim.stream import ChunkedSimulation, simulate_chunked
from tests.support.logs import log_arrays
from tests.support.scenarios import scenario_raw

SCENARIOS = Path(__file__).resolve().parents[2] / "data" / "scenarios"


def _small(variant: str) -> Scenario:
    """45 s at 100 Hz with every stream simulate() has: 2 Hz DVL, depth, GNSS, and per variant
    "beam": the per-beam noise model with dropouts and outliers, walking biases, stamps 0.25 s late, fixes from 3 s;
    "field": the velocity model with dropouts and outliers, a z-down DVL with lever arm and stamps 0.3 s early, and
    the map origin from the first fix (origin_in_log = false);
    "water": "field" in a sheared, varying current over a seafloor that the descent brings into bottom-track range
    and the ascent takes out of it (water-track pings before and after)."""
    raw = scenario_raw(
        rates={"dvl_hz": 2.0},
        segments=[
            {"kind": "static", "duration_s": 5.0},
            {"kind": "level", "duration_s": 10.0, "speed_end_m_s": 1.5},
            {"kind": "descent", "duration_s": 10.0, "peak_vertical_speed_m_s": 0.3},
            {"kind": "turn", "duration_s": 10.0, "heading_change_deg": 90.0, "bank_deg": 10.0},
            {"kind": "ascent", "duration_s": 10.0, "peak_vertical_speed_m_s": 0.3},
        ],
        depth={"rate_hz": 5.0, "noise_m": 0.05, "bias_m": 0.1, "lever_arm_m": [0.1, 0.0, 0.2]},
    )
    if variant == "beam":
        raw["dvl"].update(
            noise_model="beam", dropout_ping_prob=0.05, dropout_beam_prob=0.1, outlier_prob=0.05
        )
        raw["imu"].update(
            gyro_bias_walk_deg_per_h_per_sqrt_h=0.01, accel_bias_walk_micro_g_per_sqrt_h=20.0
        )
        raw["rates"]["dvl_time_offset_s"] = -0.25
        raw["gnss"] = {"rate_hz": 1.0, "max_depth_m": 1000.0, "start_s": 3.0}
    else:
        raw["dvl"].update(dropout_ping_prob=0.05, outlier_prob=0.05)
        raw["rates"]["dvl_time_offset_s"] = 0.3
        raw["mounting"] = {"dvl_rpy_deg": [180.0, 0.0, 0.0], "dvl_lever_arm_m": [0.5, 0.0, -0.2]}
        raw["dvl"]["face_axis"] = [0.0, 0.0, 1.0]
        raw["gnss"] = {"rate_hz": 1.0, "max_depth_m": 1000.0, "origin_in_log": False}
    # the start 100 m down, the descent 1.4 m: lock from its middle to the ascent's middle
    if variant == "water":
        raw["dvl"]["bottom_range_m"] = 20.0
        raw["seafloor"] = {"depth_m": 100.0 + 20.0 + 0.7}
        raw["current"] = {
            "surface_m_s": [0.4, 0.2],
            "reference_m_s": [0.1, -0.2],
            "reference_depth_m": 200.0,
            "variation_m_s": [0.05, 0.05],
            "variation_period_s": 30.0,
        }
    return scenario_from_dict(raw, f"small-{variant}")


def _assert_same_log(a: LogData, b: LogData, fields: tuple[str, ...] = ("source",)) -> None:
    arr_a, arr_b = log_arrays(a), log_arrays(b)
    assert arr_a.keys() == arr_b.keys()
    for k, v in arr_a.items():
        assert v.shape == arr_b[k].shape and v.dtype == arr_b[k].dtype, k
        assert np.array_equal(v, arr_b[k], equal_nan=True), k  # bit for bit (NaN where NaN)
    assert a.metadata == b.metadata
    for f in ("t0_ns", "origin", "true_calibration", "true_imu_bias", "segments", *fields):
        assert getattr(a, f) == getattr(b, f), f


@pytest.mark.parametrize(
    ("variant", "chunk_s"),
    [
        ("beam", 7.7),
        pytest.param("beam", 0.13, marks=pytest.mark.slow),
        pytest.param("field", 0.37, marks=pytest.mark.slow),
        ("field", 60.0),
        ("water", 0.37),
        ("water", 7.7),
    ],
)
def test_chunked_log_is_simulate_bit_for_bit(variant: str, chunk_s: float) -> None:
    """0.13 s and 0.37 s chunks hold zero or one ping, depth sample and candidate fix, and one or a few truth
    stamps (the single-row paths); 60 s is one chunk for the whole run."""
    sc = _small(variant)
    ref = simulate(sc, 11)
    assert ref.gnss is not None and ref.dvl.beams is not None
    # the streams are there
    assert len(ref.gnss) > 10 and np.any(~ref.dvl.valid) and np.any(~ref.dvl.beams.valid)
    if variant == "water":
        assert (
            ref.dvl.water_track is not None and ref.truth is not None and ref.truth.n_c is not None
        )
        assert 0 < ref.dvl.water_track.sum() < len(ref.dvl) - 10
    _assert_same_log(simulate_chunked(sc, 11, chunk_s=chunk_s), ref)


@pytest.mark.slow
def test_chunked_paper3d_without_white_noise(
    sim_paper3d: Scenario, sim_paper3d_clean: LogData
) -> None:
    _assert_same_log(
        simulate_chunked(sim_paper3d, 7, white_noise=False, chunk_s=600.0), sim_paper3d_clean
    )


@pytest.mark.slow
def test_chunked_survey_at_200hz() -> None:
    """survey-24h's start (static, the calibration manoeuvres and a turn: 870 s of 200 Hz / 5 Hz) in chunks that
    cut samples and pings anywhere."""
    raw = tomllib.loads((SCENARIOS / "survey-24h.toml").read_text())
    raw["segments"] = raw["segments"][:4] + raw["segments"][5:6]
    sc = scenario_from_dict(raw, "survey-cut")
    _assert_same_log(simulate_chunked(sc, 7, chunk_s=97.3), simulate(sc, 7))


@pytest.mark.slow
def test_streamed_file_is_write_log_file(tmp_path: Path) -> None:
    """write_log_stream of ChunkedSimulation writes write_log's file of simulate()'s log, byte for byte, and read_log
    reads both alike; the same seed gives the same bytes again, another seed other bytes."""
    for variant, chunk_s in (("beam", 7.7), ("field", 0.37)):
        sc = _small(variant)
        ref_path, path = tmp_path / f"{variant}-ref.mcap", tmp_path / f"{variant}.mcap"
        write_log(ref_path, simulate(sc, 5))
        counts = write_log_stream(path, ChunkedSimulation(sc, 5, chunk_s=chunk_s))
        assert path.read_bytes() == ref_path.read_bytes()
        a, b = read_log(ref_path), read_log(path)
        _assert_same_log(b, a, ())  # all but the source: the file names differ
        assert a.depth is not None and a.gnss is not None and a.truth is not None
        assert len(a.depth) == counts["depth"] and len(a.gnss) == counts["gnss"] > 0
        assert (len(a.imu), len(a.dvl), len(a.truth)) == (
            counts["imu"],
            counts["dvl"],
            counts["truth"],
        )
        assert len(a.imu) == 4501 and len(a.truth) == 451
    again = tmp_path / "again.mcap"
    write_log_stream(again, ChunkedSimulation(sc, 5, chunk_s=10.0))
    assert again.read_bytes() == path.read_bytes()
    write_log_stream(again, ChunkedSimulation(sc, 6, chunk_s=10.0))
    assert again.read_bytes() != path.read_bytes()


def test_streamed_water_log_is_write_log_file(tmp_path: Path) -> None:
    """With water track (velocity mode, altitude) and a current, the streamed file is write_log's, byte for byte."""
    sc = _small("water")
    ref_path, path = tmp_path / "ref.mcap", tmp_path / "streamed.mcap"
    write_log(ref_path, simulate(sc, 5))
    write_log_stream(path, ChunkedSimulation(sc, 5, chunk_s=7.7))
    assert path.read_bytes() == ref_path.read_bytes()
    back = read_log(path)
    assert (
        back.dvl.water_track is not None and back.truth is not None and back.truth.n_c is not None
    )


def test_parts_are_chunks() -> None:
    """The parts cover the run once, in chunks of chunk_s (a last one-sample chunk joins the one before), with
    next_t no later than any later part's first stamp."""
    sim = ChunkedSimulation(_small("field"), 3, chunk_s=10.0)
    parts = list(sim.parts())
    sizes = [len(p.imu) for p, _ in parts]
    assert sizes == [1000, 1000, 1000, 1000, 501]
    assert sum(len(p.dvl) for p, _ in parts) == sim.n_pings
    for (_, next_t), (later, _) in zip(parts[:-1], parts[1:], strict=True):
        assert next_t is not None and next_t <= min(later.imu.t[0], later.dvl.t[0])
    assert parts[-1][1] is None


def test_imu_rate_hz_is_write_logs_median() -> None:
    rng = np.random.default_rng(1)
    for n in (2, 3, 1000, 1001):
        t = np.cumsum(0.005 + rng.choice([-1e-9, 0.0, 2e-9], n))
        expected = 1.0 / float(np.median(np.diff(t)))
        for cut in ([], [1], [n // 2], sorted({1, n // 3, n - 1})):
            assert imu_rate_hz(np.split(t, cut)) == expected
    assert imu_rate_hz([np.array([0.0])]) == 0.0


def test_stream_writer_refuses_a_part_before_next_t(tmp_path: Path) -> None:
    sim = ChunkedSimulation(_small("beam"), 3, chunk_s=10.0)
    (p0, next_t), (p1, _) = list(sim.parts())[:2]
    path = tmp_path / "x.mcap"
    with pytest.raises(GtsamDvlError, match="before the previous part's next_t"):
        with LogStreamWriter(
            path, sim.head, t_first=sim.t_first, imu_rate_hz=imu_rate_hz(sim.imu_stamps())
        ) as w:
            w.write(p0, next_t)
            w.write(p0, next_t)
    assert not path.exists() and not list(tmp_path.iterdir())  # nothing left behind


def test_bad_chunk_and_no_fix() -> None:
    with pytest.raises(GtsamDvlError, match="chunk length"):
        ChunkedSimulation(_small("beam"), 1, chunk_s=0.0)
    raw = dict(_small("field").raw)
    raw["gnss"] = {**raw["gnss"], "max_depth_m": 0.001}  # never at the surface
    sc = scenario_from_dict(raw, "no-fix")
    with pytest.raises(GtsamDvlError, match="needs at least one fix") as whole:
        simulate(sc, 1)
    with pytest.raises(GtsamDvlError, match="needs at least one fix") as chunked:
        ChunkedSimulation(sc, 1, chunk_s=10.0)
    assert str(chunked.value) == str(whole.value)


def test_cli_simulate_streams_long_scenarios(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`gtsam-dvl simulate` (commands.simulate_to_file) chunks runs above STREAM_ABOVE_SAMPLES: the same file and
    the same summary as the in-memory path."""
    from gtsam_dvl.app import commands

    monkeypatch.setattr("gtsam_dvl.sim.scenario.load_scenario", lambda name: _small("field"))
    results = []
    for limit, name in ((10**12, "whole.mcap"), (0, "chunked.mcap")):
        monkeypatch.setattr(commands, "STREAM_ABOVE_SAMPLES", limit)
        results.append(
            commands.simulate_to_file("small", tmp_path / name, seed=4, show_progress=False)
        )
    whole, chunked = results
    assert chunked.path.read_bytes() == whole.path.read_bytes()
    assert (chunked.duration_s, chunked.n_imu, chunked.n_dvl) == (
        whole.duration_s,
        whole.n_imu,
        whole.n_dvl,
    )
    assert chunked.distance_m == pytest.approx(whole.distance_m, rel=1e-12)
