"""Damaged and unusual logs: one-line GtsamDvlError messages, --salvage, --repair, missing topics."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.ros2 import cdr, messages
from gtsam_dvl.io.writer import McapLogWriter, write_log
from tests.support.synthetic_log import T0_NS, make_log


@pytest.fixture(scope="module")
def long_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[LogData, bytes]:
    """300 s: about ten 1 MiB chunks, enough to lose some and keep others."""
    log = make_log(300.0, seed=2)
    path = tmp_path_factory.mktemp("err") / "long.mcap"
    write_log(path, log)
    return log, path.read_bytes()


def with_byte_flipped(data: bytes, at: int, path: Path) -> Path:
    """The file path holding data with every bit of the byte at offset at inverted."""
    damaged = bytearray(data)
    damaged[at] ^= 0xFF
    path.write_bytes(bytes(damaged))
    return path


def one_line_error(path: Path, **kw: object) -> str:
    with pytest.raises(GtsamDvlError) as e:
        read_log(path, **kw)  # type: ignore[arg-type]
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg
    return msg


def test_truncated_file_and_salvage(long_log: tuple[LogData, bytes], tmp_path: Path) -> None:
    log, data = long_log
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: len(data) * 6 // 10])
    msg = one_line_error(path)
    assert f"truncated at byte {len(data) * 6 // 10} (footer missing)" in msg and "--salvage" in msg

    got = read_log(path, salvage=True)
    n = len(got.imu)
    assert 0.4 * len(log.imu) < n < 0.65 * len(log.imu)
    np.testing.assert_array_equal(got.imu.b_omega, log.imu.b_omega[:n])  # the kept prefix is intact
    np.testing.assert_array_equal(got.dvl.d_v, log.dvl.d_v[: len(got.dvl)])
    (report,) = [w for w in got.metadata["reader_warnings"] if w.startswith("salvage")]
    kept, total, lost, at_least = map(
        int,
        re.search(
            r"kept (\d+) of (\d+) chunks; lost (\d+) chunk\(s\) "
            r"with at least (\d+) message",
            report,
        ).groups(),
    )
    assert lost == 1 and kept == total - 1 and at_least > 0
    start, end = map(float, re.search(r"log time ([\d.]+) s to ([\d.]+) s", report).groups())
    assert start == pytest.approx(got.imu.t[-1] + 0.01, abs=0.011) and end > start


def test_corrupt_chunk_and_salvage(long_log: tuple[LogData, bytes], tmp_path: Path) -> None:
    log, data = long_log
    path = with_byte_flipped(data, len(data) // 2, tmp_path / "bad.mcap")
    msg = one_line_error(path)
    assert "corrupt chunk" in msg and "--salvage" in msg

    got = read_log(path, salvage=True)
    (report,) = [w for w in got.metadata["reader_warnings"] if w.startswith("salvage")]
    lost_msgs = int(re.search(r"lost 1 chunk\(s\) with (\d+) message", report).group(1))
    # +1: /tf_static
    expected = len(log.imu) + len(log.dvl) + int(log.dvl.valid.sum()) + len(log.truth) + 1
    found = len(got.imu) + len(got.dvl) + len(got.truth)
    twist = read_log(path, salvage=True, dvl_topic="/dvl/twist")
    # exact: from the chunk's message indexes
    assert found + len(twist.dvl) + 1 + lost_msgs == expected
    gap = np.diff(got.imu.t).max()
    start, end = map(float, re.search(r"log time ([\d.]+) s to ([\d.]+) s", report).groups())
    assert gap == pytest.approx(end - start + 0.02, abs=0.011)


def test_intact_file_with_salvage_reports_nothing_lost(
    long_log: tuple[LogData, bytes], tmp_path: Path
) -> None:
    path = tmp_path / "ok.mcap"
    path.write_bytes(long_log[1])
    got = read_log(path, salvage=True)
    assert any("nothing lost" in w for w in got.metadata["reader_warnings"])
    assert len(got.imu) == len(long_log[0].imu)


def test_missing_topics_list_what_is_there(tmp_path: Path) -> None:
    path = tmp_path / "log.mcap"
    write_log(path, make_log(3.0))
    msg = one_line_error(path, imu_topic="/imu")
    assert (
        "no IMU topic /imu" in msg
        and "/imu/data_raw [sensor_msgs/msg/Imu]" in msg
        and "/dvl/data" in msg
    )
    msg = one_line_error(path, dvl_topic="/dvl/velocity")
    assert (
        "no DVL topic /dvl/velocity" in msg
        and "/dvl/twist [geometry_msgs/msg/TwistWithCovarianceStamped]" in msg
    )
    msg = one_line_error(path, dvl_topic="/ground_truth/odometry")
    assert "nav_msgs/msg/Odometry" in msg


def test_nan_imu_and_repair(tmp_path: Path) -> None:
    log = make_log(3.0)
    log.imu.b_f[123, 1] = np.nan
    path = tmp_path / "nan.mcap"
    write_log(path, log)
    msg = one_line_error(path)
    assert "/imu/data_raw: NaN in message 123 (t = 1.240000 s)" in msg and "--repair" in msg
    got = read_log(path, repair=True)
    assert len(got.imu) == len(log.imu) - 1 and np.isfinite(got.imu.b_f).all()
    assert any("dropped 1 message(s): 1 with NaN" in w for w in got.metadata["reader_warnings"])


def test_duplicate_stamps_and_repair(tmp_path: Path) -> None:
    log = make_log(3.0)
    log.imu.t[50] = log.imu.t[49]
    path = tmp_path / "dup.mcap"
    write_log(path, log)
    assert "/imu/data_raw: duplicate stamp at message 50 (t = 0.500000000 s)" in one_line_error(
        path
    )
    got = read_log(path, repair=True)
    assert len(got.imu) == len(log.imu) - 1 and (np.diff(got.imu.t) > 0).all()


def test_backwards_time_and_repair(tmp_path: Path) -> None:
    """Header stamps going back while log times (file order) go forward, as a driver's clock jump does."""
    log = make_log(3.0, truth=False)
    t = log.imu.t.copy()
    t[200] = 1.5  # 0.51 s back
    path = tmp_path / "back.mcap"
    with McapLogWriter(path, t0_ns=T0_NS) as w:
        arr = cdr.new_messages(cdr.IMU, {"frame_id": "imu_link"}, len(t))
        cdr.set_stamps(arr, w.stamps_ns(t))
        arr["angular_velocity"], arr["linear_acceleration"] = log.imu.b_omega, log.imu.b_f
        w.add_encoded("/imu/data_raw", "sensor_msgs/msg/Imu", w.stamps_ns(log.imu.t), arr)
        twist = messages.six_dof_with_covariance(
            messages.TWIST_COV,
            w.stamps_ns(log.dvl.t[log.dvl.valid]),
            log.dvl.d_v[log.dvl.valid],
            None,
            None,
            "dvl_link",
        )
        w.add_structured("/dvl/twist", messages.TWIST_COV, twist)
    msg = one_line_error(path)
    assert (
        "/imu/data_raw: time goes backwards at message 200 (t = 1.500000000 s after 2.000000000 s)"
        in msg
    )
    got = read_log(path, repair=True)
    assert len(got.imu) == len(t) - 1 and (np.diff(got.imu.t) > 0).all()
    assert any("1 going back in time" in w for w in got.metadata["reader_warnings"])
    # No /tf_static here: identity mounting, said in the warnings; zero twist covariance = unknown.
    assert any("identity mounting" in w for w in got.metadata["reader_warnings"])
    assert np.isnan(got.dvl.d_cov).all()


