"""Segment classification from the IMU alone (gtsam_dvl/analysis/segments.py): static, Type I (constant attitude
with a specific-force rate, and its body axis), turns (Type II) and cruise, against the simulated truth.

The truth used here never comes from the classifier's inputs: segment times come from the scenario definition
(data/scenarios/paper-3d.toml, or the small scenarios below), turning from the simulator's noise-free body rate
(TruthData.b_omega). Every test prints what it measured.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.segments import MIN_SEGMENT_S, TURN_RATE_DEG_S, classify_log
from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import Scenario, load_scenario, scenario_from_dict

Row = tuple[float, float, str, str]

# the body axis of a Type-I segment's specific-force rate by the segment's kind in paper-3d
# (data/scenarios/paper-3d.toml; its segments, in tests/sim/test_scenario.py's Table 1): level, surge along body x;
# descent and ascent by ballast, vertical, i.e. body z at roll 3 deg, pitch 0
TYPE1_AXIS = {"level": "x", "descent": "z", "ascent": "z"}
# Type-I boundaries: the detector slides 5 s windows over 1 s means, and the C2 blends at a segment's ends keep
# the specific-force rate below its threshold for a moment: measured within 2 s (paper-3d: 1 s)
TYPE1_TOL_S = 2.0
# a detected turn is where the 1 s mean gyro rate exceeds TURN_RATE_DEG_S; the truth's own crossing of that rate
# (noise-free body rate at 10 Hz) is within the 1 s window quantisation, plus a truth sample
TURN_TOL_S = 1.1


def _rows(segments: list[Any]) -> list[Row]:
    """(start_s, end_s, kind, type) of classify_log's rows (Segment values, or the dicts of older versions)."""
    out = []
    for s in segments:
        if isinstance(s, dict):
            out.append((float(s["start_s"]), float(s["end_s"]), str(s["kind"]), str(s["type"])))
        else:
            out.append((float(s.start_s), float(s.end_s), str(s.kind), str(s.type)))
    return out


def _scenario(segments: list[dict[str, Any]], speed0: float = 0.0) -> Scenario:
    """Paper sensors (Table 1), latitude 30 deg, a flat seafloor 60 m below the start."""
    return scenario_from_dict(
        {
            "origin": {"lat_deg": 30.0, "lon_deg": 114.0, "height_m": -100.0},
            "initial": {"roll_deg": 3.0, "yaw_deg": 10.0, "speed_m_s": speed0},
            "imu": {
                "gyro_bias_deg_per_h": 0.01,
                "accel_bias_micro_g": 50.0,
                "gyro_noise_deg_per_h_per_sqrt_hz": 0.1,
                "accel_noise_micro_g_per_sqrt_hz": 10.0,
            },
            "dvl": {"noise_m_s": 0.02, "altitude_m": 60.0},
            "segments": segments,
        },
        name="segments-test",
    )


# 0-120 static, 120-140 level acceleration to 2 m/s (Type I, x), 140-180 straight, 180-220 a 90 deg right turn,
# 220-250 straight, 250-253 a 2 deg heading blip, 253-283 straight, 283-323 ascent (Type I, z)
SHORT = [
    {"kind": "static", "duration_s": 120.0},
    {"kind": "level", "duration_s": 20.0, "speed_end_m_s": 2.0},
    {"kind": "straight", "duration_s": 40.0},
    {"kind": "turn", "duration_s": 40.0, "heading_change_deg": -90.0},
    {"kind": "straight", "duration_s": 30.0},
    {"kind": "turn", "duration_s": 3.0, "heading_change_deg": 2.0},
    {"kind": "straight", "duration_s": 30.0},
    {"kind": "ascent", "duration_s": 40.0, "peak_vertical_speed_m_s": 0.5},
]


@functools.cache
def _short_log(seed: int) -> LogData:
    return simulate(_scenario(SHORT), seed)


@functools.cache
def _paper3d_noisy() -> LogData:
    return simulate(load_scenario("paper-3d"), 7)


def _truth_turning(log: LogData) -> list[tuple[float, float]]:
    """Intervals where the simulator's noise-free body rate exceeds the classifier's turn threshold."""
    assert log.truth is not None
    fast = np.degrees(np.linalg.norm(log.truth.b_omega, axis=1)) > TURN_RATE_DEG_S
    edges = np.flatnonzero(np.diff(fast.astype(int)))
    t = log.truth.t
    starts = [t[i + 1] for i in edges if not fast[i]]
    ends = [t[i] for i in edges if fast[i]]
    if fast[0]:
        starts.insert(0, t[0])
    if fast[-1]:
        ends.append(t[-1])
    return [(float(a), float(b)) for a, b in zip(starts, ends, strict=True)]


