"""Read a log (ours or another tool's) into LogData, fast: bulk CDR decoding, no per-message objects.

Accepted storage: a bare .mcap, a bare .db3, or a rosbag2 bag directory (see ``sources``). DVL topics
may be marine_acoustic_msgs/msg/Dvl (3-D velocity and beams), geometry_msgs/msg/TwistWithCovarianceStamped
(linear 3x3 block of the covariance; an all-zero block is ROS's "unknown" and becomes NaN) or
geometry_msgs/msg/TwistStamped (no covariance: d_cov is NaN and the user must supply the DVL noise).
Times: ``t0_ns`` is the first IMU stamp rounded down to the second; all t arrays are relative to it and
come from the header stamps (log times are not used).

Streaming: the log is read in one pass, piece by piece (an MCAP's chunks, pages of a .db3), and the
high-rate topics (the IMU, the truth odometry) are decoded piece by piece into arrays of the fields the
reader uses (``TopicStream``, io/topic_stream.py: about 56 bytes per IMU sample, plus the orientation only if
some message has one), so that reading holds those arrays and one chunk, not every message body
(docs/results.md, "Log reader").
The other topics are low-rate and decoded in bulk. Errors are raised in the order of a bulk read.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.current import truth_current
from gtsam_dvl.core.earth import pressure_to_depth
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.imu_faults import drop_saturated, undo_clock_steps
from gtsam_dvl.core.types import (
    AttitudeData,
    BeamData,
    DepthData,
    DvlData,
    GnssData,
    ImuData,
    LogData,
    Mounting,
    TruthData,
)
from gtsam_dvl.io.attitude import read_attitude
from gtsam_dvl.io.gnss import (
    GNSS_TOPIC,
    NAVSATFIX_TYPE,
    first_fix_origin,
    first_fix_time,
    read_gnss,
)
from gtsam_dvl.io.log_metadata import typed_fields
from gtsam_dvl.io.read_options import ReadOptions
from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.decode import decode, decode_tf, first_string, to_base
from gtsam_dvl.io.ros2.msgdefs import normalize_type
from gtsam_dvl.io.stamps import check_stamps, gap_warning, stamp_gaps
from gtsam_dvl.io.storage.salvage import salvage_losses, salvage_report
from gtsam_dvl.io.storage.sources import Source, open_source
from gtsam_dvl.io.topic_stream import IMU_FIELDS, TRUTH_FIELDS, TopicStream, read_streaming
from gtsam_dvl.io.water_track import WATER_TOPIC_TYPES, as_water_track, merge_pings

IMU_TYPE = "sensor_msgs/msg/Imu"
ODOM_TYPE = "nav_msgs/msg/Odometry"
DVL_TYPES = (
    "marine_acoustic_msgs/msg/Dvl",
    "geometry_msgs/msg/TwistWithCovarianceStamped",
    "geometry_msgs/msg/TwistStamped",
)
PRESSURE_TYPE = "sensor_msgs/msg/FluidPressure"
POSE_COV_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
DEPTH_TYPES = (PRESSURE_TYPE, POSE_COV_TYPE, ODOM_TYPE)
DEPTH_TOPIC = "/depth/pressure"


def _type(src: Source, topic: str) -> str:
    return normalize_type(src.topics[topic].type_name)


def _missing(src: Source, what: str, topic: str, option: str) -> GtsamDvlError:
    return GtsamDvlError(
        f"{src.path}: no {what} topic {topic}; topics in the log: {src.describe_topics()} (choose with {option})"
    )


def _optional_topic(
    src: Source, given: str | None, default: str, what: str, types: tuple[str, ...], rule: str
) -> str:
    """The topic of an optional sensor ("" for none): given None takes default when the log has it, "none" takes
    none; a named topic must be in the log (else the error names the option --<what>-topic) and of one of types
    (else the error states rule)."""
    topic = (
        (default if default in src.topics else "")
        if given is None
        else ("" if given == "none" else given)
    )
    if topic and topic not in src.topics:
        raise _missing(src, what, topic, f"--{what.lower()}-topic")
    if topic and (kind := _type(src, topic)) not in types:
        raise GtsamDvlError(f"{src.path}: {topic} is {kind}; {rule}")
    return topic


def _dvl_data(src: Source, topic: str, arr: np.ndarray) -> DvlData:
    """DvlData (t left zero) from decoded Dvl, TwistWithCovarianceStamped or TwistStamped messages."""
    return dvl_from_messages(_type(src, topic), arr, src.metadata.get("gtsam_dvl", {}))


def dvl_from_messages(
    type_name: str, arr: np.ndarray, ours: dict[str, Any] | None = None
) -> DvlData:
    """DvlData (t left zero) from decoded messages of a DVL type (DVL_TYPES): the one mapping of a DVL message to
    a ping, for the reader and the ROS 2 node (app/node). ours: the log's gtsam_dvl metadata record ({} for
    another tool's log or a live topic): whether beam_quality holds our writer's per-beam validity."""
    ours = ours or {}
    m = len(arr)
    beams = None
    if type_name == "marine_acoustic_msgs/msg/Dvl":
        d_v = arr["velocity"].astype(float)
        d_cov = arr["velocity_covar"].astype(float).reshape(m, 3, 3)
        d_cov[d_cov[:, 0, 0] == -1.0] = np.nan  # the message's "not known"
        bvv = arr["beam_velocities_valid"].astype(bool)
        if bvv.any():
            nb = int(ours.get("dvl_beams", 4)) if "dvl_beam_quality" in ours else 4
            v = arr["beam_velocity"].astype(float)[:, :nb]
            # Our writer keeps per-beam validity in beam_quality; other drivers mark bad beams with NaN.
            ok = arr["beam_quality"][:, :nb] > 0 if "dvl_beam_quality" in ours else np.isfinite(v)
            beams = BeamData(
                d_u=arr["beam_unit_vec"].astype(float).reshape(m, 4, 3)[:, :nb].copy(),
                v=v,
                range=arr["range"].astype(float)[:, :nb].copy(),
                valid=ok & bvv[:, None],
            )
    else:
        d_v = arr["linear"].astype(float)
        if type_name == "geometry_msgs/msg/TwistWithCovarianceStamped":
            d_cov = arr["covariance"].astype(float).reshape(m, 6, 6)[:, :3, :3].copy()
            d_cov[(d_cov == 0).all(axis=(1, 2))] = np.nan  # all zeros = unknown (ROS convention)
        else:
            d_cov = np.full((m, 3, 3), np.nan)
    valid = np.isfinite(d_v).all(axis=1)
    water, altitude = None, None
    if type_name == "marine_acoustic_msgs/msg/Dvl":
        altitude = arr["altitude"].astype(float)
        # the mean altitude of the good beams: none (NaN, 0 or negative): unknown
        altitude[~(altitude > 0)] = np.nan
        # the message's own velocity mode: only bottom track is velocity over ground. A driver that fills the
        # field marks other pings 0 (invalid) or 2 (water track); one that never fills it leaves every ping 0,
        # and then only water-track pings are refused. Water-track pings are kept apart (DvlData.water_track)
        mode = arr["velocity_mode"]
        bottom = mode == 1
        mode_ok = bottom if bottom.any() else mode != 2
        valid &= mode_ok
        if beams is not None:
            beams.valid &= mode_ok[:, None]
        water = np.asarray(mode == 2) if (mode == 2).any() else None
    return DvlData(
        t=np.zeros(m),
        d_v=d_v,
        d_cov=d_cov,
        valid=valid,
        beams=beams,
        frame_id=first_string(arr) or "dvl_link",
        water_track=water,
        altitude=altitude,
    )


def _select(dvl: DvlData, keep: np.ndarray, t: np.ndarray) -> DvlData:
    b = dvl.beams
    beams = None if b is None else BeamData(b.d_u[keep], b.v[keep], b.range[keep], b.valid[keep])
    water = None if dvl.water_track is None else dvl.water_track[keep]
    altitude = None if dvl.altitude is None else dvl.altitude[keep]
    return DvlData(
        t,
        dvl.d_v[keep],
        dvl.d_cov[keep],
        dvl.valid[keep],
        beams,
        dvl.frame_id,
        water,
        altitude=altitude,
    )


def _metadata(src: Source) -> dict[str, Any]:
    meta: dict[str, Any] = {}
    rec = src.metadata.get("gtsam_dvl", {})
    if rec.get("scenario"):
        meta["scenario_name"] = rec[
            "scenario"
        ]  # the simulator's spelling; "scenario" is its settings
    if rec.get("generator"):
        meta["generator"] = rec["generator"]
    if rec.get("seed"):
        meta["seed"] = int(rec["seed"]) if rec["seed"].lstrip("-").isdigit() else rec["seed"]
    for key in ("truth", "sensors"):
        try:
            if value := json.loads(rec.get(key) or "null"):
                meta[key] = value
        except json.JSONDecodeError:
            meta[key] = rec[key]
    if "config.json" in src.attachments:
        try:
            att = json.loads(src.attachments["config.json"][1])
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise GtsamDvlError(f"{src.path}: attachment config.json is not valid JSON") from None
        if isinstance(att, dict):
            meta.update(att)
    meta["mcap_metadata"] = src.metadata
    return meta


@dataclass(frozen=True)
class _Topics:
    """The topics read_log reads, checked against the log: "" for a sensor it does not read; attitude None for
    the IMU topic's own orientation."""

    imu: str
    dvl: str
    dvl_type: str
    water: str
    truth: str
    tf: str
    depth: str
    gnss: str
    attitude: str | None

    def to_read(self, src: Source) -> list[str]:
        """The topics to read, in the order the storage is asked for them."""
        topics = [self.imu, self.dvl] + [self.truth] * bool(self.truth)
        topics += [self.tf] * (self.tf in src.topics) + [self.depth] * bool(self.depth)
        topics += ([self.water] if self.water else []) + [self.gnss] * bool(self.gnss)
        if self.attitude and self.attitude not in topics:
            topics.append(self.attitude)
        return topics


