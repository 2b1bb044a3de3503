"""gtsam_dvl: self-calibrating IMU + DVL navigation on GTSAM."""

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import BeamData, DvlCalibration, DvlData, ImuData, LogData, Mounting, TruthData

__version__ = "0.1.0"

__all__ = [
    "BeamData",
    "DvlCalibration",
    "DvlData",
    "GtsamDvlError",
    "ImuData",
    "LogData",
    "Mounting",
    "TruthData",
    "__version__",
]
