"""Custom GTSAM factors for the DVL (installed as gtsam_dvl.factors).

The DVL measurement model (factors/dvl_model.py, one function for one ping or N),

    y = k * b_R_d^T * ( n_R_b^T * n_v  [+ dt_d * b_vdot]  +  b_omega x b_l ) + noise,

on the keys [pose n_T_b, velocity n_v, scale k, misalignment b_R_d] with its options: a time offset dt_d, the lever
arm b_l (m, base_link) as a variable, one beam y_j = d_u_j . y, a ping between keyframes seen from the keyframe
before it through the IMU motion (factors/ping_motion.py, [solver] keyframe_spacing_s). make_dvl_factor
(factors/dvl.py) is its GTSAM factor, factors/dvl_bulk.py its evaluation for N pings at once (the batch smoother).
make_depth_factor puts a depth sensor's measurement on a pose's vertical position (factors/depth.py),
make_gnss_factor a GNSS fix on the antenna's position (factors/gnss.py), EarthImuFactor GTSAM's ImuFactor with
gravity following the position (factors/imu_earth.py). Rotation helpers: factors/so3.py.
"""

from .depth import depth_error, make_depth_factor
from .dvl import (
    DvlOptions,
    dvl_beam_error,
    dvl_error,
    dvl_velocity_error,
    dvl_velocity_offset_error,
    make_dvl_beam_factor,
    make_dvl_factor,
    make_dvl_velocity_factor,
)
from .dvl_model import DvlJacobians, OffsetInput, dvl_model
from .gnss import gnss_error, make_gnss_factor
from .imu_earth import EarthImuFactor, GravityModel, make_earth_imu_factor
from .ping_motion import PingMotion, keyframe_ping_covariance, ping_state

__all__ = [
    "DvlJacobians",
    "DvlOptions",
    "EarthImuFactor",
    "GravityModel",
    "OffsetInput",
    "PingMotion",
    "depth_error",
    "dvl_beam_error",
    "dvl_error",
    "dvl_model",
    "dvl_velocity_error",
    "dvl_velocity_offset_error",
    "gnss_error",
    "keyframe_ping_covariance",
    "make_depth_factor",
    "make_dvl_beam_factor",
    "make_dvl_factor",
    "make_dvl_velocity_factor",
    "make_earth_imu_factor",
    "make_gnss_factor",
    "ping_state",
]