@dataclass
class _Reading:
    """What the steps of read_log share: the log, the options, the warnings so far, the messages dropped by
    --repair (per topic, by reason) and the time base t0 (ns, once the IMU is read)."""

    src: Source
    options: ReadOptions
    warnings: list[str]
    dropped: dict[str, dict[str, int]] = field(default_factory=dict)
    t0: int = 0

    def keep(self, topic: str, ns: np.ndarray, bad: np.ndarray | None = None) -> np.ndarray:
        """The keep-mask of a topic's messages (io/stamps.py check_stamps: raises, or drops with repair)."""
        o = self.options
        return check_stamps(
            self.src.path, topic, ns, self.t0, bad, o.repair, self.warnings, self.dropped
        )

    def seconds(self, ns: np.ndarray) -> np.ndarray:
        """Stamps (ns) as seconds since t0."""
        return (ns - self.t0) / 1e9


@dataclass
class _Imu:
    """The IMU as read: its data, the stamps logged (s, before saturated samples were dropped: the gap record is
    of the data missing from the log), its own orientation for io/attitude.py, the clock steps undone and the
    saturated samples dropped (their reports, None: none)."""

    data: ImuData
    logged_t: np.ndarray
    attitude: np.ndarray
    clock: list[dict[str, float]]
    saturation: dict[str, Any] | None = None