def test_not_a_log(tmp_path: Path) -> None:
    assert "no such file" in one_line_error(tmp_path / "nope.mcap")
    (tmp_path / "x.mcap").write_bytes(b"hello world, not a log at all")
    assert "neither an MCAP" in one_line_error(tmp_path / "x.mcap")
    (tmp_path / "empty").mkdir()
    assert "not a rosbag2 bag" in one_line_error(tmp_path / "empty")


# ----- what was lost, structured (metadata["reader_losses"]) ----------------------------------------------


def _chunks(data: bytes, tmp_path: Path) -> list[tuple[int, int, int]]:
    """(record start, end of the chunk's data, end log time ns) of each chunk of an intact file."""
    from gtsam_dvl.io.mcap.scan import McapScan, _Chunk

    path = tmp_path / "intact.mcap"
    path.write_bytes(data)
    return [
        (s.pos, s.data.stop, s.end_ns) for s in McapScan(path).segments if isinstance(s, _Chunk)
    ]


@pytest.mark.parametrize(
    "where", ["inside a chunk", "inside the message indexes", "between two chunks"]
)
def test_truncation_is_reported_wherever_the_cut_falls(
    where: str, long_log: tuple[LogData, bytes], tmp_path: Path
) -> None:
    """A file cut short lost the rest of the recording, however little of the cut-off record was there: the
    report says so (not "lost 0 chunk(s)", nor "nothing lost" for a cut between records)."""
    log, data = long_log
    chunks = _chunks(data, tmp_path)
    k = len(chunks) // 2
    pos, stop, end_ns = chunks[k]
    cut = {
        "inside a chunk": (pos + stop) // 2,
        "inside the message indexes": stop + 20,
        "between two chunks": chunks[k + 1][0],
    }[where]
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:cut])
    got = read_log(path, salvage=True)
    losses = got.metadata["reader_losses"]["salvage"]
    (report,) = [w for w in got.metadata["reader_warnings"] if w.startswith("salvage")]
    print(report)
    assert losses["anything_lost"] and "nothing lost" not in report and "lost 0 chunk" not in report
    (truncated,) = losses["truncated"]
    assert truncated["file"] == str(path) and truncated["at_byte"] == cut
    # the end of the last chunk read
    assert truncated["data_end_s"] == pytest.approx(got.imu.t[-1], abs=0.011)
    assert (
        f"the file is cut short at byte {cut} (no footer)" in report
        and "how long it went on" in report
    )
    if where == "inside a chunk":
        assert (
            losses["chunks_lost"] == 1
            and losses["messages_lost"] > 0
            and not losses["messages_lost_exact"]
        )
        assert losses["messages_lost_per_topic"]["/imu/data_raw"] > 0
        assert sum(losses["messages_lost_per_topic"].values()) == losses["messages_lost"]
        assert got.metadata["reader_losses"]["messages_lost"] == losses["messages_lost_per_topic"]
    else:
        assert losses["chunks_lost"] == 0 and f"kept all {losses['chunks_total']} chunks" in report
        assert got.imu.t[-1] == pytest.approx((end_ns - got.t0_ns) / 1e9, abs=0.011)


