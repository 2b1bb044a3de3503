"""Logs for the tests: cut in time (the IMU, DVL and truth samples of a time window, the other streams kept), and
every array of a log by name (log_arrays), and logs compared array by array at a tolerance (assert_logs_close) or
against a stored sample of their rows (log_sample, assert_log_matches_sample)."""

from __future__ import annotations

import dataclasses
import math
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


def _assert_close(
    got: np.ndarray, want: np.ndarray, rtol: float, scale_atol: float, name: str
) -> None:
    """Float arrays within rtol of each value plus scale_atol of want's largest finite magnitude (its scale: a value
    near zero computed by cancellation carries the rounding of the large ones), NaN where NaN; other dtypes (bool
    validity, integer status) exactly."""
    assert (got.dtype, got.shape) == (want.dtype, want.shape), (name, got.dtype, got.shape)
    if want.dtype.kind != "f":
        np.testing.assert_array_equal(got, want, err_msg=name)
        return
    finite = np.abs(want[np.isfinite(want)])
    atol = scale_atol * float(finite.max()) if finite.size else 0.0
    np.testing.assert_allclose(got, want, rtol=rtol, atol=atol, err_msg=name)


def assert_tree_close(got: Any, want: Any, rtol: float, atol: float, path: str = "") -> None:
    """JSON-like trees (dicts, lists, numbers, strings) equal, floats within rtol or atol (math.isclose); ints,
    bools, strings and None exactly, and of the same type (1 and 1.0 differ)."""
    assert type(got) is type(want), (path, got, want)
    if isinstance(want, dict):
        assert got.keys() == want.keys(), (path, sorted(got), sorted(want))
        for k in want:
            assert_tree_close(got[k], want[k], rtol, atol, f"{path}.{k}")
    elif isinstance(want, list | tuple):
        assert len(got) == len(want), (path, got, want)
        for i, (a, b) in enumerate(zip(got, want, strict=True)):
            assert_tree_close(a, b, rtol, atol, f"{path}[{i}]")
    elif isinstance(want, float):
        assert math.isclose(got, want, rel_tol=rtol, abs_tol=atol) or (
            math.isnan(got) and math.isnan(want)
        ), (path, got, want)
    else:
        assert got == want, (path, got, want)


def assert_logs_close(got: LogData, want: LogData, rtol: float) -> None:
    """The same arrays (names, shapes, dtypes), float ones within rtol of each value plus rtol of the array's largest
    magnitude, others exactly; metadata and true calibration within rtol (scenario.py's values and the draws)."""
    a, b = log_arrays(got), log_arrays(want)
    assert sorted(a) == sorted(b)
    for name in b:
        _assert_close(a[name], b[name], rtol, rtol, name)
    assert_tree_close(got.metadata, want.metadata, rtol, 0.0, "metadata")
    cal_a, cal_b = (
        None if c is None else dataclasses.asdict(c)
        for c in (got.true_calibration, want.true_calibration)
    )
    assert_tree_close(cal_a, cal_b, rtol, 0.0, "true_calibration")


def log_sample(log: LogData, rows: int = 200) -> dict[str, np.ndarray]:
    """About `rows` rows of every array of the log (log_arrays): every k-th row and the last, for a stored
    reference; "<name>" the rows' values, "<name>#rows" their indices, "<name>#shape" the whole array's shape."""
    out: dict[str, np.ndarray] = {}
    for name, v in log_arrays(log).items():
        n = len(v)
        keep = (
            np.unique(np.r_[np.arange(0, n, max(1, -(-n // rows))), n - 1]) if n else np.arange(0)
        )
        out[name], out[f"{name}#rows"], out[f"{name}#shape"] = v[keep], keep, np.array(v.shape)
    return out


def assert_log_matches_sample(
    log: LogData, sample: dict[str, np.ndarray], rtol: float, scale_atol: float
) -> None:
    """The log has the sample's arrays (names and whole shapes), and at the sample's rows their values: float arrays
    within rtol of each value plus scale_atol of the sample's largest magnitude, NaN where NaN, others exactly."""
    arrays = log_arrays(log)
    names = sorted(k for k in sample if "#" not in k)
    assert sorted(arrays) == names, f"arrays added or removed: {sorted(set(arrays) ^ set(names))}"
    for name in names:
        got = arrays[name]
        assert got.shape == tuple(sample[f"{name}#shape"]), (name, got.shape)
        _assert_close(got[sample[f"{name}#rows"]], sample[name], rtol, scale_atol, name)
