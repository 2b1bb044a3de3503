"""The online estimator's IMU samples since the newest state: held raw until the next state's IMU factor is made.

The buffer keeps, first, the last sample at or before the newest state (the sample held across a gap that starts
there, estimators/inputs/gaps.py), then every sample since. Each interval's sample starts, gaps and rotation-compensated
specific forces are made as the batch smoother makes them for the whole log (gaps.find_gaps with the nominal
period measured on the first PERIOD_SAMPLES stamps, sample_starts_with_gaps, FactorMaker.compensate_rotation).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gtsam_dvl.core.config import ImuConfig
from gtsam_dvl.estimators.graph.factor_maker import FactorMaker
from gtsam_dvl.estimators.inputs.gaps import (
    ImuPieces,
    check_gaps,
    find_gaps,
    nominal_period,
    sample_starts_with_gaps,
)

PERIOD_SAMPLES = 64  # IMU stamps that measure the nominal period (the median spacing)

ImuChunk = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # stamps (s), gyro (rad/s), specific force (m/s^2)


class ImuBuffer:
    """IMU samples (base_link) since the newest state (module doc). count(kind, n): the estimator's counters
    ("imu_gaps"); source: the log's name in error messages."""

    def __init__(self, cfg: ImuConfig, source: str, count: Callable[[str, int], None]) -> None:
        self.cfg, self.source, self._count = cfg, source, count
        self._chunks: list[ImuChunk] = []
        self._period: float | None = None  # nominal IMU period, s
        self._period_t: list[float] = []  # the first IMU stamps, to measure it
        self.gaps_seen: dict[float, float] = {}  # IMU gaps crossed: start -> duration, s

    def push(self, t: np.ndarray, w: np.ndarray, f: np.ndarray) -> None:
        """IMU samples in time order, after every earlier one."""
        # the nominal period, for the gap rule (estimators/inputs/gaps.py): from the first
        if self._period is None:
            # PERIOD_SAMPLES stamps, across chunks
            self._period_t.extend(t[:PERIOD_SAMPLES].tolist())
            if len(self._period_t) >= PERIOD_SAMPLES:
                self._period = nominal_period(np.asarray(self._period_t[:PERIOD_SAMPLES]))
        if len(t):
            self._chunks.append((t, w, f))

    def t_last(self) -> float | None:
        """The newest sample's stamp (s), None when empty."""
        return float(self._chunks[-1][0][-1]) if self._chunks else None

    def samples(self) -> ImuChunk:
        """The samples held, as one chunk."""
        if len(self._chunks) > 1:
            self._chunks = [tuple(np.concatenate(c) for c in zip(*self._chunks, strict=True))]  # type: ignore[list-item]
        return self._chunks[0]

    def pieces(
        self, maker: FactorMaker, T: np.ndarray, W: np.ndarray, F: np.ndarray, final: bool
    ) -> ImuPieces:
        """Samples T, W, F (the buffer's) as the preintegrations take them: their starts (s),
        rotation-compensated specific forces (m/s^2) and gaps; final: the buffer of a new state's interval, whose
        gaps are checked and counted."""
        # until PERIOD_SAMPLES stamps have come, the median of those seen (an epoch's buffer may hold a gap)
        period = self._period or nominal_period(
            np.asarray(self._period_t) if len(self._period_t) > 2 else T
        )
        gaps = find_gaps(T, self.cfg.gap_samples, period)
        if final:
            check_gaps(gaps, self.cfg, self.source)
            for g0, g1 in zip(gaps.start.tolist(), gaps.end.tolist(), strict=True):
                if g0 not in self.gaps_seen:
                    self.gaps_seen[g0] = g1 - g0
                    self._count("imu_gaps", 1)
        starts = sample_starts_with_gaps(T, gaps)
        return ImuPieces(T, starts, maker.compensate_rotation(F, W, T - starts), W, gaps)

    def keep_from(self, t_epoch: float) -> None:
        """A state was made at t_epoch (s): keep the last sample at or before it and those after."""
        T, W, F = self.samples()
        first_kept = max(int(np.searchsorted(T, t_epoch, side="right")) - 1, 0)
        self._chunks = [(T[first_kept:], W[first_kept:], F[first_kept:])]

    def gaps_info(self) -> dict[str, float]:
        """The gaps crossed: count, total and longest (s), for NavResult.info["imu_gaps"]."""
        return {
            "count": len(self.gaps_seen),
            "total_s": float(sum(self.gaps_seen.values())),
            "longest_s": float(max(self.gaps_seen.values(), default=0.0)),
        }