def _square_turns(sc: Scenario) -> list[tuple[float, float]]:
    """The turns of the scenario's square segments, from the scenario definition."""
    turns = []
    for seg in sc.segments:
        if seg.kind != "square":
            continue
        t = seg.start_s
        for _ in range(seg.sides):
            for part in ("turn", "leg") if seg.turn_first else ("leg", "turn"):
                d = seg.turn_duration_s if part == "turn" else seg.leg_duration_s
                if part == "turn":
                    turns.append((t, t + d))
                t += d
    return turns


def _check_covering(rows: list[Row], log: LogData) -> None:
    """Rows are contiguous from the first IMU sample, none shorter than MIN_SEGMENT_S (short blips are folded
    into their neighbour), no two neighbours of the same kind, types as the paper's: I, II or -."""
    assert rows[0][0] == pytest.approx(log.imu.t[0], abs=1e-9)
    for prev, row in zip(rows, rows[1:], strict=False):
        assert row[0] == prev[1], (prev, row)
        assert row[2] != prev[2] or row[2].startswith("type1"), (prev, row)
    for s, e, kind, typ in rows:
        assert e - s >= MIN_SEGMENT_S, (s, e, kind)
        expected = "I" if kind.startswith("type1") else "II" if kind == "turn" else "-"
        assert typ == expected, (kind, typ)
        assert kind in ("static", "turn", "cruise") or kind.startswith(
            "type1 (specific-force rate along body "
        )


def _print(tag: str, rows: list[Row]) -> None:
    print(f"\n{tag}: " + "; ".join(f"{s:.0f}-{e:.0f} {k}" for s, e, k, _ in rows))


# ----- paper-3d ---------------------------------------------------------------------------------------


@pytest.fixture(params=["clean", "noisy"])
def paper3d(request: pytest.FixtureRequest, sim_paper3d_clean: LogData) -> LogData:
    return sim_paper3d_clean if request.param == "clean" else _paper3d_noisy()


def test_paper3d_static_and_type1_segments_match_the_scenario(paper3d: LogData) -> None:
    """Static until at most 5 s (STATIC_MARGIN_S) before the first manoeuvre at 600 s and never past it (measured
    598 s); then exactly the five Type-I segments of the scenario, in order, each boundary within 2 s of the
    scenario's and the specific-force axis right (measured: 598-660 x, 660-719 z, 719-749 x, 1969-2001 x,
    2001-2061 z, clean and noisy alike)."""
    rows = _rows(classify_log(paper3d))
    _print("paper-3d", rows)
    _check_covering(rows, paper3d)
    s, e, kind, _ = rows[0]
    assert kind == "static" and 595.0 <= e <= 600.0
    type1 = [r for r in rows if r[2].startswith("type1")]
    scenario_type1 = [seg for seg in paper3d.segments if seg.type == "I"]  # the scenario's rows
    assert len(type1) == len(scenario_type1) == 5
    for (s, e, kind, _), seg in zip(type1, scenario_type1, strict=True):
        ts, te = seg.start_s, seg.end_s
        assert abs(s - ts) <= TYPE1_TOL_S and abs(e - te) <= TYPE1_TOL_S, (s, e, ts, te)
        assert kind == f"type1 (specific-force rate along body {TYPE1_AXIS[seg.kind]})"


def test_paper3d_turns_are_the_square_turns(paper3d: LogData, sim_paper3d: Scenario) -> None:
    """The banked square (750-1970 s): exactly its four turns are 'turn' rows, each inside the scenario's turn
    and within 1.1 s of where the true body rate crosses 0.3 deg/s (the turn rate and the bank's roll rate ramp
    up smoothly, so the first and last 5 to 6 s of a 60 s turn are slower: measured 756-805, 1061-1109, 1366-1414,
    1670-1720 s for turns of 750-810 + 305 k s); the legs between them are cruise."""
    rows = _rows(classify_log(paper3d))
    turns = [(s, e) for s, e, kind, _ in rows if kind == "turn"]
    truth_turns = _square_turns(sim_paper3d)
    fast = _truth_turning(paper3d)
    print(
        f"\npaper-3d turns detected {turns}; scenario {truth_turns}; true rate > {TURN_RATE_DEG_S} deg/s {fast}"
    )
    assert len(turns) == len(truth_turns) == len(fast) == 4
    for (s, e), (ts, te), (fs, fe) in zip(turns, truth_turns, fast, strict=True):
        assert ts <= s < e <= te
        assert abs(s - fs) <= TURN_TOL_S and abs(e - fe) <= TURN_TOL_S, (s, e, fs, fe)
    for (_, _, kind, _), nxt in zip(rows, rows[1:], strict=False):
        if kind == "turn" and nxt[1] <= 1970.0:  # the leg after each of the first three turns
            assert nxt[2] == "cruise" and nxt[1] - nxt[0] > 200.0, nxt


