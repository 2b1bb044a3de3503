"""The typed fields of LogData (map origin, true calibration, true biases, segments) and their spelling in a
log's metadata records: the one place that knows the keys, used by the writer and the reader alike."""

from __future__ import annotations

from typing import Any

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import DvlCalibration, GeoOrigin, ImuBiases, LogData, Segment


def metadata_record(log: LogData) -> dict[str, Any]:
    """log.metadata with the typed fields written over their keys ("origin"; "truth": "dvl", "imu",
    "segments"), so that a file always says what the LogData held."""
    meta = dict(log.metadata)
    if log.origin is not None:
        meta["origin"] = log.origin.as_dict()
    truth = dict(meta.get("truth") or {})
    if log.true_calibration is not None:
        cal = log.true_calibration
        truth["dvl"] = {
            **(truth.get("dvl") or {}),
            "scale": float(cal.scale),
            "misalignment_deg": [float(a) for a in cal.misalignment_deg],
            "time_offset_s": float(cal.time_offset_s),
        }
    if log.true_imu_bias is not None:
        b = log.true_imu_bias
        truth["imu"] = {
            **(truth.get("imu") or {}),
            "gyro_bias_rad_s": list(b.gyro_rad_s),
            "accel_bias_m_s2": list(b.accel_m_s2),
        }
    if log.segments:
        truth["segments"] = [s.as_dict() for s in log.segments]
    if truth:
        meta["truth"] = truth
    return meta


def _vec3(x: Any) -> tuple[float, float, float]:
    a, b, c = (float(v) for v in x)
    return a, b, c


def typed_fields(meta: dict[str, Any], source: str) -> dict[str, Any]:
    """The LogData keyword arguments origin, true_calibration, true_imu_bias and segments read from a log's
    metadata (absent ones are None or empty). A record that is there but malformed is an error."""
    out: dict[str, Any] = {
        "origin": None,
        "true_calibration": None,
        "true_imu_bias": None,
        "segments": [],
    }
    try:
        if meta.get("origin"):
            out["origin"] = GeoOrigin.from_dict(meta["origin"])
        truth = meta.get("truth") or {}
        if not isinstance(truth, dict):
            raise TypeError("the truth record is not a table")
        if cal := truth.get("dvl"):
            out["true_calibration"] = DvlCalibration(
                float(cal["scale"]),
                _vec3(cal["misalignment_deg"]),
                float(cal.get("time_offset_s", 0.0)),
            )
        imu = truth.get("imu") or {}
        if "gyro_bias_rad_s" in imu:
            out["true_imu_bias"] = ImuBiases(
                _vec3(imu["accel_bias_m_s2"]), _vec3(imu["gyro_bias_rad_s"])
            )
        out["segments"] = [Segment.from_dict(s) for s in truth.get("segments") or []]
    except (KeyError, TypeError, ValueError) as exc:
        raise GtsamDvlError(
            f"{source}: malformed origin or truth metadata ({type(exc).__name__}: {exc})"
        ) from None
    return out
