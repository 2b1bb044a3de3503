"""Types of the online estimator (gtsam_dvl/estimators/online/estimator.py): its options, the estimate it gives
after each DVL epoch, and small helpers shared with the benchmark."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import get_args

import numpy as np

from gtsam_dvl.core.config import OnlineConfig, OnlineMode
from gtsam_dvl.core.result import CalibrationUnits, Timeline, misalignment_rpy_and_cov
from gtsam_dvl.core.units import DEG_PER_H, UG
from gtsam_dvl.estimators.online.window import EstimateExtras, StateEstimate

__all__ = [
    "ONLINE_MODES",
    "EpochHistory",
    "MessageDropped",
    "OnlineConfig",
    "OnlineEstimate",
    "latency_stats",
    "misalignment_deg_and_cov",
]

ONLINE_MODES: tuple[str, ...] = get_args(OnlineMode)  # OnlineConfig.mode's values


class MessageDropped(UserWarning):
    """A message was dropped (bad_messages = "drop"); OnlineEstimator.counters counts them by kind."""


# OnlineConfig (the options, TOML section [online]) lives in gtsam_dvl.core.config and is re-exported here.


@dataclass
class OnlineEstimate(CalibrationUnits, EstimateExtras):
    """The estimate after one DVL epoch, with marginal covariances given the data so far (SI units, GTSAM
    tangents: pose [rotation, translation] in body axes, b_R_d perturbed on the right), and EstimateExtras (the
    time offset, whether predicted at a ping, the shared states by name). The properties give the user units of
    NavResult."""

    t: float
    n_p: np.ndarray
    n_R_b: np.ndarray
    n_v: np.ndarray
    pose_cov: np.ndarray  # (6, 6)
    vel_cov: np.ndarray  # (3, 3)
    pose_vel_cross: np.ndarray  # (6, 3)
    accel_bias: np.ndarray  # m/s^2
    gyro_bias: np.ndarray  # rad/s
    bias_cov: np.ndarray  # (6, 6) [accel, gyro]
    scale: float
    scale_sigma: float
    b_R_d: np.ndarray
    b_R_d_cov: np.ndarray  # (3, 3) rad^2
    b_R_d0: np.ndarray
    calib_cov: np.ndarray  # (10, 10) [accel, gyro] bias, scale, b_R_d

    @classmethod
    def from_state(cls, s: StateEstimate, b_R_d0: np.ndarray) -> OnlineEstimate:
        return cls(
            t=s.t,
            n_p=np.asarray(s.pose.translation()),
            n_R_b=s.pose.rotation().matrix(),
            n_v=s.n_v,
            pose_cov=s.pose_cov,
            vel_cov=s.vel_cov,
            pose_vel_cross=s.pose_vel_cross,
            accel_bias=np.asarray(s.bias.accelerometer()),
            gyro_bias=np.asarray(s.bias.gyroscope()),
            bias_cov=s.cov[9:15, 9:15],
            scale=s.scale,
            scale_sigma=float(np.sqrt(s.cov[15, 15])),
            b_R_d=s.b_R_d,
            b_R_d_cov=s.cov[16:19, 16:19],
            b_R_d0=b_R_d0,
            calib_cov=s.calib_cov,
            time_offset_s=s.time_offset_s,
            time_offset_sigma_s=s.time_offset_sigma_s,
            predicted_from_t=s.predicted_from_t,
            calibration=s.calibration,
        )

    @property
    def attitude_sigma_deg(self) -> np.ndarray:
        """Attitude sigmas about map axes (east, north, up), deg."""
        return np.degrees(np.sqrt(np.diag(self.n_R_b @ self.pose_cov[:3, :3] @ self.n_R_b.T)))


# the closed form lives in gtsam_dvl.core.result; this name is kept for the online modules
misalignment_deg_and_cov = misalignment_rpy_and_cov


def latency_stats(latencies_s: Sequence[float] | np.ndarray) -> dict[str, float]:
    """p50, p99 and max of per-epoch latencies, ms."""
    lat = np.asarray(latencies_s, dtype=float) * 1e3
    if lat.size == 0:
        return {"p50": math.nan, "p99": math.nan, "max": math.nan}
    return {
        "p50": float(np.percentile(lat, 50)),
        "p99": float(np.percentile(lat, 99)),
        "max": float(lat.max()),
    }


class EpochHistory:
    """Every epoch's estimate, in numpy arrays filled block by block. No Python object is kept per epoch (the
    garbage collector's pauses grow with the number of live objects) and nothing is copied when the history
    grows (doubling an array would copy every epoch so far). A fixed number of doubles per epoch (SHAPES)
    (OnlineConfig.record_history = False keeps none)."""

    BLOCK = 4096
    SHAPES: dict[str, tuple[int, ...]] = {
        "t": (),
        "n_p": (3,),
        "n_R_b": (3, 3),
        "n_v": (3,),
        "pose_cov": (6, 6),
        "vel_cov": (3, 3),
        "pose_vel_cross": (6, 3),
        "accel_bias": (3,),
        "gyro_bias": (3,),
        "bias_cov": (6, 6),
        "scale": (),
        "scale_sigma": (),
        "b_R_d": (3, 3),
        "b_R_d_cov": (3, 3),
        "b_omega": (3,),
    }

    def __init__(self) -> None:
        self.n = 0
        self._blocks: list[dict[str, np.ndarray]] = []

    def __len__(self) -> int:
        return self.n

    def append(self, estimate: OnlineEstimate, b_omega: np.ndarray) -> None:
        """Add an epoch's estimate and its body rate (gyro minus Earth rate, rad/s)."""
        row = self.n % self.BLOCK
        if row == 0:
            self._blocks.append(
                {name: np.empty((self.BLOCK, *shape)) for name, shape in self.SHAPES.items()}
            )
        for name, a in self._blocks[-1].items():
            a[row] = b_omega if name == "b_omega" else getattr(estimate, name)
        self.n += 1

    def __getitem__(self, name: str) -> np.ndarray:
        if not self._blocks:
            return np.empty((0, *self.SHAPES[name]))
        return np.concatenate([b[name] for b in self._blocks])[: self.n]

    def timeline(self, b_R_d0: np.ndarray) -> Timeline:
        """The estimates and sigmas of every epoch, in NavResult's units (b_R_d0: the nominal mounting)."""
        mis = [
            misalignment_rpy_and_cov(R, b_R_d0, P)
            for R, P in zip(self["b_R_d"], self["b_R_d_cov"], strict=True)
        ]
        n_R_b = self["n_R_b"]
        att_cov = n_R_b @ self["pose_cov"][:, :3, :3] @ np.transpose(n_R_b, (0, 2, 1))
        bias_var = np.einsum("nii->ni", self["bias_cov"])
        return Timeline(
            t=self["t"].copy(),
            scale=self["scale"].copy(),
            scale_sigma=self["scale_sigma"].copy(),
            misalignment_deg=np.array([m[0] for m in mis]).reshape(-1, 3),
            misalignment_sigma_deg=np.sqrt(np.array([np.diag(m[1]) for m in mis]).reshape(-1, 3)),
            gyro_bias_deg_per_h=self["gyro_bias"] / DEG_PER_H,
            gyro_bias_sigma_deg_per_h=np.sqrt(bias_var[:, 3:]) / DEG_PER_H,
            accel_bias_ug=self["accel_bias"] / UG,
            accel_bias_sigma_ug=np.sqrt(bias_var[:, :3]) / UG,
            attitude_sigma_deg=np.degrees(np.sqrt(np.einsum("nii->ni", att_cov))),
        )
