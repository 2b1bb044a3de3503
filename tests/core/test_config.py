"""EstimatorConfig checked by value (enumerations, types, ranges: one line naming file, section, key, value and
what is allowed), every estimator's options reachable from it ([online], [online.relinearization], [ekf],
[iodvlc]), and the round trip of the effective configuration through dict, JSON and TOML."""

from __future__ import annotations

import copy
import functools
import json
import tomllib
import typing
from pathlib import Path

import pytest
from pydantic import BaseModel

from gtsam_dvl.core.config import (
    EkfConfig,
    EstimatorConfig,
    IodvlcConfig,
    OnlineConfig,
    RelinearizationThresholds,
)
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict
from tests.support.logs import cut_log

ENUMS = [
    ("imu", "bias_model", "'constant', 'random_walk'"),
    ("dvl", "robust", "'none', 'huber', 'cauchy'"),
    ("solver", "earth_model", "'wgs84', 'flat'"),
    ("online", "mode", "'fixed_lag', 'full'"),
    ("online", "bad_messages", "'raise', 'drop'"),
]


@functools.cache
@functools.cache
def _short_log() -> LogData:
    """paper-2d cut to 350 s: 150 s static, speed-up and two surges (one Type-I segment); simulated once (the
    estimators do not change a log)."""
    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = raw["segments"][:4]
    raw["segments"][0]["duration_s"] = 150.0
    return simulate(scenario_from_dict(raw, "paper-2d-short"), 3)


def _non_default() -> EstimatorConfig:
    """A value changed in every section, None fields set."""
    cfg = EstimatorConfig()
    cfg.imu.bias_model = "random_walk"
    cfg.dvl.robust = "huber"
    cfg.dvl.huber_k = 2.5
    cfg.priors.misalignment_sigma_deg = (0.5, 1.5, 2.0)
    cfg.alignment.initial_attitude_deg = (3.0, 0.0, 10.0)
    cfg.alignment.origin_lat_deg = 30.0
    cfg.solver.max_iterations = 12
    cfg.online.window_s = 7.5
    cfg.online.relinearization.velocity = (0.02, 0.02, 0.03)
    cfg.ekf.calibration_speed_sigmas = 3.0
    cfg.iodvlc.noise_m_s = 0.03
    cfg.iodvlc.prior_sigma_deg = None
    return cfg


def _load(tmp_path: Path, text: str) -> EstimatorConfig:
    path = tmp_path / "cfg.toml"
    path.write_text(text)
    return EstimatorConfig.from_toml(path)


def _error(tmp_path: Path, text: str) -> str:
    with pytest.raises(GtsamDvlError) as exc:
        _load(tmp_path, text)
    message = str(exc.value)
    print(message)
    assert "\n" not in message and message.startswith(f"{tmp_path / 'cfg.toml'}: ")
    return message.removeprefix(f"{tmp_path / 'cfg.toml'}: ")


def _numeric_fields() -> list[tuple[str, str]]:
    """(section, key) of every float field, nested sections as 'online.relinearization'."""
    out = []
    cfg = EstimatorConfig()
    todo = [(key, getattr(cfg, key)) for key in type(cfg).model_fields]
    while todo:
        name, section = todo.pop(0)
        hints = typing.get_type_hints(type(section))
        for key in type(section).model_fields:
            value = getattr(section, key)
            if isinstance(value, BaseModel):
                todo.append((f"{name}.{key}", value))
            elif hints[key] is float or hints[key] == float | None:
                out.append((name, key))
    return out


# ----- checked by value --------------------------------------------------------------------------


@pytest.mark.parametrize(("section", "key", "allowed"), ENUMS)
def test_bad_enum_lists_the_allowed_values(
    section: str, key: str, allowed: str, tmp_path: Path
) -> None:
    assert (
        _error(tmp_path, f'[{section}]\n{key} = "bogus"\n')
        == f"[{section}] {key} = 'bogus' is not one of {allowed}"
    )
    assert (
        _error(tmp_path, f"[{section}]\n{key} = 3\n")
        == f"[{section}] {key} = 3 is not one of {allowed}"
    )
    for value in allowed.split(", "):  # each allowed value loads
        assert getattr(
            getattr(_load(tmp_path, f"[{section}]\n{key} = {value}\n"), section), key
        ) == value.strip("'")


