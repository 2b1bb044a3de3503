"""Estimator configuration with documented defaults (the paper's sensors), loadable from TOML.

Every field carries its unit in its name. `EstimatorConfig.from_toml(path)` reads a file with the same
sections as the dataclasses: [imu], [dvl], [priors], [alignment], [solver] (the models, shared by every
estimator), [online] and [online.relinearization] (the iSAM2 estimator), [ekf] (the filter), [iodvlc]
(the ideal observer), [depth] (the depth sensor) and [gnss] (GNSS fixes). It also reads the JSON of an
effective configuration, as written with every result (config.json: {"estimator": ..., "config": {...}}, or the
bare configuration).

Everything is checked by value on load: unknown sections and keys, enumerations (Literal fields: one of
their values), types (a string where a number belongs, a float where an integer belongs) and ranges (declared
in each field's metadata: POSITIVE, NON_NEGATIVE, ...). The error is one line naming the file, section, key,
the bad value and what is allowed. An optional field (`X | None`) takes None (JSON null) or, in a TOML
file, which has no null, the string "none" or no entry where None is its default. `validate()` checks a
configuration built or changed in Python the same way; the estimators call it when they start. `to_dict()`
(None kept, for JSON) and `to_toml()` read back with `from_dict` / `from_toml` to an equal configuration.
"""

from __future__ import annotations

import dataclasses
import json
import math
import numbers
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError

# Range of a number (or of every element of a tuple of numbers), in a field's metadata.
POSITIVE: Mapping[str, float] = {"gt": 0.0}
NON_NEGATIVE: Mapping[str, float] = {"ge": 0.0}

BiasModel = Literal["constant", "random_walk"]
RobustLoss = Literal["none", "huber", "cauchy"]
EarthModel = Literal["wgs84", "flat"]
OnlineMode = Literal["fixed_lag", "full"]
BadMessages = Literal["raise", "drop"]


class _Section:
    """A section of the configuration: checked field by field against its type and metadata."""

    SECTION: ClassVar[str] = ""

    def validate(self, source: str = "config") -> None:
        """Check every value against its field's type and range (GtsamDvlError, one line); numbers are made
        float where a float belongs and sequences tuples."""
        _check_fields(self, source, self.SECTION)


@dataclass
class ImuConfig(_Section):
    """IMU noise model. Densities are white noise; bias sigmas are the priors of the random-constant bias."""

    SECTION: ClassVar[str] = "imu"

    gyro_noise_deg_per_h_rthz: float = field(default=0.1, metadata=POSITIVE)
    accel_noise_ug_rthz: float = field(default=10.0, metadata=POSITIVE)
    gyro_bias_sigma_deg_per_h: float = field(default=0.01, metadata=POSITIVE)
    accel_bias_sigma_ug: float = field(default=50.0, metadata=POSITIVE)
    bias_model: BiasModel = "constant"  # "constant" (the paper's random constant) or "random_walk"
    # random-walk density, (deg/h)/sqrt(h), random_walk only
    gyro_bias_rw_deg_per_h_per_rth: float = field(default=0.001, metadata=POSITIVE)
    accel_bias_rw_ug_per_rth: float = field(default=1.0, metadata=POSITIVE)  # micro-g/sqrt(h), random_walk only
    # position integration noise of the preintegration, m/sqrt(s)
    integration_sigma_m_rts: float = field(default=1e-5, metadata=NON_NEGATIVE)
    rotation_compensation: bool = True  # rotate each delta-v to its interval start (see factor_maker.py)
    # IMU gaps (estimators/gaps.py): a spacing longer than this many nominal periods is a gap, crossed by
    # holding the last sample with the motion-model uncertainty below added to the covariance
    gap_samples: float = field(default=3.0, metadata={"gt": 1.0})
    gap_accel_sigma_m_s2: float = field(default=0.2, metadata=POSITIVE)  # change of acceleration over a gap
    gap_rate_sigma_deg_s: float = field(default=1.0, metadata=POSITIVE)  # change of turn rate over a gap
    # longer gaps are an error: a hold that long is no motion model (its error is systematic, not white)
    max_gap_s: float = field(default=10.0, metadata=POSITIVE)


