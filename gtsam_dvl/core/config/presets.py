"""Sensor presets: datasheet values of common IMUs and DVLs, for `[imu] model = "..."` and `[dvl] model = "..."`.

A preset fills the noise, bias and scale-prior fields of the configuration that the same configuration does not set
itself (sections.py: ImuConfig, DvlConfig, PriorConfig; estimator.py: the DVL's scale accuracy becomes
[priors] scale_sigma). The values are a data table, presets.toml beside this module, read and validated once at
import; every value there carries its source, in a comment and in the preset's sources: a datasheet (or a document
quoting one) found with the search tool, named by its address, or "typical of the class" where no datasheet with the
figure was found, a class value said so.

Units as the configuration's: gyro white noise in deg/h/sqrt(Hz) (an angle random walk in deg/sqrt(h) times 60),
accelerometer white noise in micro-g/sqrt(Hz) (a velocity random walk in m/s/sqrt(h) divided by 60 and by
g = 9.80665 m/s^2, times 1e6), bias stabilities in deg/h and micro-g, DVL noise in m/s, scale accuracy as a
fraction (0.004 for +-0.4 %), altitudes in m.

How a DVL's datasheet accuracy is read. A DVL datasheet states a "long-term accuracy" of the form
"+-a % +-b mm/s": the error of the velocity averaged over a long run, not of one ping. Its proportional term a is
an error of the scale (sound speed, beam geometry) that does not average out: it is taken as the scale prior sigma
(scale_accuracy = a / 100; the +- bound read as one sigma, which is generous where the maker means a bound). Its
offset term b is an error that does not average out over the long run either, so it is not the ping noise: it is
taken as the level of the correlated (Gauss-Markov) velocity error, correlated_sigma_m_s = b / 1000, with the
default time constant of 60 s (no datasheet states one). The ping (single-ping bottom-track) noise is a separate
datasheet figure ("single-ping standard deviation" at a stated speed) and, where the datasheet found gives none,
the class value: 5-9 mm/s at 1-2 m/s for 300-1200 kHz Teledyne- and Nortek-class units, larger for smaller and
cheaper ones.
"""

from __future__ import annotations

import importlib.resources
import math
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gtsam_dvl.core.errors import GtsamDvlError

G_M_S2 = 9.80665  # standard gravity, for micro-g
FT_M = 0.3048


def _sig(x: float) -> float:
    """x to 6 significant digits (a datasheet figure converted, without the float's last-digit noise)."""
    return float(f"{x:.6g}")


def arw_to_density(arw_deg_rth: float) -> float:
    """Gyro white noise in deg/h/sqrt(Hz) from an angle random walk in deg/sqrt(h)."""
    return _sig(arw_deg_rth * 60.0)


def vrw_to_density(vrw_m_s_rth: float) -> float:
    """Accelerometer white noise in micro-g/sqrt(Hz) from a velocity random walk in m/s/sqrt(h)."""
    return _sig(vrw_m_s_rth / 60.0 / G_M_S2 * 1e6)


def deg_s_density_to_deg_h(density_deg_s_rthz: float) -> float:
    """Gyro white noise in deg/h/sqrt(Hz) from a noise density in deg/s/sqrt(Hz)."""
    return _sig(density_deg_s_rthz * 3600.0)


@dataclass(frozen=True)
class ImuPreset:
    """An IMU's datasheet values; sources: where each came from (printed by `gtsam-dvl presets NAME`)."""

    name: str
    title: str
    gyro_noise_deg_per_h_rthz: float  # white noise (angle random walk), deg/h/sqrt(Hz)
    accel_noise_ug_rthz: float  # white noise (velocity random walk), micro-g/sqrt(Hz)
    gyro_bias_stability_deg_per_h: float
    accel_bias_stability_ug: float
    sources: tuple[str, ...]

    def config_values(self) -> dict[str, float]:
        """The [imu] fields this preset fills (ImuConfig names): white noise, and the bias stabilities as the
        sigmas of the random-constant bias."""
        return {
            "gyro_noise_deg_per_h_rthz": self.gyro_noise_deg_per_h_rthz,
            "accel_noise_ug_rthz": self.accel_noise_ug_rthz,
            "gyro_bias_sigma_deg_per_h": self.gyro_bias_stability_deg_per_h,
            "accel_bias_sigma_ug": self.accel_bias_stability_ug,
        }

    def summary(self) -> str:
        return (
            f"gyro {self.gyro_noise_deg_per_h_rthz:g} deg/h/rtHz, bias {self.gyro_bias_stability_deg_per_h:g} "
            f"deg/h; accel {self.accel_noise_ug_rthz:g} ug/rtHz, bias {self.accel_bias_stability_ug:g} ug"
        )