def test_every_enum_field_is_a_literal() -> None:
    """The enumerations of the brief are Literal fields, so the loader knows their values."""
    for section, key, allowed in ENUMS:
        hint = typing.get_type_hints(type(getattr(EstimatorConfig(), section)))[key]
        assert typing.get_origin(hint) is typing.Literal
        assert ", ".join(repr(a) for a in typing.get_args(hint)) == allowed


@pytest.mark.parametrize(("section", "key"), _numeric_fields())
def test_string_where_a_number_belongs(section: str, key: str, tmp_path: Path) -> None:
    message = _error(tmp_path, f'[{section}]\n{key} = "abc"\n')
    assert message.startswith(f"[{section}] {key} must be a number") and message.endswith(
        ", got 'abc'"
    )


def test_numeric_section_list_covers_every_new_section() -> None:
    sections = {s for s, _ in _numeric_fields()}
    assert {"online", "online.relinearization", "ekf", "iodvlc"} <= sections


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('[dvl]\nnoise_m_s = "abc"\n', "[dvl] noise_m_s must be a number >= 0, got 'abc'"),
        ("[dvl]\nnoise_m_s = -0.1\n", "[dvl] noise_m_s must be a number >= 0, got -0.1"),
        ("[priors]\nscale_sigma = 0.0\n", "[priors] scale_sigma must be a number > 0, got 0.0"),
        ("[priors]\nscale_sigma = nan\n", "[priors] scale_sigma must be a number > 0, got nan"),
        (
            "[priors]\nmisalignment_sigma_deg = [1.0, 1.0]\n",
            "[priors] misalignment_sigma_deg must be a list of 3 numbers > 0, got [1.0, 1.0]",
        ),
        (
            "[priors]\nmisalignment_sigma_deg = [1.0, -1.0, 1.0]\n",
            "[priors] misalignment_sigma_deg must be a list of 3 numbers > 0, got [1.0, -1.0, 1.0]",
        ),
        (
            "[alignment]\norigin_lat_deg = 91.0\n",
            "[alignment] origin_lat_deg must be a number in [-90, 90] or 'none', got 91.0",
        ),
        (
            '[alignment]\ninitial_attitude_deg = "level"\n',
            "[alignment] initial_attitude_deg must be a list of 3 numbers or 'none', got 'level'",
        ),
        (
            "[solver]\nmax_iterations = 0\n",
            "[solver] max_iterations must be an integer >= 1, got 0",
        ),
        (
            "[solver]\nmax_iterations = 10.5\n",
            "[solver] max_iterations must be an integer >= 1, got 10.5",
        ),
        (
            '[imu]\nrotation_compensation = "yes"\n',
            "[imu] rotation_compensation must be true or false, got 'yes'",
        ),
        (
            "[imu]\nrotation_compensation = 1\n",
            "[imu] rotation_compensation must be true or false, got 1",
        ),
        ("[online]\nwindow_s = 0\n", "[online] window_s must be a number > 0, got 0"),
        (
            "[online]\nfinal_updates = -1\n",
            "[online] final_updates must be an integer >= 0, got -1",
        ),
        (
            "[online]\nrelinearization = 1.0\n",
            "[online] relinearization must be a table [online.relinearization], got 1.0",
        ),
        (
            "[online.relinearization]\npose = [1.0, 1.0, 1.0]\n",
            "[online.relinearization] pose must be a list of 6 numbers > 0, got [1.0, 1.0, 1.0]",
        ),
        (
            "[ekf]\nmin_calibration_speed_m_s = -1.0\n",
            "[ekf] min_calibration_speed_m_s must be a number >= 0, got -1.0",
        ),
        (
            '[ekf]\ncalibration_speed_sigmas = "5"\n',
            "[ekf] calibration_speed_sigmas must be a number >= 0, got '5'",
        ),
        (
            "[iodvlc]\naxis_change_deg = 200.0\n",
            "[iodvlc] axis_change_deg must be a number in (0, 180], got 200.0",
        ),
        (
            "[iodvlc]\nnoise_m_s = 0.0\n",
            "[iodvlc] noise_m_s must be a number > 0 or 'none', got 0.0",
        ),
        ("[iodvlc]\nearth_terms = 0\n", "[iodvlc] earth_terms must be true or false, got 0"),
    ],
)
def test_wrong_type_or_range_is_one_clear_line(text: str, expected: str, tmp_path: Path) -> None:
    assert _error(tmp_path, text) == expected


