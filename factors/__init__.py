"""Custom GTSAM factors for the DVL (installed as gtsam_dvl.factors).

Both factors implement, on the keys [pose n_T_b, velocity n_v, scale k, misalignment b_R_d],

    y = k * b_R_d^T * ( n_R_b^T * n_v  +  b_omega x b_l ) + noise

the 3-D velocity y in dvl_link (make_dvl_velocity_factor) or one beam y_j = d_u_j . y
(make_dvl_beam_factor). make_depth_factor puts a depth sensor's measurement on a pose's vertical position
(factors/depth.py). The pure error functions serve tests and other callers. The *_lever variants take the
lever arm b_l (m, base_link) as one more variable, a 3-vector key after the others ([dvl] estimate_lever_arm).
make_dvl_keyframe_factor puts a ping between keyframes on the keyframe before it, through the IMU motion up to
the ping (factors/dvl_keyframe.py, [solver] keyframe_spacing_s).
"""

from .depth import depth_error, make_depth_factor
from .dvl_beam import dvl_beam_error, make_dvl_beam_factor
from .dvl_beam_lever import dvl_beam_lever_error, make_dvl_beam_lever_factor
from .dvl_keyframe import PingMotion, dvl_keyframe_error, keyframe_ping_covariance, make_dvl_keyframe_factor
from .dvl_velocity import (
    dvl_velocity_error,
    dvl_velocity_lever_error,
    dvl_velocity_offset_error,
    dvl_velocity_offset_lever_error,
    make_dvl_velocity_factor,
    make_dvl_velocity_lever_factor,
    make_dvl_velocity_offset_factor,
    make_dvl_velocity_offset_lever_factor,
)
from .gnss import gnss_error, make_gnss_factor
from .imu_earth import EarthImuFactor, GravityModel, make_earth_imu_factor

__all__ = [
    "EarthImuFactor",
    "PingMotion",
    "dvl_keyframe_error",
    "keyframe_ping_covariance",
    "make_dvl_keyframe_factor",
    "GravityModel",
    "make_earth_imu_factor",
    "depth_error",
    "make_depth_factor",
    "dvl_beam_error",
    "dvl_beam_lever_error",
    "dvl_velocity_error",
    "dvl_velocity_lever_error",
    "dvl_velocity_offset_error",
    "gnss_error",
    "dvl_velocity_offset_lever_error",
    "make_dvl_beam_factor",
    "make_dvl_beam_lever_factor",
    "make_dvl_velocity_factor",
    "make_dvl_velocity_lever_factor",
    "make_dvl_velocity_offset_factor",
    "make_gnss_factor",
    "make_dvl_velocity_offset_lever_factor",
]
