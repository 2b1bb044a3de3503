"""The sections of the estimator configuration, one pydantic model per TOML table, with the documented
defaults (a real DVL; the paper's sensors). Every field carries its unit in its name; its type states what it
allows (Positive: > 0, NonNegative: >= 0, Literal: one of its values, Field(...): a range). See base.py for
how they are checked and estimator.py for the whole configuration."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Literal, Self

import numpy as np
from pydantic import Field, model_validator

from gtsam_dvl.core.config.base import ConfigModel, Flag, Integer, NonNegative, Number, Positive
from gtsam_dvl.core.config.presets import DVL_PRESETS, IMU_PRESETS

BiasModel = Literal["constant", "random_walk"]
RobustLoss = Literal["none", "huber", "cauchy"]
EarthModel = Literal["wgs84", "flat"]
OnlineMode = Literal["fixed_lag", "full"]
BadMessages = Literal["raise", "drop"]
GnssUse = Literal["origin", "start", "all"]
if TYPE_CHECKING:
    ImuModel = str
    DvlModel = str
else:  # the preset names (presets.py): an unknown name is refused on load, the error listing the known ones
    ImuModel = Literal[tuple(IMU_PRESETS)]
    DvlModel = Literal[tuple(DVL_PRESETS)]


def _fill_from_preset(section: ConfigModel, values: dict[str, Any]) -> None:
    """Set the fields of values the configuration did not set itself (pydantic's model_fields_set): explicit
    values win over a preset's. The filled fields are not counted as set, so that validate() fills them again
    from the preset named then (base.py _raw)."""
    for key, value in values.items():
        if key not in section.model_fields_set:
            section.__dict__[key] = value


class ImuConfig(ConfigModel):
    """IMU noise model. Densities are white noise; bias sigmas are the priors of the random-constant bias.
    model: an IMU preset (presets.py, `gtsam-dvl presets`): its datasheet white noise and bias stabilities fill
    the four fields below that the configuration does not set itself."""

    SECTION: ClassVar[str] = "imu"

    model: ImuModel | None = None
    gyro_noise_deg_per_h_rthz: Positive = 0.1
    accel_noise_ug_rthz: Positive = 10.0
    gyro_bias_sigma_deg_per_h: Positive = 0.01
    accel_bias_sigma_ug: Positive = 50.0
    bias_model: BiasModel = "constant"  # "constant" (the paper's random constant) or "random_walk"
    # random-walk density, (deg/h)/sqrt(h), random_walk only
    gyro_bias_rw_deg_per_h_per_rth: Positive = 0.001
    accel_bias_rw_ug_per_rth: Positive = 1.0  # micro-g/sqrt(h), random_walk only
    # position integration noise of the preintegration, m/sqrt(s)
    integration_sigma_m_rts: NonNegative = 1e-5
    # rotate each delta-v to its interval start (see factor_maker.py)
    rotation_compensation: Flag = True
    # IMU gaps (estimators/inputs/gaps.py): a spacing longer than this many nominal periods is a gap, crossed by
    # holding the last sample with the motion-model uncertainty below added to the covariance
    gap_samples: Number = Field(default=3.0, gt=1.0)
    gap_accel_sigma_m_s2: Positive = 0.2  # change of acceleration over a gap
    gap_rate_sigma_deg_s: Positive = 1.0  # change of turn rate over a gap
    # longer gaps are an error: a hold that long is no motion model (its error is systematic, not white)
    max_gap_s: Positive = 10.0

    @model_validator(mode="after")
    def _apply_model(self) -> Self:
        if self.model is not None:
            _fill_from_preset(self, IMU_PRESETS[self.model].config_values())
        return self


class DvlConfig(ConfigModel):
    """DVL measurement model options, and the screening of bogus pings before estimation.

    Robust loss (batch and online: on every DVL factor; EKF: the same kernel's weight on the whitened
    innovation, after the chi^2 gate of [ekf] gate_probability): "huber" (default), "cauchy" or "none".
    robust_k is the kernel's threshold in sigmas of the whitened error (the norm of the 3-D error, or one
    beam's). huber_k is an alias of robust_k (a TOML file may set either): when set it overrides robust_k.

    Screening (estimators/inputs/ping_screen.py, PingScreen; the same causal rule in batch, online and EKF, against
    the previous accepted ping and the IMU samples stamped since it), on when screen is true:
    - an exact zero velocity (all three components 0.0) while moving, i.e. the IMU shows motion since the
      previous accepted ping (the body's velocity changed by more than motion_dv_m_s by the specific force,
      gravity turned by the gyro) or that ping was faster than moving_speed_m_s: "dvl_zero_while_moving";
    - a non-zero velocity bit-identical to the previous accepted ping's (a frozen output), whatever the IMU
      shows; in a noise-free simulation (DvlData.noise_free) only while the IMU shows motion: "dvl_repeated";
    - a velocity change |dv| since the previous accepted ping larger than
      max_accel_m_s2 dt + accel_imu_factor * (the change the IMU allows over dt) + jump_margin_m_s:
      "dvl_implausible_accel" (3-D velocity only, not with use_beams).
    A real DVL's velocity is noisy: it never reads exact zeros, nor repeats a reading bit for bit; a
    simulator without noise does both, at rest and at constant velocity (its logs say so).

    model: a DVL preset (presets.py, `gtsam-dvl presets`): its ping noise fills default_noise_m_s and
    beam_noise_m_s, its correlated error correlated_sigma_m_s and correlated_tau_s, and its scale accuracy
    [priors] scale_sigma (estimator.py), each unless the configuration sets it itself.
    """

    SECTION: ClassVar[str] = "dvl"

    model: DvlModel | None = None
    noise_m_s: NonNegative = 0.0  # >0 overrides the per-message covariance
    default_noise_m_s: Positive = 0.02  # for messages without a covariance
    use_beams: Flag = False  # one scalar factor per valid beam instead of the 3-D velocity
    beam_noise_m_s: Positive = 0.02
    robust: RobustLoss = "huber"  # "huber" (default), "cauchy" or "none"
    # kernel threshold, in sigmas: 4 leaves a clean log's estimates where no kernel puts them, to a small fraction
    # of a sigma (docs/results.md, "Faulty logs"), and a 0.5-2 m/s outlier (25-100 sigma) still counts like a
    # 4 sigma residual
    robust_k: Positive = 4.0
    huber_k: Positive | None = None  # alias of robust_k (overrides it if set)
    max_speed_m_s: Positive = 10.0  # faster pings are outliers: dropped, counted
    # drop bogus pings (zero while moving, repeated, implausible acceleration): see above
    screen: Flag = True
    # no vehicle this package navigates accelerates this hard over a ping interval, m/s^2
    max_accel_m_s2: Positive = 2.0
    # multiple of the velocity change the IMU allows (specific-force change, gravity turned by the gyro)
    accel_imu_factor: NonNegative = 5.0
    jump_margin_m_s: NonNegative = 0.3  # DVL noise of the two pings' difference
    # the IMU shows motion when it says the DVL's velocity changed by more than this since the previous ping
    motion_dv_m_s: Positive = 0.05
    moving_speed_m_s: Positive = 0.1  # a previous ping this fast: moving
    # DVL-IMU time offset dt_d (docs/conventions.md: the ping stamped t measures the velocity at t + dt_d): a graph
    # variable T_OFFSET with this prior (batch, online), an EKF state; a tiny sigma fixes it at the prior value.
    # On by default (real DVL stamps are 0.05-1.5 s off the IMU's); off (the "paper" configuration): every
    # estimator takes dt_d = 0 and the prior value is not used
    estimate_time_offset: Flag = True
    time_offset_prior_s: Number = 0.0
    time_offset_sigma_s: Positive = 0.5
    # the IMU window averaged for the epoch's velocity rate (the time offset's Jacobian) is [t, t + dt_d], at least
    # twice this long about its middle (FactorMaker.velocity_rate_inputs), s
    time_offset_window_s: Positive = 0.25
    # DVL lever arm b_l (IMU -> DVL, m, base_link; docs/conventions.md), batch smoother only: a graph variable
    # L_LEVER with a prior around the /tf_static value (LogData.mounting.b_l), lever_arm_sigma_m per axis. Off by
    # default: then every estimator takes b_l from /tf_static. Observable only from rotation (b_omega x b_l): a
    # lever arm along the rotation axis of every turn stays at its prior
    estimate_lever_arm: Flag = False
    lever_arm_sigma_m: Positive = 0.5
    # every ping's sigma (configured, from its message, or the default) times this: the variance component the
    # estimators fit from the residuals ([noise] fit_dvl, core/config/noise.py); set here, it pins the factor
    noise_multiplier: Positive = 1.0
    # a first-order Gauss-Markov velocity error (per dvl_link axis, m/s) and its time constant (s), from a preset
    # or set here: when > 0 every estimator carries it as a state of each epoch (estimators/models/correlated.py),
    # so that the position sigma grows as the error's, and the calibration does not over-trust pings whose errors are
    # correlated; 0: the DVL's error is white (the paper's). The default, 2 mm/s over 60 s, is the offset term of
    # a 300-600 kHz bottom-track DVL's long-term accuracy, typical of the class (presets.py)
    correlated_sigma_m_s: NonNegative = 0.002
    correlated_tau_s: Positive = 60.0
    # the DVL's velocity error that stays constant over a run (per dvl_link axis, m/s): no estimator can tell it
    # from the scale and misalignment, so their covariance takes its share (estimators/models/constant_error.py); the
    # default, 2 mm/s, is the offset term of a bottom-track DVL's long-term accuracy (+-0.1 cm/s on the Teledyne
    # Workhorse Navigator and Nortek DVL1000 sheets) doubled for what a run's bottom and sound speed add (issue 31
    # measured a few mm/s at 30-60 s averaging on real logs); 0: the calibration's sigmas from the data alone
    constant_error_sigma_m_s: NonNegative = 0.002

    @model_validator(mode="after")
    def _apply_model(self) -> Self:
        if self.model is not None:
            _fill_from_preset(self, DVL_PRESETS[self.model].config_values())
        return self

    def beam_sigma_m_s(self) -> float:
        """One beam's sigma: beam_noise_m_s times the fitted noise_multiplier (m/s)."""
        return self.beam_noise_m_s * self.noise_multiplier

    def robust_threshold(self) -> float:
        """The robust kernel's threshold in sigmas: huber_k if set (its alias), else robust_k."""
        return self.robust_k if self.huber_k is None else self.huber_k


class PriorConfig(ConfigModel):
    """Priors. The defaults are those of a real DVL: scale 1 +- 1 % (a DVL's scale is 1 within its
    specification, 0.1-1 %, unless the speed of sound it assumes is wrong) and misalignment 1 deg per axis
    around the nominal mounting. The paper's priors (scale 0.8 +- 0.5: a convergence test) are the named
    configuration "paper" (NAMED_CONFIGS), which the paper's scenarios and the demo use."""

    SECTION: ClassVar[str] = "priors"

    scale_initial: Positive = 1.0
    scale_sigma: Positive = 0.01
    misalignment_sigma_deg: tuple[Positive, Positive, Positive] = (1.0, 1.0, 1.0)
    roll_pitch_sigma_deg: Positive = 1.0  # around the coarse alignment
    yaw_sigma_deg: Positive = 5.0
    position_sigma_m: Positive = 0.01  # the first state defines the map origin
    velocity_sigma_m_s: Positive = 1.0
    # the DVL's mounting tolerance (deg): when set, the misalignment prior sigma on all three axes, unless
    # misalignment_sigma_deg is set in the same configuration
    mounting_tolerance_deg: Positive | None = None
    # the batch smoother holds a direction of the DVL scale and misalignment at the prior's mean when the data's
    # information along it is below this fraction of the prior's, with the prior's uncertainty carried into every
    # sigma (estimators/models/weak_hold.py); 0: every direction estimated, however little the run informs it
    hold_weak_information: NonNegative = 0.25
    # with the hold on: the nominal calibration's check (scale 1, the mounting's misalignment) in every run; where
    # estimating the scale and misalignment does not lower the chi^2 by more than the 95 % quantile of chi^2(4), the
    # calibration is held at the nominal with its prior's sigma (estimators/models/weak_hold.py nominal_check)
    nominal_check: Flag = True

    @model_validator(mode="after")
    def _apply_mounting_tolerance(self) -> Self:
        if self.mounting_tolerance_deg is not None:
            tol = self.mounting_tolerance_deg
            _fill_from_preset(self, {"misalignment_sigma_deg": (tol, tol, tol)})
        return self


class AlignmentConfig(ConfigModel):
    """The initial attitude (estimators/inputs/alignment.py align): method "auto" takes, in this order, an attitude
    sensor in the log (LogData.attitude), initial_attitude_deg, coarse alignment on an initial static segment
    of at least min_static_s, else in-motion alignment with DVL aiding over the first in_motion_window_s.
    "attitude_topic", "static" and "in_motion" force one method (an error if it cannot be done).
    initial_attitude_deg and the map origin (origin_*, or the log's) are the attitude and the position at the log's
    first IMU stamp: when the first state (the first usable DVL ping) comes later, the estimators carry them to it
    with the gyros and the first ping's velocity and widen the prior by what that adds (alignment.first_state)."""

    SECTION: ClassVar[str] = "alignment"

    # [roll, pitch, yaw] of base_link in map at the first IMU stamp (carried to the first state); skips alignment
    initial_attitude_deg: tuple[Number, Number, Number] | None = None
    method: Literal["auto", "attitude_topic", "static", "in_motion"] = "auto"
    in_motion_window_s: Number = Field(default=120.0, ge=10.0)  # in-motion alignment window
    # attitude sensor sigmas (roll/pitch, yaw) when its messages give no covariance
    attitude_sigma_deg: tuple[Positive, Positive] = (1.0, 5.0)
    min_static_s: NonNegative = 30.0
    max_static_s: NonNegative = 0.0  # 0: the whole detected static segment
    # 1 s means of the specific force within this of the first 10 s
    accel_threshold_m_s2: Positive = 0.002
    # 1 s means of the gyro within this of the first 10 s
    gyro_threshold_deg_s: Positive = 0.01
    dvl_speed_threshold_m_s: Positive = 0.1
    # map origin when the log has none (needed for Earth rate and gravity): the vehicle's position at the first
    # IMU stamp (carried to the first state)
    origin_lat_deg: Number | None = Field(default=None, ge=-90.0, le=90.0)
    origin_lon_deg: Number | None = Field(default=None, ge=-180.0, le=360.0)
    origin_height_m: Number | None = None


class SolverConfig(ConfigModel):
    SECTION: ClassVar[str] = "solver"

    max_iterations: Integer = Field(default=30, ge=1)
    relative_error_tol: NonNegative = 1e-7
    # error = chi^2 / 2: a decrease this small moves no estimate by 0.1 sigma
    absolute_error_tol: NonNegative = 0.01
    # "wgs84" (default) or "flat": no Earth rate, constant gravity (low-grade IMUs)
    earth_model: EarthModel = "wgs84"
    # 0: a state per DVL ping; >0: only pings at least this far apart (the others are dropped: decimation)
    keyframe_interval_s: NonNegative = 0.0
    # batch smoother and online estimator: states only at pings at least this far apart (keyframes); every ping
    # between two keyframes becomes a DVL factor on the keyframe before it through the IMU motion up to the ping
    # (factors/dvl.py with a PingMotion), so that no ping's information is lost. 0: a state per ping. Applied after
    # keyframe_interval_s; must not exceed max_state_spacing_s. The EKF keeps a state per ping. 1 s: on a 5 Hz DVL
    # a fifth of the states, with calibration sigmas and estimates those of a state per ping to a small fraction
    # (docs/results.md, "Keyframes"); a 1 Hz DVL keeps a state per ping.
    keyframe_spacing_s: NonNegative = 1.0
    # DVL dropouts: where pings are missing for more than 1.5 times this, states are added this far apart
    # without a DVL factor, so that no IMU factor spans more than this (what the EKF's propagation does)
    max_state_spacing_s: Positive = 1.0


class RelinearizationThresholds(ConfigModel):
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
    iSAM2's default, 0.1 on everything, is far above the scale's and the misalignment's sigmas: they would stay
    linearised where they were first set while they converge.
    TOML section [online.relinearization]."""

    SECTION: ClassVar[str] = "online.relinearization"

    # rad (body x, y, z), m (body axes)
    pose: tuple[Positive, Positive, Positive, Positive, Positive, Positive] = (
        5e-4,
        5e-4,
        5e-3,
        10.0,
        10.0,
        10.0,
    )
    velocity: tuple[Positive, Positive, Positive] = (0.01, 0.01, 0.01)  # m/s, map
    # accel m/s^2, gyro rad/s
    bias: tuple[Positive, Positive, Positive, Positive, Positive, Positive] = (
        1e-3,
        1e-3,
        1e-3,
        1e-5,
        1e-5,
        1e-5,
    )
    scale: Positive = 0.02
    misalignment_rad: Positive = 5e-3

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


class OnlineConfig(ConfigModel):
    """Options of the online estimator (TOML section [online]). The models, priors and alignment thresholds
    come from the other sections."""

    SECTION: ClassVar[str] = "online"

    # "fixed_lag" (bounded cost) or "full" (every state kept; see the module doc)
    mode: OnlineMode = "fixed_lag"
    # fixed_lag: states this far behind the newest are marginalised, s
    window_s: Positive = 20.0
    # seconds of the initial static segment to align on before the first estimate
    align_s: Positive = 60.0
    # slower pings do not inform scale and misalignment (online/dvl_factors.py module doc)
    calibration_min_speed_m_s: NonNegative = 0.1
    # "raise" (GtsamDvlError) or "drop" (counted, warned once per kind)
    bad_messages: BadMessages = "raise"
    covariances: Flag = True  # marginal covariances after every epoch (the timeline needs them)
    record_history: Flag = True  # keep every epoch's estimate for timeline() and result()
    # iSAM2 updates without new data at finish(), until nothing is relinearised
    final_updates: Integer = Field(default=10, ge=0)
    relinearization: RelinearizationThresholds = Field(default_factory=RelinearizationThresholds)

    def check(self) -> None:
        """An alias of validate()."""
        self.validate()


class EkfConfig(ConfigModel):
    """Options of the error-state EKF (TOML section [ekf]). Below min_calibration_speed_m_s a DVL update is taken
    as insensitive to scale and misalignment; above it but under calibration_speed_sigmas velocity sigmas (the
    velocity still unknown) they are consider states of that update (see gtsam_dvl/estimators/ekf/filter.py)."""

    SECTION: ClassVar[str] = "ekf"

    min_calibration_speed_m_s: NonNegative = 0.1
    calibration_speed_sigmas: NonNegative = 5.0
    # chi^2 gate of a DVL update: a ping whose normalised innovation squared exceeds the chi^2 quantile of
    # this probability (dof: the measurement's dimension) is not used, only counted ("dvl_gated"); 1: no gate.
    # 0.99999 (NIS 25.9 for 3-D): a 0.5 m/s outlier at 2 cm/s noise has NIS above 500; at 0.9999 (21.1) sound
    # pings of a clean paper-3d run are gated
    gate_probability: Number = Field(default=0.99999, gt=0.0, le=1.0)
    # after this many consecutive gated pings the next one is used anyway (a filter that lost track recovers)
    gate_reopen_after: Integer = Field(default=10, ge=1)
    # with [dvl] estimate_time_offset: filter the warm-up window ([noise] warmup_s) first and centre the time
    # offset's prior at the window's estimate (its sigma kept), so that the whole log is filtered linearised at
    # the offset the data show: an EKF never relinearises the past (straight-transect and steady-turn, DVL stamped
    # 1 s early, seeds 1-4: pitch misalignment 1.2-1.5 sigma off instead of 1.9-2.3, block NEES 4-27 instead of 7-29)
    recentre_time_offset: Flag = True


class IodvlcConfig(ConfigModel):
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

    window_s: Positive = 5.0
    gyro_threshold_deg_h: Positive = 1.0
    sf_rate_threshold_m_s3: Positive = 2e-4
    max_gap_s: NonNegative = 5.0
    axis_change_deg: Number = Field(default=45.0, gt=0.0, le=180.0)
    min_segment_s: NonNegative = 10.0
    min_quiet_s: NonNegative = 20.0
    # the last this many seconds of the quiet stretch form the reference
    reference_s: Positive = 60.0
    earth_terms: Flag = True
    # integrate the gyro's residual rotation theta (part of the earth terms)
    track_attitude: Flag = True
    # DVL noise (1 sigma per axis); None: the median of the log's covariances
    noise_m_s: Positive | None = None
    # the pointwise k = |gamma| / |beta| is reported only where |beta| exceeds this
    min_beta_m_s: NonNegative = 0.05
    # weak prior at the nominal mounting (None: the paper's pure Wahba)
    prior_sigma_deg: Positive | None = 10.0


class DepthConfig(ConfigModel):
    """Depth sensor (TOML section [depth]; every estimator, see estimators/inputs/depth.py). With use (the
    default) a log that has depth (LogData.depth) gets one factor per depth sample on the vertical position of
    its nearest state, the time between them bridged by that state's vertical velocity; a sample farther than
    max_time_to_state_s from every state is not used (counted). A pressure is converted to depth with
    water_density_kg_m3, atmospheric_pa and the mean normal gravity of the water column (core/earth.py); the
    water surface is at ellipsoidal height 0. noise_m > 0 overrides the message's variance; a message without
    one takes default_noise_m. lever_arm_m: the pressure sensor in base_link (m); None takes /tf_static's
    base_link -> pressure frame, else zero."""

    SECTION: ClassVar[str] = "depth"

    use: Flag = True
    water_density_kg_m3: Positive = 1025.0
    atmospheric_pa: NonNegative = 101325.0
    noise_m: NonNegative = 0.0  # >0 overrides the message's variance
    default_noise_m: Positive = 0.1  # for messages without a variance
    # every sample's sigma (noise_m, the message's or the default) times this: the variance component the batch
    # smoother fits from the residuals ([noise] fit_depth, core/config/noise.py); set here, it pins the factor
    noise_multiplier: Positive = 1.0
    lever_arm_m: tuple[Number, Number, Number] | None = None
    max_time_to_state_s: NonNegative = 0.5


class GnssConfig(ConfigModel):
    """GNSS fixes at the surface (TOML section [gnss]; the batch smoother and the online estimator, see
    estimators/inputs/gnss.py and estimators/online/gnss_queue.py). A good fix
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
    max_depth_m: NonNegative = 1.0  # depth gate (depth sensor), m
    surface_gap_s: Positive = 10.0  # a longer gap between fixes ends an interval
    noise_m: NonNegative = 0.0  # >0 overrides the message's covariance
    default_noise_m: Positive = 5.0  # for messages without a covariance
    # every fix's sigma (noise_m, the message's or the default) times this: the variance component the batch
    # smoother fits from the residuals ([noise] fit_gnss, core/config/noise.py); set here, it pins the factor
    noise_multiplier: Positive = 1.0
    lever_arm_m: tuple[Number, Number, Number] | None = None
    max_time_to_state_s: NonNegative = 0.5


class ObservabilityConfig(ConfigModel):
    """The accuracy at which the observability verdict (analysis/observability.py) calls a state "determined":
    its posterior sigma at or below the target, and the log (or plan) having informed it (posterior below 90 % of
    the prior). A state the log informed that stays above its target is "weakly determined". The defaults are
    what makes a DVL-aided navigation good to 0.1 % of distance travelled: the scale to 0.1 % and the
    misalignment to 0.1 deg (0.17 % of distance across track); the biases to half the paper's priors."""

    SECTION: ClassVar[str] = "observability"

    scale_ppm: Positive = 1000.0
    misalignment_deg: Positive = 0.1
    accel_bias_ug: Positive = 25.0
    gyro_bias_deg_per_h: Positive = 0.005


class CalibrationConfig(ConfigModel):
    """A vehicle's calibration file as the prior of a new dive (`smooth --calibration FILE`; TOML section
    [calibration]), and the verdict on the new estimate against it (analysis/calibration_check.py)."""

    SECTION: ClassVar[str] = "calibration"

    # the file's covariance grows with the days from its date to the dive's: each variance by this fraction of
    # itself per day, cov * (1 + inflation_per_day * days), correlations kept. 0.01: the variances doubled after
    # 100 days (sigmas x 1.41), x 4.65 after a year (sigmas x 2.2); 0: the file as written, whatever its age
    inflation_per_day: NonNegative = 0.01
    # a state "moved" since the file when the new estimate is beyond this many sigmas of the file's value (sigmas
    # of what the dive could move it: the file's variance minus the new one); the joint chi^2 test over the file's
    # states flags the dive at the same tail probability (3: 0.27 % of consistent dives flagged)
    moved_sigmas: Positive = 3.0
