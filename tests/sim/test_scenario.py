"""Scenario files: built-ins reproduce the paper's Table 1; bad files fail with one line naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.sim.scenario import list_builtin_scenarios, load_scenario, scenario_from_dict

TABLE1_3D = [
    (0, 600, "-"),
    (600, 660, "I"),
    (660, 720, "I"),
    (720, 750, "I"),
    (750, 1970, "I+II"),
    (1970, 2000, "I"),
    (2000, 2060, "I"),
]
TABLE1_2D = [(0, 600, "-"), (600, 800, "I"), (800, 2040, "I+II")]
DATA = Path(__file__).resolve().parents[2] / "data" / "scenarios"

MINIMAL = """
[origin]
lat_deg = 30.0
lon_deg = 114.0

[[segments]]
kind = "static"
duration_s = 10.0
"""


def test_builtins_listed_and_loadable() -> None:
    names = list_builtin_scenarios()
    print(names)
    assert {"paper-3d", "paper-2d", "straight-20km"} <= set(names)
    for name in names:
        sc = load_scenario(name)
        assert sc.name == name
        by_path = load_scenario(DATA / f"{name}.toml")
        assert by_path.segments == sc.segments and by_path.raw == sc.raw


@pytest.mark.parametrize(("name", "table"), [("paper-3d", TABLE1_3D), ("paper-2d", TABLE1_2D)])
def test_paper_scenarios_reproduce_table1(name: str, table: list[tuple[int, int, str]]) -> None:
    sc = load_scenario(name)
    rows = sc.segment_table()
    print(rows)
    assert [(r["start_s"], r["end_s"], r["type"]) for r in rows] == table
    kinds = [r["kind"] for r in rows]
    assert kinds[0] == "static" and "square" in kinds
    assert "descent" in kinds if name == "paper-3d" else "descent" not in kinds
    # Table 1 sensors and calibration truth, CONVENTIONS.md units and axes
    assert sc.imu.gyro_bias_deg_per_h == 0.01 and sc.imu.gyro_noise_deg_per_h_per_sqrt_hz == 0.1
    assert sc.imu.accel_bias_micro_g == 50.0 and sc.imu.accel_noise_micro_g_per_sqrt_hz == 10.0
    assert sc.dvl.noise_m_s == 0.02 and sc.dvl.scale == 0.9998
    assert sc.dvl.misalignment_deg == (-0.1, 0.2, -0.5)
    assert (sc.initial.roll_deg, sc.initial.pitch_deg, sc.initial.yaw_deg) == (3.0, 0.0, 10.0)
    assert (sc.rates.imu_hz, sc.rates.dvl_hz, sc.origin.lat_deg) == (100.0, 1.0, 30.0)


def test_straight_20km_has_calibration_manoeuvres_then_a_20km_transit() -> None:
    sc = load_scenario("straight-20km")
    rows = sc.segment_table()
    assert rows[0]["kind"] == "static" and rows[0]["end_s"] == 600.0
    assert sum(r["type"] == "I" for r in rows) >= 3
    assert any(r["kind"] == "square" for r in rows)  # Type II before the transit
    transit = [r for r in rows if r["kind"] == "straight"]
    assert len(transit) == 1 and (transit[0]["end_s"] - transit[0]["start_s"]) * 2.5 >= 20_000.0


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (lambda s: s.replace("lat_deg = 30.0\n", ""), "origin.lat_deg"),
        (lambda s: s + '\n[imu]\ngyro_bias_deg_per_h = "lots"\n', "imu.gyro_bias_deg_per_h"),
        (lambda s: s + "\n[dvl]\nnoise_sigma = 0.02\n", "dvl.noise_sigma"),
        (lambda s: s.replace('kind = "static"', 'kind = "loop"'), "segments[0].kind"),
        (lambda s: s.replace("duration_s = 10.0", "duration_s = -1.0"), "segments[0].duration_s"),
        (
            lambda s: s + '\n[[segments]]\nkind = "turn"\nduration_s = 5.0\n',
            "segments[1].heading_change_deg",
        ),
        (lambda s: s + "\n[rates]\ntruth_hz = 7.0\n", "rates.truth_hz"),
        (lambda s: s + '\n[dvl]\nnoise_model = "magic"\n', "dvl.noise_model"),
        (lambda s: s + "\n[mounting]\ndvl_rpy_deg = [0.0, 180.0]\n", "mounting.dvl_rpy_deg"),
        (lambda s: s.split("[[segments]]")[0], "segments"),
        (
            lambda s: (
                s + '\n[[segments]]\nkind = "level"\nduration_s = 5.0\nspeed_end_m_s = 1.0\n'
                '\n[[segments]]\nkind = "static"\nduration_s = 5.0\n'
            ),
            "segments[2]",
        ),
    ],
)
def test_bad_files_raise_one_line_naming_file_and_key(tmp_path: Path, edit, key: str) -> None:  # noqa: ANN001
    path = _write(tmp_path, edit(MINIMAL))
    with pytest.raises(GtsamDvlError) as info:
        load_scenario(path)
    msg = str(info.value)
    print(msg)
    assert "\n" not in msg
    assert str(path) in msg and f"'{key}'" in msg


def test_invalid_toml_and_missing_file(tmp_path: Path) -> None:
    with pytest.raises(GtsamDvlError, match="invalid TOML"):
        load_scenario(_write(tmp_path, "[origin\nlat_deg = 1"))
    with pytest.raises(GtsamDvlError, match="not found"):
        load_scenario("no-such-scenario")


def test_minimal_file_defaults(tmp_path: Path) -> None:
    sc = load_scenario(_write(tmp_path, MINIMAL))
    assert sc.name == "bad" and sc.duration_s == 10.0
    assert (
        sc.rates.imu_hz == 100.0
        and sc.dvl.scale == 1.0
        and sc.mounting.dvl_rpy_deg == (0.0, 0.0, 0.0)
    )
    assert sc.t0_ns == 1_700_000_000 * 10**9


def test_square_expands_to_its_duration() -> None:
    raw = {
        "origin": {"lat_deg": 0.0, "lon_deg": 0.0},
        "initial": {"speed_m_s": 1.0},
        "segments": [
            {
                "kind": "square",
                "leg_duration_s": 10.0,
                "turn_duration_s": 5.0,
                "sides": 3,
                "direction": "right",
                "bank_deg": 10.0,
            }
        ],
    }
    sc = scenario_from_dict(raw)
    assert sc.segment_table() == [{"start_s": 0.0, "end_s": 45.0, "kind": "square", "type": "I+II"}]