@dataclass
class DvlConfig(_Section):
    """DVL measurement model options, and the screening of bogus pings before estimation.

    Robust loss (batch and online: on every DVL factor; EKF: the same kernel's weight on the whitened
    innovation, after the chi^2 gate of [ekf] gate_probability): "huber" (default), "cauchy" or "none".
    robust_k is the kernel's threshold in sigmas of the whitened error (the norm of the 3-D error, or one
    beam's). huber_k is its old name, kept as an alias: when set it overrides robust_k.

    Screening (estimators/selection.py, PingScreen; the same causal rule in batch, online and EKF, against
    the previous accepted ping and the IMU samples stamped since it), on when screen is true:
    - an exact zero velocity (all three components 0.0) while moving, i.e. the IMU shows motion since the
      previous accepted ping (the body's velocity changed by more than motion_dv_m_s by the specific force,
      gravity turned by the gyro) or that ping was faster than moving_speed_m_s: "dvl_zero_while_moving";
    - a velocity bit-identical to the previous accepted ping's while the IMU shows motion: "dvl_repeated";
    - a velocity change |dv| since the previous accepted ping larger than
      max_accel_m_s2 dt + accel_imu_factor * (the change the IMU allows over dt) + jump_margin_m_s:
      "dvl_implausible_accel" (3-D velocity only, not with use_beams).
    A real DVL's velocity is noisy: it never reads exact zeros, nor repeats a reading bit for bit; a
    simulator without noise does both, at rest and at constant velocity (the IMU then shows no motion).
    """

    SECTION: ClassVar[str] = "dvl"

    noise_m_s: float = field(default=0.0, metadata=NON_NEGATIVE)  # >0 overrides the per-message covariance
    default_noise_m_s: float = field(default=0.02, metadata=POSITIVE)  # for messages without a covariance
    use_beams: bool = False  # one scalar factor per valid beam instead of the 3-D velocity
    beam_noise_m_s: float = field(default=0.02, metadata=POSITIVE)
    robust: RobustLoss = "huber"  # "huber" (default), "cauchy" or "none"
    # kernel threshold, in sigmas: 4 leaves a clean log's estimates within 0.02 sigma of no kernel on paper-3d
    # (3: up to 0.1 sigma), and a 0.5-2 m/s outlier (25-100 sigma) still counts like a 4 sigma residual
    robust_k: float = field(default=4.0, metadata=POSITIVE)
    huber_k: float | None = field(default=None, metadata=POSITIVE)  # old name of robust_k (overrides it if set)
    max_speed_m_s: float = field(default=10.0, metadata=POSITIVE)  # faster pings are outliers: dropped, counted
    screen: bool = True  # drop bogus pings (zero while moving, repeated, implausible acceleration): see above
    # no vehicle this package navigates accelerates this hard over a ping interval, m/s^2
    max_accel_m_s2: float = field(default=2.0, metadata=POSITIVE)
    # multiple of the velocity change the IMU allows (specific-force change, gravity turned by the gyro)
    accel_imu_factor: float = field(default=5.0, metadata=NON_NEGATIVE)
    jump_margin_m_s: float = field(default=0.3, metadata=NON_NEGATIVE)  # DVL noise of the two pings' difference
    # the IMU shows motion when it says the DVL's velocity changed by more than this since the previous ping
    motion_dv_m_s: float = field(default=0.05, metadata=POSITIVE)
    moving_speed_m_s: float = field(default=0.1, metadata=POSITIVE)  # a previous ping this fast: moving
    # DVL-IMU time offset dt_d (docs/conventions.md: the ping stamped t measures the velocity at t + dt_d): a graph
    # variable T_OFFSET with this prior (batch, online), an EKF state; a tiny sigma fixes it at the prior value.
    # On by default (real DVL stamps are 0.05-1.5 s off the IMU's); off (the "paper" configuration): every
    # estimator takes dt_d = 0 and the prior value is not used
    estimate_time_offset: bool = True
    time_offset_prior_s: float = 0.0
    time_offset_sigma_s: float = field(default=0.5, metadata=POSITIVE)
    # half-width of the IMU window averaged for the epoch's velocity rate (the time offset's Jacobian), s
    time_offset_window_s: float = field(default=0.25, metadata=POSITIVE)
    # DVL lever arm b_l (IMU -> DVL, m, base_link; docs/conventions.md), batch smoother only: a graph variable
    # L_LEVER with a prior around the /tf_static value (LogData.mounting.b_l), lever_arm_sigma_m per axis. Off by
    # default: then every estimator takes b_l from /tf_static. Observable only from rotation (b_omega x b_l): a
    # lever arm along the rotation axis of every turn stays at its prior
    estimate_lever_arm: bool = False
    lever_arm_sigma_m: float = field(default=0.5, metadata=POSITIVE)

    def robust_threshold(self) -> float:
        """The robust kernel's threshold in sigmas: huber_k if set (the old name), else robust_k."""
        return self.robust_k if self.huber_k is None else self.huber_k


