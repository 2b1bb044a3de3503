"""In-memory log data: what the reader returns and the simulator produces.

All times are float64 seconds relative to ``t0_ns`` (integer nanoseconds of the log's time base,
ROS time), so that 100 Hz intervals stay exact to the nanosecond. Units are SI unless a name says
otherwise; names carry frames (see CONVENTIONS.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gtsam_dvl.core.rotations import rpy_deg_to_matrix


@dataclass
class ImuData:
    """IMU samples. Sample i integrates the interval (t[i-1], t[i]]: its stamp is the interval's end.

    b_omega: gyro output, rate averaged over the interval (delta-theta / dt), rad/s, in imu_link.
    b_f: accelerometer output, specific force averaged over the interval (delta-v / dt), m/s^2.
    """

    t: np.ndarray  # (N,)
    b_omega: np.ndarray  # (N, 3) rad/s
    b_f: np.ndarray  # (N, 3) m/s^2
    frame_id: str = "imu_link"

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass
class BeamData:
    """Per-beam DVL data, beam j of epoch i. d_u: unit vector of the beam in dvl_link (pointing from the
    DVL towards the bottom); v: beam velocity y_j = d_u_j . y in m/s; range: slant range in m."""

    d_u: np.ndarray  # (M, B, 3)
    v: np.ndarray  # (M, B) m/s
    range: np.ndarray  # (M, B) m
    valid: np.ndarray  # (M, B) bool


@dataclass
class DvlData:
    """DVL bottom-track velocity y in dvl_link at each stamp (instantaneous), with its 3x3 covariance."""

    t: np.ndarray  # (M,)
    d_v: np.ndarray  # (M, 3) m/s, NaN where not valid
    d_cov: np.ndarray  # (M, 3, 3) m^2/s^2
    valid: np.ndarray  # (M,) bool: the 3-D velocity is usable
    beams: BeamData | None = None
    frame_id: str = "dvl_link"

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass
class TruthData:
    """Simulated truth of base_link in the map frame."""

    t: np.ndarray  # (K,)
    n_p: np.ndarray  # (K, 3) m, map frame (ENU at the origin)
    n_q_b: np.ndarray  # (K, 4) [x, y, z, w], rotates base_link vectors into map
    n_v: np.ndarray  # (K, 3) m/s, velocity relative to the Earth, in map
    b_omega: np.ndarray  # (K, 3) rad/s, body rate relative to map, in base_link

    def __len__(self) -> int:
        return int(self.t.shape[0])


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
    in body FLU axes (CONVENTIONS.md). misalignment_deg = [roll, pitch, yaw]."""

    scale: float
    misalignment_deg: tuple[float, float, float]

    @property
    def R_c(self) -> np.ndarray:
        return rpy_deg_to_matrix(self.misalignment_deg)

    def b_R_d(self, b_R_d0: np.ndarray) -> np.ndarray:
        return self.R_c @ b_R_d0


@dataclass
class LogData:
    """Everything one log holds, as numpy arrays. truth is None for real logs."""

    imu: ImuData
    dvl: DvlData
    mounting: Mounting = field(default_factory=Mounting)
    truth: TruthData | None = None
    t0_ns: int = 0  # ROS time of t = 0
    metadata: dict[str, Any] = field(default_factory=dict)  # scenario, seed, truth calibration, config
    source: str = ""  # file the data came from, for messages

    @property
    def true_calibration(self) -> DvlCalibration | None:
        cal = self.metadata.get("truth", {}).get("dvl")
        if not cal:
            return None
        return DvlCalibration(float(cal["scale"]), tuple(cal["misalignment_deg"]))  # type: ignore[arg-type]