# ----- small scenarios --------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2])
def test_short_log_classified_as_simulated(seed: int) -> None:
    """static 0-120, Type I (x) 120-140, straight, a 90 deg right turn 180-220, straight with a 3 s heading blip,
    ascent (Type I, z) 283-323: measured static 0-118, type1 x 118-142, cruise 142-184, turn 184-216, cruise
    216-282 (the blip, under MIN_SEGMENT_S, folded into it), type1 z 282-324."""
    log = _short_log(seed)
    rows = _rows(classify_log(log))
    _print(f"short seed {seed}", rows)
    _check_covering(rows, log)
    kinds = [k for _, _, k, _ in rows]
    assert kinds == [
        "static",
        "type1 (specific-force rate along body x)",
        "cruise",
        "turn",
        "cruise",
        "type1 (specific-force rate along body z)",
    ]
    (_, e_static, _, _), t1, _, turn, cruise, t2 = rows
    assert 115.0 <= e_static <= 120.0
    assert abs(t1[0] - 120.0) <= TYPE1_TOL_S and abs(t1[1] - 140.0) <= TYPE1_TOL_S
    assert abs(t2[0] - 283.0) <= TYPE1_TOL_S
    (fs, fe), *others = _truth_turning(log)
    assert 180.0 <= turn[0] < turn[1] <= 220.0
    assert abs(turn[0] - fs) <= TURN_TOL_S and abs(turn[1] - fe) <= TURN_TOL_S, (turn, fs, fe)
    # the 2 deg blip at 250-253 s does exceed the turn rate, but for less than MIN_SEGMENT_S
    assert len(others) == 1 and 250.0 <= others[0][0] < others[0][1] <= 253.0
    assert cruise[0] < others[0][0] and others[0][1] < cruise[1]


def test_classification_uses_the_imu_alone_and_any_time_base() -> None:
    """A real log has no truth and starts at an arbitrary time: without truth or metadata and with every stamp
    shifted by 1000.3 s, the rows are the same, shifted (to 1e-6 s)."""
    log = _short_log(1)
    ref = _rows(classify_log(log))
    dt = 1000.3
    real = dataclasses.replace(
        log,
        imu=dataclasses.replace(log.imu, t=log.imu.t + dt),
        dvl=dataclasses.replace(log.dvl, t=log.dvl.t + dt),
        truth=None,
        metadata={},
    )
    rows = _rows(classify_log(real))
    assert [r[2:] for r in rows] == [r[2:] for r in ref]
    np.testing.assert_allclose(
        [r[:2] for r in rows], np.array([r[:2] for r in ref]) + dt, atol=1e-6
    )


def test_log_starting_in_motion_has_no_static_segment() -> None:
    """At 1.5 m/s from the first sample (straight 0-60, 90 deg left turn 60-100, deceleration 100-130): no static
    row; measured cruise 0-64, turn 64-96, cruise 96-101, type1 x 101-131."""
    sc = _scenario(
        [
            {"kind": "straight", "duration_s": 60.0},
            {"kind": "turn", "duration_s": 40.0, "heading_change_deg": 90.0},
            {"kind": "level", "duration_s": 30.0, "speed_end_m_s": 1.0},
        ],
        speed0=1.5,
    )
    log = simulate(sc, 1)
    rows = _rows(classify_log(log))
    _print("moving from the start", rows)
    _check_covering(rows, log)
    assert "static" not in [k for _, _, k, _ in rows]
    assert [k for _, _, k, _ in rows] == [
        "cruise",
        "turn",
        "cruise",
        "type1 (specific-force rate along body x)",
    ]
    turn = rows[1]
    assert 60.0 <= turn[0] < turn[1] <= 100.0
    assert abs(rows[3][0] - 100.0) <= TYPE1_TOL_S


def test_rows_end_with_the_log(sim_paper3d_clean: LogData) -> None:
    """The rows cover the log, not beyond its last sample."""
    log = sim_paper3d_clean
    rows = _rows(classify_log(log))
    print(f"\nlast row ends at {rows[-1][1]} s, last IMU sample at {log.imu.t[-1]} s")
    assert rows[-1][1] <= log.imu.t[-1] + 1e-9
