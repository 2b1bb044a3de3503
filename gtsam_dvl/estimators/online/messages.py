"""The checks every message pushed into the online estimator passes before it is used.

Bad input: a message older than or as old as the previous one of its kind, or with a non-finite value, is rejected
with GtsamDvlError (OnlineConfig.bad_messages = "raise", the default) or dropped with a MessageDropped warning the
first time and counted in the estimator's counters ("drop"). A message of the wrong shape is always an error. What
the pings' content says (no valid velocity, too fast, bogus) is the epoch scheduler's to decide
(selection.EpochScheduler), not an error.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, Literal

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.estimators.inputs.selection import Ping
from gtsam_dvl.estimators.online.types import MessageDropped

ImuChunk = tuple[
    np.ndarray, np.ndarray, np.ndarray
]  # stamps (s), gyro (rad/s), specific force (m/s^2)


def vector3(name: str, x: Any) -> np.ndarray:
    """x as a float 3-vector, else GtsamDvlError naming it."""
    arr = np.asarray(x, dtype=float)
    if arr.shape != (3,):
        raise GtsamDvlError(f"{name} must be a 3-vector, got shape {arr.shape}")
    return arr


class MessageChecks:
    """Stamp order and finiteness of the IMU samples, pings and depth samples of one estimator (module doc).
    counters: the estimator's, where dropped messages are counted by kind."""

    def __init__(
        self, bad_messages: Literal["raise", "drop"], source: str, counters: dict[str, int]
    ) -> None:
        self.bad_messages, self.source, self.counters = bad_messages, source, counters
        self.last_imu_t = -math.inf
        self.last_dvl_t = -math.inf
        self.last_depth_t = -math.inf
        self._warned: set[str] = set()

    def bad(self, kind: str, message: str, n: int = 1, stacklevel: int = 4) -> None:
        """Raise, or count n messages of this kind and warn the first time (module doc); stacklevel: the
        warning's, which names the line that pushed the message."""
        if self.bad_messages == "raise":
            raise GtsamDvlError(f"{self.source + ': ' if self.source else ''}{message}")
        self.counters[kind] = self.counters.get(kind, 0) + n
        if kind not in self._warned:
            self._warned.add(kind)
            warnings.warn(
                f"{message}: dropped (further ones are counted in counters['{kind}'])",
                MessageDropped,
                stacklevel=stacklevel,
            )

    def imu_sample(self, t: float, b_omega: Any, b_f: Any) -> ImuChunk | None:
        """One IMU sample as a chunk of one, or None when dropped."""
        w, f = vector3("IMU b_omega", b_omega), vector3("IMU b_f", b_f)
        if not (math.isfinite(t) and t > self.last_imu_t):
            if not math.isfinite(t):
                self.bad("imu_bad_time", f"IMU sample with a non-finite stamp ({t})")
            elif t == self.last_imu_t:
                self.bad("imu_duplicate", f"IMU sample at t = {t:.6f} s repeats the previous stamp")
            else:
                self.bad(
                    "imu_out_of_order",
                    f"IMU sample at t = {t:.6f} s is older than the previous one "
                    f"({self.last_imu_t:.6f} s)",
                )
            return None
        if not (np.isfinite(w).all() and np.isfinite(f).all()):
            self.bad("imu_not_finite", f"IMU sample at t = {t:.6f} s has a non-finite value")
            return None
        self.last_imu_t = t
        return np.array([t]), w[None, :], f[None, :]

    def imu_batch(self, t: Any, b_omega: Any, b_f: Any) -> ImuChunk | None:
        """IMU samples in time order, (N,), (N, 3), (N, 3): those that pass, or None when none does."""
        t = np.asarray(t, dtype=float).reshape(-1)
        w, f = np.asarray(b_omega, dtype=float), np.asarray(b_f, dtype=float)
        if w.shape != (len(t), 3) or f.shape != (len(t), 3):
            raise GtsamDvlError(
                f"IMU batch: {len(t)} stamps need gyro and accelerometer arrays of shape "
                f"({len(t)}, 3), got {w.shape} and {f.shape}"
            )
        if len(t) == 0:
            return None
        stamped = np.isfinite(t)
        prev = np.maximum.accumulate(
            np.concatenate([[self.last_imu_t], np.where(stamped, t, -np.inf)])
        )[:-1]
        in_order = stamped & (t > prev)
        finite = np.isfinite(w).all(axis=1) & np.isfinite(f).all(axis=1)
        keep = in_order & finite
        if not keep.all():
            for mask, kind, what in (
                (~stamped, "imu_bad_time", "has a non-finite stamp"),
                (stamped & (t == prev), "imu_duplicate", "repeats the previous stamp"),
                (stamped & (t < prev), "imu_out_of_order", "is older than the previous one"),
                (in_order & ~finite, "imu_not_finite", "has a non-finite value"),
            ):
                n_bad = int(mask.sum())
                if n_bad:
                    j = int(np.argmax(mask))
                    self.bad(kind, f"IMU sample {j} of the batch (t = {t[j]:.6f} s) {what}", n_bad)
            t, w, f = t[keep], w[keep], f[keep]
            if len(t) == 0:
                return None
        self.last_imu_t = float(t[-1])
        return t, w, f

    def ping(
        self, t: float, d_v: Any, d_cov: Any, valid: bool, beams: tuple[Any, Any, Any] | None
    ) -> Ping | None:
        """One ping (OnlineEstimator.push_dvl's arguments) as a Ping, or None when dropped."""
        if not self._in_order(
            "dvl",
            "DVL ping",
            t,
            self.last_dvl_t,
            "repeats the previous ping's stamp",
            "is older than the previous ping",
        ):
            return None
        self.last_dvl_t = t
        d_v = vector3("DVL d_v", d_v)
        d_cov = np.full((3, 3), np.nan) if d_cov is None else np.asarray(d_cov, dtype=float)
        if d_cov.shape != (3, 3):
            raise GtsamDvlError(f"DVL d_cov must be 3x3, got shape {d_cov.shape}")
        if beams is not None:
            d_u, v, ok = (
                np.asarray(beams[0], dtype=float),
                np.asarray(beams[1], dtype=float),
                np.asarray(beams[2], dtype=bool),
            )
            if d_u.shape != (len(v), 3) or ok.shape != v.shape:
                raise GtsamDvlError(
                    f"DVL beams: d_u {d_u.shape}, v {v.shape}, valid {ok.shape} do not match"
                )
            beams = (d_u, v, ok)
        return Ping(t, d_v, d_cov, bool(valid), beams)

    def depth_stamp(self, t: float) -> bool:
        """Whether a depth sample at t (s) is in order (else dropped)."""
        if not self._in_order(
            "depth",
            "depth sample",
            t,
            self.last_depth_t,
            "repeats the previous stamp",
            "is older than the previous one",
        ):
            return False
        self.last_depth_t = t
        return True

    def _in_order(self, kind: str, noun: str, t: float, last: float, same: str, older: str) -> bool:
        """Whether stamp t is finite and after the previous one of its stream (last, s), else bad() with kind
        "<kind>_bad_time", "<kind>_duplicate" or "<kind>_out_of_order"."""
        if not math.isfinite(t):
            self.bad(f"{kind}_bad_time", f"{noun} with a non-finite stamp ({t})", stacklevel=5)
            return False
        if t <= last:
            dup = t == last
            self.bad(
                f"{kind}_duplicate" if dup else f"{kind}_out_of_order",
                f"{noun} at t = {t:.6f} s {same if dup else older} ({last:.6f} s)",
                stacklevel=5,
            )
            return False
        return True
