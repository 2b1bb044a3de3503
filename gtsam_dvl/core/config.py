"""Estimator configuration with documented defaults (the paper's sensors), loadable from TOML.

Every field carries its unit in its name. `EstimatorConfig.from_toml(path)` reads a file with the
same sections as the dataclasses ([imu], [dvl], [priors], [alignment], [solver]); unknown keys are an
error so a typo never goes unnoticed. The effective configuration is written next to every result.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gtsam_dvl.core.errors import GtsamDvlError


@dataclass
class ImuConfig:
    """IMU noise model. Densities are white noise; bias sigmas are the priors of the random-constant bias."""

    gyro_noise_deg_per_h_rthz: float = 0.1
    accel_noise_ug_rthz: float = 10.0
    gyro_bias_sigma_deg_per_h: float = 0.01
    accel_bias_sigma_ug: float = 50.0
    bias_model: str = "constant"  # "constant" (the paper's random constant) or "random_walk"
    gyro_bias_rw_deg_per_h_per_rth: float = 0.001  # random-walk density, (deg/h)/sqrt(h), random_walk only
    accel_bias_rw_ug_per_rth: float = 1.0  # micro-g/sqrt(h), random_walk only
    integration_sigma_m_rts: float = 1e-5  # position integration noise of the preintegration, m/sqrt(s)
    rotation_compensation: bool = True  # rotate each delta-v to its interval start (see graph.py)


@dataclass
class DvlConfig:
    """DVL measurement model options."""

    noise_m_s: float = 0.0  # >0 overrides the per-message covariance with an isotropic sigma
    default_noise_m_s: float = 0.02  # used when a message has no covariance (TwistStamped)
    use_beams: bool = False  # one scalar factor per valid beam instead of the 3-D velocity
    beam_noise_m_s: float = 0.02
    robust: str = "none"  # "none" or "huber"
    huber_k: float = 3.0  # in sigmas
    max_speed_m_s: float = 10.0  # faster pings are outliers: dropped and counted


@dataclass
class PriorConfig:
    """Priors. The scale starts at 0.8 and the misalignment at the nominal mounting, as in the paper."""

    scale_initial: float = 0.8
    scale_sigma: float = 0.5
    misalignment_sigma_deg: tuple[float, float, float] = (1.0, 1.0, 1.0)
    roll_pitch_sigma_deg: float = 1.0  # around the coarse alignment
    yaw_sigma_deg: float = 5.0
    position_sigma_m: float = 0.01  # the first state defines the map origin
    velocity_sigma_m_s: float = 1.0


@dataclass
class AlignmentConfig:
    """Coarse alignment on the initial static segment, or a configured initial attitude."""

    initial_attitude_deg: tuple[float, float, float] | None = None  # [roll, pitch, yaw]; skips alignment
    min_static_s: float = 30.0
    max_static_s: float = 0.0  # 0: use the whole detected static segment
    accel_threshold_m_s2: float = 0.002  # 1 s means of the specific force within this of the first 10 s
    gyro_threshold_deg_s: float = 0.01  # 1 s means of the gyro within this of the first 10 s
    dvl_speed_threshold_m_s: float = 0.1
    origin_lat_deg: float | None = None  # map origin when the log has none (needed for Earth rate/gravity)
    origin_lon_deg: float | None = None
    origin_height_m: float | None = None


@dataclass
class SolverConfig:
    max_iterations: int = 30
    relative_error_tol: float = 1e-7
    absolute_error_tol: float = 0.01  # error = chi^2 / 2: a decrease this small moves no estimate by 0.1 sigma
    earth_model: str = "wgs84"  # "wgs84" (default) or "flat": no Earth rate, constant gravity (low-grade IMUs)
    keyframe_interval_s: float = 0.0  # 0: a state per DVL ping; >0: only pings at least this far apart


@dataclass
class EstimatorConfig:
    imu: ImuConfig = field(default_factory=ImuConfig)
    dvl: DvlConfig = field(default_factory=DvlConfig)
    priors: PriorConfig = field(default_factory=PriorConfig)
    alignment: AlignmentConfig = field(default_factory=AlignmentConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> EstimatorConfig:
        cfg = cls()
        for section, values in data.items():
            if not hasattr(cfg, section) or not isinstance(values, dict):
                raise GtsamDvlError(f"{source}: unknown section [{section}]")
            sub = getattr(cfg, section)
            names = {f.name for f in dataclasses.fields(sub)}
            for key, value in values.items():
                if key not in names:
                    raise GtsamDvlError(f"{source}: unknown key '{key}' in [{section}] (known: {sorted(names)})")
                current = getattr(sub, key)
                if isinstance(current, tuple) or (current is None and isinstance(value, list)):
                    value = tuple(value)
                setattr(sub, key, value)
        return cfg

    @classmethod
    def from_toml(cls, path: Path | str) -> EstimatorConfig:
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except tomllib.TOMLDecodeError as exc:
            raise GtsamDvlError(f"{path}: not valid TOML ({exc})") from None
        return cls.from_dict(data, source=str(path))