def test_unknown_sections_and_keys_still_rejected(tmp_path: Path) -> None:
    assert _error(tmp_path, "[priors]\nscale_sigmaa = 1.0\n").startswith(
        "unknown key 'scale_sigmaa' in [priors] (known: scale_initial, scale_sigma, "
    )
    assert _error(tmp_path, "[onlin]\nwindow_s = 1.0\n") == (
        "unknown section [onlin] (known: alignment, calibration, current, depth, dvl, ekf, gnss, imu, iodvlc, noise, "
        "observability, online, priors, solver)"
    )
    assert _error(tmp_path, "[online.relinearization]\nscales = 1.0\n").startswith(
        "unknown key 'scales' in [online.relinearization] (known: pose, velocity, bias, scale, misalignment_rad)"
    )
    assert _error(tmp_path, "[ekf]\nmin_speed = 1.0\n").startswith(
        "unknown key 'min_speed' in [ekf]"
    )
    assert _error(tmp_path, "bias_model = 'walk'\n").startswith("unknown section [bias_model]")
    assert _error(tmp_path, "imu = 3\n") == "[imu] must be a table of keys, got 3"


def test_values_are_normalised_on_load(tmp_path: Path) -> None:
    """An int where a float belongs is that float; lists are tuples; optional fields accept a value."""
    cfg = _load(
        tmp_path,
        "[dvl]\nnoise_m_s = 1\n[alignment]\ninitial_attitude_deg = [3, 0, 10]\n"
        "[online.relinearization]\nvelocity = [1, 2, 3]\n[iodvlc]\nnoise_m_s = 0.05\n",
    )
    assert cfg.dvl.noise_m_s == 1.0 and isinstance(cfg.dvl.noise_m_s, float)
    assert cfg.alignment.initial_attitude_deg == (3.0, 0.0, 10.0)
    assert cfg.online.relinearization.velocity == (1.0, 2.0, 3.0)
    assert cfg.iodvlc.noise_m_s == 0.05
    # TOML has no null: an optional field takes "none"
    assert _load(tmp_path, '[iodvlc]\nprior_sigma_deg = "none"\n').iodvlc.prior_sigma_deg is None
    assert 'prior_sigma_deg = "none"' in _non_default().to_toml()
    # the rest keeps its defaults
    assert (
        cfg.online.relinearization.pose == RelinearizationThresholds().pose
        and cfg.ekf == EkfConfig()
    )


def test_config_built_in_python_is_validated() -> None:
    cfg = EstimatorConfig()
    cfg.validate()
    cfg.imu.bias_model = "walk"  # type: ignore[assignment]
    with pytest.raises(
        GtsamDvlError, match=r"^config: \[imu\] bias_model = 'walk' is not one of 'constant', "
    ):
        cfg.validate()
    with pytest.raises(GtsamDvlError, match=r"\[online\] window_s must be a number > 0, got -1"):
        OnlineConfig(window_s=-1.0).check()
    with pytest.raises(
        GtsamDvlError, match=r"\[iodvlc\] min_beta_m_s must be a number >= 0, got 'x'"
    ):
        IodvlcConfig(min_beta_m_s="x").validate()  # type: ignore[arg-type]


@pytest.mark.parametrize("estimator", ["batch", "online", "ekf", "io-dvlc"])
def test_estimators_check_the_config_when_they_start(estimator: str) -> None:
    from gtsam_dvl.app.commands import run_estimator
    from gtsam_dvl.estimators.ekf import run_ekf
    from gtsam_dvl.estimators.iodvlc import run_iodvlc
    from gtsam_dvl.estimators.online import OnlineEstimator

    log = _short_log()
    cfg = EstimatorConfig()
    if estimator == "io-dvlc":
        cfg.iodvlc.window_s = "5"  # type: ignore[assignment]
        match = r"\[iodvlc\] window_s must be a number > 0, got '5'"
        with pytest.raises(GtsamDvlError, match=match):
            run_iodvlc(log, cfg.iodvlc)
    else:
        cfg.dvl.robust = "tukey"  # type: ignore[assignment]
        match = r"\[dvl\] robust = 'tukey' is not one of 'none', 'huber', 'cauchy'"
        if estimator == "online":
            with pytest.raises(GtsamDvlError, match=match):
                OnlineEstimator.for_log(log, cfg)
        if estimator == "ekf":
            with pytest.raises(GtsamDvlError, match=match):
                run_ekf(log, cfg)
    with pytest.raises(GtsamDvlError, match=match):
        run_estimator(log, estimator, cfg)