@dataclass
class PriorConfig(_Section):
    """Priors. The defaults are those of a real DVL: scale 1 +- 1 % (a DVL's scale is 1 within its
    specification, 0.1-1 %, unless the speed of sound it assumes is wrong) and misalignment 1 deg per axis
    around the nominal mounting. The paper's priors (scale 0.8 +- 0.5: a convergence test) are the named
    configuration "paper" (NAMED_CONFIGS), which the paper's scenarios and the demo use."""

    SECTION: ClassVar[str] = "priors"

    scale_initial: float = field(default=1.0, metadata=POSITIVE)
    scale_sigma: float = field(default=0.01, metadata=POSITIVE)
    misalignment_sigma_deg: tuple[float, float, float] = field(default=(1.0, 1.0, 1.0), metadata=POSITIVE)
    roll_pitch_sigma_deg: float = field(default=1.0, metadata=POSITIVE)  # around the coarse alignment
    yaw_sigma_deg: float = field(default=5.0, metadata=POSITIVE)
    position_sigma_m: float = field(default=0.01, metadata=POSITIVE)  # the first state defines the map origin
    velocity_sigma_m_s: float = field(default=1.0, metadata=POSITIVE)


@dataclass
class AlignmentConfig(_Section):
    """The initial attitude (estimators/alignment.py align): method "auto" takes, in this order, an attitude
    sensor in the log (LogData.attitude), initial_attitude_deg, coarse alignment on an initial static segment
    of at least min_static_s, else in-motion alignment with DVL aiding over the first in_motion_window_s.
    "attitude_topic", "static" and "in_motion" force one method (an error if it cannot be done)."""

    SECTION: ClassVar[str] = "alignment"

    initial_attitude_deg: tuple[float, float, float] | None = None  # [roll, pitch, yaw]; skips alignment
    method: Literal["auto", "attitude_topic", "static", "in_motion"] = "auto"
    in_motion_window_s: float = field(default=120.0, metadata={"ge": 10.0})  # in-motion alignment window
    # attitude sensor sigmas (roll/pitch, yaw) when its messages give no covariance
    attitude_sigma_deg: tuple[float, float] = field(default=(1.0, 5.0), metadata=POSITIVE)
    min_static_s: float = field(default=30.0, metadata=NON_NEGATIVE)
    max_static_s: float = field(default=0.0, metadata=NON_NEGATIVE)  # 0: the whole detected static segment
    # 1 s means of the specific force within this of the first 10 s
    accel_threshold_m_s2: float = field(default=0.002, metadata=POSITIVE)
    # 1 s means of the gyro within this of the first 10 s
    gyro_threshold_deg_s: float = field(default=0.01, metadata=POSITIVE)
    dvl_speed_threshold_m_s: float = field(default=0.1, metadata=POSITIVE)
    # map origin when the log has none (needed for Earth rate and gravity)
    origin_lat_deg: float | None = field(default=None, metadata={"ge": -90.0, "le": 90.0})
    origin_lon_deg: float | None = field(default=None, metadata={"ge": -180.0, "le": 360.0})
    origin_height_m: float | None = None


@dataclass
class SolverConfig(_Section):
    SECTION: ClassVar[str] = "solver"

    max_iterations: int = field(default=30, metadata={"ge": 1})
    relative_error_tol: float = field(default=1e-7, metadata=NON_NEGATIVE)
    # error = chi^2 / 2: a decrease this small moves no estimate by 0.1 sigma
    absolute_error_tol: float = field(default=0.01, metadata=NON_NEGATIVE)
    earth_model: EarthModel = "wgs84"  # "wgs84" (default) or "flat": no Earth rate, constant gravity (low-grade IMUs)
    # 0: a state per DVL ping; >0: only pings at least this far apart (the others are dropped: decimation)
    keyframe_interval_s: float = field(default=0.0, metadata=NON_NEGATIVE)
    # batch smoother and online estimator: states only at pings at least this far apart (keyframes); every ping
    # between two keyframes becomes a DVL factor on the keyframe before it through the IMU motion up to the ping
    # (factors/dvl_keyframe.py), so that no ping's information is lost. 0: a state per ping. Applied after
    # keyframe_interval_s; must not exceed max_state_spacing_s. The EKF keeps a state per ping. 1 s: on a 5 Hz DVL the
    # calibration sigmas within 0.05 % and the estimates within 0.003 sigma of a state per ping, with a fifth of
    # the states (tests/estimators/test_keyframes.py); a 1 Hz DVL keeps a state per ping.
    keyframe_spacing_s: float = field(default=1.0, metadata=NON_NEGATIVE)
    # DVL dropouts: where pings are missing for more than 1.5 times this, states are added this far apart
    # without a DVL factor, so that no IMU factor spans more than this (what the EKF's propagation does)
    max_state_spacing_s: float = field(default=1.0, metadata=POSITIVE)