@dataclass(frozen=True)
class DvlPreset:
    """A DVL's datasheet values; sources: where each came from (printed by `gtsam-dvl presets NAME`)."""

    name: str
    title: str
    ping_noise_m_s: float  # single-ping bottom-track noise per horizontal axis, m/s
    ping_noise_speed_m_s: float  # the speed at which ping_noise_m_s is stated
    scale_accuracy: float  # fraction (0.004: +-0.4 %): the scale prior sigma
    min_altitude_m: float  # bottom-track range
    max_altitude_m: float
    beam_angle_deg: float  # from the instrument's axis (Janus)
    sources: tuple[str, ...]
    correlated_sigma_m_s: float = 0.0  # Gauss-Markov velocity error level, m/s
    correlated_tau_s: float = 60.0  # and its time constant, s

    def beam_noise_m_s(self) -> float:
        """One beam's noise from the horizontal noise of a four-beam Janus DVL: a horizontal axis is the
        difference of two opposite beams over 2 sin(beam angle), so sigma_h = sigma_beam / (sqrt(2) sin)."""
        return self.ping_noise_m_s * math.sqrt(2.0) * math.sin(math.radians(self.beam_angle_deg))

    def config_values(self) -> dict[str, float]:
        """The [dvl] fields this preset fills (DvlConfig names). The ping noise is the default for messages without a
        covariance (default_noise_m_s), not an override of a message's own (noise_m_s)."""
        return {
            "default_noise_m_s": self.ping_noise_m_s,
            "beam_noise_m_s": _sig(self.beam_noise_m_s()),
            "correlated_sigma_m_s": self.correlated_sigma_m_s,
            "correlated_tau_s": self.correlated_tau_s,
        }

    def summary(self) -> str:
        return (
            f"ping {self.ping_noise_m_s * 1000:g} mm/s at {self.ping_noise_speed_m_s:g} m/s, scale "
            f"{self.scale_accuracy * 100:g} %, altitude {self.min_altitude_m:g}-{self.max_altitude_m:g} m"
        )


_GYRO_NOISE_FORMS: dict[str, Callable[[float], float]] = {
    # the key a preset states its gyro white noise with -> to deg/h/sqrt(Hz)
    "gyro_noise_deg_per_h_rthz": float,
    "gyro_arw_deg_rth": arw_to_density,
    "gyro_noise_deg_s_rthz": deg_s_density_to_deg_h,
}
_ACCEL_NOISE_FORMS: dict[str, Callable[[float], float]] = {
    # the key a preset states its accelerometer white noise with -> to micro-g/sqrt(Hz)
    "accel_noise_ug_rthz": float,
    "accel_vrw_ft_s_rth": lambda vrw_ft_s_rth: vrw_to_density(vrw_ft_s_rth * FT_M),
}
_IMU_NUMBERS = ("gyro_bias_stability_deg_per_h", "accel_bias_stability_ug")
_DVL_NUMBERS = (
    "ping_noise_m_s",
    "ping_noise_speed_m_s",
    "scale_accuracy",
    "min_altitude_m",
    "max_altitude_m",
    "beam_angle_deg",
)
_DVL_OPTIONAL_NUMBERS = ("correlated_sigma_m_s", "correlated_tau_s")


class _PresetEntry:
    """One [imu.NAME] or [dvl.NAME] table of presets.toml, taken key by key: a missing, unknown or non-numeric key
    is a GtsamDvlError naming the preset (the file ships with the package: an error here is a packaging bug)."""

    def __init__(self, kind: str, name: str, table: dict[str, Any], references: dict[str, str]):
        self.where = f"presets.toml [{kind}.{name}]"
        self.table = dict(table)
        self.references = references

    def number(self, key: str) -> float:
        value = self.table.pop(key, None)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise GtsamDvlError(f"{self.where}: '{key}' must be a number, not {value!r}")
        return float(value)

    def converted(self, forms: dict[str, Callable[[float], float]]) -> float:
        """The one value stated in one of these keys, converted to the configuration's unit."""
        stated = [key for key in forms if key in self.table]
        if len(stated) != 1:
            raise GtsamDvlError(
                f"{self.where}: exactly one of {', '.join(forms)} (got {stated or 'none'})"
            )
        return forms[stated[0]](self.number(stated[0]))

    def text(self, key: str) -> str:
        value = self.table.pop(key, None)
        if not isinstance(value, str) or not value.strip():
            raise GtsamDvlError(f"{self.where}: '{key}' must be a non-empty string")
        return value

    def sources(self) -> tuple[str, ...]:
        """The sources, each {reference} replaced by its [references] entry."""
        value = self.table.pop("sources", None)
        if not isinstance(value, list) or not value or not all(isinstance(s, str) for s in value):
            raise GtsamDvlError(f"{self.where}: 'sources' must be a non-empty list of strings")
        try:
            return tuple(s.format_map(self.references) for s in value)
        except KeyError as exc:
            raise GtsamDvlError(f"{self.where}: no reference {exc} in [references]") from None

    def done(self) -> None:
        if self.table:
            raise GtsamDvlError(f"{self.where}: unknown keys {', '.join(self.table)}")