# ----- round trip --------------------------------------------------------------------------------


def test_round_trip_through_dict_json_and_toml(tmp_path: Path) -> None:
    for cfg in (EstimatorConfig(), _non_default()):
        d = cfg.to_dict()
        assert d["alignment"]["origin_height_m"] is None  # None kept for JSON
        assert EstimatorConfig.from_dict(d) == cfg
        assert EstimatorConfig.from_dict(json.loads(json.dumps(d))) == cfg
        text = cfg.to_toml()
        assert EstimatorConfig.from_dict(tomllib.loads(text)) == cfg
        path = tmp_path / "written.toml"
        path.write_text(text)
        assert EstimatorConfig.from_toml(path) == cfg
    assert _non_default() != EstimatorConfig()


def test_json_of_a_result_reads_back(tmp_path: Path) -> None:
    """`-c` takes the config.json written with a result ({"estimator", "config"}) or a bare config dict."""
    cfg = _non_default()
    wrapped, bare = tmp_path / "config.json", tmp_path / "bare.json"
    wrapped.write_text(
        json.dumps({"estimator": "ekf", "config": cfg.to_dict()}, default=str, indent=2)
    )
    bare.write_text(json.dumps(cfg.to_dict()))
    assert EstimatorConfig.from_toml(wrapped) == cfg == EstimatorConfig.from_toml(bare)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"config": {"imu": {"bias_model": "walk"}}}))
    with pytest.raises(GtsamDvlError, match=rf"^{bad}: \[imu\] bias_model = 'walk' is not one of"):
        EstimatorConfig.from_toml(bad)
    bad.write_text("{not json")
    with pytest.raises(GtsamDvlError, match="not valid JSON"):
        EstimatorConfig.from_toml(bad)


def test_old_names_are_the_config_sections() -> None:
    from gtsam_dvl.estimators.ekf.filter import CALIBRATION_SPEED_SIGMAS, MIN_CALIBRATION_SPEED_M_S
    from gtsam_dvl.estimators.iodvlc import IoDvlcOptions
    from gtsam_dvl.estimators.online import ONLINE_MODES as MODES
    from gtsam_dvl.estimators.online import OnlineConfig as OldOnlineConfig
    from gtsam_dvl.estimators.online import RelinearizationThresholds as OldThresholds

    assert OldOnlineConfig is OnlineConfig and OldThresholds is RelinearizationThresholds
    assert IoDvlcOptions is IodvlcConfig
    assert MODES == ("fixed_lag", "full")
    assert (MIN_CALIBRATION_SPEED_M_S, CALIBRATION_SPEED_SIGMAS) == (0.1, 5.0)
    assert RelinearizationThresholds().threshold_map() is not None


# ----- every option reaches its estimator ----------------------------------------------------------


def test_ekf_section_reaches_the_filter() -> None:
    from gtsam_dvl.estimators.ekf import run_ekf

    log = _short_log()
    base = run_ekf(log)
    cfg = EstimatorConfig()
    cfg.ekf.min_calibration_speed_m_s = 0.0
    cfg.ekf.calibration_speed_sigmas = 0.0
    never_slow = run_ekf(log, cfg)
    # faster than the vehicle ever goes (or is estimated to go)
    cfg.ekf.min_calibration_speed_m_s = 10.0
    always_slow = run_ekf(log, cfg)
    counts = [r.info["counters"]["dvl_slow"] for r in (never_slow, base, always_slow)]
    print(
        "slow pings (never, default, always):", counts, "of", base.info["counters"]["dvl_updates"]
    )
    assert counts[0] < counts[1] < counts[2] == always_slow.info["counters"]["dvl_updates"]
    assert always_slow.scale == cfg.priors.scale_initial  # never updated from its prior
    assert always_slow.config["ekf"] == {
        "min_calibration_speed_m_s": 10.0,
        "calibration_speed_sigmas": 0.0,
        "gate_probability": 0.99999,
        "gate_reopen_after": 10,
        "recentre_time_offset": True,
    }
    # the keyword still works, overrides the config and is written to the effective configuration
    kw = run_ekf(log, cfg, min_calibration_speed_m_s=0.0)
    assert (
        kw.info["counters"]["dvl_slow"] == counts[0]
        and kw.config["ekf"]["min_calibration_speed_m_s"] == 0.0
    )
    assert cfg.ekf.min_calibration_speed_m_s == 10.0  # the caller's config is not changed