@dataclass
class RelinearizationThresholds(_Section):
    """iSAM2 relinearises a variable when a component of its update since its last linearisation exceeds
    these (tangent components, GTSAM order). A stale linearisation leaves an error of second order in the
    update; the thresholds keep it far below the noise of one factor (accelerometer noise: 1e-4 m/s in an IMU
    factor's velocity over 1 s; DVL: 0.02 m/s):
    - attitude about the body x, y axes: g dth^2 / 2 = 1.2e-6 m/s at 5e-4 rad; about body z (near the
      vertical) gravity does not move, and the DVL sees v dth^2 / 2 = 2.5e-5 m/s at 5e-3 rad;
    - position enters through gravity (its gradient is in the Jacobian) and through the coupling of Pose3's
      rotation and translation, which cancels between neighbouring states when the window shifts as a whole,
      as it does when the calibration is refined at the end of kilometres of dead reckoning: 10 m;
    - velocity, scale and misalignment enter the DVL model bilinearly (k R^T v): dk dv = 2e-4 m/s at 0.02 and
      0.01 m/s; the misalignment's curvature v dc^2 / 2 = 2.5e-5 m/s at 5e-3 rad;
    - the IMU factor is linear in the bias (first-order bias correction of the preintegration): 100 micro-g,
      2 deg/h, i.e. the bias never triggers a relinearisation in practice.
    iSAM2's default, 0.1 on everything, let the scale wander to 0.04 in a prototype.
    TOML section [online.relinearization]."""

    SECTION: ClassVar[str] = "online.relinearization"

    # rad (body x, y, z), m (body axes)
    pose: tuple[float, float, float, float, float, float] = field(default=(5e-4, 5e-4, 5e-3, 10.0, 10.0, 10.0),
                                                                  metadata=POSITIVE)
    velocity: tuple[float, float, float] = field(default=(0.01, 0.01, 0.01), metadata=POSITIVE)  # m/s, map
    # accel m/s^2, gyro rad/s
    bias: tuple[float, float, float, float, float, float] = field(default=(1e-3, 1e-3, 1e-3, 1e-5, 1e-5, 1e-5),
                                                                  metadata=POSITIVE)
    scale: float = field(default=0.02, metadata=POSITIVE)
    misalignment_rad: float = field(default=5e-3, metadata=POSITIVE)

    def threshold_map(self) -> Any:
        """The thresholds as a gtsam.ISAM2ThresholdMap (keyed by symbol character)."""
        import gtsam

        m = gtsam.ISAM2ThresholdMap()
        m.insert(("x", np.asarray(self.pose, dtype=float)))
        m.insert(("v", np.asarray(self.velocity, dtype=float)))
        m.insert(("b", np.asarray(self.bias, dtype=float)))
        m.insert(("k", np.array([self.scale])))
        m.insert(("c", np.full(3, self.misalignment_rad)))
        return m


@dataclass
class OnlineConfig(_Section):
    """Options of the online estimator (TOML section [online]). The models, priors and alignment thresholds
    come from the other sections."""

    SECTION: ClassVar[str] = "online"

    mode: OnlineMode = "fixed_lag"  # "fixed_lag" (bounded cost) or "full" (every state kept; see the module doc)
    # fixed_lag: states this far behind the newest are marginalised, s
    window_s: float = field(default=20.0, metadata=POSITIVE)
    # seconds of the initial static segment to align on before the first estimate
    align_s: float = field(default=60.0, metadata=POSITIVE)
    # slower pings do not inform scale and misalignment (online/estimator.py module doc)
    calibration_min_speed_m_s: float = field(default=0.1, metadata=NON_NEGATIVE)
    bad_messages: BadMessages = "raise"  # "raise" (GtsamDvlError) or "drop" (counted, warned once per kind)
    covariances: bool = True  # marginal covariances after every epoch (the timeline needs them)
    record_history: bool = True  # keep every epoch's estimate for timeline() and result()
    # iSAM2 updates without new data at finish(), until nothing is relinearised
    final_updates: int = field(default=10, metadata={"ge": 0})
    relinearization: RelinearizationThresholds = field(default_factory=RelinearizationThresholds)

    def check(self) -> None:
        """validate() under its old name."""
        self.validate()


@dataclass
class EkfConfig(_Section):
    """Options of the error-state EKF (TOML section [ekf]). Below a speed ("slow": under
    min_calibration_speed_m_s, or under calibration_speed_sigmas velocity sigmas) a DVL update is taken as
    insensitive to scale and misalignment (see gtsam_dvl/estimators/ekf/filter.py)."""

    SECTION: ClassVar[str] = "ekf"

    min_calibration_speed_m_s: float = field(default=0.1, metadata=NON_NEGATIVE)
    calibration_speed_sigmas: float = field(default=5.0, metadata=NON_NEGATIVE)
    # chi^2 gate of a DVL update: a ping whose normalised innovation squared exceeds the chi^2 quantile of
    # this probability (dof: the measurement's dimension) is not used, only counted ("dvl_gated"); 1: no gate.
    # 0.99999 (NIS 25.9 for 3-D): a 0.5 m/s outlier at 2 cm/s noise has NIS above 500; at 0.9999 (21.1) a
    # clean paper-3d run lost 2 sound pings, which moved its estimates by 0.09 sigma
    gate_probability: float = field(default=0.99999, metadata={"gt": 0.0, "le": 1.0})
    # after this many consecutive gated pings the next one is used anyway (a filter that lost track recovers)
    gate_reopen_after: int = field(default=10, metadata={"ge": 1})