def read_log(
    path: str | Path,
    options: ReadOptions | None = None,
    *,
    progress: Callable[[float], None] | None = None,
    **option_values: Any,
) -> LogData:
    """Read an IMU+DVL log as options say (ReadOptions, io/read_options.py: the topics, frames, salvage and
    repair; None: the defaults). option_values: ReadOptions' fields by name, over options' (``read_log(path,
    dvl_topic="/dvl/twist")``); a bad one is one GtsamDvlError line. progress(fraction) is called while reading.

    NaN IMU data, duplicate or backwards stamps raise GtsamDvlError, or with ``repair`` are dropped and counted.
    Warnings go to metadata["reader_warnings"], and what was lost, structured, to metadata["reader_losses"]:
    "repair" (per topic: messages dropped by reason), "gaps" (per topic: missing stretches, see stamp_gaps),
    "clock_steps" (the IMU's, undone with ``repair``, else an error) and "saturation" (the IMU samples at their
    range limit, dropped: core/imu_faults.py), "salvage" (with ``salvage``: io.storage.salvage.salvage_losses)
    and "messages_lost" (per topic).

    Depth (LogData.depth): a sensor_msgs/msg/FluidPressure topic keeps the pressure (the estimators convert it
    with their [depth] settings) and fills depth_m with the defaults of core/earth.py at the origin's latitude
    (45 deg without one); a geometry_msgs/msg/PoseWithCovarianceStamped or nav_msgs/msg/Odometry topic gives
    depth = -z (z up, the ROS convention), or +z with depth_z_down, and its variance from the zz covariance (0
    or negative: unknown). GNSS (LogData.gnss, io/gnss.py): when the log records no map origin, LogData.origin is
    the first good fix (estimators/inputs/gnss.py decides which fixes are good and how they are used). Attitude
    (LogData.attitude, io/attitude.py): turned into base_link in ENU. Water track on a topic of its own (a twist:
    io/water_track.py): its pings join the DVL's in stamp order, marked DvlData.water_track. Simulated truth gets
    the current the metadata records (TruthData.n_c, core/current.py truth_current)."""
    o = options or ReadOptions()
    if option_values:
        o = o.replace(**option_values)
    src = open_source(path, salvage=o.salvage)
    r = _Reading(src, o, [])
    topics = _choose_topics(src, o)
    r.warnings.extend(src.warnings)
    if o.truth_topic in src.topics and not topics.truth:
        r.warnings.append(f"{o.truth_topic} is not {ODOM_TYPE}; truth ignored")
    imu_stream, truth_stream, raw = _read_pieces(src, topics, progress)
    imu = _read_imu(r, topics, imu_stream)
    meta = _metadata(src)
    if meta.get("white_noise") is not False:
        imu.data, imu.saturation = drop_saturated(imu.data, topics.imu, r.warnings)
    dvl = _read_dvl(r, topics, raw)
    truth = _read_truth(r, topics.truth, truth_stream, meta)
    mounting = _read_mounting(r, raw, imu.data.frame_id, dvl.frame_id)
    # a simulation without noise (DvlData.noise_free)
    dvl.noise_free = meta.get("white_noise") is False
    depth, gnss, attitude = _read_aiding(r, topics, raw, imu, mounting, meta)
    meta["reader_warnings"] = r.warnings
    meta["reader_losses"] = _losses(r, topics, imu, dvl, truth)
    typed = typed_fields(meta, str(src.path))
    if typed.get("origin") is None and gnss is not None:
        typed["origin"] = first_fix_origin(gnss)
        if typed["origin"] is not None:
            r.warnings.append(
                f"map origin from the first good GNSS fix on {topics.gnss} (t = "
                f"{first_fix_time(gnss):.1f} s)"
            )
    return LogData(
        imu.data,
        dvl,
        mounting,
        truth,
        r.t0,
        meta,
        str(src.path),
        **typed,
        depth=depth,
        gnss=gnss,
        attitude=attitude,
    )