def test_online_section_reaches_the_estimator() -> None:
    from gtsam_dvl.estimators.online import smooth_online

    log = _short_log()
    base = smooth_online(log)
    # the log's configuration (its scenario names "paper"), with a shorter window
    cfg = EstimatorConfig.paper()
    cfg.online.window_s = 5.0
    short = smooth_online(log, cfg)
    print(
        "window 20 s / 5 s: variables",
        base.info["isam2"]["variables"],
        short.info["isam2"]["variables"],
    )
    assert base.info["window_s"] == 20.0 and short.info["window_s"] == 5.0
    assert short.info["isam2"]["variables"] < base.info["isam2"]["variables"]
    assert short.config["online"]["window_s"] == 5.0
    # the keyword arguments and options= still override the section (on the log's first 200 s: a setting's path)
    start = cut_log(log, 200.0)
    assert smooth_online(start, cfg, window_s=10.0).info["window_s"] == 10.0
    assert smooth_online(start, cfg, options=OnlineConfig(window_s=8.0)).info["window_s"] == 8.0
    cfg.online.mode = "full"
    full = smooth_online(log, cfg)
    assert full.estimator == "online-full" and full.info["window_s"] is None
    assert full.config["online"]["mode"] == "full"


def test_online_relinearization_section_reaches_isam2(tmp_path: Path) -> None:
    from gtsam_dvl.estimators.online import smooth_online

    log = _short_log()
    base = smooth_online(log)
    cfg = _load(
        tmp_path,
        'preset = "paper"\n[online.relinearization]\nscale = 10.0\nmisalignment_rad = 10.0\n'
        "velocity = [100.0, 100.0, 100.0]\npose = [10.0, 10.0, 10.0, 1e3, 1e3, 1e3]\n",
    )
    loose = smooth_online(log, cfg)
    print(
        "rebases with the default / loose thresholds:",
        base.info["isam2"]["rebases"],
        loose.info["isam2"]["rebases"],
    )
    assert loose.info["isam2"]["rebases"] < base.info["isam2"]["rebases"]
    assert loose.config["online"]["relinearization"]["scale"] == 10.0


def test_iodvlc_section_reaches_the_observer(tmp_path: Path) -> None:
    from gtsam_dvl.app.commands import run_estimator
    from gtsam_dvl.estimators.iodvlc import run_iodvlc

    log = _short_log()
    base = run_iodvlc(log)
    cfg = _load(tmp_path, "[iodvlc]\nnoise_m_s = 0.05\n")
    noisy = run_estimator(log, "io-dvlc", cfg)  # what `smooth --mode io-dvlc -c` runs
    print(
        f"segments {len(base.segments)}, scale sigma {base.final_scale_sigma:.5f} -> {noisy.final_scale_sigma:.5f}"
    )
    assert base.noise_m_s == pytest.approx(0.02, rel=0.05) and noisy.noise_m_s == 0.05
    assert noisy.final_scale_sigma > 2 * base.final_scale_sigma
    cfg.iodvlc.min_segment_s = 1000.0  # longer than the log: no segment
    assert len(base.segments) >= 1 and run_iodvlc(log, cfg).segments == []


# ----- named configurations ------------------------------------------------------------------------------------
def test_defaults_are_a_real_dvls_priors_and_paper_is_named() -> None:
    """The defaults: scale 1 +- 1 %, misalignment 1 deg per axis; "paper": 0.8 +- 0.5, the rest identical."""
    cfg, paper = EstimatorConfig(), EstimatorConfig.paper()
    assert (cfg.priors.scale_initial, cfg.priors.scale_sigma) == (1.0, 0.01)
    assert cfg.priors.misalignment_sigma_deg == (1.0, 1.0, 1.0)
    assert (paper.priors.scale_initial, paper.priors.scale_sigma) == (0.8, 0.5)
    assert not paper.dvl.estimate_time_offset and cfg.dvl.estimate_time_offset
    assert (
        paper.model_copy(update={"priors": cfg.priors, "dvl": cfg.dvl, "noise": cfg.noise}) == cfg
    )
    assert not paper.noise.from_data and cfg.noise.from_data
    assert EstimatorConfig.named("default") == cfg