@dataclass
class IodvlcConfig(_Section):
    """Segment detector thresholds and observer options of IO-DVLC (TOML section [iodvlc]; defaults for a
    navigation-grade IMU at 100 Hz; gtsam_dvl.estimators.iodvlc.IoDvlcOptions is this class).

    The detector works on windows of window_s seconds slid by 1 s over 1 s means of the IMU:
    - constant attitude: | |mean gyro| - Earth rate | < gyro_threshold_deg_h. It must exceed the gyro bias
      plus a few noise sigmas over the window (0.1 deg/h/sqrt(Hz) gives 0.05 deg/h over 5 s);
    - specific-force rate: the least-squares slope of the specific force over the window; "non-zero" when
      its norm exceeds sf_rate_threshold_m_s3 (4 sigma of the slope's noise for 10 micro-g/sqrt(Hz) over
      5 s is 1.6e-4 m/s^3; the paper-3d manoeuvres peak at 3e-3 to 1e-2 m/s^3);
    - a segment is a run of such windows; the rate passes through zero inside a manoeuvre, so gaps up to
      max_gap_s are bridged; a new segment starts when the rate's axis turns by more than axis_change_deg
      from the segment's principal axis (a descent after a surge) or the attitude changes;
    - segments shorter than min_segment_s are dropped;
    - a quiet stretch (constant attitude, rate below the threshold) of at least min_quiet_s seconds in the
      same constant-attitude interval gives the zero-acceleration specific force b_f0: its last
      reference_s seconds, so that the gyro's angle random walk between reference and segment stays small
      (0.1 deg/h/sqrt(Hz) over 100 s is 5e-6 rad, 5e-5 m/s^2 of tilted gravity).
    """

    SECTION: ClassVar[str] = "iodvlc"

    window_s: float = field(default=5.0, metadata=POSITIVE)
    gyro_threshold_deg_h: float = field(default=1.0, metadata=POSITIVE)
    sf_rate_threshold_m_s3: float = field(default=2e-4, metadata=POSITIVE)
    max_gap_s: float = field(default=5.0, metadata=NON_NEGATIVE)
    axis_change_deg: float = field(default=45.0, metadata={"gt": 0.0, "le": 180.0})
    min_segment_s: float = field(default=10.0, metadata=NON_NEGATIVE)
    min_quiet_s: float = field(default=20.0, metadata=NON_NEGATIVE)
    # the last this many seconds of the quiet stretch form the reference
    reference_s: float = field(default=60.0, metadata=POSITIVE)
    earth_terms: bool = True
    track_attitude: bool = True  # integrate the gyro's residual rotation theta (part of the earth terms)
    # DVL noise (1 sigma per axis); None: the median of the log's covariances
    noise_m_s: float | None = field(default=None, metadata=POSITIVE)
    # the pointwise k = |gamma| / |beta| is reported only where |beta| exceeds this
    min_beta_m_s: float = field(default=0.05, metadata=NON_NEGATIVE)
    # weak prior at the nominal mounting (None: the paper's pure Wahba)
    prior_sigma_deg: float | None = field(default=10.0, metadata=POSITIVE)


@dataclass
class DepthConfig(_Section):
    """Depth sensor (TOML section [depth]; every estimator, see estimators/depth.py). With use (the
    default) a log that has depth (LogData.depth) gets one factor per depth sample on the vertical position of
    its nearest state, the time between them bridged by that state's vertical velocity; a sample farther than
    max_time_to_state_s from every state is not used (counted). A pressure is converted to depth with
    water_density_kg_m3, atmospheric_pa and the mean normal gravity of the water column (core/earth.py); the
    water surface is at ellipsoidal height 0. noise_m > 0 overrides the message's variance; a message without
    one takes default_noise_m. lever_arm_m: the pressure sensor in base_link (m); None takes /tf_static's
    base_link -> pressure frame, else zero."""

    SECTION: ClassVar[str] = "depth"

    use: bool = True
    water_density_kg_m3: float = field(default=1025.0, metadata=POSITIVE)
    atmospheric_pa: float = field(default=101325.0, metadata=NON_NEGATIVE)
    noise_m: float = field(default=0.0, metadata=NON_NEGATIVE)  # >0 overrides the message's variance
    default_noise_m: float = field(default=0.1, metadata=POSITIVE)  # for messages without a variance
    lever_arm_m: tuple[float, float, float] | None = None
    max_time_to_state_s: float = field(default=0.5, metadata=NON_NEGATIVE)


