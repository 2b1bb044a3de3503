"""Sensor presets (core/config/presets.py): every preset loads into the configuration, its values land where they
belong unless the configuration sets them, an unknown name is one line naming the known ones, the mounting tolerance
is the misalignment prior, a configuration with presets reads back from its TOML, and `gtsam-dvl presets` prints
them."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.config.presets import (
    DVL_PRESETS,
    IMU_PRESETS,
    arw_to_density,
    describe_preset,
    vrw_to_density,
)
from gtsam_dvl.core.errors import GtsamDvlError


@pytest.mark.parametrize("name", sorted(IMU_PRESETS))
def test_every_imu_preset_loads_and_fills_the_imu_section(name: str) -> None:
    preset = IMU_PRESETS[name]
    cfg = EstimatorConfig.from_dict({"imu": {"model": name}}, source="cfg.toml")
    default = EstimatorConfig()
    assert cfg.imu.model == name
    assert cfg.imu.gyro_noise_deg_per_h_rthz == preset.gyro_noise_deg_per_h_rthz
    assert cfg.imu.accel_noise_ug_rthz == preset.accel_noise_ug_rthz
    assert cfg.imu.gyro_bias_sigma_deg_per_h == preset.gyro_bias_stability_deg_per_h
    assert cfg.imu.accel_bias_sigma_ug == preset.accel_bias_stability_ug
    # an IMU preset touches nothing else
    assert cfg.dvl == default.dvl and cfg.priors == default.priors
    assert preset.sources and all(s.strip() for s in preset.sources)


@pytest.mark.parametrize("name", sorted(DVL_PRESETS))
def test_every_dvl_preset_loads_and_fills_the_dvl_section_and_the_scale_prior(name: str) -> None:
    preset = DVL_PRESETS[name]
    cfg = EstimatorConfig.from_dict({"dvl": {"model": name}}, source="cfg.toml")
    assert cfg.dvl.default_noise_m_s == preset.ping_noise_m_s
    assert cfg.priors.scale_sigma == preset.scale_accuracy
    assert cfg.dvl.correlated_sigma_m_s == preset.correlated_sigma_m_s
    assert cfg.dvl.correlated_tau_s == preset.correlated_tau_s
    # one beam of a four-beam Janus: a horizontal axis is (b1 - b2) / (2 sin(angle))
    sin = math.sin(math.radians(preset.beam_angle_deg))
    assert cfg.dvl.beam_noise_m_s * math.sqrt(2 * (2 * sin) ** -2) == pytest.approx(
        preset.ping_noise_m_s, rel=1e-5
    )
    assert 0 < preset.min_altitude_m < preset.max_altitude_m
    assert 0 < preset.scale_accuracy < 0.05 and 0.001 <= preset.ping_noise_m_s <= 0.05
    assert cfg.imu == EstimatorConfig().imu
    assert preset.sources and all(s.strip() for s in preset.sources)


def test_unit_conversions_of_datasheet_figures() -> None:
    # 0.125 deg/sqrt(h) = 0.125 deg / sqrt(3600 s) per sqrt(s) = 7.5 deg/h/sqrt(Hz)
    assert arw_to_density(0.125) == pytest.approx(0.125 / math.sqrt(3600.0) * 3600.0)
    # 0.065 ft/s/sqrt(h) (the HG1700's VRW): 3.302e-4 m/s^2/sqrt(Hz) = 33.67 micro-g/sqrt(Hz)
    assert vrw_to_density(0.065 * 0.3048) == pytest.approx(
        0.065 * 0.3048 / 60.0 / 9.80665 * 1e6, rel=1e-5
    )
    assert vrw_to_density(0.065 * 0.3048) == pytest.approx(33.67, abs=0.01)


def test_explicit_values_win_over_the_preset() -> None:
    cfg = EstimatorConfig.from_dict(
        {
            "imu": {"model": "honeywell-hg1700", "gyro_noise_deg_per_h_rthz": 2.5},
            "dvl": {"model": "teledyne-pathfinder", "default_noise_m_s": 0.015},
            "priors": {"scale_sigma": 0.02},
        }
    )
    assert cfg.imu.gyro_noise_deg_per_h_rthz == 2.5  # explicit
    # from the preset
    assert cfg.imu.accel_bias_sigma_ug == IMU_PRESETS["honeywell-hg1700"].accel_bias_stability_ug
    assert cfg.dvl.default_noise_m_s == 0.015
    assert cfg.priors.scale_sigma == 0.02
    # an explicit value equal to the default is explicit too
    default_sigma = EstimatorConfig().priors.scale_sigma
    cfg = EstimatorConfig.from_dict(
        {"dvl": {"model": "teledyne-tasman"}, "priors": {"scale_sigma": default_sigma}}
    )
    assert cfg.priors.scale_sigma == default_sigma != DVL_PRESETS["teledyne-tasman"].scale_accuracy


def test_a_named_configurations_values_are_explicit() -> None:
    # preset = "paper" sets [priors] scale_sigma = 0.5: the DVL preset does not override it
    cfg = EstimatorConfig.from_dict({"preset": "paper", "dvl": {"model": "nortek-dvl1000"}})
    assert cfg.priors.scale_sigma == 0.5
    assert cfg.dvl.default_noise_m_s == DVL_PRESETS["nortek-dvl1000"].ping_noise_m_s


def test_unknown_model_is_one_line_naming_the_known_ones() -> None:
    with pytest.raises(GtsamDvlError) as err:
        EstimatorConfig.from_dict({"imu": {"model": "kvh-9999"}}, source="cfg.toml")
    text = str(err.value)
    assert "\n" not in text and text.startswith("cfg.toml: [imu] model")
    assert "'kvh-9999'" in text and all(f"'{n}'" in text for n in IMU_PRESETS)
    with pytest.raises(GtsamDvlError) as err:
        # an IMU is no DVL
        EstimatorConfig.from_dict({"dvl": {"model": "kvh-1750"}}, source="cfg.toml")
    assert "\n" not in str(err.value) and all(f"'{n}'" in str(err.value) for n in DVL_PRESETS)
    with pytest.raises(
        GtsamDvlError, match=r"^no preset 'nope' \(known: ixblue-phins, .*sonardyne-syrinx\)$"
    ):
        describe_preset("nope")


def test_mounting_tolerance_is_the_misalignment_prior_unless_that_is_set() -> None:
    cfg = EstimatorConfig.from_dict({"priors": {"mounting_tolerance_deg": 0.5}})
    assert cfg.priors.misalignment_sigma_deg == (0.5, 0.5, 0.5)
    cfg = EstimatorConfig.from_dict(
        {"priors": {"mounting_tolerance_deg": 0.5, "misalignment_sigma_deg": [0.2, 0.3, 2.0]}}
    )
    assert cfg.priors.misalignment_sigma_deg == (0.2, 0.3, 2.0)
    assert EstimatorConfig().priors.misalignment_sigma_deg == (
        1.0,
        1.0,
        1.0,
    )  # none set: the default
    with pytest.raises(
        GtsamDvlError, match=r"\[priors\] mounting_tolerance_deg must be a number > 0"
    ):
        EstimatorConfig.from_dict({"priors": {"mounting_tolerance_deg": -1.0}})


def test_a_model_set_in_python_takes_effect_on_validate_and_unsetting_it_restores_the_defaults() -> (
    None
):
    cfg, default = EstimatorConfig(), EstimatorConfig()
    cfg.imu.model, cfg.dvl.model = "adis16495", "teledyne-tasman"
    cfg.priors.mounting_tolerance_deg = 0.3
    cfg.validate()
    assert (
        cfg.imu.gyro_bias_sigma_deg_per_h == IMU_PRESETS["adis16495"].gyro_bias_stability_deg_per_h
    )
    assert cfg.priors.scale_sigma == DVL_PRESETS["teledyne-tasman"].scale_accuracy
    assert cfg.priors.misalignment_sigma_deg == (0.3, 0.3, 0.3)
    cfg.imu.model = cfg.dvl.model = cfg.priors.mounting_tolerance_deg = None
    cfg.validate()
    assert cfg == default


@pytest.mark.parametrize("via", ["toml", "json"])
def test_configuration_with_presets_reads_back_to_the_same_values(via: str, tmp_path: Path) -> None:
    cfg = EstimatorConfig.from_dict(
        {
            "imu": {"model": "kvh-1775", "accel_bias_sigma_ug": 77.0},
            "dvl": {"model": "teledyne-workhorse-navigator-600"},
            "priors": {"mounting_tolerance_deg": 0.5},
        }
    )
    if via == "toml":
        text = cfg.to_toml()
        assert 'model = "kvh-1775"' in text and "mounting_tolerance_deg = 0.5" in text
        again = EstimatorConfig.from_dict(tomllib.loads(text))
    else:
        path = tmp_path / "config.json"
        path.write_text(json.dumps({"estimator": "batch", "config": cfg.to_dict()}))
        again = EstimatorConfig.load(path)
    assert again == cfg
    assert again.to_toml() == cfg.to_toml()
    assert (
        again.priors.scale_sigma == DVL_PRESETS["teledyne-workhorse-navigator-600"].scale_accuracy
    )
    assert again.imu.accel_bias_sigma_ug == 77.0


def test_presets_command_lists_every_preset_and_describes_one() -> None:
    from gtsam_dvl.app.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["presets"])
    assert res.exit_code == 0, res.output
    names = [line.split()[0] for line in res.output.splitlines()[1:]]
    assert names == [*IMU_PRESETS, *DVL_PRESETS]
    res = runner.invoke(app, ["presets", "teledyne-pathfinder"])
    assert res.exit_code == 0, res.output
    assert "sources:" in res.output and "[priors] scale_sigma = 0.004" in res.output
    block = res.output.split("TOML:\n", 1)[1]
    assert EstimatorConfig.from_dict(tomllib.loads(block)).dvl.model == "teledyne-pathfinder"
    res = runner.invoke(app, ["presets", "nope"])
    assert res.exit_code == 1 and "known: ixblue-phins" in res.output


def test_docs_table_has_every_preset_with_its_values() -> None:
    text = (Path(__file__).resolve().parents[2] / "docs" / "sensors.md").read_text()
    rows = {
        line.split("|")[1].strip().strip("`"): [c.strip() for c in line.split("|")[3:-2]]
        for line in text.splitlines()
        if line.startswith("| `")
    }
    for name, p in IMU_PRESETS.items():
        assert rows[name] == [
            f"{p.gyro_noise_deg_per_h_rthz:g}",
            f"{p.accel_noise_ug_rthz:g}",
            f"{p.gyro_bias_stability_deg_per_h:g}",
            f"{p.accel_bias_stability_ug:g}",
        ], name
    for name, d in DVL_PRESETS.items():
        assert rows[name][:3] == [
            f"{d.ping_noise_m_s * 1000:g}",
            f"{d.scale_accuracy * 100:g}",
            f"{d.min_altitude_m:g}-{d.max_altitude_m:g}",
        ], name