def _imu_preset(entry: _PresetEntry, name: str) -> ImuPreset:
    preset = ImuPreset(
        name,
        entry.text("title"),
        gyro_noise_deg_per_h_rthz=entry.converted(_GYRO_NOISE_FORMS),
        accel_noise_ug_rthz=entry.converted(_ACCEL_NOISE_FORMS),
        **{key: entry.number(key) for key in _IMU_NUMBERS},
        sources=entry.sources(),
    )
    entry.done()
    return preset


def _dvl_preset(entry: _PresetEntry, name: str) -> DvlPreset:
    optional = {key: entry.number(key) for key in _DVL_OPTIONAL_NUMBERS if key in entry.table}
    preset = DvlPreset(
        name,
        entry.text("title"),
        **{key: entry.number(key) for key in _DVL_NUMBERS},
        sources=entry.sources(),
        **optional,
    )
    entry.done()
    return preset


def _load_presets() -> tuple[dict[str, ImuPreset], dict[str, DvlPreset]]:
    """presets.toml (shipped beside this module), read and validated once at import."""
    text = (importlib.resources.files("gtsam_dvl.core.config") / "presets.toml").read_text()
    data = tomllib.loads(text)
    references = data.pop("references")
    imu = {
        name: _imu_preset(_PresetEntry("imu", name, table, references), name)
        for name, table in data.pop("imu").items()
    }
    dvl = {
        name: _dvl_preset(_PresetEntry("dvl", name, table, references), name)
        for name, table in data.pop("dvl").items()
    }
    if data:
        raise GtsamDvlError(f"presets.toml: unknown tables {', '.join(data)}")
    return imu, dvl


IMU_PRESETS, DVL_PRESETS = _load_presets()


def imu_preset(name: str) -> ImuPreset:
    """The IMU preset of this name, else GtsamDvlError naming the known ones."""
    if name not in IMU_PRESETS:
        raise GtsamDvlError(f"no IMU preset '{name}' (known: {', '.join(IMU_PRESETS)})")
    return IMU_PRESETS[name]


def dvl_preset(name: str) -> DvlPreset:
    """The DVL preset of this name, else GtsamDvlError naming the known ones."""
    if name not in DVL_PRESETS:
        raise GtsamDvlError(f"no DVL preset '{name}' (known: {', '.join(DVL_PRESETS)})")
    return DVL_PRESETS[name]


def preset_table() -> list[str]:
    """Every preset, one line each: name, kind, key values."""
    rows = [("name", "kind", "values")]
    rows += [(p.name, "imu", p.summary()) for p in IMU_PRESETS.values()]
    rows += [(p.name, "dvl", p.summary()) for p in DVL_PRESETS.values()]
    width = max(len(r[0]) for r in rows)
    return [f"{n:<{width}}  {k:<4}  {v}" for n, k, v in rows]


def describe_preset(name: str) -> str:
    """One preset: its values, their sources and the TOML block that selects it."""
    if name in IMU_PRESETS:
        imu = IMU_PRESETS[name]
        values: dict[str, float] = imu.config_values()
        title, sources, section = imu.title, imu.sources, "imu"
        extra: list[str] = []
    elif name in DVL_PRESETS:
        dvl = DVL_PRESETS[name]
        values, title, sources, section = dvl.config_values(), dvl.title, dvl.sources, "dvl"
        extra = [
            f"ping noise {dvl.ping_noise_m_s:g} m/s at {dvl.ping_noise_speed_m_s:g} m/s; bottom track "
            f"{dvl.min_altitude_m:g}-{dvl.max_altitude_m:g} m altitude; beam angle {dvl.beam_angle_deg:g} deg"
        ]
    else:
        raise GtsamDvlError(
            f"no preset '{name}' (known: {', '.join([*IMU_PRESETS, *DVL_PRESETS])})"
        )
    lines = [f"{name}: {title}", *extra, "fills (unless the configuration sets them):"]
    lines += [f"  [{section}] {k} = {v:g}" for k, v in values.items()]
    if section == "dvl":
        accuracy = DVL_PRESETS[name].scale_accuracy
        lines.append(
            f"  [priors] scale_sigma = {accuracy:g} (scale accuracy +-{accuracy * 100:g} %)"
        )
    lines += [
        "sources:",
        *(f"  - {s}" for s in sources),
        "",
        "TOML:",
        f"[{section}]",
        f'model = "{name}"',
    ]
    return "\n".join(lines)