GnssUse = Literal["origin", "start", "all"]


@dataclass
class GnssConfig(_Section):
    """GNSS fixes at the surface (TOML section [gnss]; batch smoother only, see estimators/gnss.py). A good fix
    has status >= 0 and, when the log has depth, the depth sensor no deeper than max_depth_m at its time;
    consecutive good fixes closer than surface_gap_s apart form one surface interval. use: "origin" (only the
    map origin comes from the first fix: that fix is the one position factor when the log records no origin),
    "start" (the default: the fixes of the first surface interval, before the first dive, are position
    factors; later fixes are held out for the surfacing error) or "all" (every good fix aids). Each fix is a
    factor on the antenna position of its nearest state within max_time_to_state_s (the time between bridged
    by the state's velocity); farther ones are not used (counted). noise_m > 0 overrides the message's
    covariance (sigma per axis, m); a message without one takes default_noise_m. lever_arm_m: the antenna in
    base_link (m); None takes /tf_static's base_link -> gnss_link, else zero."""

    SECTION: ClassVar[str] = "gnss"

    use: GnssUse = "start"
    max_depth_m: float = field(default=1.0, metadata=NON_NEGATIVE)  # depth gate (depth sensor), m
    surface_gap_s: float = field(default=10.0, metadata=POSITIVE)  # a longer gap between fixes ends an interval
    noise_m: float = field(default=0.0, metadata=NON_NEGATIVE)  # >0 overrides the message's covariance
    default_noise_m: float = field(default=5.0, metadata=POSITIVE)  # for messages without a covariance
    lever_arm_m: tuple[float, float, float] | None = None
    max_time_to_state_s: float = field(default=0.5, metadata=NON_NEGATIVE)


@dataclass
class ObservabilityConfig(_Section):
    """The accuracy at which the observability verdict (analysis/observability.py) calls a state "determined":
    its posterior sigma at or below the target, and the log (or plan) having informed it (posterior below 90 % of
    the prior). A state the log informed that stays above its target is "weakly determined". The defaults are
    what makes a DVL-aided navigation good to 0.1 % of distance travelled: the scale to 0.1 % and the
    misalignment to 0.1 deg (0.17 % of distance across track); the biases to half the paper's priors."""

    SECTION: ClassVar[str] = "observability"

    scale_ppm: float = field(default=1000.0, metadata=POSITIVE)
    misalignment_deg: float = field(default=0.1, metadata=POSITIVE)
    accel_bias_ug: float = field(default=25.0, metadata=POSITIVE)
    gyro_bias_deg_per_h: float = field(default=0.005, metadata=POSITIVE)


# Named configurations: the differences from the defaults, as a TOML file would give them. `-c NAME` on the
# command line, EstimatorConfig.named(NAME) in scripts, `preset = "NAME"` at the top of a TOML file (its own
# keys then override the preset's), and a scenario's estimator_config key (the configuration its runs are
# meant for, used by smooth and plan when no configuration is given).
NAMED_CONFIGS: dict[str, dict[str, dict[str, Any]]] = {
    "default": {},  # a real DVL: scale 1 +- 1 %, misalignment 1 deg per axis
    # Pan & Wu's runs: the scale starts at 0.8 with a 0.5 sigma so that its convergence can be watched
    # and their logs' stamps agree (no DVL time offset estimated)
    "paper": {"priors": {"scale_initial": 0.8, "scale_sigma": 0.5}, "dvl": {"estimate_time_offset": False}},
}


def recommended_config_name(metadata: Mapping[str, Any]) -> str:
    """The named configuration a log's metadata recommends: its scenario's estimator_config if that is a known
    name, else "default" (real logs)."""
    scenario = metadata.get("scenario")
    name = scenario.get("estimator_config", "default") if isinstance(scenario, Mapping) else "default"
    return name if isinstance(name, str) and name in NAMED_CONFIGS else "default"


