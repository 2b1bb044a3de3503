"""Other tools read our logs, and we read theirs.

rosbags (0.11) opens only rosbag2 bag directories, not a bare .mcap: ``make_bag_dir`` puts the .mcap next
to the metadata.yaml rosbag2 would write. Both rosbags and mcap_ros2 decode through the ros2msg schemas
stored in the file, including marine_acoustic_msgs/msg/Dvl, which neither ships.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.ros2.msgdefs import message_text
from gtsam_dvl.io.storage.bagdir import make_bag_dir
from gtsam_dvl.io.writer import write_log
from tests.support.synthetic_log import T0_NS, make_log


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[LogData, Path]:
    log = make_log(20.0, seed=5)
    path = tmp_path_factory.mktemp("interop") / "log.mcap"
    write_log(path, log)
    return log, path


def _vec(v: Any, names: str = "xyz") -> list[float]:
    return [getattr(v, c) for c in names]


def check_decoded(msgs: dict[str, list[tuple[int, Any]]], log: LogData) -> None:
    """Every topic decoded by another library holds the values written."""
    stamp = {
        k: np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in v])
        for k, v in msgs.items()
        if k != "/tf_static"
    }
    for k in stamp:
        np.testing.assert_array_equal(stamp[k], [t for t, _ in msgs[k]])  # log time = header stamp
    imu = [m for _, m in msgs["/imu/data_raw"]]
    np.testing.assert_array_equal(
        stamp["/imu/data_raw"], T0_NS + np.rint(log.imu.t * 1e9).astype(np.int64)
    )
    np.testing.assert_array_equal([_vec(m.angular_velocity) for m in imu], log.imu.b_omega)
    np.testing.assert_array_equal([_vec(m.linear_acceleration) for m in imu], log.imu.b_f)
    assert {m.header.frame_id for m in imu} == {"imu_link"}

    ok = log.dvl.valid
    twist = [m for _, m in msgs["/dvl/twist"]]
    np.testing.assert_array_equal([_vec(m.twist.twist.linear) for m in twist], log.dvl.d_v[ok])
    np.testing.assert_array_equal(
        [np.reshape(m.twist.covariance, (6, 6))[:3, :3] for m in twist], log.dvl.d_cov[ok]
    )

    dvl = [m for _, m in msgs["/dvl/data"]]
    b = log.dvl.beams
    assert b is not None
    np.testing.assert_array_equal([_vec(m.velocity) for m in dvl], log.dvl.d_v)
    np.testing.assert_array_equal(
        [np.reshape(m.velocity_covar, (3, 3)) for m in dvl], log.dvl.d_cov
    )
    np.testing.assert_array_equal([[_vec(u) for u in m.beam_unit_vec] for m in dvl], b.d_u)
    np.testing.assert_array_equal([list(m.range) for m in dvl], b.range)
    np.testing.assert_array_equal([list(m.beam_velocity) for m in dvl], b.v.astype(np.float32))
    np.testing.assert_array_equal([np.asarray(m.beam_quality) > 0 for m in dvl], b.valid)
    assert [m.num_good_beams for m in dvl] == b.valid.sum(axis=1).tolist()
    assert {(m.velocity_mode, m.dvl_type, m.beam_velocities_valid) for m in dvl} == {(1, 0, True)}

    assert log.truth is not None
    odo = [m for _, m in msgs["/ground_truth/odometry"]]
    assert {(m.header.frame_id, m.child_frame_id) for m in odo} == {("map", "base_link")}
    np.testing.assert_array_equal([_vec(m.pose.pose.position) for m in odo], log.truth.n_p)
    np.testing.assert_array_equal(
        [_vec(m.pose.pose.orientation, "xyzw") for m in odo], log.truth.n_q_b
    )
    np.testing.assert_array_equal([_vec(m.twist.twist.angular) for m in odo], log.truth.b_omega)
    n_v = Rotation.from_quat(log.truth.n_q_b).apply([_vec(m.twist.twist.linear) for m in odo])
    np.testing.assert_allclose(n_v, log.truth.n_v, atol=1e-13)

    ((_, tf),) = msgs["/tf_static"]
    frames = {t.child_frame_id: t for t in tf.transforms}
    assert {t.header.frame_id for t in tf.transforms} == {"base_link"}
    dvl_tf = frames["dvl_link"].transform
    np.testing.assert_array_equal(_vec(dvl_tf.translation), log.mounting.b_p_dvl)
    R = Rotation.from_quat(_vec(dvl_tf.rotation, "xyzw")).as_matrix()
    np.testing.assert_allclose(R, log.mounting.b_R_d0, atol=1e-15)


def test_rosbags_reads_our_log(written: tuple[LogData, Path], tmp_path: Path) -> None:
    log, path = written
    bag = make_bag_dir(path, tmp_path / "bag")
    msgs: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([bag]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections}["/imu/data_raw"] == len(log.imu)
        for conn, t, raw in reader.messages():
            msgs.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    check_decoded(msgs, log)


def test_mcap_ros2_reads_our_log(written: tuple[LogData, Path]) -> None:
    log, path = written
    msgs: dict[str, list[tuple[int, Any]]] = {}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            msgs.setdefault(channel.topic, []).append((message.log_time, decoded))
    check_decoded(msgs, log)


def _write_foreign_bag(folder: Path, plugin: StoragePlugin) -> None:
    """A bag as another tool would record it: own topic names, frames, a TwistStamped and a
    TwistWithCovarianceStamped DVL, a marine_acoustic_msgs/Dvl with NaN bad beams, no /tf_static."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(
        get_types_from_msg(
            message_text("marine_acoustic_msgs/msg/Dvl"), "marine_acoustic_msgs/msg/Dvl"
        )
    )
    T = ts.types
    V3, Twist = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Twist"]

    def header(ns: int, frame: str) -> Any:
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
            frame_id=frame,
        )

    with Writer(folder, version=9, storage_plugin=plugin) as w:
        ci = w.add_connection("/sensors/imu", "sensor_msgs/msg/Imu", typestore=ts)
        cd = w.add_connection("/sensors/dvl_twist", "geometry_msgs/msg/TwistStamped", typestore=ts)
        cc = w.add_connection(
            "/sensors/dvl_cov", "geometry_msgs/msg/TwistWithCovarianceStamped", typestore=ts
        )
        cm = w.add_connection("/sensors/dvl", "marine_acoustic_msgs/msg/Dvl", typestore=ts)
        for i in range(500):
            ns = 1_600_000_000_250_000_000 + i * 5_000_000
            imu = T["sensor_msgs/msg/Imu"](
                header=header(ns, "xsens"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=V3(x=0.01, y=-0.02, z=float(i)),
                angular_velocity_covariance=np.zeros(9),
                linear_acceleration=V3(x=0.0, y=0.0, z=9.8),
                linear_acceleration_covariance=np.zeros(9),
            )
            w.write(ci, ns, ts.serialize_cdr(imu, "sensor_msgs/msg/Imu"))
            if i % 50:
                continue
            tw = Twist(linear=V3(x=1.0, y=2.0, z=float(i)), angular=V3(x=0.0, y=0.0, z=0.0))
            w.write(
                cd,
                ns,
                ts.serialize_cdr(
                    T["geometry_msgs/msg/TwistStamped"](header=header(ns, "dvl"), twist=tw),
                    "geometry_msgs/msg/TwistStamped",
                ),
            )
            cov = np.diag([1e-4, 2e-4, 3e-4, -1.0, -1.0, -1.0]).ravel()
            twc = T["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=cov)
            w.write(
                cc,
                ns,
                ts.serialize_cdr(
                    T["geometry_msgs/msg/TwistWithCovarianceStamped"](
                        header=header(ns, "dvl"), twist=twc
                    ),
                    "geometry_msgs/msg/TwistWithCovarianceStamped",
                ),
            )
            dvl = T["marine_acoustic_msgs/msg/Dvl"](
                # ping 150 in water-track mode (velocity through the water, not over ground)
                header=header(ns, "teledyne"),
                velocity_mode=2 if i == 150 else 1,
                dvl_type=1,
                velocity=V3(x=1.0, y=2.0, z=float(i)),
                velocity_covar=np.full(9, -1.0),
                altitude=10.0,
                course_gnd=0.0,
                speed_gnd=0.0,
                num_good_beams=3,
                sound_speed=1500.0,
                beam_ranges_valid=True,
                beam_velocities_valid=True,
                beam_unit_vec=[V3(x=0.5, y=0.0, z=0.866)] * 4,
                range=np.full(4, 11.0),
                range_covar=np.zeros(4, np.float32),
                beam_quality=np.zeros(4, np.float32),
                beam_velocity=np.array([0.5, np.nan, 0.25, 1.0], np.float32),
                beam_velocity_covar=np.full(4, -1.0, np.float32),
            )
            w.write(cm, ns, ts.serialize_cdr(dvl, "marine_acoustic_msgs/msg/Dvl"))


@pytest.mark.parametrize("plugin", [StoragePlugin.SQLITE3, StoragePlugin.MCAP])
def test_read_rosbags_written_bags(tmp_path: Path, plugin: StoragePlugin) -> None:
    bag = tmp_path / "bag"
    _write_foreign_bag(bag, plugin)
    storage = next(p for p in bag.iterdir() if p.suffix in (".db3", ".mcap"))
    for source in (bag, storage):  # the bag directory and its bare storage file
        got = read_log(source, imu_topic="/sensors/imu", dvl_topic="/sensors/dvl_twist")
        assert got.t0_ns == 1_600_000_000_000_000_000
        np.testing.assert_allclose(got.imu.t[:2], [0.25, 0.255], rtol=0, atol=1e-12)
        assert (
            len(got.imu) == 500 and got.imu.frame_id == "xsens" and got.imu.b_omega[-1, 2] == 499.0
        )
        assert len(got.dvl) == 10 and got.dvl.d_v[3].tolist() == [1.0, 2.0, 150.0]
        # TwistStamped: covariance unknown
        assert np.isnan(got.dvl.d_cov).all() and got.dvl.beams is None
        assert any("identity mounting" in w for w in got.metadata["reader_warnings"])
        np.testing.assert_array_equal(got.mounting.b_R_d0, np.eye(3))
    got = read_log(bag, imu_topic="/sensors/imu", dvl_topic="/sensors/dvl_cov")
    np.testing.assert_array_equal(got.dvl.d_cov[0], np.diag([1e-4, 2e-4, 3e-4]))
    got = read_log(bag, imu_topic="/sensors/imu", dvl_topic="/sensors/dvl")
    # velocity_covar -1: unknown
    assert got.dvl.frame_id == "teledyne" and np.isnan(got.dvl.d_cov).all()
    # the message's own velocity mode is honoured: the water-track ping is not a bottom-track velocity
    assert got.dvl.valid.tolist() == [j != 3 for j in range(10)]
    assert got.dvl.beams is not None and not got.dvl.beams.valid[3].any()
    assert got.dvl.beams is not None
    # NaN beam = bad
    np.testing.assert_array_equal(got.dvl.beams.valid[0], [True, False, True, True])
    np.testing.assert_array_equal(got.dvl.beams.v[0], [0.5, np.nan, 0.25, 1.0])


def test_read_bag_dir_made_from_our_log(written: tuple[LogData, Path], tmp_path: Path) -> None:
    log, path = written
    seen: list[float] = []
    got = read_log(make_bag_dir(path, tmp_path / "bag"), progress=seen.append)
    np.testing.assert_array_equal(got.imu.b_f, log.imu.b_f)
    assert seen and seen == sorted(seen) and 0 < seen[-1] <= 1.0


@pytest.mark.parametrize("compression", ["zstd", "none"])
def test_read_stock_mcap_writer_with_varying_frames(tmp_path: Path, compression: str) -> None:
    """mcap_ros2's own writer (small chunks; schema/channel records outside chunks), with an IMU
    frame_id that changes length mid-log, which forces the per-message decoding path."""
    from mcap.writer import CompressionType
    from mcap_ros2.writer import Writer as Ros2Writer

    from gtsam_dvl.io.ros2.msgdefs import full_definition

    path = tmp_path / "stock.mcap"
    with path.open("wb") as f:
        w = Ros2Writer(f, chunk_size=4096, compression=CompressionType[compression.upper()])
        imu_s = w.register_msgdef("sensor_msgs/msg/Imu", full_definition("sensor_msgs/msg/Imu"))
        tw_s = w.register_msgdef(
            "geometry_msgs/msg/TwistStamped", full_definition("geometry_msgs/msg/TwistStamped")
        )
        vec = {"x": 0.0, "y": 0.0, "z": 0.0}
        for i in range(400):
            ns = 1_650_000_000_000_000_000 + 7 + i * 10_000_000
            stamp = {"sec": ns // 10**9, "nanosec": ns % 10**9}
            imu = {
                "header": {"stamp": stamp, "frame_id": "imu" if i < 200 else "imu_link_2"},
                "orientation": {**vec, "w": 1.0},
                "orientation_covariance": [0.0] * 9,
                "angular_velocity": {**vec, "z": i * 0.5},
                "angular_velocity_covariance": [0.0] * 9,
                "linear_acceleration": {**vec, "z": 9.81},
                "linear_acceleration_covariance": [0.0] * 9,
            }
            w.write_message("/imu", imu_s, imu, ns, ns, i)
            if i % 100 == 0:
                tw = {
                    "header": {"stamp": stamp, "frame_id": "dvl"},
                    "twist": {"linear": {**vec, "x": 1.5}, "angular": vec},
                }
                w.write_message("/dvl", tw_s, tw, ns, ns, i // 100)
        w.finish()
    got = read_log(path, imu_topic="/imu", dvl_topic="/dvl")
    assert len(got.imu) == 400 and got.imu.frame_id == "imu"
    np.testing.assert_array_equal(got.imu.b_omega[:, 2], np.arange(400) * 0.5)
    np.testing.assert_array_equal(
        np.rint(got.imu.t * 1e9).astype(np.int64), 7 + np.arange(400) * 10_000_000
    )
    assert got.dvl.d_v.tolist() == [[1.5, 0.0, 0.0]] * 4