def test_unknown_named_configuration_is_one_line() -> None:
    with pytest.raises(
        GtsamDvlError,
        match=r"no configuration named 'papr' \(named configurations: default, paper\)",
    ):
        EstimatorConfig.named("papr")
    with pytest.raises(GtsamDvlError, match="not a named configuration"):
        EstimatorConfig.load("papr")


def test_preset_key_starts_from_a_named_configuration(tmp_path: Path) -> None:
    toml = tmp_path / "c.toml"
    toml.write_text('preset = "paper"\n[priors]\nscale_sigma = 0.2\n')
    cfg = EstimatorConfig.load(toml)
    assert (cfg.priors.scale_initial, cfg.priors.scale_sigma) == (0.8, 0.2)
    assert EstimatorConfig.load("paper") == EstimatorConfig.paper()
    toml.write_text('preset = "nope"\n')
    with pytest.raises(GtsamDvlError, match="preset must be the name of a named configuration"):
        EstimatorConfig.load(toml)


def test_a_log_names_its_configuration() -> None:
    """Simulated logs of the paper's scenarios recommend "paper"; other logs get the defaults."""
    from gtsam_dvl.sim.scenario import load_scenario

    assert load_scenario("paper-3d").estimator_config == "paper"
    assert load_scenario("paper-2d").estimator_config == "paper"
    assert load_scenario("straight-20km").estimator_config == "default"
    assert (
        EstimatorConfig.for_log({"scenario": {"estimator_config": "paper"}})
        == EstimatorConfig.paper()
    )
    assert EstimatorConfig.for_log({}) == EstimatorConfig()
    assert EstimatorConfig.for_log({"scenario": "not a table"}) == EstimatorConfig()


# ----- files written by an earlier version of the package still load ------------------------------------------
# config_fixtures/: result_config_paper.json is the config.json of `gtsam-dvl smooth` on a paper-2d log;
# default_config.json and default.toml are the default configuration's to_dict() (as JSON) and to_toml();
# paper_modified.toml / .json a paper configuration with optional fields set and unset; all written by the
# package's dataclass configuration, whose keys, defaults and TOML text these models keep.
FIXTURES = Path(__file__).parent / "config_fixtures"
# keys those files do not have: the noise levels from the data ([noise], and the fitted [dvl], [depth] and [gnss]
# noise_multiplier), the sensor presets ([imu] / [dvl] model), the DVL's correlated error and the mounting
# tolerance. A file without them takes their defaults (the fit on, no preset), also a paper configuration's; but a
# result's config.json without the correlated error takes it as white, as the runs that wrote it did (test below)
ADDED = {
    "noise": None,
    "current": None,
    "calibration": None,
    "imu": {"model"},
    "dvl": {
        "noise_multiplier",
        "model",
        "correlated_sigma_m_s",
        "correlated_tau_s",
        "constant_error_sigma_m_s",
    },
    "priors": {"mounting_tolerance_deg", "hold_weak_information", "nominal_check"},
    "ekf": {"recentre_time_offset"},
    "depth": {"noise_multiplier"},
    "gnss": {"noise_multiplier"},
}


def _without_added(d: dict) -> dict:  # type: ignore[type-arg]
    out = {k: v for k, v in d.items() if not (k in ADDED and ADDED[k] is None)}
    for section, keys in ADDED.items():
        if keys is not None and section in out:
            out[section] = {k: v for k, v in out[section].items() if k not in keys}
    return out


def _lines_in_order(old: str, new: str) -> bool:
    """Every line of old appears in new, in the same order (new may have more)."""
    it = iter(new.splitlines())
    return all(any(line == n for n in it) for line in old.splitlines())


def _tuples(value: object) -> object:
    """JSON's lists as tuples, as to_dict() gives them."""
    if isinstance(value, dict):
        return {k: _tuples(v) for k, v in value.items()}
    return tuple(value) if isinstance(value, list) else value


