"""The online estimator's start: the messages kept until the initial attitude is known.

The estimator waits for `align_s` seconds of the initial static segment (or motion, if sooner, after
alignment.min_static_s) and aligns on them with the batch smoother's coarse alignment (estimators/inputs/alignment.py,
method "static"), then processes the buffered messages; it reports nothing before. alignment.initial_attitude_deg
skips the wait. The in-motion alignment and attitude topics are the batch smoother's and the EKF's only: they are
not causal.
"""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core.config import AlignmentConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import DvlData, ImuData
from gtsam_dvl.estimators.inputs.alignment import STATIC_MARGIN_S, Alignment, align
from gtsam_dvl.estimators.inputs.selection import Ping

ImuChunk = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # stamps (s), gyro (rad/s), specific force (m/s^2)


def given_attitude(frame: LocalFrame, cfg: AlignmentConfig) -> Alignment:
    """The alignment from alignment.initial_attitude_deg, without data."""
    return align(
        ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))),
        DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, dtype=bool)),
        frame,
        cfg.model_copy(update={"method": "auto"}),
    )


class AlignmentWait:
    """IMU samples (base_link) and pings kept until the alignment (module doc). align_s: the static seconds to
    wait for (OnlineConfig.align_s); source: the log's name in error messages."""

    def __init__(
        self, frame: LocalFrame, cfg: AlignmentConfig, align_s: float, source: str
    ) -> None:
        self.frame, self.cfg, self.align_s, self.source = frame, cfg, align_s, source
        self.imu: list[ImuChunk] = []
        self.pings: list[Ping] = []

    def push_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray, t_first: float) -> bool:
        """Keep IMU samples; returns whether enough have come since the first (at t_first, s) to align."""
        self.imu.append((t, w, f))
        return bool(t[-1] - t_first >= self.align_s + STATIC_MARGIN_S + 1.0)

    def align(self) -> tuple[Alignment, ImuChunk, list[Ping]]:
        """Align on what was kept; returns the alignment, the IMU samples and the pings kept (then forgotten)."""
        t = np.concatenate([c[0] for c in self.imu])
        w = np.concatenate([c[1] for c in self.imu])
        f = np.concatenate([c[2] for c in self.imu])
        pings = self.pings
        dvl = DvlData(
            np.array([p.t for p in pings]),
            np.array([p.d_v for p in pings]).reshape(-1, 3),
            np.array([p.d_cov for p in pings]).reshape(-1, 3, 3),
            np.array([p.valid for p in pings], bool),
        )
        cfg = self.cfg.model_copy()
        cfg.max_static_s = (
            min(cfg.max_static_s, self.align_s) if cfg.max_static_s > 0 else self.align_s
        )
        where = f"{self.source + ': ' if self.source else ''}"
        need = (
            "online needs an attitude source or a static start: set alignment.initial_attitude_deg, or log "
            f"a static start of alignment.min_static_s ({cfg.min_static_s:g} s)"
        )
        if cfg.method in ("attitude_topic", "in_motion"):
            raise GtsamDvlError(
                f"{where}{need}; alignment.method = {cfg.method!r} is for the batch smoother and "
                "the EKF"
            )
        cfg.method = "static"
        try:
            alignment = align(ImuData(t, w, f), dvl, self.frame, cfg)
        except GtsamDvlError as exc:
            if str(exc).startswith("no static segment"):
                raise GtsamDvlError(
                    f"{where}online alignment: {str(exc).split(';')[0]}; {need}"
                ) from None
            raise GtsamDvlError(f"{where}online alignment: {exc}") from None
        self.imu, self.pings = [], []
        return alignment, (t, w, f), pings