@dataclass
class EstimatorConfig:
    imu: ImuConfig = field(default_factory=ImuConfig)
    dvl: DvlConfig = field(default_factory=DvlConfig)
    priors: PriorConfig = field(default_factory=PriorConfig)
    alignment: AlignmentConfig = field(default_factory=AlignmentConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    online: OnlineConfig = field(default_factory=OnlineConfig)
    ekf: EkfConfig = field(default_factory=EkfConfig)
    iodvlc: IodvlcConfig = field(default_factory=IodvlcConfig)
    depth: DepthConfig = field(default_factory=DepthConfig)
    observability: ObservabilityConfig = field(default_factory=ObservabilityConfig)
    gnss: GnssConfig = field(default_factory=GnssConfig)

    def to_dict(self) -> dict[str, Any]:
        """Nested plain dict (tuples stay tuples, None stays None): json.dumps writes it, from_dict reads it."""
        return dataclasses.asdict(self)

    def to_toml(self) -> str:
        """The configuration as TOML text. TOML has no null: None is written "none", or left out where it is
        the default."""
        lines: list[str] = []
        for f in dataclasses.fields(self):
            _toml_table(getattr(self, f.name), f.name, lines)
        return "\n".join(lines)

    def validate(self, source: str = "config") -> EstimatorConfig:
        """Check every section (see _Section.validate); returns self."""
        hints = typing.get_type_hints(type(self))
        for f in dataclasses.fields(self):
            section = getattr(self, f.name)
            if not isinstance(section, hints[f.name]):
                raise GtsamDvlError(f"{source}: [{f.name}] must be a {hints[f.name].__name__}, got {section!r}")
            section.validate(source)
        return self

    @classmethod
    def named(cls, name: str) -> EstimatorConfig:
        """A named configuration (NAMED_CONFIGS: "default", "paper")."""
        if name not in NAMED_CONFIGS:
            raise GtsamDvlError(f"no configuration named '{name}' (named configurations: {', '.join(NAMED_CONFIGS)})")
        return cls.from_dict(NAMED_CONFIGS[name], source=f"configuration '{name}'")

    @classmethod
    def paper(cls) -> EstimatorConfig:
        """The paper's configuration (scale prior 0.8 +- 0.5): NAMED_CONFIGS["paper"]."""
        return cls.named("paper")

    @classmethod
    def for_log(cls, metadata: Mapping[str, Any]) -> EstimatorConfig:
        """The configuration a log's scenario names (its estimator_config key: a simulated paper run names
        "paper"), else the defaults: what every estimator uses when no configuration is given."""
        return cls.named(recommended_config_name(metadata))

    @classmethod
    def load(cls, spec: Path | str) -> EstimatorConfig:
        """A configuration from the command line's -c: a file (TOML, or a result's config.json), else the
        name of a named configuration."""
        if not Path(spec).exists() and str(spec) in NAMED_CONFIGS:
            return cls.named(str(spec))
        if not Path(spec).exists():
            raise GtsamDvlError(f"{spec}: no such configuration file, and not a named configuration "
                                f"({', '.join(NAMED_CONFIGS)})")
        return cls.from_toml(spec)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "config") -> EstimatorConfig:
        """Sections from a dict shaped like the TOML file. A top-level key preset = "NAME" starts from that
        named configuration instead of the defaults."""
        if not isinstance(data, Mapping):
            raise GtsamDvlError(f"{source}: a configuration is a table of sections, got {data!r}")
        cfg = cls()
        if "preset" in data:
            preset = data["preset"]
            if not isinstance(preset, str) or preset not in NAMED_CONFIGS:
                raise GtsamDvlError(f"{source}: preset must be the name of a named configuration "
                                    f"({', '.join(NAMED_CONFIGS)}), got {preset!r}")
            cfg = cls.named(preset)
            data = {k: v for k, v in data.items() if k != "preset"}
        sections = {f.name for f in dataclasses.fields(cfg)}
        for section, values in data.items():
            if section not in sections:
                raise GtsamDvlError(f"{source}: unknown section [{section}] (known: {', '.join(sorted(sections))})")
            if not isinstance(values, Mapping):
                raise GtsamDvlError(f"{source}: [{section}] must be a table of keys, got {values!r}")
            _load_into(getattr(cfg, section), values, source, section)
        return cfg.validate(source)

    @classmethod
    def from_toml(cls, path: Path | str) -> EstimatorConfig:
        """A TOML configuration file, or (*.json) the effective configuration written with a result."""
        if str(path).lower().endswith(".json"):
            return cls.from_json(path)
        try:
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except tomllib.TOMLDecodeError as exc:
            raise GtsamDvlError(f"{path}: not valid TOML ({exc})") from None
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_json(cls, path: Path | str) -> EstimatorConfig:
        """The config.json of a result ({"estimator": ..., "config": {...}}) or a bare configuration dict."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except FileNotFoundError:
            raise GtsamDvlError(f"{path}: no such configuration file") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise GtsamDvlError(f"{path}: not valid JSON ({exc})") from None
        if isinstance(data, dict) and "config" in data and set(data) <= {"estimator", "config"}:
            data = data["config"]
        return cls.from_dict(data, source=str(path))


# ----- checking by value -------------------------------------------------------------------------------

def _load_into(obj: Any, values: Mapping[str, Any], source: str, section: str) -> None:
    """Set the fields of section dataclass obj from a table (nested dataclasses from sub-tables)."""
    fields = {f.name: f for f in dataclasses.fields(obj)}
    for key, value in values.items():
        if key not in fields:
            raise GtsamDvlError(f"{source}: unknown key '{key}' in [{section}] (known: {', '.join(fields)})")
        current = getattr(obj, key)
        if dataclasses.is_dataclass(current):
            if not isinstance(value, Mapping):
                raise GtsamDvlError(f"{source}: [{section}] {key} must be a table [{section}.{key}], got {value!r}")
            _load_into(current, value, source, f"{section}.{key}")
        else:
            setattr(obj, key, value)  # checked by validate() once the section is read


def _check_fields(obj: Any, source: str, section: str) -> None:
    hints = typing.get_type_hints(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            if not isinstance(value, hints[f.name]):
                raise GtsamDvlError(f"{source}: [{section}] {f.name} must be a {hints[f.name].__name__}, "
                                    f"got {value!r}")
            _check_fields(value, source, f"{section}.{f.name}")
            continue
        setattr(obj, f.name, _checked(value, hints[f.name], f.metadata, f"{source}: [{section}] {f.name}"))


def _range_text(meta: Mapping[str, Any]) -> str:
    lo = ("[", meta["ge"]) if "ge" in meta else ("(", meta["gt"]) if "gt" in meta else None
    hi = ("]", meta["le"]) if "le" in meta else (")", meta["lt"]) if "lt" in meta else None
    if lo and hi:
        return f" in {lo[0]}{lo[1]:g}, {hi[1]:g}{hi[0]}"
    if lo:
        return f" {'>=' if lo[0] == '[' else '>'} {lo[1]:g}"
    if hi:
        return f" {'<=' if hi[0] == ']' else '<'} {hi[1]:g}"
    return ""


def _in_range(x: float, meta: Mapping[str, Any]) -> bool:
    return (math.isfinite(x) and x >= meta.get("ge", -math.inf) and x > meta.get("gt", -math.inf)
            and x <= meta.get("le", math.inf) and x < meta.get("lt", math.inf))


def _is_number(value: Any, integer: bool = False) -> bool:
    if isinstance(value, bool | np.bool_):
        return False
    return isinstance(value, numbers.Integral if integer else numbers.Real)


def _checked(value: Any, tp: Any, meta: Mapping[str, Any], where: str, or_none: str = "") -> Any:
    """value if it fits type tp and the range in meta (ints made float, sequences tuples), else GtsamDvlError."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (types.UnionType, typing.Union) and type(None) in args:  # X | None: None, or "none" in a TOML
        if value is None or (isinstance(value, str) and value == "none"):
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _checked(value, inner, meta, where, " or 'none'")
    if origin is Literal:
        if not (isinstance(value, str) and value in args):
            raise GtsamDvlError(f"{where} = {value!r} is not one of {', '.join(repr(a) for a in args)}")
        return value
    if tp is bool:
        if not isinstance(value, bool | np.bool_):
            raise GtsamDvlError(f"{where} must be true or false{or_none}, got {value!r}")
        return bool(value)
    if tp is int:
        if not (_is_number(value, integer=True) and _in_range(float(value), meta)):
            raise GtsamDvlError(f"{where} must be an integer{_range_text(meta)}{or_none}, got {value!r}")
        return int(value)
    if tp is float:
        if not (_is_number(value) and _in_range(float(value), meta)):
            raise GtsamDvlError(f"{where} must be a number{_range_text(meta)}{or_none}, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise GtsamDvlError(f"{where} must be a string{or_none}, got {value!r}")
        return value
    if origin is tuple and all(a is float for a in args):
        seq = value.tolist() if isinstance(value, np.ndarray) else value
        if not (isinstance(seq, list | tuple) and len(seq) == len(args)
                and all(_is_number(x) and _in_range(float(x), meta) for x in seq)):
            raise GtsamDvlError(f"{where} must be a list of {len(args)} numbers{_range_text(meta)}{or_none}, "
                                f"got {value!r}")
        return tuple(float(x) for x in seq)
    raise TypeError(f"{where}: no check for the field type {tp!r}")  # a field type this module does not know


# ----- TOML writing -------------------------------------------------------------------------------------

def _toml_table(section: Any, name: str, lines: list[str]) -> None:
    lines.append(f"[{name}]")
    nested = []
    for f in dataclasses.fields(section):
        value = getattr(section, f.name)
        if dataclasses.is_dataclass(value):
            nested.append((f"{name}.{f.name}", value))
        elif value is not None:
            lines.append(f"{f.name} = {_toml_value(value)}")
        elif f.default is not None:  # TOML has no null: "none" (a field whose default is None is left out)
            lines.append(f'{f.name} = "none"')
    lines.append("")
    for sub_name, sub in nested:
        _toml_table(sub, sub_name, lines)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        x = float(value)
        return repr(x) if math.isfinite(x) else ("nan" if math.isnan(x) else "inf" if x > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a TOML basic string
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} to TOML")
