"""The calibration file: a vehicle's calibration (core/calibration.py VehicleCalibration) as TOML.

Human-readable first: the header says which vehicle, when, from which logs, and a [summary] table gives the scale
in ppm and the misalignment in degrees with their sigmas; the exact content the estimators read is [values]
(SI; the misalignment as the matrix b_R_d, dvl_link -> base_link) and [covariance] (the joint covariance, SI, its
columns named). Read back with read_calibration; a file that is not one is a one-line error. TOML is written by
hand here (the standard library reads TOML but does not write it; the file holds only strings, numbers and arrays).

    format = 1
    vehicle = "auv-1"
    date = "2026-11-02T10:15:00Z"
    method = "smooth"
    config_hash = "3f2c..."
    states = ["scale", "misalignment"]
    [[source]]  path, sha256
    [summary]   scale_ppm, scale_sigma_ppm, misalignment_rpy_deg, misalignment_sigma_deg, ...
    [values]    scale = [1.0009], misalignment = [[...], [...], [...]]
    [covariance] columns = [...], matrix = [[...], ...]
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.calibration import SourceLog, VehicleCalibration
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import matrix_to_rpy_deg
from gtsam_dvl.io.atomic import atomic_write_text, check_writable

FORMAT = 1

# the columns of each state's tangent, for the file's reader (core/states.py names them the same way)
_COMPONENTS = {
    "scale": [""],
    "misalignment": ["roll", "pitch", "yaw"],
    "time_offset": [""],
    "lever_arm": ["x", "y", "z"],
}


def _num(x: float) -> str:
    x = float(x)
    if not np.isfinite(x):
        raise GtsamDvlError(f"calibration: a value is not finite ({x})")
    return repr(x)


def _array(a: Any) -> str:
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:
        return _num(float(a))
    if a.ndim == 1:
        return "[" + ", ".join(_num(v) for v in a) + "]"
    return "[\n    " + ",\n    ".join(_array(row) for row in a) + ",\n]"


def _string(s: str) -> str:
    return '"' + str(s).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _rounded(a: Any, digits: int) -> str:
    return _array(np.round(np.asarray(a, dtype=float), digits))


def _summary(cal: VehicleCalibration) -> list[str]:
    """Display units, rounded for reading (ppm to 0.01, degrees and ms to 1e-4)."""
    lines = []
    for name in cal.states:
        value, sigma = np.asarray(cal.values[name], dtype=float), cal.sigma(name)
        if name == "scale":
            lines += [
                f"scale_ppm = {_rounded((value[0] - 1.0) * 1e6, 2)}",
                f"scale_sigma_ppm = {_rounded(sigma[0] * 1e6, 2)}",
            ]
        elif name == "misalignment":
            lines += [
                f"misalignment_rpy_deg = {_rounded(matrix_to_rpy_deg(value), 4)}",
                f"misalignment_sigma_deg = {_rounded(np.degrees(sigma), 4)}",
            ]
        elif name == "time_offset":
            lines += [
                f"time_offset_ms = {_rounded(value[0] * 1e3, 4)}",
                f"time_offset_sigma_ms = {_rounded(sigma[0] * 1e3, 4)}",
            ]
        else:
            lines += [f"{name}_m = {_rounded(value, 4)}", f"{name}_sigma_m = {_rounded(sigma, 4)}"]
    return lines


def calibration_text(cal: VehicleCalibration) -> str:
    """The TOML text of a calibration (module doc)."""
    columns = [
        f"{n} {c}".strip()
        for n in cal.states
        for c in _COMPONENTS.get(n, [str(i) for i in range(3)])
    ]
    lines = [
        "# gtsam_dvl vehicle calibration: the posterior of the vehicle's DVL calibration states.",
        "# [summary] is for reading; the estimators use [values] and [covariance] (SI; the misalignment",
        "# is b_R_d, dvl_link -> base_link, its covariance about b_R_d's own axes, perturbed on the right).",
        f"format = {FORMAT}",
        f"vehicle = {_string(cal.vehicle)}",
        f"date = {_string(cal.date)}",
        f"method = {_string(cal.method)}",
        f"config_hash = {_string(cal.config_hash)}",
        "states = [" + ", ".join(_string(s) for s in cal.states) + "]",
        "",
    ]
    for src in cal.sources:
        lines += [
            "[[source]]",
            f"path = {_string(src.path)}",
            f"sha256 = {_string(src.sha256)}",
            "",
        ]
    lines += ["[summary]"] + _summary(cal) + [""]
    lines += ["[values]"] + [f"{n} = {_array(cal.values[n])}" for n in cal.states] + [""]
    lines += [
        "[covariance]",
        "columns = [" + ", ".join(_string(c) for c in columns) + "]",
        f"matrix = {_array(cal.cov)}",
        "",
    ]
    return "\n".join(lines)


def write_calibration(path: Path | str, cal: VehicleCalibration) -> Path:
    """Write a calibration file (a temporary file renamed into place: an existing file is replaced whole or not
    at all). A missing folder or an unwritable path is a one-line error."""
    check_writable(path)
    return atomic_write_text(path, calibration_text(cal))


def read_calibration(path: Path | str) -> VehicleCalibration:
    """Read a calibration file; anything that is not one is a one-line GtsamDvlError naming the file."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise GtsamDvlError(f"{path}: no such calibration file") from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise GtsamDvlError(f"{path}: not a calibration file ({exc})") from None
    return calibration_from_dict(raw, str(path))


def calibration_from_dict(raw: dict[str, Any], source: str = "<dict>") -> VehicleCalibration:
    """A calibration from the parsed TOML (read_calibration), every key checked."""
    if raw.get("format") != FORMAT:
        raise GtsamDvlError(
            f"{source}: not a gtsam_dvl calibration file (format = {raw.get('format')!r}, "
            f"expected {FORMAT})"
        )
    try:
        states = tuple(str(s) for s in raw["states"])
        values = {n: np.asarray(raw["values"][n], dtype=float) for n in states}
        cov = np.asarray(raw["covariance"]["matrix"], dtype=float)
        sources = tuple(
            SourceLog(str(s["path"]), str(s.get("sha256", ""))) for s in raw.get("source", [])
        )
        for n, v in values.items():
            want = (3, 3) if n == "misalignment" else (len(_COMPONENTS.get(n, [0, 0, 0])),)
            if v.shape != want:
                raise GtsamDvlError(f"{source}: [values] {n} has shape {v.shape}, expected {want}")
        if "misalignment" in values:
            R = values["misalignment"]
            if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
                raise GtsamDvlError(f"{source}: [values] misalignment is not a rotation matrix")
        return VehicleCalibration(
            vehicle=str(raw.get("vehicle", "")),
            date=str(raw["date"]),
            states=states,
            values=values,
            cov=cov,
            sources=sources,
            config_hash=str(raw.get("config_hash", "")),
            method=str(raw.get("method", "")),
        )
    except KeyError as exc:
        raise GtsamDvlError(f"{source}: calibration file has no {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise GtsamDvlError(f"{source}: calibration file has a malformed value ({exc})") from None