def _read_aiding(
    r: _Reading,
    topics: _Topics,
    raw: dict[str, Any],
    imu: _Imu,
    mounting: Mounting,
    meta: dict[str, Any],
) -> tuple[DepthData | None, GnssData | None, AttitudeData | None]:
    """The aiding sensors the topics name (None each without): depth and GNSS with their positions in base_link
    from the tf topic, attitude (io/attitude.py; the IMU's own orientation when no attitude topic is named)."""
    o = r.options
    depth = None
    if topics.depth:
        depth = _depth_data(r, topics.depth, raw[topics.depth], meta.get("origin"))
        if (b_p := _sensor_position(r, raw, depth.frame_id)) is not None:
            depth.b_p_sensor = b_p
    gnss = None
    if topics.gnss:
        gnss = read_gnss(
            r.src, topics.gnss, raw[topics.gnss], r.t0, o.repair, r.warnings, r.dropped
        )
        if (b_p := _sensor_position(r, raw, gnss.frame_id)) is not None:
            gnss.b_p_antenna = b_p
    attitude = read_attitude(
        r.src,
        topics.attitude,
        topics.imu,
        raw,
        imu.attitude,
        r.t0,
        mounting,
        o.repair,
        r.warnings,
        r.dropped,
        o.attitude_frame,
    )
    return depth, gnss, attitude


