"""In-memory log data: what the reader returns and the simulator produces.

All times are float64 seconds relative to ``t0_ns`` (integer nanoseconds of the log's time base,
ROS time), so that 100 Hz intervals stay exact to the nanosecond. Units are SI unless a name says
otherwise; names carry frames (see docs/conventions.md).

What the estimators and the evaluation rely on is typed (the map origin, the simulated truth of the
calibration, the biases and the segments): a renamed key fails the type check, not a run. `metadata` keeps
the rest for people and files (scenario settings, seed, sensor specification, reader warnings).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core.rotations import rpy_deg_to_matrix


class Stamped:
    """Samples stamped in time (the data classes below declare t and their per-sample arrays): len() is the
    number of samples."""

    t: np.ndarray  # (N,) s

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass
class ImuData(Stamped):
    """IMU samples. Sample i integrates the interval (t[i-1], t[i]]: its stamp is the interval's end.

    b_omega: gyro output, rate averaged over the interval (delta-theta / dt), rad/s, in imu_link.
    b_f: accelerometer output, specific force averaged over the interval (delta-v / dt), m/s^2.
    """

    t: np.ndarray  # (N,)
    b_omega: np.ndarray  # (N, 3) rad/s
    b_f: np.ndarray  # (N, 3) m/s^2
    frame_id: str = "imu_link"


@dataclass
class BeamData:
    """Per-beam DVL data, beam j of epoch i. d_u: unit vector of the beam in dvl_link (pointing from the
    DVL towards the bottom); v: beam velocity y_j = d_u_j . y in m/s; range: slant range in m."""

    d_u: np.ndarray  # (M, B, 3)
    v: np.ndarray  # (M, B) m/s
    range: np.ndarray  # (M, B) m
    valid: np.ndarray  # (M, B) bool


@dataclass
class DvlData(Stamped):
    """DVL bottom-track velocity y in dvl_link at each stamp (instantaneous), with its 3x3 covariance."""

    t: np.ndarray  # (M,)
    d_v: np.ndarray  # (M, 3) m/s, NaN where not valid
    d_cov: np.ndarray  # (M, 3, 3) m^2/s^2
    valid: np.ndarray  # (M,) bool: the 3-D velocity is usable
    beams: BeamData | None = None
    frame_id: str = "dvl_link"
    # (M,) bool: water-track pings (velocity relative to the water, its own mode in the message), never valid
    # as velocity over ground; their d_v (and beam velocities) are kept, finite where measured; None: none
    water_track: np.ndarray | None = None
    # a simulation without white noise: its velocity repeats bit for bit at constant velocity, which a real
    # DVL's never does (estimators/inputs/ping_screen.py drops such repeats as frozen output unless this is set)
    noise_free: bool = False
    # (M,) m: the DVL's range to the seafloor along the vertical (the message's altitude), NaN where not known or
    # out of bottom-track range; None: the log has none
    altitude: np.ndarray | None = None


@dataclass
class TruthData(Stamped):
    """Simulated truth of base_link in the map frame."""

    t: np.ndarray  # (K,)
    n_p: np.ndarray  # (K, 3) m, map frame (ENU at the origin)
    n_q_b: np.ndarray  # (K, 4) [x, y, z, w], rotates base_link vectors into map
    n_v: np.ndarray  # (K, 3) m/s, velocity relative to the Earth, in map
    b_omega: np.ndarray  # (K, 3) rad/s, body rate relative to map, in base_link
    # (K, 3) m/s: the water current in map at base_link's depth and time (vertical component 0); None: no current
    n_c: np.ndarray | None = None


@dataclass
class Mounting:
    """Nominal sensor mounting from /tf_static: rotations into base_link and the DVL lever arm."""

    b_R_imu: np.ndarray = field(default_factory=lambda: np.eye(3))
    b_p_imu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    b_R_d0: np.ndarray = field(default_factory=lambda: np.eye(3))  # nominal DVL mounting
    b_p_dvl: np.ndarray = field(default_factory=lambda: np.zeros(3))  # DVL origin in base_link, m

    @property
    def b_l(self) -> np.ndarray:
        """Lever arm from the IMU to the DVL in base_link, m."""
        return np.asarray(self.b_p_dvl - self.b_p_imu, dtype=float)


@dataclass(frozen=True)
class DvlCalibration:
    """DVL scale factor and misalignment: b_R_d = R_c * b_R_d0 with R_c = Rz(yaw) Ry(pitch) Rx(roll)
    in body FLU axes (docs/conventions.md). misalignment_deg = [roll, pitch, yaw]."""

    scale: float
    misalignment_deg: tuple[float, float, float]
    # DVL-IMU time offset dt_d: the ping stamped t measures the velocity at t + dt_d
    time_offset_s: float = 0.0

    @property
    def R_c(self) -> np.ndarray:
        return rpy_deg_to_matrix(self.misalignment_deg)

    def b_R_d(self, b_R_d0: np.ndarray) -> np.ndarray:
        return self.R_c @ b_R_d0


@dataclass(frozen=True)
class GeoOrigin:
    """Geodetic origin of the map frame on WGS84: latitude and longitude in degrees, height in metres
    (ellipsoidal). Earth rate and gravity in map depend on it."""

    lat_deg: float
    lon_deg: float
    height_m: float

    def as_dict(self) -> dict[str, float]:
        return {"lat_deg": self.lat_deg, "lon_deg": self.lon_deg, "height_m": self.height_m}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> GeoOrigin:
        return cls(float(d["lat_deg"]), float(d["lon_deg"]), float(d["height_m"]))


@dataclass(frozen=True)
class ImuBiases:
    """IMU biases in SI: accelerometer m/s^2 and gyro rad/s, in imu_link (the truth of a simulated log: its
    random constants, or the values at t = 0 of a random walk)."""

    accel_m_s2: tuple[float, float, float]
    gyro_rad_s: tuple[float, float, float]


SEGMENT_KINDS = (
    "static",
    "level",
    "descent",
    "ascent",
    "straight",
    "turn",
    "square",
    "type1",
    "motion",
)


@dataclass(frozen=True)
class Segment:
    """A stretch of a log with one kind of motion: [start_s, end_s] relative to the log's t0, its kind (static,
    level, descent, ascent, straight, turn, ...) and the paper's segment type ("-", "I", "II", "I and II")."""

    start_s: float
    end_s: float
    kind: str
    type: str = "-"

    def label(self) -> str:
        return f"{self.kind} {self.start_s:.0f}-{self.end_s:.0f} s"

    def as_dict(self) -> dict[str, Any]:
        return {"start_s": self.start_s, "end_s": self.end_s, "kind": self.kind, "type": self.type}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Segment:
        return cls(float(d["start_s"]), float(d["end_s"]), str(d["kind"]), str(d.get("type", "-")))


