"""Write a LogData as a ROS 2 MCAP log exactly as docs/conventions.md ("Logs: ROS 2 MCAP") lays it out.

Topics: /tf_static, /imu/data_raw, /dvl/twist, /dvl/data, /depth/pressure (when the log has depth), /gnss/fix
(when it has fixes) and, for
simulated logs, /ground_truth/odometry. Choices the conventions leave open:

* /gnss/fix (sensor_msgs/msg/NavSatFix, frame gnss_link) holds GnssData (io/gnss.py), when the log has fixes.
* /depth/pressure (sensor_msgs/msg/FluidPressure, frame pressure_link) holds DepthData.pressure_pa and its
  variance (0 = unknown); its lever arm goes into /tf_static as base_link -> pressure_link (identity
  rotation) when DepthData.b_p_sensor is set.

* /dvl/twist carries only valid 3-D velocities (invalid pings are skipped there but kept in
  /dvl/data). Its 6x6 covariance holds d_cov in the linear block; the DVL does not measure angular
  velocity, so the angular block is ``UNMEASURED_VARIANCE`` on the diagonal (the ROS habit of a large
  variance for an unmeasured axis; -1 would break consumers that take square roots). A NaN d_cov
  (unknown) is written as zeros, ROS's "covariance unknown".
* /dvl/data (marine_acoustic_msgs/msg/Dvl) holds 4 beams; fewer are padded with invalid beams. An invalid
  3-D velocity is written as NaN (DvlData's contract) with its covariance kept; an unknown d_cov is
  -1 everywhere (the message's "not known"). Per-beam validity goes in ``beam_quality`` (1 = valid,
  0 = invalid, which the message leaves DVL-specific; recorded in the "gtsam_dvl" metadata); beam
  velocities are float32 in that message, so they round-trip to float32 precision only. Range and beam
  velocity variances are -1 (not known); sound speed from metadata["sensors"]["dvl"]["sound_speed"]
  or 1500 m/s. A water-track ping (DvlData.water_track) has velocity_mode 2 (DVL_MODE_WATER), its velocity
  relative to the water (not over ground: course_gnd and speed_gnd NaN), and its measuring beams 1 in
  ``beam_quality``. ``altitude``: DvlData.altitude when the log has it (NaN: none), else the mean vertical range
  of the valid beams.
* IMU covariance: diag from metadata["sensors"]["imu"]: "gyro_variance"/"accel_variance" (per-sample,
  SI), else the white-noise density (the simulator's "gyro_noise_deg_per_h_per_sqrt_hz" and
  "accel_noise_micro_g_per_sqrt_hz", or SI "gyro_noise_density"/"accel_noise_density") squared times the
  sample rate; else zeros (ROS: unknown).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from gtsam_dvl import __version__
from gtsam_dvl.core.earth import depth_to_pressure, pressure_to_depth
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import DvlData, LogData
from gtsam_dvl.io.atomic import AtomicWriter
from gtsam_dvl.io.gnss import GNSS_TOPIC, NAVSATFIX_TYPE, navsatfix_messages
from gtsam_dvl.io.log_metadata import metadata_record
from gtsam_dvl.io.mcap.writer import McapLogWriter, McapStreamWriter
from gtsam_dvl.io.ros2 import cdr, messages

__all__ = [
    "McapLogWriter",
    "write_log",
    "LogStreamWriter",
    "LogSource",
    "write_log_stream",
    "imu_rate_hz",
    "UNMEASURED_VARIANCE",
    "BEAM_QUALITY_NOTE",
]

UNMEASURED_VARIANCE = 1e6  # (rad/s)^2 on the angular diagonal of /dvl/twist
BEAM_QUALITY_NOTE = "1 = beam valid, 0 = beam invalid"
MAX_BEAMS = 4


def json_default(o: Any) -> Any:
    """JSON for numpy values and paths in metadata."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    raise TypeError(f"{type(o).__name__} is not JSON serializable")


