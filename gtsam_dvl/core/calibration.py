"""A vehicle's calibration: the posterior of the shared states that belong to the vehicle, carried across dives.

A VehicleCalibration holds, for the shared states of core/states.py that are properties of the vehicle (scale,
misalignment, and the time offset and lever arm when estimated), their values and their JOINT covariance (SI, in
each state's tangent: the misalignment b_R_d perturbed on the right, as GTSAM), with where it came from: the
vehicle's name, the date (ISO 8601, UTC) of the newest dive it holds, the source logs (path and SHA-256 of their
content), the hash of the configuration that made it and the method ("smooth": one dive; "calibrate": several).
`smooth --calibration-out` and `calibrate` write it (io/calibration_file.py, TOML); `smooth --calibration` reads it
as the prior of the next dive, its covariance inflated for the days since its date (inflated).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError


@dataclass(frozen=True)
class SourceLog:
    """A log a calibration was made from: its path as given and the SHA-256 of its content."""

    path: str
    sha256: str


@dataclass(frozen=True)
class VehicleCalibration:
    """The posterior of a vehicle's calibration states (module doc). `states` are names of core/states.py STATES
    in the order of `cov`'s blocks; `values[name]` a vector (the misalignment: b_R_d as a 3x3 matrix)."""

    vehicle: str
    date: str  # ISO 8601 UTC, e.g. "2026-11-02T10:15:00Z": when the newest source dive was recorded
    states: tuple[str, ...]
    values: dict[str, np.ndarray]
    cov: np.ndarray  # (n, n), SI, tangents concatenated in `states` order
    sources: tuple[SourceLog, ...] = ()
    config_hash: str = ""
    method: str = "smooth"
    notes: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = sum(_dim(name) for name in self.states)
        cov = np.asarray(self.cov, dtype=float)
        if cov.shape != (n, n):
            raise GtsamDvlError(
                f"calibration of {self.vehicle!r}: covariance is {cov.shape}, its states "
                f"{', '.join(self.states)} need ({n}, {n})"
            )
        if not np.all(np.isfinite(cov)) or np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) <= 0):
            raise GtsamDvlError(
                f"calibration of {self.vehicle!r}: covariance is not positive definite"
            )
        missing = [s for s in self.states if s not in self.values]
        if missing:
            raise GtsamDvlError(
                f"calibration of {self.vehicle!r}: no value for {', '.join(missing)}"
            )

    def slices(self) -> dict[str, slice]:
        """Each state's columns in cov."""
        out, col = {}, 0
        for name in self.states:
            out[name] = slice(col, col + _dim(name))
            col += _dim(name)
        return out

    def sigma(self, name: str) -> np.ndarray:
        """(dim,) marginal sigmas of one state, SI (about b_R_d's axes for the misalignment)."""
        s = self.slices()[name]
        return np.sqrt(np.diag(np.asarray(self.cov)[s, s]))

    def block(self, names: list[str] | tuple[str, ...]) -> np.ndarray:
        """The joint covariance of some of its states, in the order given."""
        sl = self.slices()
        idx = (
            np.concatenate([np.arange(sl[n].start, sl[n].stop) for n in names])
            if names
            else np.zeros(0, int)
        )
        return np.asarray(self.cov)[np.ix_(idx, idx)]

    def days_before(self, when: str | dt.datetime) -> float:
        """Days from this calibration's date to `when` (ISO 8601 or a datetime; negative if before)."""
        return (_parse_date(when) - _parse_date(self.date)).total_seconds() / 86400.0

    def inflated(self, days: float, per_day: float) -> VehicleCalibration:
        """The covariance grown for `days` since the date: each variance by a fraction `per_day` of itself per
        day ([calibration] inflation_per_day; cov * (1 + per_day * days), correlations kept). No growth for days
        <= 0 (a calibration dated after the dive)."""
        factor = 1.0 + max(per_day, 0.0) * max(days, 0.0)
        return replace(self, cov=np.asarray(self.cov) * factor)


