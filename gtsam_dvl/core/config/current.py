"""[current]: water-track pings and the water current they need (estimators/models/current.py).

A DVL that loses the seafloor (out of range on a descent, over steep terrain, in mid-water) measures its velocity
relative to a water layer instead: a water-track ping (velocity_mode 2 of marine_acoustic_msgs/msg/Dvl, or a
separate topic). Such a ping is the bottom-track model with the vehicle's velocity relative to the water,
n_v - n_c, where n_c = [c_east, c_north, 0] is the horizontal current in map: the same scale, misalignment and lever
arm (docs/conventions.md). With water_track "auto" (the default) a log's water-track pings are used when it has
any, and the estimators then carry the current as a state of every epoch W(i):

- its first value has the prior N(0, prior_sigma_m_s^2) per axis;
- it moves as a random walk in time and in depth: between two states dt s and dz m apart its change has the
  variance time_rw_m_s_per_sqrt_s^2 dt + depth_rw_m_s_per_sqrt_m^2 |dz| per axis. The time term is the slow
  change of the current at one place (tides: ~0.1 m/s an hour, 1.7e-3 m/s/sqrt(s)); the depth term the shear met
  descending or ascending through the water column (0.25 m/s over 300 m is 0.014 m/s/sqrt(m)).

Water-track pings have their own noise: the message's covariance, or water_track_sigma_m_s per axis when set (> 0),
or water_track_default_sigma_m_s for a message without one (a water-track ping averages over a water layer whose
own turbulence adds to the Doppler noise; about twice a bottom-track ping's on 300-600 kHz units, typical of the
class), scaled like every DVL sigma by [dvl] noise_multiplier. water_track "refuse" counts them
("dvl_water_track") and leaves them out, as does a log without them. With water_track_scale the water-track pings
have their own scale factor (a DVL whose water-track calibration differs from its bottom track's; batch and
online), the misalignment and lever arm still shared. Each estimator resolves "auto" for its log
(current.resolve_water_track): its result's configuration says "use" or "refuse".

With layer_thickness_m > 0 the depth dependence is per layer: the water column is cut into layers of that
thickness from the surface down, the current is uniform within a layer up to a random walk in time shared by all
of them, and the change across each boundary crossed is a state with the variance depth_rw_m_s_per_sqrt_m^2 times
the thickness. A vehicle that descends and ascends through the same water meets the same layers twice, and the
pings of both passes inform one current per layer.
"""

from __future__ import annotations

from typing import ClassVar, Literal

from gtsam_dvl.core.config.base import ConfigModel, Flag, NonNegative, Positive


class CurrentConfig(ConfigModel):
    SECTION: ClassVar[str] = "current"

    # "auto": use water-track pings when the log has any (each estimator resolves it to "use" or "refuse" for the
    # log: its effective configuration says which); "use": always, the current a state even without them;
    # "refuse": never
    water_track: Literal["auto", "use", "refuse"] = "auto"
    # a water-track ping's white noise per axis, m/s: > 0 overrides the message's covariance; 0 takes it, and a
    # message without one takes water_track_default_sigma_m_s
    water_track_sigma_m_s: NonNegative = 0.0
    water_track_default_sigma_m_s: Positive = 0.01
    prior_sigma_m_s: Positive = 0.5  # the first state's current, per horizontal axis, m/s (mean 0)
    time_rw_m_s_per_sqrt_s: Positive = 1.0e-3  # the current's random walk in time, m/s/sqrt(s)
    depth_rw_m_s_per_sqrt_m: Positive = 0.02  # and in depth (shear), m/s/sqrt(m)
    # a DVL whose water-track calibration differs from its bottom track's: the water-track pings get their own scale
    # factor k_w (a shared state, "water_scale", batch and online), k_w - k ~ N(0, (sigma k_0)^2), sigma this
    # fraction (1 %: a DVL's water-track and bottom-track scales differ by less, typical of the class)
    water_track_scale: Flag = False
    water_track_scale_sigma: Positive = 0.01
    # > 0: the current per depth layer of this thickness (m, from the water surface down) plus one random walk in
    # time shared by every layer, instead of the random walk in depth per state (estimators/models/current.py,
    # "Layers"): a layer crossed on the descent and again on the ascent is one unknown, not two
    layer_thickness_m: NonNegative = 0.0