# Spellings of the IMU white-noise densities in metadata["sensors"]["imu"] -> factor to SI per sqrt(Hz):
# the simulator's scenario units (deg/h/sqrt(Hz), micro-g/sqrt(Hz)) and plain SI.
_NOISE_KEYS = {
    "gyro": (
        ("gyro_noise_deg_per_h_per_sqrt_hz", np.pi / 180.0 / 3600.0),
        ("gyro_noise_density", 1.0),
    ),
    "accel": (("accel_noise_micro_g_per_sqrt_hz", 1e-6 * 9.80665), ("accel_noise_density", 1.0)),
}


def _imu_variances(
    meta: dict[str, Any], t: np.ndarray
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per-sample variances (diagonal) of gyro and accelerometer white noise: density^2 * rate."""
    return _imu_variances_at(meta, 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 0.0)


def imu_rate_hz(t_parts: Iterable[np.ndarray]) -> float:
    """The IMU rate write_log takes from a log's IMU stamps t (1 / median(diff(t)), 0 for fewer than two
    samples), bit for bit, from t given in consecutive parts (each (K,) s) without holding all of it: the
    steps are counted by value, and a median of counts is np.median's."""
    values: dict[float, int] = {}
    last: float | None = None
    for part in t_parts:
        part = np.asarray(part, dtype=float)
        if not len(part):
            continue
        steps = np.diff(part) if last is None else np.diff(np.concatenate([[last], part]))
        last = float(part[-1])
        for v, c in zip(*np.unique(steps, return_counts=True), strict=True):
            values[float(v)] = values.get(float(v), 0) + int(c)
    m = sum(values.values())
    if m == 0:
        return 0.0
    v = np.array(sorted(values))
    ends = np.cumsum([values[x] for x in v])  # the sorted steps k with k < ends[i] have value v[i]

    def kth(k: int) -> np.float64:
        return np.float64(v[int(np.searchsorted(ends, k, side="right"))])

    median = kth(m // 2) if m % 2 else (kth(m // 2 - 1) + kth(m // 2)) / 2.0
    return 1.0 / float(median)


def _imu_variances_at(
    meta: dict[str, Any], rate: float
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """_imu_variances at a given IMU rate (Hz)."""
    imu = (meta.get("sensors") or {}).get("imu") or {}
    out: list[np.ndarray | None] = []
    for kind, keys in _NOISE_KEYS.items():
        var = imu.get(f"{kind}_variance")
        for key, to_si in keys:
            if var is None and imu.get(key) is not None:
                var = np.square(np.asarray(imu[key], dtype=float) * to_si) * rate
        out.append(None if var is None else np.broadcast_to(np.asarray(var, dtype=float), (3,)))
    return out[0], out[1]


def _scenario_name(meta: dict[str, Any]) -> str:
    if meta.get("scenario_name"):
        return str(meta["scenario_name"])
    s = meta.get("scenario", "")
    return str(s.get("name", "")) if isinstance(s, dict) else str(s)


def _dvl_messages(dvl: DvlData, meta: dict[str, Any], stamps: np.ndarray, path: Path) -> np.ndarray:
    m = len(dvl)
    arr = cdr.new_messages(cdr.DVL, {"frame_id": dvl.frame_id}, m)
    cdr.set_stamps(arr, stamps)
    finite = np.isfinite(dvl.d_v).all(axis=1)
    valid = np.asarray(dvl.valid, bool) & finite
    water = (
        np.zeros(m, bool) if dvl.water_track is None else np.asarray(dvl.water_track, dtype=bool)
    )
    v = np.where(valid[:, None], dvl.d_v, np.nan)  # over ground
    cov = np.asarray(dvl.d_cov, dtype=float).reshape(m, 9)
    arr["velocity_mode"], arr["dvl_type"] = 1, 0  # DVL_MODE_BOTTOM, DVL_TYPE_PISTON
    arr["velocity_mode"][water] = 2  # DVL_MODE_WATER
    # water track: through the water
    arr["velocity"] = np.where((valid | water & finite)[:, None], dvl.d_v, np.nan)
    arr["velocity_covar"] = np.where(np.isnan(cov).all(axis=1, keepdims=True), -1.0, cov)
    arr["course_gnd"] = np.arctan2(v[:, 1], v[:, 0])
    arr["speed_gnd"] = np.hypot(v[:, 0], v[:, 1])
    arr["sound_speed"] = float(
        ((meta.get("sensors") or {}).get("dvl") or {}).get("sound_speed", 1500.0)
    )
    arr["range_covar"] = arr["beam_velocity_covar"] = -1.0
    b = dvl.beams
    if b is None:
        arr["altitude"] = np.nan if dvl.altitude is None else dvl.altitude
        return arr
    nb = b.d_u.shape[1]
    if nb > MAX_BEAMS:
        raise GtsamDvlError(
            f"{path}: marine_acoustic_msgs/msg/Dvl holds {MAX_BEAMS} beams, the log has {nb}"
        )

    def pad(a: np.ndarray, fill: float) -> np.ndarray:
        out = np.full((m, MAX_BEAMS, *a.shape[2:]), fill)
        out[:, :nb] = a
        # (m, -1) is ambiguous for m = 0
        return out.reshape(m, MAX_BEAMS * int(np.prod(a.shape[2:])))

    bvalid = np.asarray(b.valid, bool)
    if water.any():  # a water-track ping's beams measured the water where they have a velocity
        bvalid = bvalid | water[:, None] & np.isfinite(b.v)
    arr["beam_ranges_valid"] = arr["beam_velocities_valid"] = True
    arr["beam_unit_vec"] = pad(b.d_u, 0.0)
    arr["range"] = pad(b.range, 0.0)
    arr["beam_velocity"] = pad(b.v, 0.0)
    arr["beam_quality"] = pad(bvalid.astype(float), 0.0)
    arr["num_good_beams"] = bvalid.sum(axis=1)
    vertical = np.where(bvalid, b.range * np.abs(b.d_u[..., 2]), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        arr["altitude"] = vertical.sum(axis=1) / bvalid.sum(axis=1)
    if dvl.altitude is not None:  # the DVL's own altitude (NaN: none)
        arr["altitude"] = dvl.altitude
    return arr


def _pressure_messages(log: LogData, w: McapLogWriter) -> np.ndarray:
    """/depth/pressure: the absolute pressure and its variance as measured; a depth-only DepthData (no
    pressure) is converted with the default density and atmosphere at the origin's latitude (45 deg without
    an origin). An unknown variance (NaN) is written 0, the message's "unknown"."""
    dep = log.depth
    assert dep is not None
    if dep.pressure_pa is not None:
        p = np.asarray(dep.pressure_pa, dtype=float)
        var = (
            np.full(len(p), np.nan)
            if dep.pressure_variance_pa2 is None
            else np.asarray(dep.pressure_variance_pa2, dtype=float)
        )
    else:
        lat = np.radians(log.origin.lat_deg if log.origin is not None else 45.0)
        p = depth_to_pressure(dep.depth_m, float(lat))
        _, dd_dp = pressure_to_depth(p, float(lat))
        var = np.asarray(dep.variance_m2, dtype=float) / dd_dp**2
    arr = cdr.new_messages(cdr.FLUID_PRESSURE, {"frame_id": dep.frame_id}, len(dep))
    cdr.set_stamps(arr, w.stamps_ns(dep.t))
    arr["fluid_pressure"] = p
    arr["variance"] = np.nan_to_num(var, nan=0.0)
    return arr


def write_log(
    path: str | os.PathLike[str],
    log: LogData,
    *,
    config: dict[str, Any] | None = None,
    imu_orientation: tuple[np.ndarray, np.ndarray | None] | None = None,
    dvl_water_topic: str | None = None,
) -> None:
    """Write ``log`` to ``path`` as a ROS 2 MCAP per docs/conventions.md (atomically: temporary file, then
    rename). Metadata record "gtsam_dvl" holds scenario, seed, generator and JSON strings of the truth
    and the sensor spec; attachment "config.json" holds log.metadata with ``config`` under "config".
    imu_orientation: (q (K, 4) [x, y, z, w] of imu_link per IMU sample, covariance (3, 3) or (K, 3, 3) rad^2 or
    None) written into the IMU messages' orientation (an AHRS-like IMU); None: no orientation (covariance[0]
    = -1), the convention. dvl_water_topic: the water-track pings on this topic (TwistWithCovarianceStamped) instead
    of /dvl/data, as drivers that publish water track apart do."""
    path = Path(path)
    meta = metadata_record(log)
    times = [
        a
        for a in (log.imu.t, log.dvl.t, log.truth.t if log.truth else None)
        if a is not None and len(a)
    ]
    t_first = float(min(a[0] for a in times)) if times else 0.0
    with McapLogWriter(path, t0_ns=log.t0_ns) as w:
        _write_head(w, path, log, meta, config, t_first)
        gyro_var, accel_var = _imu_variances(meta, log.imu.t)
        if dvl_water_topic and log.dvl.water_track is not None:
            wt = np.asarray(log.dvl.water_track, dtype=bool)
            _write_data(
                w,
                path,
                dataclasses.replace(log, dvl=_dvl_rows(log.dvl, ~wt)),
                meta,
                gyro_var,
                accel_var,
                imu_orientation,
                gnss_channel=False,
            )
            water = _dvl_rows(log.dvl, wt)
            cov = np.zeros((len(water), 6, 6))
            cov[:, :3, :3] = np.nan_to_num(water.d_cov, nan=0.0)
            cov[:, [3, 4, 5], [3, 4, 5]] = UNMEASURED_VARIANCE
            twist = messages.six_dof_with_covariance(
                messages.TWIST_COV, w.stamps_ns(water.t), water.d_v, None, cov, water.frame_id
            )
            w.add_structured(dvl_water_topic, messages.TWIST_COV, twist)
        else:
            _write_data(
                w, path, log, meta, gyro_var, accel_var, imu_orientation, gnss_channel=False
            )


def _dvl_rows(dvl: DvlData, keep: np.ndarray) -> DvlData:
    """The pings keep of dvl."""

    def rows(obj: Any) -> Any:
        return dataclasses.replace(
            obj,
            **{
                f.name: getattr(obj, f.name)[keep]
                for f in dataclasses.fields(obj)
                if isinstance(getattr(obj, f.name), np.ndarray)
            },
        )

    return dataclasses.replace(rows(dvl), beams=None if dvl.beams is None else rows(dvl.beams))


def _write_head(
    w: McapLogWriter,
    path: Path,
    log: LogData,
    meta: dict[str, Any],
    config: dict[str, Any] | None,
    t_first: float,
) -> None:
    """The metadata records, the config.json attachment and /tf_static (stamped t_first)."""
    try:
        attachment = json.dumps(
            {**meta, "config": config} if config is not None else meta, default=json_default
        )
        truth_json = json.dumps(meta.get("truth", {}), default=json_default)
        sensors_json = json.dumps(meta.get("sensors", {}), default=json_default)
    except (TypeError, ValueError) as e:
        raise GtsamDvlError(f"{path}: metadata cannot be written as JSON ({e})") from None
    beams = log.dvl.beams
    w.add_metadata(
        "gtsam_dvl",
        {
            "scenario": _scenario_name(meta),
            "seed": str(meta.get("seed", "")),
            "generator": str(meta.get("generator", f"gtsam_dvl {__version__}")),
            "truth": truth_json,
            "sensors": sensors_json,
            "dvl_beam_quality": BEAM_QUALITY_NOTE,
            "dvl_beams": str(beams.d_u.shape[1] if beams is not None else 0),
        },
    )
    w.add_attachment("config.json", attachment.encode(), "application/json")
    mnt = log.mounting
    w.add_tf_static(
        "/tf_static",
        t_first,
        [
            ("base_link", log.imu.frame_id, mnt.b_R_imu, mnt.b_p_imu),
            ("base_link", log.dvl.frame_id, mnt.b_R_d0, mnt.b_p_dvl),
        ]
        + (
            []
            if log.depth is None or log.depth.b_p_sensor is None
            else [("base_link", log.depth.frame_id, np.eye(3), log.depth.b_p_sensor)]
        )
        + (
            []
            if log.gnss is None or log.gnss.b_p_antenna is None
            else [("base_link", log.gnss.frame_id, np.eye(3), log.gnss.b_p_antenna)]
        ),
    )


def _write_data(
    w: McapLogWriter,
    path: Path,
    log: LogData,
    meta: dict[str, Any],
    gyro_var: np.ndarray | None,
    accel_var: np.ndarray | None,
    imu_orientation: tuple[np.ndarray, np.ndarray | None] | None,
    gnss_channel: bool,
) -> None:
    """The messages of log's sensor data and truth, one batch per topic in the conventions' order (so channel
    ids follow it). gnss_channel: write /gnss/fix even without fixes (its channel exists from here on)."""
    q_imu, cov_imu = imu_orientation if imu_orientation is not None else (None, None)
    imu = messages.imu(
        w.stamps_ns(log.imu.t),
        log.imu.b_omega,
        log.imu.b_f,
        log.imu.frame_id,
        gyro_var,
        accel_var,
        q_imu,
        cov_imu,
    )
    w.add_structured("/imu/data_raw", messages.IMU, imu)

    dvl = log.dvl
    ok = np.asarray(dvl.valid, bool) & np.isfinite(dvl.d_v).all(axis=1)
    cov = np.zeros((int(ok.sum()), 6, 6))
    cov[:, :3, :3] = np.nan_to_num(np.asarray(dvl.d_cov, dtype=float)[ok], nan=0.0)
    cov[:, [3, 4, 5], [3, 4, 5]] = UNMEASURED_VARIANCE
    twist = messages.six_dof_with_covariance(
        messages.TWIST_COV, w.stamps_ns(dvl.t[ok]), dvl.d_v[ok], None, cov, dvl.frame_id
    )
    w.add_structured("/dvl/twist", messages.TWIST_COV, twist)
    dvl_arr = _dvl_messages(dvl, meta, w.stamps_ns(dvl.t), path)
    w.add_structured("/dvl/data", "marine_acoustic_msgs/msg/Dvl", dvl_arr)

    if log.depth is not None:
        w.add_structured(
            "/depth/pressure", "sensor_msgs/msg/FluidPressure", _pressure_messages(log, w)
        )

    if log.gnss is not None and (len(log.gnss) or gnss_channel):
        w.add_structured(
            GNSS_TOPIC, NAVSATFIX_TYPE, navsatfix_messages(log.gnss, w.stamps_ns(log.gnss.t))
        )

    if log.truth is not None:
        tr = log.truth
        b_v = Rotation.from_quat(tr.n_q_b).inv().apply(tr.n_v) if len(tr) else np.zeros((0, 3))
        odometry = messages.odometry(
            w.stamps_ns(tr.t),
            tr.n_p,
            tr.n_q_b,
            b_v,
            tr.b_omega,
            frame_id="map",
            child_frame_id="base_link",
        )
        w.add_structured("/ground_truth/odometry", messages.ODOMETRY, odometry)


class LogStreamWriter(AtomicWriter):
    """Write a log too long to hold in memory, part by part, as write_log writes the whole log.

    head: the log's metadata and typed fields, mounting, frames and sensors (its arrays are not written; a
    sensor it has, every part has, possibly empty). t_first: the first stamp of the IMU, DVL and truth
    (/tf_static's stamp); imu_rate_hz: write_log's IMU rate of the whole log (imu_rate_hz()); gnss_fixes: the
    log's GNSS has fixes (/gnss/fix gets its channel where write_log gives it; False: no channel, as write_log
    of a GnssData without fixes, and a part with fixes is an error). Each ``write(part, next_t)``
    adds the part's messages and writes those stamped before next_t, which no later part may stamp earlier
    (None: this was the last part). Parts that together are a LogData give the file write_log writes of it,
    byte for byte (McapStreamWriter), so read_log reads both alike."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        head: LogData,
        *,
        t_first: float,
        imu_rate_hz: float,
        gnss_fixes: bool = True,
        config: dict[str, Any] | None = None,
    ) -> None:
        self.path = Path(path)
        self.head = head
        self._gnss = head.gnss is not None and gnss_fixes
        self._meta = metadata_record(head)
        self._w = McapStreamWriter(self.path, t0_ns=head.t0_ns)
        try:
            _write_head(self._w, self.path, head, self._meta, config, t_first)
        except BaseException:
            self._w.abort()
            raise
        self._gyro_var, self._accel_var = _imu_variances_at(self._meta, imu_rate_hz)
        self._bound = -np.inf  # no message may come before this time (s)
        self.counts = {"imu": 0, "dvl": 0, "truth": 0, "depth": 0, "gnss": 0}

    def write(self, part: LogData, next_t: float | None) -> None:
        """Add a part (the next stretch of the log) and write what is complete; next_t (s): no later part has
        a stamp before it (None: no later part)."""
        head = self.head
        for name in ("truth", "depth"):
            if (getattr(part, name) is None) != (getattr(head, name) is None):
                raise GtsamDvlError(
                    f"{self.path}: a part {'lacks' if getattr(head, name) is not None else 'has'} "
                    f"the log's {name}"
                )
        if not self._gnss and part.gnss is not None and len(part.gnss):
            raise GtsamDvlError(
                f"{self.path}: a part has GNSS fixes, the log was opened without them"
            )
        firsts = [
            float(a[0])
            for a in (
                part.imu.t,
                part.dvl.t,
                part.truth.t if part.truth is not None else None,
                part.depth.t if part.depth is not None else None,
                part.gnss.t if part.gnss is not None else None,
            )
            if a is not None and len(a)
        ]
        if firsts and min(firsts) < self._bound:
            raise GtsamDvlError(
                f"{self.path}: a part starts at t = {min(firsts):.9g} s, before the previous "
                f"part's next_t {self._bound:.9g} s"
            )
        gnss = part.gnss
        if self._gnss and gnss is None:
            assert head.gnss is not None
            gnss = dataclasses.replace(
                head.gnss,
                t=np.zeros(0),
                lat_deg=np.zeros(0),
                lon_deg=np.zeros(0),
                height_m=np.zeros(0),
                cov_enu_m2=np.zeros((0, 3, 3)),
                status=np.zeros(0, dtype=int),
            )
        part = dataclasses.replace(part, origin=head.origin, gnss=gnss if self._gnss else None)
        _write_data(
            self._w,
            self.path,
            part,
            self._meta,
            self._gyro_var,
            self._accel_var,
            None,
            gnss_channel=self._gnss,
        )
        for name in self.counts:
            data = getattr(part, name)
            self.counts[name] += 0 if data is None else len(data)
        if next_t is not None:
            self._bound = float(next_t)
        self._w.flush(None if next_t is None else int(self._w.stamps_ns([next_t])[0]))

    def close(self) -> None:
        """Write the rest, the summary and footer; then move the file into place."""
        self._w.close()

    def abort(self) -> None:
        """Drop the temporary file; nothing appears under the final name."""
        self._w.abort()


class LogSource(Protocol):
    """A log given in parts (sim/stream.py's ChunkedSimulation is one): head, t_first and gnss_fixes as
    LogStreamWriter takes them, imu_stamps() the IMU stamps in consecutive parts, parts() (part, next_t) pairs
    as LogStreamWriter.write takes them."""

    head: LogData
    t_first: float
    gnss_fixes: bool

    def imu_stamps(self) -> Iterator[np.ndarray]: ...

    def parts(
        self, progress: Callable[[float], None] | None = None
    ) -> Iterator[tuple[LogData, float | None]]: ...


def write_log_stream(
    path: str | os.PathLike[str],
    source: LogSource,
    *,
    config: dict[str, Any] | None = None,
    progress: Callable[[float], None] | None = None,
) -> dict[str, Any]:
    """Write a log given in parts to ``path`` (atomically) with LogStreamWriter, in memory bounded by a part:
    write_log's file of the log the parts make. Returns the message counts per sensor ("imu", "dvl" pings,
    "truth", "depth", "gnss"), "seconds" (wall time) and "write_seconds" (of it, in the writer: encoding,
    compression, file; the rest is the source's)."""
    start = time.perf_counter()
    t_write = 0.0
    with LogStreamWriter(
        path,
        source.head,
        t_first=source.t_first,
        imu_rate_hz=imu_rate_hz(source.imu_stamps()),
        gnss_fixes=source.gnss_fixes,
        config=config,
    ) as w:
        for part, next_t in source.parts(progress):
            t1 = time.perf_counter()
            w.write(part, next_t)
            t_write += time.perf_counter() - t1
        t1 = time.perf_counter()
    t_write += time.perf_counter() - t1  # closing: the last chunk and the summary
    return {**w.counts, "seconds": time.perf_counter() - start, "write_seconds": t_write}