def test_defaults_are_those_written_before() -> None:
    cfg = EstimatorConfig()
    written = (FIXTURES / "default_config.json").read_text()
    assert _without_added(cfg.model_dump()) == _tuples(json.loads(written))
    # the same keys, order and number types
    assert json.dumps(_without_added(cfg.to_dict()), indent=2) + "\n" == written
    assert _lines_in_order((FIXTURES / "default.toml").read_text(), cfg.to_toml())


def test_result_config_json_written_before_loads() -> None:
    path = FIXTURES / "result_config_paper.json"
    cfg = EstimatorConfig.load(path)
    # written before water-track pings were used: its runs refused them
    assert cfg.current.water_track == "refuse"
    paper = EstimatorConfig.paper()
    assert cfg.priors.hold_weak_information == 0.0  # written before the hold: its runs held nothing
    assert not cfg.priors.nominal_check  # nor checked the nominal calibration
    # nor gave the calibration a constant DVL error's share
    assert cfg.dvl.constant_error_sigma_m_s == 0.0
    assert cfg.model_copy(update={"noise": paper.noise, "current": paper.current}) == paper
    assert _without_added(cfg.to_dict()) == _tuples(json.loads(path.read_text())["config"])


def test_config_json_without_the_correlated_error_repeats_a_white_dvl(tmp_path: Path) -> None:
    """A config.json written before [dvl] correlated_sigma_m_s existed describes runs with a white DVL error: it
    loads with 0, while a TOML file leaving it out (a user's partial configuration) takes the default."""
    d = EstimatorConfig().to_dict()
    d["dvl"].pop("correlated_sigma_m_s")
    old = tmp_path / "config.json"
    old.write_text(json.dumps({"estimator": "batch", "config": d}))
    assert EstimatorConfig.load(old).dvl.correlated_sigma_m_s == 0.0
    toml = tmp_path / "mine.toml"
    toml.write_text("[dvl]\nnoise_m_s = 0.007\n")
    assert (
        EstimatorConfig.load(toml).dvl.correlated_sigma_m_s
        == EstimatorConfig().dvl.correlated_sigma_m_s
        > 0
    )


def test_toml_written_before_loads_and_writes_back_the_same_text() -> None:
    text = (FIXTURES / "paper_modified.toml").read_text()
    cfg = EstimatorConfig.load(FIXTURES / "paper_modified.toml")
    assert cfg == EstimatorConfig.from_json(FIXTURES / "paper_modified.json")
    assert (
        cfg.alignment.initial_attitude_deg,
        cfg.iodvlc.noise_m_s,
        cfg.iodvlc.prior_sigma_deg,
    ) == ((1.0, 2.0, 3.0), None, None)
    assert _lines_in_order(text, cfg.to_toml())
    assert EstimatorConfig.from_dict(tomllib.loads(cfg.to_toml())) == cfg


@pytest.mark.parametrize(
    "path",
    sorted((Path(__file__).parents[2] / "data" / "scenarios").glob("*.toml")),
    ids=lambda p: p.stem,
)
def test_every_scenarios_configuration_loads(path: Path) -> None:
    scenario = load_scenario(path.stem)
    assert EstimatorConfig.for_log(
        {"scenario": {"estimator_config": scenario.estimator_config}}
    ) == (EstimatorConfig.named(scenario.estimator_config))


def test_error_names_the_bad_table_of_a_section(tmp_path: Path) -> None:
    """A section's constructor, and validate() after an assignment, give the same one line as a file."""
    with pytest.raises(
        GtsamDvlError, match=r"^config: \[priors\] scale_sigma must be a number > 0, got -1.0$"
    ):
        EstimatorConfig(priors={"scale_sigma": -1.0})
    cfg = EstimatorConfig()
    cfg.online.relinearization.velocity = [0.1, 0.1]  # type: ignore[assignment]
    with pytest.raises(
        GtsamDvlError, match=r"^config: \[online.relinearization\] velocity must be a list of 3 "
    ):
        cfg.validate()
    cfg.online.relinearization.velocity = [1, 2, 3]  # type: ignore[assignment]
    assert cfg.validate().online.relinearization.velocity == (1.0, 2.0, 3.0)  # normalised in place