def _choose_topics(src: Source, o: ReadOptions) -> _Topics:
    """The topics to read, checked: the IMU and DVL (present, of their types), the optional ones (present when
    named, of their types); the truth when the log has it as nav_msgs/msg/Odometry. One GtsamDvlError line naming
    the option to choose with, else."""
    path = src.path
    if o.imu_topic not in src.topics:
        raise _missing(src, "IMU", o.imu_topic, "--imu-topic")
    dvl_topic = o.dvl_topic
    if dvl_topic is None:
        dvl_topic = "/dvl/data" if "/dvl/data" in src.topics else "/dvl/twist"
    if dvl_topic not in src.topics:
        raise _missing(src, "DVL", dvl_topic, "--dvl-topic")
    if (kind := _type(src, o.imu_topic)) != IMU_TYPE:
        raise GtsamDvlError(f"{path}: {o.imu_topic} is {kind}, expected {IMU_TYPE}")
    if (dvl_type := _type(src, dvl_topic)) not in DVL_TYPES:
        raise GtsamDvlError(
            f"{path}: {dvl_topic} is {dvl_type}; DVL topics must be one of {', '.join(DVL_TYPES)}"
        )
    water = o.dvl_water_topic or ""
    if water and water not in src.topics:
        raise _missing(src, "DVL water-track", water, "--dvl-water-topic")
    if water and (kind := _type(src, water)) not in WATER_TOPIC_TYPES:
        raise GtsamDvlError(
            f"{path}: {water} is {kind}; water-track topics must be one of "
            f"{', '.join(WATER_TOPIC_TYPES)}"
        )
    depth = _optional_topic(
        src,
        o.depth_topic,
        DEPTH_TOPIC,
        "depth",
        DEPTH_TYPES,
        f"depth topics must be one of {', '.join(DEPTH_TYPES)}",
    )
    has_truth = o.truth_topic in src.topics and _type(src, o.truth_topic) == ODOM_TYPE
    gnss = _optional_topic(
        src,
        o.gnss_topic,
        GNSS_TOPIC,
        "GNSS",
        (NAVSATFIX_TYPE,),
        f"the GNSS topic must be {NAVSATFIX_TYPE}",
    )
    attitude = "" if o.attitude_topic == "none" else o.attitude_topic
    if attitude and attitude not in src.topics:
        raise _missing(src, "attitude", attitude, "--attitude-topic")
    return _Topics(
        o.imu_topic,
        dvl_topic,
        dvl_type,
        water,
        o.truth_topic if has_truth else "",
        o.tf_topic,
        depth,
        gnss,
        attitude,
    )


def _read_pieces(
    src: Source, topics: _Topics, progress: Callable[[float], None] | None
) -> tuple[TopicStream, TopicStream | None, dict[str, Any]]:
    """The one pass over the log: the IMU (with its own orientation when no attitude topic is named) and the
    truth decoded piece by piece into their TopicStream, the other topics' bodies collected (module doc)."""
    counts = src.message_counts()
    imu_stream = TopicStream(
        src.path,
        topics.imu,
        IMU_TYPE,
        IMU_FIELDS,
        counts.get(topics.imu, 0),
        orientation=topics.attitude is None,
    )
    streams = {topics.imu: imu_stream}
    truth_stream = None
    if topics.truth:
        truth_stream = TopicStream(
            src.path, topics.truth, ODOM_TYPE, TRUTH_FIELDS, counts.get(topics.truth, 0)
        )
        streams[topics.truth] = truth_stream
    # streamed topics another step decodes itself (e.g. the truth as the attitude topic) keep their bodies too
    others = {topics.depth, topics.gnss, topics.attitude, topics.tf, topics.dvl, topics.water}
    keep_bodies = {t for t in streams if t in others}
    raw = read_streaming(src, topics.to_read(src), streams, keep_bodies, progress)
    return imu_stream, truth_stream, raw