def _dim(name: str) -> int:
    # lazy: core/states.py imports GTSAM, which a file reader does not need
    from gtsam_dvl.core.states import BY_NAME

    if name not in BY_NAME:
        raise GtsamDvlError(f"calibration: unknown state {name!r} (known: {', '.join(BY_NAME)})")
    return BY_NAME[name].dim


def _parse_date(when: str | dt.datetime) -> dt.datetime:
    if isinstance(when, dt.datetime):
        return when if when.tzinfo else when.replace(tzinfo=dt.UTC)
    try:
        parsed = dt.datetime.fromisoformat(str(when).replace("Z", "+00:00"))
    except ValueError:
        raise GtsamDvlError(
            f"calibration: date {when!r} is not ISO 8601 (e.g. 2026-11-02T10:15:00Z)"
        ) from None
    return parsed if parsed.tzinfo else parsed.replace(tzinfo=dt.UTC)


def iso_date(t_ns: int) -> str:
    """A log's time (ns since the Unix epoch) as the ISO 8601 UTC date of a calibration."""
    return dt.datetime.fromtimestamp(t_ns * 1e-9, tz=dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def config_hash(config: dict[str, Any]) -> str:
    """A short hash of a configuration (its JSON with sorted keys): two calibrations made with the same settings
    have the same hash."""
    text = json.dumps(config, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def vehicle_state_names(config: Any) -> list[str]:
    """The vehicle's calibration states that a configuration (EstimatorConfig) estimates, in joint order."""
    from gtsam_dvl.core.states import joint_states

    return [s.name for s in joint_states(config) if s.vehicle]


def from_result(
    result: Any, config: Any, vehicle: str, sources: tuple[SourceLog, ...] = (), ekf: bool = False
) -> VehicleCalibration:
    """The vehicle calibration of one result (NavResult): its vehicle states' values and their joint covariance
    from result.shared_joint_cov (or, when it has none, the marginals with the calibration block's joint over the
    scale and misalignment, without the other correlations). ekf: the
    result's joint covariance has the EKF's columns (states.joint_states(config, ekf=True))."""
    from gtsam_dvl.core.states import joint_slices

    names = [n for n in vehicle_state_names(config) if n in result.calibration]
    if not names:
        raise GtsamDvlError(
            "calibration: the result estimates none of the vehicle's calibration states"
        )
    joint = result.shared_joint_cov
    sl = joint_slices(config, ekf)
    if joint is not None and all(n in sl for n in names):
        idx = np.concatenate([np.arange(sl[n].start, sl[n].stop) for n in names])
        cov = np.asarray(joint)[np.ix_(idx, idx)]
    else:
        blocks = [np.asarray(result.calibration[n].cov) for n in names]
        cov = np.zeros((sum(b.shape[0] for b in blocks),) * 2)
        col = 0
        for b in blocks:
            cov[col : col + b.shape[0], col : col + b.shape[0]] = b
            col += b.shape[0]
        # the online estimator's: scale and misalignment
        if getattr(result, "calib_joint_cov", None) is not None:
            from gtsam_dvl.core.states import (  # jointly from the calibration block
                BY_NAME,
                block_states,
            )

            order = [s.name for s in block_states()]
            own = [n for n in names if n in order]
            at = np.cumsum([0] + [BY_NAME[n].dim for n in order])
            here = np.cumsum([0] + [BY_NAME[n].dim for n in names])
            src = np.concatenate(
                [np.arange(at[order.index(n)], at[order.index(n) + 1]) for n in own]
            )
            dst = np.concatenate(
                [np.arange(here[names.index(n)], here[names.index(n) + 1]) for n in own]
            )
            cov[np.ix_(dst, dst)] = np.asarray(result.calib_joint_cov)[np.ix_(src, src)]
    values = {n: np.array(result.calibration[n].value, dtype=float) for n in names}
    return VehicleCalibration(
        vehicle=vehicle,
        date=iso_date(int(result.t0_ns)),
        states=tuple(names),
        values=values,
        cov=0.5 * (cov + cov.T),
        sources=sources,
        config_hash=config_hash(result.config),
        method="smooth",
    )
