"""Logs for the tests: cut in time (the IMU, DVL and truth samples of a time window, the other streams kept), and
every array of a log by name (log_arrays, for comparing or digesting logs)."""

from __future__ import annotations

import dataclasses
from typing import Any, TypeVar

import numpy as np

from gtsam_dvl.core.types import BeamData, DvlData, ImuData, LogData, TruthData

Samples = TypeVar("Samples", ImuData, DvlData, BeamData, TruthData)


def rows(data: Samples, keep: np.ndarray) -> Samples:
    """data with the samples keep (a boolean mask over its first axis) of each per-sample array; a DVL's beams
    with the same pings."""
    changes = {}
    for f in dataclasses.fields(data):
        value = getattr(data, f.name)
        if isinstance(value, np.ndarray):
            changes[f.name] = value[keep]
        elif isinstance(value, BeamData):
            changes[f.name] = rows(value, keep)
    return dataclasses.replace(data, **changes)


def cut_log(
    log: LogData,
    t_end: float = np.inf,
    *,
    t_start: float = -np.inf,
    beams: bool = True,
    cut_truth: bool = True,
) -> LogData:
    """The log's IMU, DVL and truth samples stamped in [t_start, t_end] (times kept): the DVL without its beams
    unless beams, the truth whole unless cut_truth; the other streams (depth, GNSS, attitude) as they are."""

    def window(t: np.ndarray) -> np.ndarray:
        return (t >= t_start) & (t <= t_end)

    dvl = rows(log.dvl, window(log.dvl.t))
    if not beams:
        dvl = dataclasses.replace(dvl, beams=None)
    truth = log.truth
    if truth is not None and cut_truth:
        truth = rows(truth, window(truth.t))
    return dataclasses.replace(log, imu=rows(log.imu, window(log.imu.t)), dvl=dvl, truth=truth)


def log_arrays(log: LogData) -> dict[str, np.ndarray]:
    """Every array of the log's data classes by dotted name (imu.b_f, dvl.beams.v, truth.n_p, ...)."""
    out: dict[str, np.ndarray] = {}

    def put(prefix: str, obj: Any) -> None:
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if isinstance(v, np.ndarray):
                out[f"{prefix}.{f.name}"] = v
            elif dataclasses.is_dataclass(v):
                put(f"{prefix}.{f.name}", v)

    for name in ("imu", "dvl", "truth", "depth", "gnss", "mounting"):
        if getattr(log, name) is not None:
            put(name, getattr(log, name))
    return out