# ----- schema_version and the migration table (core/config/schema.py) ----------------------------------------
# what each older version's runs did about the keys added after it: a whole written configuration of version v
# (without schema_version) lacks the keys of the steps after v and loads with these values for them
OLD_RUNS = {
    2: ("dvl", "correlated_sigma_m_s", 0.0),
    3: ("current", "water_track", "refuse"),
    4: ("priors", "hold_weak_information", 0.0),
    5: ("priors", "nominal_check", False),
    6: ("dvl", "constant_error_sigma_m_s", 0.0),
}


def _written_at(version: int) -> dict:  # type: ignore[type-arg]
    """The default configuration as a version's writer wrote it: without the keys later versions added."""
    d = EstimatorConfig().to_dict()
    for v, (section, key, _) in OLD_RUNS.items():
        if v > version:
            if section == "current":
                d.pop("current")
            else:
                d[section].pop(key)
    return d


def test_migration_table_is_ordered_and_ends_at_the_schema_version() -> None:
    from gtsam_dvl.core.config.schema import MIGRATIONS, SCHEMA_VERSION

    assert [m.version for m in MIGRATIONS] == list(range(2, SCHEMA_VERSION + 1))
    assert all(m.change for m in MIGRATIONS)
    assert set(OLD_RUNS) == {m.version for m in MIGRATIONS if m.added is not None}


@pytest.mark.parametrize("version", [1, 2, 3, 4, 5, 6])
def test_a_file_of_each_old_version_migrates(version: int, tmp_path: Path) -> None:
    """A result's config.json of each older version (no schema_version) is detected by its keys and loads with
    the later keys as its runs had them; the same file stating its schema_version loads the same."""
    from gtsam_dvl.core.config.schema import SCHEMA_VERSION, detected_version

    d = _written_at(version)
    assert detected_version(d) == version
    old = tmp_path / "config.json"
    old.write_text(json.dumps({"estimator": "batch", "config": d}))
    cfg = EstimatorConfig.load(old)
    default = EstimatorConfig()
    for v, (section, key, value) in OLD_RUNS.items():
        expected = value if v > version else getattr(getattr(default, section), key)
        assert getattr(getattr(cfg, section), key) == expected, (v, section, key)
    stated = tmp_path / "stated.json"
    stated.write_text(json.dumps({"schema_version": version, "estimator": "batch", "config": d}))
    assert EstimatorConfig.load(stated) == cfg
    # a user's partial file is current: the keys it leaves out take their defaults
    assert detected_version({"dvl": {"noise_m_s": 0.007}}) == SCHEMA_VERSION


def test_written_configurations_state_their_schema_version(tmp_path: Path) -> None:
    from gtsam_dvl.core.config.schema import SCHEMA_VERSION

    cfg = _non_default()
    text = cfg.to_toml()
    assert text.startswith(f"schema_version = {SCHEMA_VERSION}\n")
    assert tomllib.loads(text)["schema_version"] == SCHEMA_VERSION
    path = tmp_path / "written.toml"
    path.write_text(text)
    assert EstimatorConfig.load(path) == cfg


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (
            99,
            "schema_version 99 is newer than this gtsam_dvl reads (at most {v}): written by a newer version",
        ),
        ('"7"', "schema_version must be an integer from 1 to {v}, got '7'"),
        (0, "schema_version must be an integer from 1 to {v}, got 0"),
    ],
)
def test_a_bad_or_newer_schema_version_is_one_line(
    value: object, message: str, tmp_path: Path
) -> None:
    from gtsam_dvl.core.config.schema import SCHEMA_VERSION

    path = tmp_path / "new.toml"
    path.write_text(f"schema_version = {value}\n\n[dvl]\nnoise_m_s = 0.007\n")
    with pytest.raises(GtsamDvlError) as err:
        EstimatorConfig.load(path)
    assert str(err.value).startswith(f"{path}: {message.format(v=SCHEMA_VERSION)}")
    assert "\n" not in str(err.value)
    wrapped = tmp_path / "config.json"
    wrapped.write_text(json.dumps({"schema_version": 99, "estimator": "ekf", "config": {}}))
    with pytest.raises(GtsamDvlError, match=rf"^{wrapped}: schema_version 99 is newer"):
        EstimatorConfig.load(wrapped)
