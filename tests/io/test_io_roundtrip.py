"""write_log -> read_log round trip, the file's structure (profile, encodings, zstd chunks, QoS,
metadata, CRCs), atomic writing and the generic McapLogWriter."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.rosbag2.metadata import parse_qos

from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.log_metadata import metadata_record
from gtsam_dvl.io.mcap import container as mcap_container
from gtsam_dvl.io.reader import read_log, read_odometry, read_topic
from gtsam_dvl.io.ros2 import messages
from gtsam_dvl.io.writer import UNMEASURED_VARIANCE, McapLogWriter, write_log
from tests.support.synthetic_log import T0_NS, make_log


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[LogData, Path]:
    log = make_log(60.0)
    path = tmp_path_factory.mktemp("rt") / "log.mcap"
    write_log(path, log, config={"solver": {"lag_s": 30}})
    return log, path


def ns(t: np.ndarray, t0: int) -> np.ndarray:
    return t0 + np.rint(np.asarray(t) * 1e9).astype(np.int64)


def test_round_trip_is_exact(written: tuple[LogData, Path]) -> None:
    log, path = written
    got = read_log(path)
    assert got.t0_ns == T0_NS  # first IMU stamp (t0 + 0.01 s) rounded down to the second
    assert got.metadata["reader_warnings"] == []
    for a, b in ((got.imu.t, log.imu.t), (got.dvl.t, log.dvl.t), (got.truth.t, log.truth.t)):
        # stamps to the nanosecond
        np.testing.assert_array_equal(ns(a, got.t0_ns), ns(b, log.t0_ns))
    np.testing.assert_array_equal(got.imu.b_omega, log.imu.b_omega)
    np.testing.assert_array_equal(got.imu.b_f, log.imu.b_f)
    assert got.imu.frame_id == "imu_link" and got.dvl.frame_id == "dvl_link"
    np.testing.assert_array_equal(got.dvl.d_v, log.dvl.d_v)  # NaN where invalid, in the same places
    np.testing.assert_array_equal(got.dvl.d_cov, log.dvl.d_cov)
    np.testing.assert_array_equal(got.dvl.valid, log.dvl.valid)
    b, wb = got.dvl.beams, log.dvl.beams
    np.testing.assert_array_equal(b.d_u, wb.d_u)
    np.testing.assert_array_equal(b.range, wb.range)
    np.testing.assert_array_equal(b.valid, wb.valid)
    # float32 in marine_acoustic_msgs/Dvl
    np.testing.assert_array_equal(b.v, wb.v.astype(np.float32))
    tr, wt = got.truth, log.truth
    np.testing.assert_array_equal(tr.n_p, wt.n_p)
    np.testing.assert_array_equal(tr.n_q_b, wt.n_q_b)
    np.testing.assert_array_equal(tr.b_omega, wt.b_omega)
    np.testing.assert_allclose(tr.n_v, wt.n_v, rtol=0, atol=1e-13)  # through n_R_b^T and back
    m, wm = got.mounting, log.mounting
    np.testing.assert_allclose(m.b_R_d0, wm.b_R_d0, atol=1e-15)
    np.testing.assert_array_equal(m.b_p_dvl, wm.b_p_dvl)
    np.testing.assert_allclose(m.b_R_imu, np.eye(3), atol=1e-15)
    for key, value in log.metadata.items():
        assert got.metadata[key] == value
    assert got.metadata["config"] == {"solver": {"lag_s": 30}}
    assert got.true_calibration is not None and got.true_calibration.scale == 0.9998
    # the typed contract: what the estimators and evaluation read, decoded to the values simulated
    assert got.origin == log.origin and log.origin is not None and log.origin.lat_deg == 30.0
    assert got.metadata["truth"]["dvl"]["scale"] == 0.9998  # and the record a person reads
    assert got.true_calibration == log.true_calibration
    assert got.true_imu_bias == log.true_imu_bias and log.true_imu_bias is not None
    assert got.segments == log.segments and len(log.segments) == 3


def test_read_twist_topic_instead_of_dvl_data(written: tuple[LogData, Path]) -> None:
    log, path = written
    got = read_log(path, dvl_topic="/dvl/twist")
    ok = log.dvl.valid
    np.testing.assert_array_equal(got.dvl.t, np.rint(log.dvl.t[ok] * 1e9) / 1e9)
    np.testing.assert_array_equal(got.dvl.d_v, log.dvl.d_v[ok])
    np.testing.assert_array_equal(got.dvl.d_cov, log.dvl.d_cov[ok])
    assert got.dvl.beams is None


def test_file_structure(written: tuple[LogData, Path]) -> None:
    log, path = written
    with path.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        assert summary.chunk_indexes and {c.compression for c in summary.chunk_indexes} == {"zstd"}
        topics = {c.topic: c for c in summary.channels.values()}
        assert set(topics) == {
            "/tf_static",
            "/imu/data_raw",
            "/dvl/twist",
            "/dvl/data",
            "/ground_truth/odometry",
        }
        for topic, ch in topics.items():
            (qos,) = parse_qos(ch.metadata["offered_qos_profiles"])
            assert qos.reliability.name == "RELIABLE"
            assert qos.durability.name == (
                "TRANSIENT_LOCAL" if topic == "/tf_static" else "VOLATILE"
            )
        schema = summary.schemas[topics["/imu/data_raw"].schema_id]
        assert schema.name == "sensor_msgs/msg/Imu"
        assert ("\n" + "=" * 80 + "\nMSG: std_msgs/msg/Header\n") in schema.data.decode()
        counts = summary.statistics.channel_message_counts
        assert counts[topics["/imu/data_raw"].id] == len(log.imu)
        assert counts[topics["/dvl/data"].id] == len(log.dvl)
        assert counts[topics["/dvl/twist"].id] == int(log.dvl.valid.sum())
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta["gtsam_dvl"]["scenario"] == "unit-test" and meta["gtsam_dvl"]["seed"] == "0"
        assert json.loads(meta["gtsam_dvl"]["truth"]) == metadata_record(log)["truth"]
        assert json.loads(meta["gtsam_dvl"]["sensors"]) == log.metadata["sensors"]
        (att,) = list(reader.iter_attachments())
        assert att.name == "config.json" and att.media_type == "application/json"
        assert json.loads(att.data)["scenario"] == "unit-test"
        first = {}
        seqs: dict[str, list[int]] = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            # header.stamp after the CDR header (and count)
            at = 8 if channel.topic == "/tf_static" else 4
            sec, nsec = struct.unpack_from("<iI", message.data, at)
            assert message.log_time == message.publish_time == sec * 10**9 + nsec
            first.setdefault(channel.topic, message.log_time)
            seqs.setdefault(channel.topic, []).append(message.sequence)
        assert first["/tf_static"] == min(first.values())
        assert all(s == list(range(len(s))) for s in seqs.values())
    data = path.read_bytes()  # the CRCs the reader above does not check
    footer = len(data) - 8 - 29
    summary_start, offsets_start, summary_crc = struct.unpack_from("<QQI", data, footer + 9)
    assert zlib.crc32(data[summary_start : footer + 25]) == summary_crc
    data_end = summary_start - 13
    assert data[data_end] == mcap_container.OP_DATA_END
    assert struct.unpack_from("<I", data, data_end + 9)[0] == zlib.crc32(data[:data_end])


def test_imu_and_twist_covariances(written: tuple[LogData, Path]) -> None:
    log, path = written
    ((_, imu),) = read_topic(path, "/imu/data_raw")[:1]
    rate_var = np.square(log.metadata["sensors"]["imu"]["gyro_noise_density"]) * 100.0
    np.testing.assert_allclose(
        np.asarray(imu.angular_velocity_covariance)[[0, 4, 8]], rate_var, rtol=1e-6
    )
    assert imu.orientation_covariance[0] == -1.0
    ((_, tw),) = read_topic(path, "/dvl/twist")[:1]
    cov = np.asarray(tw.twist.covariance).reshape(6, 6)
    np.testing.assert_array_equal(np.diag(cov)[3:], UNMEASURED_VARIANCE)
    np.testing.assert_array_equal(cov[:3, 3:], 0.0)


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "log.mcap"
    path.write_bytes(b"old")

    def boom(self: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(mcap_container.McapContainer, "finish", boom)
    with pytest.raises(KeyboardInterrupt):
        write_log(path, make_log(5.0))
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["log.mcap"]  # no temporary file left behind


def test_generic_writer_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    k = 50
    t = np.arange(k) * 0.1
    q = rng.normal(size=(k, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p, v, w, cov = (
        rng.normal(size=(k, 3)),
        rng.normal(size=(k, 3)),
        rng.normal(size=(k, 3)),
        rng.normal(size=(k, 6, 6)),
    )
    path = tmp_path / "result.mcap"
    with McapLogWriter(path, t0_ns=T0_NS) as out:
        odometry = messages.odometry(out.stamps_ns(t), p, q, v, w, cov, 2 * cov)
        out.add_structured("/gtsam_dvl/odometry", messages.ODOMETRY, odometry)
        out.add_path("/gtsam_dvl/path", t, p, q)
        bias = messages.six_dof_with_covariance(
            messages.ACCEL_COV, out.stamps_ns(t), v, w, cov, "base_link"
        )
        out.add_structured("/gtsam_dvl/imu_bias", messages.ACCEL_COV, bias)
        out.add_pose_with_covariance("/gtsam_dvl/pose", t, p, q, cov, "map")
        out.add_vector3_stamped("/gtsam_dvl/misalignment_deg", t, v, "base_link")
        out.add_scalar_with_variance("/gtsam_dvl/scale", t, w[:, 0], w[:, 1] ** 2, "dvl_link")
        out.add_metadata("run", {"a": "b"})
        out.add_attachment("effective_config.json", b"{}", "application/json")
    got = read_odometry(path, "/gtsam_dvl/odometry")
    np.testing.assert_array_equal(ns(got[0], T0_NS), ns(t, T0_NS))
    for a, b in zip(got[1:], (p, q, v, w, cov, 2 * cov), strict=True):
        np.testing.assert_array_equal(a, b)
    ((_, path_msg),) = read_topic(path, "/gtsam_dvl/path")
    assert len(path_msg.poses) == k and path_msg.header.frame_id == "map"
    assert (
        path_msg.poses[7].pose.position.y == p[7, 1]
        and path_msg.poses[7].pose.orientation.w == q[7, 3]
    )
    bias = read_topic(path, "/gtsam_dvl/imu_bias")
    assert (
        bias[3][1].accel.accel.linear.z == v[3, 2] and bias[3][1].accel.accel.angular.x == w[3, 0]
    )
    assert list(bias[3][1].accel.covariance) == cov[3].ravel().tolist()
    pose = read_topic(path, "/gtsam_dvl/pose")
    assert pose[-1][1].pose.pose.position.x == p[-1, 0]
    vec = read_topic(path, "/gtsam_dvl/misalignment_deg")
    assert vec[5][1].vector.y == v[5, 1] and vec[5][0] == T0_NS + 500_000_000
    scale = read_topic(path, "/gtsam_dvl/scale")
    assert scale[9][1].temperature == w[9, 0] and scale[9][1].variance == w[9, 1] ** 2
