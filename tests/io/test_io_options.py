"""ReadOptions (io/read_options.py): documented defaults, one-line errors for bad values, the record a result keeps
and reads back, the options given on a command line over the recorded ones; read_log takes the object or its
fields as keywords alike."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.io.read_options import ReadOptions
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from tests.support.synthetic_log import make_log


def test_defaults() -> None:
    o = ReadOptions()
    assert (o.imu_topic, o.dvl_topic, o.truth_topic, o.tf_topic) == (
        "/imu/data_raw",
        None,
        "/ground_truth/odometry",
        "/tf_static",
    )
    assert (o.depth_topic, o.gnss_topic, o.attitude_topic, o.dvl_water_topic) == (None,) * 4
    assert (o.salvage, o.repair, o.depth_z_down, o.attitude_frame) == (False, False, False, "enu")
    assert o.model_fields_set == set()


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"salvage": "yes"}, "read options: salvage must be true or false, got 'yes'"),
        ({"repair": 1}, "read options: repair must be true or false, got 1"),
        ({"imu_topic": 3}, "read options: imu_topic must be a str, got 3"),
        ({"dvl_topic": 3}, "read options: dvl_topic must be a str or 'none', got 3"),
        (
            {"attitude_frame": "nwu"},
            "read options: attitude_frame must be one of enu, ned, got 'nwu'",
        ),
        (
            {"dvl_topc": "/dvl"},
            "read options: unknown option 'dvl_topc' (known: imu_topic, dvl_topic, ",
        ),
    ],
)
def test_a_bad_value_is_one_line(given: dict[str, object], message: str) -> None:
    with pytest.raises(GtsamDvlError) as err:
        ReadOptions(**given)  # type: ignore[arg-type]
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_frozen_replace_and_over() -> None:
    o = ReadOptions(dvl_topic="/dvl/twist", repair=True)
    with pytest.raises(Exception):  # noqa: B017, PT011 - pydantic's frozen-instance error
        o.repair = False  # type: ignore[misc]
    p = o.replace(salvage=True)
    assert (p.dvl_topic, p.repair, p.salvage) == ("/dvl/twist", True, True)
    assert p.model_fields_set == {"dvl_topic", "repair", "salvage"}
    with pytest.raises(GtsamDvlError, match="^read options: salvage must be true or false"):
        o.replace(salvage="no")
    # evaluate: the options given on its command line (and only those) over the ones smooth recorded
    recorded = ReadOptions(imu_topic="/imu", depth_topic="none", repair=True)
    merged = ReadOptions(repair=False).over(recorded)
    assert (merged.imu_topic, merged.depth_topic, merged.repair) == ("/imu", "none", False)
    assert ReadOptions().over(recorded) == recorded


def test_record_and_from_record() -> None:
    assert ReadOptions().record() == {
        "imu_topic": "/imu/data_raw",
        "dvl_topic": None,
        "salvage": False,
        "repair": False,
    }
    o = ReadOptions(repair=True, gnss_topic="none", attitude_frame="ned", depth_z_down=True)
    record = o.record()
    assert list(record)[:4] == ["imu_topic", "dvl_topic", "salvage", "repair"]
    assert record == {
        "imu_topic": "/imu/data_raw",
        "dvl_topic": None,
        "salvage": False,
        "repair": True,
        "depth_z_down": True,
        "gnss_topic": "none",
        "attitude_frame": "ned",
    }
    assert ReadOptions.from_record(record) == o
    # a newer version's option is ignored; a damaged value is one line naming the source
    assert ReadOptions.from_record({**record, "future_option": 1}) == o
    with pytest.raises(
        GtsamDvlError, match=r"^r\.mcap: read_options: repair must be true or false"
    ):
        ReadOptions.from_record({"repair": "yes"}, "r.mcap: read_options")


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("options") / "log.mcap"
    write_log(path, make_log(20.0, seed=3))
    return path


def _same(a: LogData, b: LogData) -> None:
    np.testing.assert_array_equal(a.imu.t, b.imu.t)
    np.testing.assert_array_equal(a.dvl.d_v, b.dvl.d_v)
    assert a.metadata["reader_warnings"] == b.metadata["reader_warnings"]


def test_read_log_takes_the_object_or_its_fields(written: Path) -> None:
    import gtsam_dvl

    default = gtsam_dvl.read_log(written)
    _same(default, read_log(written, ReadOptions()))
    twist = read_log(written, ReadOptions(dvl_topic="/dvl/twist", tf_topic="/nope"))
    _same(twist, read_log(written, dvl_topic="/dvl/twist", tf_topic="/nope"))
    assert "no /nope in the log: identity mounting assumed" in " ".join(
        twist.metadata["reader_warnings"]
    )
    # keywords over the object's options
    _same(
        twist,
        read_log(
            written, ReadOptions(dvl_topic="/dvl/data"), dvl_topic="/dvl/twist", tf_topic="/nope"
        ),
    )
    with pytest.raises(GtsamDvlError, match=r"^read options: unknown option 'dvl'"):
        read_log(written, dvl="/dvl/twist")
