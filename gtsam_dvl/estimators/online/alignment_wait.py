"""The online estimator's start: the messages kept until the initial attitude is known, then aligned on.

The estimator buffers the IMU samples, pings and attitude samples it is given and aligns on them with the batch
smoother's and the EKF's own functions (estimators/inputs/alignment.py), in the order of alignment.method "auto":
1. an attitude sample (OnlineEstimator.push_attitude: the IMU message's own orientation when the driver fills it,
   an AHRS, an INS): the first at or after the first IMU sample (alignment._attitude_alignment, the batch's), at
   once;
2. alignment.initial_attitude_deg: no wait at all (the estimator starts when it is made);
3. a static start: once `align_s` (+ STATIC_MARGIN_S + 1 s) seconds of IMU have come, coarse alignment on the
   static segment (method "static", the segment capped at align_s);
4. else in motion with the DVL: once alignment.in_motion_window_s (+ IN_MOTION_MARGIN_S) seconds of IMU have come,
   the batch's in_motion_alignment on the buffered window (from the first IMU sample, over in_motion_window_s: the
   same samples and pings as the batch smoother's, so the same attitude, to rounding).
A forced alignment.method waits for that method alone. The estimator then runs on what it buffered (the states
from the first usable ping on) and reports nothing before: the first estimate comes in_motion_window_s + 1 s of
data after the first sample (120 s + 1 s by default) in motion, align_s + 6 s from a static start, at the first
attitude sample with an attitude source; NavResult.info["alignment"]["latency"] gives it (OnlineEstimator).
At the end of the data (finish) a wait still open aligns on what there is (a shorter window).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gtsam_dvl.core.config import AlignmentConfig, EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_quat_xyzw, quat_xyzw_to_matrix
from gtsam_dvl.core.types import AttitudeData, DvlData, ImuData, Mounting
from gtsam_dvl.estimators.inputs.alignment import (
    ATTITUDE_SOURCES,
    STATIC_MARGIN_S,
    Alignment,
    align,
)
from gtsam_dvl.estimators.inputs.selection import Ping

ImuChunk = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # stamps (s), gyro (rad/s), specific force (m/s^2)

# the in-motion alignment runs this long after its window's end, so that the pings stamped inside the window have
# come (a DVL message arrives after the IMU samples up to its stamp; later on another computer's clock)
IN_MOTION_MARGIN_S = 1.0


def given_attitude(frame: LocalFrame, cfg: AlignmentConfig) -> Alignment:
    """The alignment from alignment.initial_attitude_deg, without data."""
    return align(
        ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3))),
        DvlData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0, dtype=bool)),
        frame,
        cfg.model_copy(update={"method": "auto"}),
    )


@dataclass
class Aligned:
    """What AlignmentWait.try_align gives: the alignment, the IMU samples kept (base_link) and the pings kept."""

    alignment: Alignment
    imu: ImuChunk
    pings: list[Ping]


class AlignmentWait:
    """IMU samples (base_link), pings and attitude samples kept until the alignment (module doc). config: its
    [alignment] and the IMU's bias sigmas ([imu], for the in-motion alignment's); align_s: the static seconds to wait
    for (OnlineConfig.align_s); mounting: the DVL's nominal mounting and lever arm; source: the log's name in error
    messages."""

    def __init__(
        self,
        frame: LocalFrame,
        config: EstimatorConfig,
        align_s: float,
        source: str,
        mounting: Mounting | None = None,
    ) -> None:
        self.frame, self.cfg, self.align_s, self.source = frame, config.alignment, align_s, source
        self.mounting, self.imu_cfg = mounting or Mounting(), config.imu
        # when the first estimate came (module doc; set by the estimator): info["alignment"]["latency"]
        self.latency: dict[str, float] = {}
        self.imu: list[ImuChunk] = []
        self.pings: list[Ping] = []
        # attitude samples of base_link in map: stamp (s), [x, y, z, w], covariance (3x3 rad^2, body axes; NaN:
        # unknown)
        self.attitude: list[tuple[float, np.ndarray, np.ndarray]] = []
        self.t_first: float | None = None  # the first IMU stamp (s)
        self.t_last: float | None = None  # the newest IMU stamp (s)
        # "auto": the static segment ruled out (too short), waiting for the in-motion window; with its message
        self.static_refused: str | None = None

    # ----- input ---------------------------------------------------------------------------------------------
    def push_imu(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> None:
        """Keep IMU samples (base_link)."""
        if len(t):
            self.imu.append((t, w, f))
            self.t_first = float(t[0]) if self.t_first is None else self.t_first
            self.t_last = float(t[-1])

    def push_attitude(self, t: float, n_q_s: Any, cov: Any, b_R_s: np.ndarray) -> bool:
        """Keep an attitude sample: the orientation of a sensor frame s in map ([x, y, z, w]; b_R_s: s in base_link)
        and its covariance (3x3 rad^2 about the sensor's axes; None, all zeros or NaN: unknown), turned into base_link
        as io/attitude.py turns a log's. A zero or non-finite quaternion, or cov[0][0] = -1 (ROS: no orientation),
        is no sample. Returns whether it was kept."""
        q = np.asarray(n_q_s, dtype=float).reshape(4)
        c = np.full((3, 3), np.nan) if cov is None else np.array(cov, dtype=float).reshape(3, 3)
        if self.cfg.method not in ("auto", "attitude_topic") or c[0, 0] == -1.0:
            return False
        if not (np.isfinite(q).all() and np.linalg.norm(q) > 0.5):
            return False
        if not np.any(c):  # all zeros: unknown (ROS)
            c[:] = np.nan
        n_R_b = quat_xyzw_to_matrix(q / np.linalg.norm(q)) @ b_R_s.T
        self.attitude.append((float(t), matrix_to_quat_xyzw(n_R_b), b_R_s @ c @ b_R_s.T))
        return True

    # ----- the decision --------------------------------------------------------------------------------------
    def try_align(self, final: bool = False) -> Aligned | None:
        """The alignment when the data kept allow it (module doc), else None; final: the end of the data, align
        on what there is (or a GtsamDvlError saying why not). The data kept are handed over and forgotten."""
        if self.t_first is None or self.t_last is None:
            if final and self.cfg.method == "attitude_topic":
                raise self._error(self._no_attitude())
            return None
        method, span = self.cfg.method, self.t_last - self.t_first
        alignment = None
        if method in ("auto", "attitude_topic") and self._attitude_ready(final):
            alignment = align(
                *self._data(), self.frame, self._cfg("attitude_topic"), attitude=self._att()
            )
        elif method == "attitude_topic":
            if final:
                raise self._error(self._no_attitude())
        elif method in ("auto", "static") and self.static_refused is None:
            if final or span >= self.align_s + STATIC_MARGIN_S + 1.0:
                alignment = self._static()
        if (
            alignment is None
            and (method == "in_motion" or self.static_refused is not None)
            and (final or span >= self.cfg.in_motion_window_s + IN_MOTION_MARGIN_S)
        ):
            alignment = self._in_motion()
        if alignment is None:
            return None
        out = Aligned(alignment, self._imu_chunk(), self.pings)
        self.imu, self.pings, self.attitude = [], [], []
        return out

    def _attitude_ready(self, final: bool) -> bool:
        """An attitude sample at or after the first IMU sample has come (at the end: any)."""
        assert self.t_first is not None
        return any(a[0] >= self.t_first for a in self.attitude) or (final and bool(self.attitude))

    def _static(self) -> Alignment | None:
        """Coarse alignment on the static start (the segment capped at align_s); in "auto" a start too short
        leaves it to the in-motion alignment (static_refused), forced it is an error."""
        cfg = self._cfg("static")
        cfg.max_static_s = (
            min(cfg.max_static_s, self.align_s) if cfg.max_static_s > 0 else self.align_s
        )
        try:
            return align(*self._data(), self.frame, cfg)
        except GtsamDvlError as exc:
            if not str(exc).startswith("no static segment"):
                raise self._error(str(exc)) from None
            if self.cfg.method == "static":
                raise self._error(f"{str(exc).split(';')[0]}; give {ATTITUDE_SOURCES}") from None
            self.static_refused = str(exc).split(";")[0]
            return None

    def _in_motion(self) -> Alignment:
        """The batch smoother's in-motion alignment on the buffered window (a GtsamDvlError in one line, with why
        the static start did not serve)."""
        try:
            return align(
                *self._data(),
                self.frame,
                self._cfg("in_motion"),
                mounting=self.mounting,
                imu_cfg=self.imu_cfg,
            )
        except GtsamDvlError as exc:
            why = f"{self.static_refused}, and " if self.static_refused else ""
            raise self._error(f"{why}{exc}") from None

    # ----- helpers -------------------------------------------------------------------------------------------
    def _cfg(self, method: str) -> AlignmentConfig:
        return self.cfg.model_copy(update={"method": method})

    def _imu_chunk(self) -> ImuChunk:
        return (
            np.concatenate([c[0] for c in self.imu]),
            np.concatenate([c[1] for c in self.imu]),
            np.concatenate([c[2] for c in self.imu]),
        )

    def _data(self) -> tuple[ImuData, DvlData]:
        """The IMU samples and pings kept, as the batch's alignment takes them."""
        t, w, f = self._imu_chunk()
        pings = self.pings
        dvl = DvlData(
            np.array([p.t for p in pings]),
            np.array([p.d_v for p in pings]).reshape(-1, 3),
            np.array([p.d_cov for p in pings]).reshape(-1, 3, 3),
            np.array([p.valid for p in pings], bool),
        )
        return ImuData(t, w, f), dvl

    def _att(self) -> AttitudeData:
        a = self.attitude
        return AttitudeData(
            np.array([s[0] for s in a]),
            np.array([s[1] for s in a]).reshape(-1, 4),
            np.array([s[2] for s in a]).reshape(-1, 3, 3),
            "attitude samples (OnlineEstimator.push_attitude)",
        )

    def _no_attitude(self) -> str:
        return (
            'alignment.method = "attitude_topic" but no attitude sample came (OnlineEstimator.push_attitude: '
            "the IMU message's orientation, an AHRS, an INS)"
        )

    def _error(self, message: str) -> GtsamDvlError:
        where = f"{self.source + ': ' if self.source else ''}"
        return GtsamDvlError(f"{where}online alignment: {message}")