@dataclass
class DepthData(Stamped):
    """Depth of the pressure sensor (positive down, metres below the water surface) at each stamp.

    From a pressure topic (sensor_msgs/msg/FluidPressure) pressure_pa and pressure_variance_pa2 hold the
    absolute pressure and its variance as measured; depth_m and variance_m2 are then the reader's
    conversion with the defaults of core/earth.py (pressure_to_depth), and the estimators convert the pressure
    again with the [depth] section of the configuration (water density, atmospheric pressure). From a depth
    topic (a pose's z) pressure_pa is None and depth_m is used as it is. NaN variance: unknown.
    b_p_sensor: the sensor's position in base_link from /tf_static (None if the log has none).
    """

    t: np.ndarray  # (K,)
    depth_m: np.ndarray  # (K,) m, positive down
    variance_m2: np.ndarray  # (K,) m^2, NaN where unknown
    pressure_pa: np.ndarray | None = None  # (K,) absolute pressure, Pa
    pressure_variance_pa2: np.ndarray | None = None  # (K,) Pa^2, NaN where unknown
    frame_id: str = "pressure_link"
    b_p_sensor: np.ndarray | None = None


@dataclass
class GnssData(Stamped):
    """GNSS fixes of the antenna (sensor_msgs/msg/NavSatFix), geodetic on WGS84, taken at the surface.

    status: the message's NavSatStatus.status (-1 no fix, 0 fix, 1 SBAS, 2 GBAS/RTK); a fix with status < 0
    or a non-finite latitude is not a fix. cov_enu_m2: the message's position_covariance (ROS: East, North,
    Up, m^2), NaN where the message says unknown (position_covariance_type 0). b_p_antenna: the antenna in
    base_link from /tf_static (None if the log has none).
    """

    t: np.ndarray  # (K,)
    lat_deg: np.ndarray  # (K,)
    lon_deg: np.ndarray  # (K,)
    height_m: np.ndarray  # (K,) ellipsoidal height
    cov_enu_m2: np.ndarray  # (K, 3, 3) m^2, NaN where unknown
    status: np.ndarray  # (K,) int
    frame_id: str = "gnss_link"
    b_p_antenna: np.ndarray | None = None


@dataclass
class AttitudeData(Stamped):
    """Attitude of base_link in map from a sensor (an IMU's or AHRS's orientation, an INS pose), already
    turned into base_link and ENU by the reader. cov_rad2: covariance of the attitude error in body axes
    (rad^2), NaN where unknown. source: the topic it came from, for messages."""

    t: np.ndarray  # (K,)
    n_q_b: np.ndarray  # (K, 4) [x, y, z, w], rotates base_link vectors into map (ENU)
    cov_rad2: np.ndarray  # (K, 3, 3) rad^2
    source: str = ""


@dataclass
class LogData:
    """Everything one log holds, as numpy arrays. truth and the true_* fields are None for real logs."""

    imu: ImuData
    dvl: DvlData
    mounting: Mounting = field(default_factory=Mounting)
    truth: TruthData | None = None
    t0_ns: int = 0  # ROS time of t = 0
    # scenario, seed, sensor spec, reader warnings
    metadata: dict[str, Any] = field(default_factory=dict)
    source: str = ""  # file the data came from, for messages
    origin: GeoOrigin | None = None  # map origin, when the log records one
    true_calibration: DvlCalibration | None = None  # simulated logs
    true_imu_bias: ImuBiases | None = None  # simulated logs
    segments: list[Segment] = field(default_factory=list)  # simulated logs: the scenario's segments
    depth: DepthData | None = None  # pressure sensor or depth topic, when the log has one
    gnss: GnssData | None = None  # GNSS fixes (at the surface), when the log has them
    # an attitude sensor (IMU orientation, AHRS, INS), when read
    attitude: AttitudeData | None = None
