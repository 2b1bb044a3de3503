"""The paper's error-state EKF (filter.py) on a strapdown in the Earth-fixed map frame (strapdown.py)."""

from gtsam_dvl.estimators.ekf.filter import run_ekf
from gtsam_dvl.estimators.ekf.measurements import measurement_model
from gtsam_dvl.estimators.ekf.strapdown import FilterState

__all__ = ["FilterState", "measurement_model", "run_ekf"]
