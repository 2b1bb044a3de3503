"""The typed result every estimator returns, and how its numbers are read (calibration in user units)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.states import Estimate, required_states
from gtsam_dvl.core.summary import Summary
from gtsam_dvl.core.units import DEG_PER_H, UG


def misalignment_rpy_and_cov(
    b_R_d: np.ndarray, b_R_d0: np.ndarray, cov_right: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """[roll, pitch, yaw] (deg) of R_c = b_R_d b_R_d0^T and their covariance (deg^2), from the covariance of
    b_R_d in GTSAM's right tangent (rad^2). R_c's perturbation in body axes is b_R_d times the right one;
    with R_c = Rz(y) Ry(p) Rx(r), a body-axes perturbation Exp(e) R_c moves the angles by E^-1 e,
    E = [Rz Ry x, Rz y, z] (ZYX Euler rates). Closed form: it is called at every epoch by the filters."""
    R_c = b_R_d @ b_R_d0.T
    roll = math.atan2(R_c[2, 1], R_c[2, 2])
    pitch = -math.asin(max(-1.0, min(1.0, R_c[2, 0])))
    yaw = math.atan2(R_c[1, 0], R_c[0, 0])
    cp, sp, cy, sy = math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    E = np.array([[cp * cy, -sy, 0.0], [cp * sy, cy, 0.0], [-sp, 0.0, 1.0]])
    J = np.linalg.inv(E)
    cov_body = b_R_d @ cov_right @ b_R_d.T
    return np.degrees([roll, pitch, yaw]), np.degrees(np.degrees(J @ cov_body @ J.T))


class EstimatorResult(Protocol):
    """What every estimator returns (estimators/run.py): which estimator made it, the shared states it estimated
    by name (core/states.py; an Estimate: value and marginal covariance in the state's tangent, SI) and its wall
    times (s). A NavResult (batch, online, EKF: a trajectory too) and an IoDvlcResult (the DVL calibration alone,
    with its timelines over the DVL epochs) are both one."""

    estimator: str
    calibration: dict[str, Estimate]
    timing_s: dict[str, float]


class CalibrationUnits:
    """User-unit views (degrees, deg/h, micro-g) shared by every result type that holds b_R_d, b_R_d0,
    b_R_d_cov, gyro_bias, accel_bias and bias_cov in SI units (as attributes, or NavResult's properties)."""

    b_R_d0: np.ndarray
    if TYPE_CHECKING:  # read-only here: NavResult reads them from its calibration

        @property
        def b_R_d(self) -> np.ndarray: ...

        @property
        def b_R_d_cov(self) -> np.ndarray: ...

        @property
        def gyro_bias(self) -> np.ndarray: ...

        @property
        def accel_bias(self) -> np.ndarray: ...

        @property
        def bias_cov(self) -> np.ndarray: ...

    @property
    def misalignment_deg(self) -> np.ndarray:
        return misalignment_rpy_and_cov(self.b_R_d, self.b_R_d0, self.b_R_d_cov)[0]

    @property
    def misalignment_sigma_deg(self) -> np.ndarray:
        return np.sqrt(
            np.diag(misalignment_rpy_and_cov(self.b_R_d, self.b_R_d0, self.b_R_d_cov)[1])
        )

    @property
    def gyro_bias_deg_per_h(self) -> np.ndarray:
        return self.gyro_bias / DEG_PER_H

    @property
    def gyro_bias_sigma_deg_per_h(self) -> np.ndarray:
        return np.sqrt(np.diag(self.bias_cov)[3:]) / DEG_PER_H

    @property
    def accel_bias_ug(self) -> np.ndarray:
        return self.accel_bias / UG

    @property
    def accel_bias_sigma_ug(self) -> np.ndarray:
        return np.sqrt(np.diag(self.bias_cov)[:3]) / UG


@dataclass
class WaterCurrentProfile:
    """The water current an estimator carried (estimators/models/current.py profile): per state (or filter update),
    its time t_s (s), depth_m (m, down), the current east_m_s / north_m_s (m/s, map) with its sigmas (at the state's
    depth: with layers its layer's and the spread within it) and whether it was determined (sigma below half the
    prior's); the model's parameters; how many states had water-track pings and whether the current was determined
    over all of them; the largest speed (m/s); with layers ([current] layer_thickness_m > 0) the thickness, the
    boundaries crossed and the change of the current across each (layer_shear: boundary, depth_m, east_m_s,
    north_m_s and their sigmas); the verdict in one sentence. Written to a result file as info["water_current"]
    (as_dict, from_dict)."""

    t_s: np.ndarray
    depth_m: np.ndarray
    east_m_s: np.ndarray
    north_m_s: np.ndarray
    east_sigma_m_s: np.ndarray
    north_sigma_m_s: np.ndarray
    determined: np.ndarray  # (N,) bool
    prior_sigma_m_s: float
    time_rw_m_s_per_sqrt_s: float
    depth_rw_m_s_per_sqrt_m: float
    # "from the messages" when the pings' own covariances are used
    water_track_sigma_m_s: float | str
    max_speed_m_s: float
    verdict: str
    water_track_states: int | None = None
    determined_during_water_track: bool | None = None
    layer_thickness_m: float | None = None
    layer_boundaries: list[int] | None = None
    layer_shear: list[dict[str, Any]] | None = None

    _SERIES = (
        "t_s",
        "depth_m",
        "east_m_s",
        "north_m_s",
        "east_sigma_m_s",
        "north_sigma_m_s",
        "determined",
    )

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON, the keys in the order of the fields (the optional ones when given, the verdict last)."""
        out: dict[str, Any] = {
            name: np.asarray(getattr(self, name)).tolist() for name in self._SERIES
        }
        out.update(
            prior_sigma_m_s=self.prior_sigma_m_s,
            time_rw_m_s_per_sqrt_s=self.time_rw_m_s_per_sqrt_s,
            depth_rw_m_s_per_sqrt_m=self.depth_rw_m_s_per_sqrt_m,
            water_track_sigma_m_s=self.water_track_sigma_m_s,
        )
        if self.water_track_states is not None:
            out["water_track_states"] = self.water_track_states
            out["determined_during_water_track"] = self.determined_during_water_track
        out["max_speed_m_s"] = self.max_speed_m_s
        if self.layer_thickness_m is not None:
            out["layer_thickness_m"] = self.layer_thickness_m
            out["layer_boundaries"] = list(self.layer_boundaries or [])
            out["layer_shear"] = list(self.layer_shear or [])
        out["verdict"] = self.verdict
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> WaterCurrentProfile:
        """The profile from its as_dict form (a result file's info["water_current"])."""
        series = {
            name: np.asarray(d.get(name, []), dtype=bool if name == "determined" else float)
            for name in cls._SERIES
        }
        return cls(
            **series,
            prior_sigma_m_s=float(d.get("prior_sigma_m_s", math.nan)),
            time_rw_m_s_per_sqrt_s=float(d.get("time_rw_m_s_per_sqrt_s", math.nan)),
            depth_rw_m_s_per_sqrt_m=float(d.get("depth_rw_m_s_per_sqrt_m", math.nan)),
            water_track_sigma_m_s=d.get("water_track_sigma_m_s", math.nan),
            max_speed_m_s=float(d.get("max_speed_m_s", math.nan)),
            verdict=str(d.get("verdict", "")),
            water_track_states=d.get("water_track_states"),
            determined_during_water_track=d.get("determined_during_water_track"),
            layer_thickness_m=d.get("layer_thickness_m"),
            layer_boundaries=d.get("layer_boundaries"),
            layer_shear=d.get("layer_shear"),
        )


@dataclass(init=False)
class NavResult(CalibrationUnits):
    """Estimates of one estimator on one log. Angles in radians and SI units inside; the accessors and
    the summary give degrees, deg/h and micro-g.

    The shared states (core/states.py) are `calibration`: state name -> Estimate (value and marginal covariance
    in its tangent), the estimated ones only. Their attributes of old (scale, scale_sigma, b_R_d, b_R_d_cov,
    accel_bias, gyro_bias, bias_cov, time_offset_s, time_offset_sigma_s, lever_arm_m, lever_arm_cov) read it, and
    the constructor takes them as keywords too (hand-written for that): a result is made from either."""

    estimator: str
    t: np.ndarray  # (N,) s, relative to t0_ns
    n_p: np.ndarray  # (N, 3) m
    n_R_b: np.ndarray  # (N, 3, 3)
    n_v: np.ndarray  # (N, 3) m/s
    pose_cov: np.ndarray  # (N, 6, 6) GTSAM Pose3 tangent [rotation (body), translation (body)]
    vel_cov: np.ndarray  # (N, 3, 3) m^2/s^2, map frame
    calibration: dict[
        str, Estimate
    ]  # the estimated shared states by name (final; or the constants)
    b_R_d0: np.ndarray  # nominal mounting
    t0_ns: int
    # (N, 3) rad/s body rate relative to map at each state (gyro - bias - earth)
    b_omega: np.ndarray | None
    pose_vel_cross: np.ndarray | None  # (N, 6, 3) cross-covariance of pose tangent and n_v
    # (10, 10) joint of the calibration block (states.block_states): [accel, gyro] bias, scale, b_R_d right tangent
    calib_joint_cov: np.ndarray | None
    # joint of every estimated shared state at the last state (states.joint_states, columns named by
    # states.joint_columns): [accel, gyro] bias, scale, b_R_d right tangent, then the time offset and the lever arm
    # when estimated; SI. The geometry verdict (analysis/geometry.py) reads it; None: not given (online)
    shared_joint_cov: np.ndarray | None
    timeline: Timeline | None  # filtering history (online estimators and the EKF)
    timing_s: dict[str, float]
    info: dict[str, Any]  # solver report, counters, alignment
    # how the initial attitude was found: "attitude_topic", "configured", "static" or "in_motion" (details,
    # with its sigmas, in info["alignment"])
    alignment_method: str
    config: dict[str, Any]  # the effective configuration (EstimatorConfig.to_dict)
    # the indices of the DVL pings the estimator found usable (estimators/inputs/selection.py: before keyframe
    # thinning), in the log's DVL data (online: in the order pushed); None: not recorded (a result read from an older
    # file)
    dvl_pings: np.ndarray | None
    # the water current per state when the estimator carried it (water-track pings used), else None
    water_current: WaterCurrentProfile | None

    def __init__(
        self,
        estimator: str,
        t: np.ndarray,
        n_p: np.ndarray,
        n_R_b: np.ndarray,
        n_v: np.ndarray,
        pose_cov: np.ndarray,
        vel_cov: np.ndarray,
        *,
        b_R_d0: np.ndarray,
        calibration: dict[str, Estimate] | None = None,
        t0_ns: int = 0,
        b_omega: np.ndarray | None = None,
        pose_vel_cross: np.ndarray | None = None,
        calib_joint_cov: np.ndarray | None = None,
        shared_joint_cov: np.ndarray | None = None,
        timeline: Timeline | None = None,
        timing_s: dict[str, float] | None = None,
        info: dict[str, Any] | None = None,
        alignment_method: str = "",
        config: dict[str, Any] | None = None,
        dvl_pings: np.ndarray | None = None,
        water_current: WaterCurrentProfile | None = None,
        accel_bias: np.ndarray | None = None,
        gyro_bias: np.ndarray | None = None,
        bias_cov: np.ndarray | None = None,
        scale: float | None = None,
        scale_sigma: float | None = None,
        b_R_d: np.ndarray | None = None,
        b_R_d_cov: np.ndarray | None = None,
        time_offset_s: float = 0.0,
        time_offset_sigma_s: float = float("nan"),
        lever_arm_m: np.ndarray | None = None,
        lever_arm_cov: np.ndarray | None = None,
    ) -> None:
        self.estimator, self.t, self.n_p, self.n_R_b, self.n_v = estimator, t, n_p, n_R_b, n_v
        self.pose_cov, self.vel_cov, self.b_R_d0, self.t0_ns = pose_cov, vel_cov, b_R_d0, t0_ns
        self.b_omega, self.pose_vel_cross, self.calib_joint_cov, self.timeline = (
            b_omega,
            pose_vel_cross,
            calib_joint_cov,
            timeline,
        )
        self.shared_joint_cov = shared_joint_cov
        self.timing_s = {} if timing_s is None else timing_s
        self.info = {} if info is None else info
        self.alignment_method = alignment_method
        self.config = {} if config is None else config
        self.dvl_pings = None if dvl_pings is None else np.asarray(dvl_pings, dtype=np.int64)
        self.water_current = water_current
        self.calibration = dict(calibration or {})
        # the keywords of old: the states they give (a time offset only when estimated, or not zero)
        if bias_cov is not None:
            bias_cov = np.asarray(bias_cov)
        given: dict[str, tuple[Any, Any]] = {
            "accel_bias": (accel_bias, None if bias_cov is None else bias_cov[:3, :3]),
            "gyro_bias": (gyro_bias, None if bias_cov is None else bias_cov[3:, 3:]),
            "scale": (
                None if scale is None else [scale],
                None if scale_sigma is None else [[float(scale_sigma) ** 2]],
            ),
            "misalignment": (b_R_d, b_R_d_cov),
            "time_offset": (
                ([time_offset_s], [[float(time_offset_sigma_s) ** 2]])
                if math.isfinite(time_offset_sigma_s) or time_offset_s != 0.0
                else (None, None)
            ),
            "lever_arm": (lever_arm_m, lever_arm_cov),
        }
        for name, (value, cov) in given.items():
            if value is not None and cov is not None:
                self.calibration[name] = Estimate(
                    np.asarray(value, dtype=float), np.asarray(cov, dtype=float)
                )
            elif value is not None or cov is not None:
                raise ValueError(f"NavResult: {name} needs both its value and its covariance")
        missing = [s.name for s in required_states() if s.name not in self.calibration]
        if missing:
            raise ValueError(f"NavResult: no estimate of {', '.join(missing)}")

    # ----- the shared states by their attributes of old -------------------------------------------------
    @property
    def accel_bias(self) -> np.ndarray:  # (3,) m/s^2 (final; or the constant)
        return self.calibration["accel_bias"].value

    @property
    def gyro_bias(self) -> np.ndarray:  # (3,) rad/s
        return self.calibration["gyro_bias"].value

    @property
    def bias_cov(self) -> np.ndarray:
        """(6, 6) [accel, gyro] SI: the calibration block's (with their cross-covariance), else the two blocks."""
        if self.calib_joint_cov is not None:
            return np.asarray(self.calib_joint_cov)[:6, :6]
        out = np.zeros((6, 6))
        out[:3, :3], out[3:, 3:] = (
            self.calibration["accel_bias"].cov,
            self.calibration["gyro_bias"].cov,
        )
        return out

    @property
    def scale(self) -> float:
        return float(self.calibration["scale"].value[0])

    @property
    def scale_sigma(self) -> float:
        return float(self.calibration["scale"].sigma[0])

    @property
    def b_R_d(self) -> np.ndarray:  # (3, 3)
        return self.calibration["misalignment"].value

    @property
    def b_R_d_cov(self) -> np.ndarray:  # (3, 3) rad^2, right tangent of b_R_d
        return self.calibration["misalignment"].cov

    @property
    def time_offset_s(self) -> float:
        """The DVL-IMU time offset dt_d, s (0 when not estimated: every estimator then takes dt_d = 0)."""
        est = self.calibration.get("time_offset")
        return 0.0 if est is None else float(est.value[0])

    @property
    def time_offset_sigma_s(self) -> float:
        """Its sigma, s (nan: not estimated)."""
        est = self.calibration.get("time_offset")
        return float("nan") if est is None else float(est.sigma[0])

    @property
    def lever_arm_m(self) -> np.ndarray | None:
        """The DVL lever arm b_l (IMU -> DVL, m, base_link) with [dvl] estimate_lever_arm (None: not estimated, b_l
        taken from /tf_static)."""
        est = self.calibration.get("lever_arm")
        return None if est is None else est.value

    @property
    def lever_arm_cov(self) -> np.ndarray | None:
        """Its 3x3 marginal covariance, m^2 (None: not estimated)."""
        est = self.calibration.get("lever_arm")
        return None if est is None else est.cov

    @functools.cached_property
    def estimator_config(self) -> EstimatorConfig | None:
        """The configuration the result was made with, read once from `config` (None: a result written by
        another version, whose configuration does not read)."""
        try:
            return EstimatorConfig.from_dict(self.config) if self.config else EstimatorConfig()
        except GtsamDvlError:
            return None

    @property
    def noise_config(self) -> EstimatorConfig | None:
        """The configuration with the noise levels the estimator used: `config` holds the configuration as given
        (reading it back with -c reproduces the run), info["noise"] the levels taken from the data
        (estimators/models/noise_levels.py: the IMU white noise raised to its quantisation floor, the fitted DVL, depth
        and
        GNSS noise factors, the DVL's fitted correlated error). What the residuals are judged against. None: the
        configuration does not read."""
        config = self.estimator_config
        noise = self.info.get("noise") if isinstance(self.info, dict) else None
        if config is None or not isinstance(noise, dict):
            return config
        imu_update = {
            key: float(entry["used"])
            for name, key in (
                ("gyro", "gyro_noise_deg_per_h_rthz"),
                ("accel", "accel_noise_ug_rthz"),
            )
            if isinstance(entry := noise.get("imu", {}).get(name), dict)
            and entry.get("used") is not None
        }
        multiplier = noise.get("dvl", {}).get("multiplier")
        update: dict[str, Any] = {}
        if imu_update:
            update["imu"] = config.imu.model_copy(update=imu_update)
        dvl_update: dict[str, float] = {}
        if multiplier is not None and math.isfinite(float(multiplier)):
            dvl_update["noise_multiplier"] = float(multiplier)
        # the batch smoother's fitted correlated error (estimators/models/correlated_fit.py)
        gm = noise.get("dvl_correlated")
        if isinstance(gm, dict) and all(
            isinstance(gm.get(k), float) and math.isfinite(gm[k]) and gm[k] > 0
            for k in ("sigma_m_s", "tau_s")
        ):
            dvl_update.update(correlated_sigma_m_s=gm["sigma_m_s"], correlated_tau_s=gm["tau_s"])
        if dvl_update:
            update["dvl"] = config.dvl.model_copy(update=dvl_update)
        for sensor in ("depth", "gnss"):  # the batch smoother's fitted depth and GNSS factors
            entry = noise.get(sensor)
            if (
                isinstance(entry, dict)
                and entry.get("multiplier") is not None
                and math.isfinite(float(entry["multiplier"]))
            ):
                update[sensor] = getattr(config, sensor).model_copy(
                    update={"noise_multiplier": float(entry["multiplier"])}
                )
        return config.model_copy(update=update) if update else config

    @property
    def lever_arm_sigma_m(self) -> np.ndarray | None:
        """(3,) marginal sigmas of the estimated lever arm along base_link x, y, z, m (None: not estimated)."""
        return None if self.lever_arm_cov is None else np.sqrt(np.diag(self.lever_arm_cov))

    @property
    def attitude_sigma_deg(self) -> np.ndarray:
        """(N, 3) attitude sigmas about map axes (east, north, up), deg."""
        cov_map = self.n_R_b @ self.pose_cov[:, :3, :3] @ np.transpose(self.n_R_b, (0, 2, 1))
        return np.degrees(np.sqrt(np.einsum("nii->ni", cov_map)))

    @property
    def position_sigma_m(self) -> np.ndarray:
        """(N, 3) position sigmas in map axes, m (GTSAM's translation tangent is in body axes)."""
        cov_map = self.n_R_b @ self.pose_cov[:, 3:, 3:] @ np.transpose(self.n_R_b, (0, 2, 1))
        return np.sqrt(np.einsum("nii->ni", cov_map))

    @property
    def velocity_sigma_m_s(self) -> np.ndarray:
        """(N, 3) velocity sigmas in map axes, m/s."""
        return np.sqrt(np.einsum("nii->ni", self.vel_cov))


@dataclass
class StoredResult:
    """A result as read back from a result log (gtsam_dvl.io.result_reader): the NavResult that was written,
    the summary written with it (its typed model, core/summary.py: migrated when older), and where it came from:
    the source log's absolute path when smoothed, its path relative to the result file's folder, and the options it
    was read with (imu_topic, dvl_topic, salvage, repair; empty for a result written before they were recorded);
    the SHA-256 of the source log's content and the map origin it read (lat_deg, lon_deg, height_m), "" and None
    when not recorded."""

    result: NavResult
    summary: Summary
    path: str = ""
    source_log: str = ""
    source_log_relative: str = ""
    read_options: dict[str, Any] = field(default_factory=dict)
    source_sha256: str = ""
    source_origin: dict[str, float] | None = None


@dataclass
class Timeline:
    """Filtering estimates and marginal sigmas of the calibration, biases and attitude after each epoch:
    the paper's Figures 4-9 and 12. Units as named; misalignment = [roll, pitch, yaw] of R_c in body axes;
    attitude sigmas about map axes (east, north, up)."""

    t: np.ndarray  # (N,) s
    scale: np.ndarray  # (N,)
    scale_sigma: np.ndarray  # (N,)
    misalignment_deg: np.ndarray  # (N, 3)
    misalignment_sigma_deg: np.ndarray  # (N, 3)
    gyro_bias_deg_per_h: np.ndarray  # (N, 3)
    gyro_bias_sigma_deg_per_h: np.ndarray  # (N, 3)
    accel_bias_ug: np.ndarray  # (N, 3)
    accel_bias_sigma_ug: np.ndarray  # (N, 3)
    attitude_sigma_deg: np.ndarray  # (N, 3)
    # when estimated (None otherwise): the DVL time offset (s) and lever arm (m, base_link)
    time_offset_s: np.ndarray | None = None  # (N,)
    time_offset_sigma_s: np.ndarray | None = None  # (N,)
    lever_arm_m: np.ndarray | None = None  # (N, 3)
    lever_arm_sigma_m: np.ndarray | None = None  # (N, 3)

    FIELDS = (
        "t",
        "scale",
        "scale_sigma",
        "misalignment_deg",
        "misalignment_sigma_deg",
        "gyro_bias_deg_per_h",
        "gyro_bias_sigma_deg_per_h",
        "accel_bias_ug",
        "accel_bias_sigma_ug",
        "attitude_sigma_deg",
    )
    OPTIONAL = ("time_offset_s", "time_offset_sigma_s", "lever_arm_m", "lever_arm_sigma_m")

    def as_arrays(self) -> dict[str, np.ndarray]:
        out = {name: np.asarray(getattr(self, name)) for name in self.FIELDS}
        out.update(
            {
                name: np.asarray(getattr(self, name))
                for name in self.OPTIONAL
                if getattr(self, name) is not None
            }
        )
        return out

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> Timeline:
        return cls(
            **{name: np.asarray(arrays[name]) for name in cls.FIELDS},
            **{name: np.asarray(arrays[name]) for name in cls.OPTIONAL if name in arrays},
        )