def _read_imu(r: _Reading, topics: _Topics, imu_stream: TopicStream) -> _Imu:
    """The IMU's samples checked (NaN, stamps, a clock step: core/imu_faults.py), the time base r.t0 set (the first
    kept stamp rounded down to the second), and the IMU's own orientation taken before the stream lets go of it."""
    path, topic = r.src.path, topics.imu
    imu = imu_stream.array()
    if not len(imu):
        raise GtsamDvlError(f"{path}: {topic} has no messages")
    imu_ns = stamps_ns(imu)
    # views of the decoded messages, not copies (two fewer arrays over every IMU sample at the reader's peak)
    b_omega, b_f = (
        imu[f] if imu.dtype[f].base == np.float64 else imu[f].astype(float)
        for f in ("angular_velocity", "linear_acceleration")
    )
    r.t0 = int(imu_ns[0] // 1_000_000_000) * 1_000_000_000
    nan = ~(np.isfinite(b_omega).all(axis=1) & np.isfinite(b_f).all(axis=1))
    # a clock step (core/imu_faults.py) is undone with repair, else named in an error
    try:
        imu_ns, clock = undo_clock_steps(
            imu_ns, r.t0, b_omega, b_f, topic, r.options.repair, r.warnings
        )
    except GtsamDvlError as exc:
        raise GtsamDvlError(f"{path}: {exc}") from None
    keep = r.keep(topic, imu_ns, nan)
    # the IMU's own orientation (when no attitude topic) now, then the stream's references let go (b_omega and
    # b_f keep the decoded messages' buffer, of which they are views)
    attitude = imu_stream.attitude_array(keep) if topics.attitude is None else imu[:0].copy()
    imu_stream.out, imu_stream.orient, imu = None, None, imu[:0].copy()
    if not keep.all():
        imu_ns, b_omega, b_f = imu_ns[keep], b_omega[keep], b_f[keep]
    r.t0 = int(imu_ns[0] // 1_000_000_000) * 1_000_000_000
    data = ImuData(r.seconds(imu_ns), b_omega, b_f, imu_stream.frame_id or "imu_link")
    return _Imu(data, data.t, attitude, clock)


def _read_dvl(r: _Reading, topics: _Topics, raw: dict[str, Any]) -> DvlData:
    """The DVL's pings (stamps checked), with the pings of a separate water-track topic merged in stamp order."""
    path = r.src.path
    dvl_arr = decode(path, topics.dvl, topics.dvl_type, raw[topics.dvl])
    if not len(dvl_arr):
        raise GtsamDvlError(f"{path}: {topics.dvl} has no messages")
    dvl, dvl_ns = _dvl_data(r.src, topics.dvl, dvl_arr), stamps_ns(dvl_arr)
    keep = r.keep(topics.dvl, dvl_ns)
    dvl = _select(dvl, keep, r.seconds(dvl_ns[keep]))
    if not topics.water:
        return dvl
    w_arr = decode(path, topics.water, _type(r.src, topics.water), raw[topics.water])
    w_ns = stamps_ns(w_arr)
    keep = r.keep(topics.water, w_ns)
    water = _select(_dvl_data(r.src, topics.water, w_arr), keep, r.seconds(w_ns[keep]))
    if water.frame_id != dvl.frame_id:
        r.warnings.append(
            f"{topics.water} is in frame {water.frame_id}, {topics.dvl} in {dvl.frame_id}: its "
            f"velocity taken in {dvl.frame_id}"
        )
    return merge_pings(dvl, as_water_track(water))


def _read_truth(
    r: _Reading, topic: str, stream: TopicStream | None, meta: dict[str, Any]
) -> TruthData | None:
    """The ground truth (None without a truth topic): velocity turned into the map frame, and the water current
    a simulation's metadata records."""
    if stream is None:
        return None
    od = stream.array()
    ns = stamps_ns(od)
    keep = r.keep(topic, ns)
    q = od["orientation"].astype(float)[keep]
    n_v = (
        Rotation.from_quat(q).apply(od["linear"].astype(float)[keep])
        if keep.any()
        else np.zeros((0, 3))
    )
    n_p, t_truth = od["position"].astype(float)[keep], r.seconds(ns[keep])
    return TruthData(
        t_truth,
        n_p,
        q,
        n_v,
        od["angular"].astype(float)[keep],
        truth_current(meta, t_truth, n_p),
    )


def _read_mounting(r: _Reading, raw: dict[str, Any], imu_frame: str, dvl_frame: str) -> Mounting:
    """The IMU's and the DVL's poses in base_link from the tf topic; identity (warned) where it has none."""
    mounting = Mounting()
    tf_topic = r.options.tf_topic
    if tf_topic not in r.src.topics:
        r.warnings.append(
            f"no {tf_topic} in the log: identity mounting assumed (IMU and DVL frames = base_link)"
        )
        return mounting
    tfs = decode_tf(r.src.path, tf_topic, raw[tf_topic])
    for frame, attrs in (
        (imu_frame, ("b_R_imu", "b_p_imu")),
        (dvl_frame, ("b_R_d0", "b_p_dvl")),
    ):
        if (pose := to_base(tfs, frame)) is None:
            r.warnings.append(f"{tf_topic} has no transform base_link -> {frame}: identity assumed")
        else:
            setattr(mounting, attrs[0], pose[0])
            setattr(mounting, attrs[1], pose[1])
    return mounting


def _sensor_position(r: _Reading, raw: dict[str, Any], frame: str) -> np.ndarray | None:
    """A sensor's position in base_link (m) from the tf topic, None when the log has no such transform."""
    tf_topic = r.options.tf_topic
    if tf_topic not in r.src.topics:
        return None
    pose = to_base(decode_tf(r.src.path, tf_topic, raw[tf_topic]), frame)
    return None if pose is None else pose[1]


def _losses(
    r: _Reading, topics: _Topics, imu: _Imu, dvl: DvlData, truth: TruthData | None
) -> dict[str, Any]:
    """metadata["reader_losses"] (read_log's doc), the gaps and salvage report also among the warnings."""
    gaps: dict[str, dict[str, Any]] = {}
    for topic, t in ((topics.imu, imu.logged_t), (topics.dvl, dvl.t)) + (
        ((topics.truth, truth.t),) if truth else ()
    ):
        if (gap := stamp_gaps(t)) is not None:
            gaps[topic] = gap
            r.warnings.append(gap_warning(topic, gap))
    losses: dict[str, Any] = {"repair": r.dropped, "gaps": gaps}
    if imu.clock:
        losses["clock_steps"] = {topics.imu: imu.clock}
    if imu.saturation:
        losses["saturation"] = {topics.imu: imu.saturation}
    if r.options.salvage:
        losses["salvage"] = salvage_losses(r.src, r.t0)
        r.warnings.append(salvage_report(losses["salvage"], r.src.path))
    losses["messages_lost"] = _messages_lost(losses)
    return losses


def _depth_data(r: _Reading, topic: str, bodies: Any, origin: Any) -> DepthData:
    """DepthData from a FluidPressure, PoseWithCovarianceStamped or Odometry topic (read_log's doc)."""
    type_name = _type(r.src, topic)
    arr = decode(r.src.path, topic, type_name, bodies)
    ns = stamps_ns(arr)
    frame_id = first_string(arr) or "pressure_link"
    if type_name == PRESSURE_TYPE:
        p, var = pressure_from_messages(arr)
        keep = r.keep(topic, ns, ~np.isfinite(p))
        p, var = p[keep], var[keep]
        lat_deg = (
            float(origin["lat_deg"]) if isinstance(origin, dict) and "lat_deg" in origin else 45.0
        )
        d, dd_dp = pressure_to_depth(p, float(np.radians(lat_deg)))
        return DepthData(r.seconds(ns[keep]), d, var * dd_dp**2, p, var, frame_id)
    z = arr["position"].astype(float)[:, 2]
    cov = arr["covariance" if type_name == POSE_COV_TYPE else "pose_covariance"].astype(float)[
        :, 14
    ]
    keep = r.keep(topic, ns, ~np.isfinite(z))
    d = z[keep] if r.options.depth_z_down else -z[keep]
    return DepthData(
        r.seconds(ns[keep]), d, np.where(cov[keep] > 0, cov[keep], np.nan), frame_id=frame_id
    )


def pressure_from_messages(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(absolute pressure Pa, its variance Pa^2) of decoded sensor_msgs/msg/FluidPressure messages; a variance of
    0 or below is ROS's "unknown" and becomes NaN. The reader and the ROS 2 node (app/node) share it."""
    var = arr["variance"].astype(float)
    return arr["fluid_pressure"].astype(float), np.where(var > 0, var, np.nan)


def _messages_lost(losses: dict[str, Any]) -> dict[str, int]:
    """Messages lost per topic: dropped by --repair plus those in chunks --salvage could not read."""
    out = {topic: d["dropped"] for topic, d in losses["repair"].items()}
    for topic, n in losses.get("salvage", {}).get("messages_lost_per_topic", {}).items():
        out[topic] = out.get(topic, 0) + n
    return out


def read_odometry(
    path: str | Path, topic: str, *, t0_ns: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """nav_msgs/msg/Odometry on ``topic``: (t, n_p, n_q_b [x,y,z,w], b_v, b_omega, pose_cov (K,6,6),
    twist_cov (K,6,6)). t is relative to t0_ns; by default the t0 the writer recorded (metadata
    "gtsam_dvl_time"), else the first stamp rounded down to the second."""
    src = open_source(path)
    if topic not in src.topics:
        raise _missing(src, "odometry", topic, "the topic argument")
    if (kind := _type(src, topic)) != ODOM_TYPE:
        raise GtsamDvlError(f"{src.path}: {topic} is {kind}, expected {ODOM_TYPE}")
    od = decode(src.path, topic, ODOM_TYPE, src.read([topic])[topic])
    ns = stamps_ns(od)
    if t0_ns is None:
        rec = src.metadata.get("gtsam_dvl_time", {}).get("t0_ns", "")
        t0_ns = (
            int(rec) if rec.lstrip("-").isdigit() else int(ns[0] // 10**9 * 10**9) if len(ns) else 0
        )
    k = len(od)
    return (
        (ns - t0_ns) / 1e9,
        od["position"].astype(float),
        od["orientation"].astype(float),
        od["linear"].astype(float),
        od["angular"].astype(float),
        od["pose_covariance"].astype(float).reshape(k, 6, 6),
        od["twist_covariance"].astype(float).reshape(k, 6, 6),
    )


def read_topic(path: str | Path, topic: str) -> list[tuple[int, Any]]:
    """Every message on ``topic`` as (log time ns, decoded message object), decoded one by one with
    mcap_ros2 through the definition stored in the log (for low-volume topics of any type)."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    src = open_source(path)
    if topic not in src.topics:
        raise _missing(src, "such", topic, "the topic argument")
    info = src.topics[topic]
    if not info.schema:
        raise GtsamDvlError(f"{src.path}: {topic} has no message definition in the log")
    schema = Schema(id=1, name=info.type_name, encoding="ros2msg", data=info.schema.encode())
    decoder = DecoderFactory().decoder_for("cdr", schema)
    assert decoder is not None
    bodies = src.read([topic])[topic]
    try:
        return [(int(t), decoder(b)) for t, b in zip(bodies.log_time, bodies.items(), strict=True)]
    except Exception as e:  # mcap_ros2 raises assorted errors on a bad body or definition
        raise GtsamDvlError(f"{src.path}: {topic}: cannot decode ({e})") from None
