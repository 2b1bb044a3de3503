"""Streaming reading: the log is read chunk by chunk (pages of a .db3) and the IMU and truth are
decoded as they come, into arrays of the fields used; the result must be the bulk read's, bit for bit, with
the file memory-mapped or read, with the storage's message counts right or missing, and its peak memory must
stay below the IMU's message bodies (which the bulk read held, twice)."""

from __future__ import annotations

import sqlite3
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.mcap import scan
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.storage import sources
from gtsam_dvl.io.storage.sources import open_source
from gtsam_dvl.io.writer import write_log
from tests.support.synthetic_log import make_log

TOPICS = ["/imu/data_raw", "/dvl/data", "/ground_truth/odometry", "/tf_static"]


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> tuple[LogData, Path]:
    log = make_log(150.0, seed=3)  # 15,000 IMU messages: several 1 MiB chunks
    path = tmp_path_factory.mktemp("stream") / "log.mcap"
    write_log(path, log)
    return log, path


def _same(a: LogData, b: LogData) -> None:
    for name in ("t", "b_omega", "b_f"):
        np.testing.assert_array_equal(getattr(a.imu, name), getattr(b.imu, name))
    for name in ("t", "d_v", "d_cov", "valid"):
        np.testing.assert_array_equal(getattr(a.dvl, name), getattr(b.dvl, name))
    assert a.truth is not None and b.truth is not None
    for name in ("t", "n_p", "n_q_b", "n_v", "b_omega"):
        np.testing.assert_array_equal(getattr(a.truth, name), getattr(b.truth, name))
    assert a.imu.frame_id == b.imu.frame_id and a.t0_ns == b.t0_ns
    assert a.metadata["reader_warnings"] == b.metadata["reader_warnings"]


def test_pieces_are_the_chunks_and_add_up_to_the_bulk_read(written: tuple[LogData, Path]) -> None:
    _, path = written
    src = open_source(path)
    pieces = list(src.iter_read(TOPICS))
    assert len(pieces) == src.chunk_count() > 3
    bulk = src.read(TOPICS)
    imu = [p["/imu/data_raw"] for p in pieces if "/imu/data_raw" in p]
    assert sum(len(b) for b in imu) == len(bulk["/imu/data_raw"]) == 15_000
    assert bulk["/imu/data_raw"].fixed is not None
    np.testing.assert_array_equal(
        np.concatenate([b.fixed for b in imu if b.fixed is not None]), bulk["/imu/data_raw"].fixed
    )


def test_streamed_read_decodes_what_was_written(
    written: tuple[LogData, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    log, path = written
    got = read_log(path)
    np.testing.assert_array_equal(got.imu.t, log.imu.t)
    np.testing.assert_array_equal(got.imu.b_omega, log.imu.b_omega)
    np.testing.assert_array_equal(got.imu.b_f, log.imu.b_f)
    assert got.truth is not None and log.truth is not None
    np.testing.assert_allclose(got.truth.n_p, log.truth.n_p, rtol=0, atol=1e-12)
    assert got.attitude is None  # no IMU orientation written (covariance[0] = -1)
    # memory-mapped instead of read; the storage's message counts missing (arrays grown as they come)
    monkeypatch.setattr(scan, "MMAP_MIN_BYTES", 0)
    _same(read_log(path), got)
    monkeypatch.setattr(sources.Source, "message_counts", lambda self: {})
    _same(read_log(path), got)


def test_streamed_read_peak_memory_is_below_the_imu_bodies(
    written: tuple[LogData, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    log, path = written
    # as for a large log: the file itself is mapped, not read
    monkeypatch.setattr(scan, "MMAP_MIN_BYTES", 0)
    src = open_source(path)
    bodies = src.read(["/imu/data_raw"])["/imu/data_raw"]
    assert bodies.fixed is not None
    body_bytes = bodies.fixed.nbytes  # what the bulk read held (and once more while concatenating)
    del bodies, src
    tracemalloc.start()
    try:
        got = read_log(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # 56 bytes per sample
    out_bytes = got.imu.t.nbytes + got.imu.b_omega.nbytes + got.imu.b_f.nbytes
    assert len(got.imu) == len(log.imu)
    # measured on this 150 s log: 4.4 MB, 0.9 x the IMU bodies (the output arrays, their decoded copies, one
    # 1 MiB chunk, the low-rate topics); the bulk read peaked at 16.0 MB, 3.3 x, and grew with the bodies
    assert peak < 1.5 * body_bytes, (peak, body_bytes, out_bytes)


def test_db3_read_in_pages(
    tmp_path: Path, written: tuple[LogData, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A .db3 copy of the log (rosbag2's schema) read in pages of 1000 rows gives the MCAP's result."""
    _, path = written
    src = open_source(path)
    db = tmp_path / "log.db3"
    con = sqlite3.connect(db)
    con.execute(
        "CREATE TABLE topics (id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT, "
        "offered_qos_profiles TEXT)"
    )
    con.execute(
        "CREATE TABLE messages (id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB)"
    )
    bulk = src.read(TOPICS)
    for tid, topic in enumerate(TOPICS, 1):
        con.execute(
            "INSERT INTO topics VALUES (?, ?, ?, 'cdr', '')",
            (tid, topic, src.topics[topic].type_name),
        )
        b = bulk[topic]
        con.executemany(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
            [(tid, int(t), body) for t, body in zip(b.log_time.tolist(), b.items(), strict=True)],
        )
    con.commit()
    con.close()
    want = read_log(path)
    monkeypatch.setattr(sources, "DB3_PAGE", 1000)
    assert len(list(open_source(db).iter_read(["/imu/data_raw"]))) == 15
    got = read_log(db)
    _same(got, want)