def test_corrupt_chunk_losses_per_topic_and_gap(
    long_log: tuple[LogData, bytes], tmp_path: Path
) -> None:
    from gtsam_dvl.analysis.health import assess_log_health

    log, data = long_log
    path = with_byte_flipped(data, len(data) // 2, tmp_path / "bad.mcap")
    got = read_log(path, salvage=True)
    losses = got.metadata["reader_losses"]
    salv = losses["salvage"]
    assert salv["chunks_lost"] == 1 and salv["messages_lost_exact"] and salv["truncated"] == []
    per = salv["messages_lost_per_topic"]
    assert per["/imu/data_raw"] == len(log.imu) - len(got.imu)
    assert per["/dvl/data"] == len(log.dvl) - len(got.dvl) and per["/ground_truth/odometry"] == len(
        log.truth
    ) - len(got.truth)
    (span,) = salv["lost_spans_s"]
    gap = losses["gaps"]["/imu/data_raw"]
    assert gap["count"] == 1 and gap["seconds"] == pytest.approx(
        span[1] - span[0] + 0.01, abs=0.011
    )
    assert any(
        w.startswith("/imu/data_raw: 1 gap(s) in the data") for w in got.metadata["reader_warnings"]
    )
    health = assess_log_health(got)
    assert health.status == "degraded"
    assert any(w.startswith("--salvage dropped 1 damaged chunk(s) with ") for w in health.warnings)
    assert health.figures["losses"]["messages_lost"]["/imu/data_raw"] == per["/imu/data_raw"]


def test_repair_losses_are_recorded_by_reason(tmp_path: Path) -> None:
    log = make_log(3.0)
    log.imu.b_f[123, 1] = np.nan
    log.imu.t[50] = log.imu.t[49]
    path = tmp_path / "bad.mcap"
    write_log(path, log)
    got = read_log(path, repair=True)
    losses = got.metadata["reader_losses"]
    assert losses["repair"] == {
        "/imu/data_raw": {
            "dropped": 2,
            "nan": 1,
            "duplicate": 1,
            "backwards": 0,
            "of": len(log.imu),
        }
    }
    assert losses["messages_lost"] == {"/imu/data_raw": 2} and "salvage" not in losses
    assert losses["gaps"] == {}  # two samples missing at 100 Hz is no gap
    clean = tmp_path / "clean.mcap"
    write_log(clean, make_log(3.0))
    assert read_log(clean).metadata["reader_losses"] == {
        "repair": {},
        "gaps": {},
        "messages_lost": {},
    }


def test_gaps_in_an_intact_log(tmp_path: Path) -> None:
    """Stamps that skip 5 s of IMU data: not an error, but recorded and warned."""
    log = make_log(30.0, truth=False)
    keep = (log.imu.t < 10.0) | (log.imu.t >= 15.0)
    log.imu = dataclasses.replace(
        log.imu, t=log.imu.t[keep], b_omega=log.imu.b_omega[keep], b_f=log.imu.b_f[keep]
    )
    path = tmp_path / "gap.mcap"
    write_log(path, log)
    got = read_log(path)
    gap = got.metadata["reader_losses"]["gaps"]["/imu/data_raw"]
    assert gap["count"] == 1 and gap["seconds"] == pytest.approx(5.0, abs=1e-6)
    assert gap["spans_s"] == [[pytest.approx(9.99), pytest.approx(15.0)]]
    assert (
        "/imu/data_raw: 1 gap(s) in the data, 5.0 s missing in all (longest 9.99 s to 15.00 s)"
        in got.metadata["reader_warnings"]
    )


def test_damaged_message_index_falls_back_to_the_intact_chunk(
    long_log: tuple[LogData, bytes], tmp_path: Path
) -> None:
    """A flipped byte in a MessageIndex record (outside the chunks, no CRC) made an offset negative and the
    reader died with an IndexError; the chunk itself is intact (its CRC holds), so its records are walked and
    every message is read exactly."""
    from gtsam_dvl.io.mcap.scan import McapScan

    log, data = long_log
    good = tmp_path / "good.mcap"
    good.write_bytes(data)
    scan = McapScan(good)
    chunk = next(s for s in scan.segments if not isinstance(s, list) and s.index)
    import struct

    # the MessageIndex record with the most entries (the IMU's): opcode, length, channel, entries length, entries
    pos = max(chunk.index.values(), key=lambda q: struct.unpack_from("<I", data, q + 11)[0])
    assert struct.unpack_from("<I", data, pos + 11)[0] >= 32
    # the top byte of the second entry's offset
    path = with_byte_flipped(data, pos + 15 + 16 + 15, tmp_path / "bad-index.mcap")
    got, ref = read_log(path), read_log(good)
    np.testing.assert_array_equal(got.imu.t, ref.imu.t)
    np.testing.assert_array_equal(got.imu.b_f, ref.imu.b_f)
    np.testing.assert_array_equal(got.dvl.d_v, ref.dvl.d_v)
