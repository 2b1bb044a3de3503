"""Read a log (ours or another tool's) into LogData, fast: bulk CDR decoding, no per-message objects.

Accepted storage: a bare .mcap, a bare .db3, or a rosbag2 bag directory (see ``sources``). DVL topics
may be marine_acoustic_msgs/msg/Dvl (3-D velocity and beams), geometry_msgs/msg/TwistWithCovarianceStamped
(linear 3x3 block of the covariance; an all-zero block is ROS's "unknown" and becomes NaN) or
geometry_msgs/msg/TwistStamped (no covariance: d_cov is NaN and the user must supply the DVL noise).
Times: ``t0_ns`` is the first IMU stamp rounded down to the second; all t arrays are relative to it and
come from the header stamps (log times are not used).

Streaming: the log is read in one pass, piece by piece (an MCAP's chunks, pages of a .db3), and the
high-rate topics (the IMU, the truth odometry) are decoded piece by piece into arrays of the fields the
reader uses (``_Stream``: about 56 bytes per IMU sample, plus the orientation only if some message has one),
so that reading holds those arrays and one chunk, not every message body (docs/results.md, "Log reader").
The other topics are low-rate and decoded in bulk. Errors are raised in the order of a bulk read.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.current import truth_current
from gtsam_dvl.core.earth import pressure_to_depth
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.imu_faults import drop_saturated, undo_clock_steps
from gtsam_dvl.core.types import BeamData, DepthData, DvlData, ImuData, LogData, Mounting, TruthData
from gtsam_dvl.io.attitude import read_attitude
from gtsam_dvl.io.gnss import (
    GNSS_TOPIC,
    NAVSATFIX_TYPE,
    first_fix_origin,
    first_fix_time,
    read_gnss,
)
from gtsam_dvl.io.log_metadata import typed_fields
from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.decode import decode, decode_tf, first_string, to_base
from gtsam_dvl.io.ros2.msgdefs import normalize_type
from gtsam_dvl.io.stamps import check_stamps, gap_warning, stamp_gaps
from gtsam_dvl.io.storage.raw import Bodies
from gtsam_dvl.io.storage.salvage import salvage_losses, salvage_report
from gtsam_dvl.io.storage.sources import Source, open_source
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
        altitude[~(altitude > 0)] = (
            np.nan
        )  # the mean altitude of the good beams: none (NaN, 0 or negative): unknown
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


IMU_FIELDS = ("sec", "nanosec", "angular_velocity", "linear_acceleration")
IMU_ORIENTATION_FIELDS = ("orientation", "orientation_covariance", "frame_id")
TRUTH_FIELDS = ("sec", "nanosec", "position", "orientation", "linear", "angular")


class _Stream:
    """One topic decoded piece by piece into preallocated arrays of some of its fields (grown by doubling
    when the storage's message count was missing or short). Decoding errors are kept, not raised, so that
    the caller raises them where a bulk read would (after the storage's own errors). With ``orientation``
    (IMU only): the orientation and its covariance too, but stored only from the first piece in which some
    message has one (orientation_covariance[0] != -1); earlier rows get "no orientation"."""

    def __init__(
        self,
        path: Path,
        topic: str,
        type_name: str,
        fields: tuple[str, ...],
        capacity: int,
        orientation: bool = False,
    ) -> None:
        self.path, self.topic, self.type_name, self.fields = path, topic, type_name, fields
        self.capacity, self.n, self.frame_id = max(capacity, 1), 0, ""
        self.orientation = orientation
        self.out: np.ndarray | None = None
        self.orient: np.ndarray | None = None
        self.error: GtsamDvlError | None = None

    def add(self, bodies: Any) -> None:
        if self.error is not None or not len(bodies):
            return
        try:
            arr = decode(self.path, self.topic, self.type_name, bodies)
        except GtsamDvlError as e:
            self.error = e
            return
        if self.out is None:
            self.frame_id = first_string(arr)
            self.out = np.empty(self.capacity, np.dtype([(f, arr.dtype[f]) for f in self.fields]))
        k = len(arr)
        if self.n + k > len(self.out):
            self.out = self._grow(self.out, self.n + k)
        for f in self.fields:
            self.out[f][self.n : self.n + k] = arr[f]
        if self.orientation:
            self._add_orientation(arr)
        self.n += k

    def _grow(self, a: np.ndarray, need: int) -> np.ndarray:
        b = np.empty(max(need, 2 * len(a)), a.dtype)
        b[: self.n] = a[: self.n]
        return b

    def _add_orientation(self, arr: np.ndarray) -> None:
        k = len(arr)
        if self.orient is None:
            if not (arr["orientation_covariance"][:, 0] != -1.0).any():
                return
            self.orient = np.zeros(
                len(self.out) if self.out is not None else k,
                [("orientation", "<f8", (4,)), ("orientation_covariance", "<f8", (9,))],
            )
            self.orient["orientation_covariance"][: self.n] = -1.0
        if self.n + k > len(self.orient):
            self.orient = self._grow(self.orient, self.n + k)
        self.orient["orientation"][self.n : self.n + k] = arr["orientation"]
        self.orient["orientation_covariance"][self.n : self.n + k] = arr["orientation_covariance"]

    def array(self) -> np.ndarray:
        """The decoded fields of every message (raises a decoding error first)."""
        if self.error is not None:
            raise self.error
        if self.out is None:
            return np.zeros(0, [(f, "<f8") for f in self.fields])
        return self.out[: self.n]

    def attitude_array(self, keep: np.ndarray) -> np.ndarray:
        """What io/attitude.read_attitude needs of the IMU's own orientation, for the messages kept: a
        one-message array with "no orientation" when none had one (read_attitude then returns None)."""
        stamps = self.array()
        dt = [
            ("sec", "<i4"),
            ("nanosec", "<u4"),
            ("orientation", "<f8", (4,)),
            ("orientation_covariance", "<f8", (9,)),
            ("frame_id", "O"),
        ]
        if self.orient is None:
            out = np.zeros(1, dt)
            out["orientation_covariance"] = -1.0
            return out
        out = np.zeros(int(keep.sum()), dt)
        for f in ("sec", "nanosec"):
            out[f] = stamps[f][keep]
        for f in ("orientation", "orientation_covariance"):
            out[f] = self.orient[f][: self.n][keep]
        out["frame_id"] = self.frame_id
        return out


def _read_streaming(
    src: Source,
    topics: list[str],
    streams: dict[str, _Stream],
    keep_bodies: set[str],
    progress: Callable[[float], None] | None,
) -> dict[str, Any]:
    """One pass over the log: streamed topics into their _Stream, the others' bodies (and those of streamed
    topics in keep_bodies, which another part of the reader decodes itself) collected as src.read would."""
    pieces: dict[str, list[Bodies]] = {
        t: [] for t in topics if t not in streams or t in keep_bodies
    }
    for got in src.iter_read(topics, progress):
        for topic, bodies in got.items():
            if topic in streams:
                streams[topic].add(bodies)
            if topic in pieces:
                pieces[topic].append(bodies)
    return {
        t: p[0] if len(p) == 1 else Bodies.concat(p)
        for t, p in pieces.items()
        if p or t in src.topics
    }


def read_log(
    path: str | Path,
    *,
    imu_topic: str = "/imu/data_raw",
    dvl_topic: str | None = None,
    dvl_water_topic: str | None = None,
    truth_topic: str = "/ground_truth/odometry",
    tf_topic: str = "/tf_static",
    depth_topic: str | None = None,
    depth_z_down: bool = False,
    gnss_topic: str | None = None,
    attitude_topic: str | None = None,
    attitude_frame: str = "enu",
    salvage: bool = False,
    repair: bool = False,
    progress: Callable[[float], None] | None = None,
) -> LogData:
    """Read an IMU+DVL log. dvl_topic None: /dvl/data if present, else /dvl/twist. Without tf_topic the
    mounting is identity (warned). NaN IMU data, duplicate or backwards stamps raise GtsamDvlError, or
    with ``repair`` are dropped and counted. ``salvage`` recovers the intact chunks of a damaged MCAP.
    Warnings go to metadata["reader_warnings"], and what was lost, structured, to metadata["reader_losses"]:
    "repair" (per topic: messages dropped by reason), "gaps" (per topic: missing stretches, see stamp_gaps),
    "clock_steps" (the IMU's, undone with ``repair``, else an error) and "saturation" (the IMU samples at their
    range limit, dropped: core/imu_faults.py),
    "salvage" (with ``salvage``: io.storage.salvage.salvage_losses) and "messages_lost" (per topic).
    progress(fraction) is called while reading.

    Depth (LogData.depth): depth_topic None reads /depth/pressure if the log has it; "" or "none" reads no
    depth. A sensor_msgs/msg/FluidPressure topic keeps the pressure (the estimators convert it with their
    [depth] settings) and fills depth_m with the defaults of core/earth.py at the origin's latitude (45 deg
    without one); a geometry_msgs/msg/PoseWithCovarianceStamped or nav_msgs/msg/Odometry topic gives depth
    = -z (z up, the ROS convention), or +z with depth_z_down, and its variance from the zz covariance (0 or
    negative: unknown).

    GNSS (LogData.gnss): gnss_topic None reads /gnss/fix if the log has it; "" or "none" reads none; the topic
    must be sensor_msgs/msg/NavSatFix (io/gnss.py). When the log records no map origin, LogData.origin is the
    first good fix (estimators/inputs/gnss.py decides which fixes are good and how they are used).

    Attitude (LogData.attitude, io/attitude.py): attitude_topic None takes the IMU topic's own orientation when
    its covariance says it is valid; "" or "none" reads none; else the named topic (sensor_msgs/msg/Imu,
    nav_msgs/msg/Odometry or geometry_msgs/msg/PoseWithCovarianceStamped). attitude_frame: "enu" (REP-103) or
    "ned" (an AHRS publishing NED orientation of an FRD body), turned into base_link in ENU.

    Water track on a topic of its own (dvl_water_topic, a twist: io/water_track.py): its pings join the DVL's in
    stamp order, marked DvlData.water_track. Simulated truth gets the current the metadata records
    (TruthData.n_c, core/current.py truth_current)."""
    src = open_source(path, salvage=salvage)
    path = src.path
    if imu_topic not in src.topics:
        raise _missing(src, "IMU", imu_topic, "--imu-topic")
    if dvl_topic is None:
        dvl_topic = "/dvl/data" if "/dvl/data" in src.topics else "/dvl/twist"
    if dvl_topic not in src.topics:
        raise _missing(src, "DVL", dvl_topic, "--dvl-topic")
    if (kind := _type(src, imu_topic)) != IMU_TYPE:
        raise GtsamDvlError(f"{path}: {imu_topic} is {kind}, expected {IMU_TYPE}")
    if (dvl_type := _type(src, dvl_topic)) not in DVL_TYPES:
        raise GtsamDvlError(
            f"{path}: {dvl_topic} is {dvl_type}; DVL topics must be one of {', '.join(DVL_TYPES)}"
        )
    if dvl_water_topic and dvl_water_topic not in src.topics:
        raise _missing(src, "DVL water-track", dvl_water_topic, "--dvl-water-topic")
    if dvl_water_topic and (kind := _type(src, dvl_water_topic)) not in WATER_TOPIC_TYPES:
        raise GtsamDvlError(
            f"{path}: {dvl_water_topic} is {kind}; water-track topics must be one of "
            f"{', '.join(WATER_TOPIC_TYPES)}"
        )
    depth_topic = _optional_topic(
        src,
        depth_topic,
        DEPTH_TOPIC,
        "depth",
        DEPTH_TYPES,
        f"depth topics must be one of {', '.join(DEPTH_TYPES)}",
    )
    warnings = list(src.warnings)
    dropped: dict[str, dict[str, int]] = {}
    has_truth = truth_topic in src.topics and _type(src, truth_topic) == ODOM_TYPE
    if truth_topic in src.topics and not has_truth:
        warnings.append(f"{truth_topic} is not {ODOM_TYPE}; truth ignored")
    topics = (
        [imu_topic, dvl_topic] + [truth_topic] * has_truth + [tf_topic] * (tf_topic in src.topics)
    )
    topics += [depth_topic] * bool(depth_topic) + ([dvl_water_topic] if dvl_water_topic else [])
    gnss_topic = _optional_topic(
        src,
        gnss_topic,
        GNSS_TOPIC,
        "GNSS",
        (NAVSATFIX_TYPE,),
        f"the GNSS topic must be {NAVSATFIX_TYPE}",
    )
    topics += [gnss_topic] * bool(gnss_topic)
    if attitude_topic == "none":
        attitude_topic = ""
    if attitude_topic and attitude_topic not in src.topics:
        raise _missing(src, "attitude", attitude_topic, "--attitude-topic")
    if attitude_topic and attitude_topic not in topics:
        topics.append(attitude_topic)
    counts = src.message_counts()
    imu_stream = _Stream(
        path,
        imu_topic,
        IMU_TYPE,
        IMU_FIELDS,
        counts.get(imu_topic, 0),
        orientation=attitude_topic is None,
    )
    streams = {imu_topic: imu_stream}
    if has_truth:
        streams[truth_topic] = _Stream(
            path, truth_topic, ODOM_TYPE, TRUTH_FIELDS, counts.get(truth_topic, 0)
        )
    others = {depth_topic, gnss_topic, attitude_topic, tf_topic, dvl_topic, dvl_water_topic}
    raw = _read_streaming(src, topics, streams, {t for t in streams if t in others}, progress)

    imu = imu_stream.array()
    if not len(imu):
        raise GtsamDvlError(f"{path}: {imu_topic} has no messages")
    imu_ns = stamps_ns(imu)
    # views of the decoded messages, not copies (two fewer arrays over every IMU sample at the reader's peak)
    b_omega, b_f = (
        imu[f] if imu.dtype[f].base == np.float64 else imu[f].astype(float)
        for f in ("angular_velocity", "linear_acceleration")
    )
    t0 = int(imu_ns[0] // 1_000_000_000) * 1_000_000_000
    nan = ~(np.isfinite(b_omega).all(axis=1) & np.isfinite(b_f).all(axis=1))
    # a clock step (core/imu_faults.py) is undone with repair, else named in an error
    try:
        imu_ns, clock = undo_clock_steps(imu_ns, t0, b_omega, b_f, imu_topic, repair, warnings)
    except GtsamDvlError as exc:
        raise GtsamDvlError(f"{path}: {exc}") from None
    keep = check_stamps(path, imu_topic, imu_ns, t0, nan, repair, warnings, dropped)
    # the IMU's own orientation (when no attitude topic) now, then the stream's references let go (b_omega and
    # b_f keep the decoded messages' buffer, of which they are views)
    imu_attitude = imu_stream.attitude_array(keep) if attitude_topic is None else imu[:0].copy()
    imu_stream.out, imu_stream.orient, imu = None, None, imu[:0].copy()
    if not keep.all():
        imu_ns, b_omega, b_f = imu_ns[keep], b_omega[keep], b_f[keep]
    t0 = int(imu_ns[0] // 1_000_000_000) * 1_000_000_000
    imu_data = ImuData((imu_ns - t0) / 1e9, b_omega, b_f, imu_stream.frame_id or "imu_link")
    del imu_ns
    # saturated samples dropped (core/imu_faults.py; not in a noise-free simulation, whose values repeat by
    # design); the gap record below is of the data missing from the log
    meta = _metadata(src)
    imu_logged_t = imu_data.t
    saturation = None
    if meta.get("white_noise") is not False:
        imu_data, saturation = drop_saturated(imu_data, imu_topic, warnings)

    dvl_arr = decode(path, dvl_topic, dvl_type, raw[dvl_topic])
    if not len(dvl_arr):
        raise GtsamDvlError(f"{path}: {dvl_topic} has no messages")
    dvl, dvl_ns = _dvl_data(src, dvl_topic, dvl_arr), stamps_ns(dvl_arr)
    keep = check_stamps(path, dvl_topic, dvl_ns, t0, None, repair, warnings, dropped)
    dvl = _select(dvl, keep, (dvl_ns[keep] - t0) / 1e9)
    if dvl_water_topic:
        w_arr = decode(path, dvl_water_topic, _type(src, dvl_water_topic), raw[dvl_water_topic])
        w_ns = stamps_ns(w_arr)
        keep = check_stamps(path, dvl_water_topic, w_ns, t0, None, repair, warnings, dropped)
        water = _select(_dvl_data(src, dvl_water_topic, w_arr), keep, (w_ns[keep] - t0) / 1e9)
        if water.frame_id != dvl.frame_id:
            warnings.append(
                f"{dvl_water_topic} is in frame {water.frame_id}, {dvl_topic} in {dvl.frame_id}: its "
                f"velocity taken in {dvl.frame_id}"
            )
        dvl = merge_pings(dvl, as_water_track(water))

    truth = None
    if has_truth:
        od = streams[truth_topic].array()
        ns = stamps_ns(od)
        keep = check_stamps(path, truth_topic, ns, t0, None, repair, warnings, dropped)
        q = od["orientation"].astype(float)[keep]
        n_v = (
            Rotation.from_quat(q).apply(od["linear"].astype(float)[keep])
            if keep.any()
            else np.zeros((0, 3))
        )
        n_p, t_truth = od["position"].astype(float)[keep], (ns[keep] - t0) / 1e9
        truth = TruthData(
            t_truth,
            n_p,
            q,
            n_v,
            od["angular"].astype(float)[keep],
            truth_current(meta, t_truth, n_p),
        )

    mounting = Mounting()
    if tf_topic not in src.topics:
        warnings.append(
            f"no {tf_topic} in the log: identity mounting assumed (IMU and DVL frames = base_link)"
        )
    else:
        tfs = decode_tf(path, tf_topic, raw[tf_topic])
        for frame, attrs in (
            (imu_data.frame_id, ("b_R_imu", "b_p_imu")),
            (dvl.frame_id, ("b_R_d0", "b_p_dvl")),
        ):
            if (pose := to_base(tfs, frame)) is None:
                warnings.append(
                    f"{tf_topic} has no transform base_link -> {frame}: identity assumed"
                )
            else:
                setattr(mounting, attrs[0], pose[0])
                setattr(mounting, attrs[1], pose[1])

    dvl.noise_free = (
        meta.get("white_noise") is False
    )  # a simulation without noise (DvlData.noise_free)
    depth = None
    if depth_topic:
        depth = _depth_data(
            src,
            depth_topic,
            raw[depth_topic],
            t0,
            repair,
            warnings,
            dropped,
            depth_z_down,
            meta.get("origin"),
        )
        if (
            tf_topic in src.topics
            and (pose := to_base(decode_tf(path, tf_topic, raw[tf_topic]), depth.frame_id))
            is not None
        ):
            depth.b_p_sensor = pose[1]
    gnss = None
    if gnss_topic:
        gnss = read_gnss(src, gnss_topic, raw[gnss_topic], t0, repair, warnings, dropped)
        if (
            tf_topic in src.topics
            and (pose := to_base(decode_tf(path, tf_topic, raw[tf_topic]), gnss.frame_id))
            is not None
        ):
            gnss.b_p_antenna = pose[1]
    attitude = read_attitude(
        src,
        attitude_topic,
        imu_topic,
        raw,
        imu_attitude,
        t0,
        mounting,
        repair,
        warnings,
        dropped,
        attitude_frame,
    )
    gaps: dict[str, dict[str, Any]] = {}
    for topic, t in ((imu_topic, imu_logged_t), (dvl_topic, dvl.t)) + (
        ((truth_topic, truth.t),) if truth else ()
    ):
        if (gap := stamp_gaps(t)) is not None:
            gaps[topic] = gap
            warnings.append(gap_warning(topic, gap))
    losses: dict[str, Any] = {"repair": dropped, "gaps": gaps}
    if clock:
        losses["clock_steps"] = {imu_topic: clock}
    if saturation:
        losses["saturation"] = {imu_topic: saturation}
    if salvage:
        losses["salvage"] = salvage_losses(src, t0)
        warnings.append(salvage_report(losses["salvage"], src.path))
    losses["messages_lost"] = _messages_lost(losses)
    meta["reader_warnings"] = warnings
    meta["reader_losses"] = losses
    typed = typed_fields(meta, str(path))
    if typed.get("origin") is None and gnss is not None:
        typed["origin"] = first_fix_origin(gnss)
        if typed["origin"] is not None:
            warnings.append(
                f"map origin from the first good GNSS fix on {gnss_topic} (t = "
                f"{first_fix_time(gnss):.1f} s)"
            )
    return LogData(
        imu_data,
        dvl,
        mounting,
        truth,
        t0,
        meta,
        str(path),
        **typed,
        depth=depth,
        gnss=gnss,
        attitude=attitude,
    )


def _depth_data(
    src: Source,
    topic: str,
    bodies: Any,
    t0: int,
    repair: bool,
    warnings: list[str],
    dropped: dict[str, dict[str, int]],
    z_down: bool,
    origin: Any,
) -> DepthData:
    """DepthData from a FluidPressure, PoseWithCovarianceStamped or Odometry topic (read_log's doc)."""
    type_name = _type(src, topic)
    arr = decode(src.path, topic, type_name, bodies)
    ns = stamps_ns(arr)
    frame_id = first_string(arr) or "pressure_link"
    if type_name == PRESSURE_TYPE:
        p, var = pressure_from_messages(arr)
        keep = check_stamps(src.path, topic, ns, t0, ~np.isfinite(p), repair, warnings, dropped)
        p, var = p[keep], var[keep]
        lat_deg = (
            float(origin["lat_deg"]) if isinstance(origin, dict) and "lat_deg" in origin else 45.0
        )
        d, dd_dp = pressure_to_depth(p, float(np.radians(lat_deg)))
        return DepthData((ns[keep] - t0) / 1e9, d, var * dd_dp**2, p, var, frame_id)
    z = arr["position"].astype(float)[:, 2]
    cov = arr["covariance" if type_name == POSE_COV_TYPE else "pose_covariance"].astype(float)[
        :, 14
    ]
    keep = check_stamps(src.path, topic, ns, t0, ~np.isfinite(z), repair, warnings, dropped)
    d = z[keep] if z_down else -z[keep]
    return DepthData(
        (ns[keep] - t0) / 1e9, d, np.where(cov[keep] > 0, cov[keep], np.nan), frame_id=frame_id
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
