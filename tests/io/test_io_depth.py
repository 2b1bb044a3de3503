"""The depth topics: /depth/pressure (sensor_msgs/msg/FluidPressure) written and read back exactly, the
lever arm through /tf_static, depth from a pose topic (z up or down), --depth-topic, and logs without depth
unchanged."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from gtsam_dvl.app.cli import app
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import DepthData
from gtsam_dvl.io.mcap.writer import McapLogWriter
from gtsam_dvl.io.reader import read_log, read_topic
from gtsam_dvl.io.ros2 import messages
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict
from tests.support.synthetic_log import make_log


def _with_depth(seed: int = 0) -> DepthData:
    rng = np.random.default_rng(seed)
    t = np.arange(1, 121) / 2.0
    p = 101325.0 + 1.0e4 * rng.uniform(5, 50, len(t))
    var = np.full(len(t), 2500.0)
    var[::7] = np.nan  # unknown: written 0, read back NaN
    return DepthData(
        t, (p - 101325.0) / 1.0e4, var / 1e8, p, var, "pressure_link", np.array([0.2, -0.1, 0.4])
    )


def test_pressure_round_trip_is_exact(tmp_path: Path) -> None:
    log = dataclasses.replace(make_log(60.0), depth=_with_depth())
    path = tmp_path / "log.mcap"
    write_log(path, log)
    with open(path, "rb") as fh:
        channels = {c.topic: c for c in make_reader(fh).get_summary().channels.values()}
    assert "/depth/pressure" in channels
    got = read_log(path)
    d, want = got.depth, log.depth
    assert d is not None and want is not None and want.pressure_pa is not None
    np.testing.assert_array_equal(d.t, want.t)
    np.testing.assert_array_equal(d.pressure_pa, want.pressure_pa)
    # NaN where unknown
    np.testing.assert_array_equal(d.pressure_variance_pa2, want.pressure_variance_pa2)
    np.testing.assert_array_equal(d.b_p_sensor, want.b_p_sensor)
    assert d.frame_id == "pressure_link"
    # defaults: rho 1025, g(45 deg)
    assert np.all(np.abs(d.depth_m - want.depth_m) < 0.02 * want.depth_m)
    # other tools decode it with the definition the log carries
    msgs = read_topic(path, "/depth/pressure")
    assert len(msgs) == len(want) and msgs[3][1].fluid_pressure == want.pressure_pa[3]
    assert read_log(path, depth_topic="none").depth is None
    with pytest.raises(GtsamDvlError, match="no depth topic /nope.*--depth-topic"):
        read_log(path, depth_topic="/nope")
    with pytest.raises(GtsamDvlError, match="depth topics must be one of"):
        read_log(path, depth_topic="/imu/data_raw")


@pytest.mark.parametrize("z_down", [False, True])
def test_depth_from_a_pose_topic(tmp_path: Path, z_down: bool) -> None:
    log = make_log(20.0)
    path = tmp_path / "pose.mcap"
    write_log(path, log)
    t = np.arange(1, 21, dtype=float)
    z = -np.linspace(5.0, 25.0, len(t))
    cov = np.zeros((len(t), 6, 6))
    cov[:, 2, 2] = 0.01
    cov[0, 2, 2] = 0.0  # unknown
    # a second file with the pose topic added (the writer is generic)
    with McapLogWriter(tmp_path / "with_pose.mcap", t0_ns=log.t0_ns) as w:
        imu = messages.imu(w.stamps_ns(log.imu.t), log.imu.b_omega, log.imu.b_f, "imu_link")
        w.add_structured("/imu/data_raw", messages.IMU, imu)
        twist = messages.six_dof_with_covariance(
            messages.TWIST_COV,
            w.stamps_ns(log.dvl.t[log.dvl.valid]),
            log.dvl.d_v[log.dvl.valid],
            None,
            np.zeros((int(log.dvl.valid.sum()), 6, 6)),
            "dvl_link",
        )
        w.add_structured("/dvl/twist", messages.TWIST_COV, twist)
        w.add_pose_with_covariance(
            "/depth/pose",
            t,
            np.c_[np.zeros((len(t), 2)), z],
            np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1)),
            cov,
            "depth_link",
        )
    got = read_log(tmp_path / "with_pose.mcap", depth_topic="/depth/pose", depth_z_down=z_down)
    assert got.depth is not None and got.depth.pressure_pa is None
    np.testing.assert_array_equal(got.depth.depth_m, z if z_down else -z)
    assert np.isnan(got.depth.variance_m2[0]) and np.all(got.depth.variance_m2[1:] == 0.01)
    # no /depth/pressure: no depth by default
    assert read_log(tmp_path / "with_pose.mcap").depth is None


def test_logs_without_depth_have_no_pressure_topic(tmp_path: Path) -> None:
    raw = copy.deepcopy(load_scenario("paper-2d").raw)
    raw["segments"] = raw["segments"][:2]
    plain = simulate(scenario_from_dict(raw), 5)
    assert plain.depth is None
    raw["depth"] = {"rate_hz": 1.0, "noise_m": 0.1, "bias_m": 0.3}
    with_depth = simulate(scenario_from_dict(raw), 5)
    # the other sensors are bit for bit those of the scenario without [depth]
    np.testing.assert_array_equal(plain.imu.b_f, with_depth.imu.b_f)
    np.testing.assert_array_equal(plain.dvl.d_v, with_depth.dvl.d_v)
    write_log(tmp_path / "plain.mcap", plain)
    with open(tmp_path / "plain.mcap", "rb") as fh:
        topics = {c.topic for c in make_reader(fh).get_summary().channels.values()}
    assert "/depth/pressure" not in topics
    d = with_depth.depth
    assert d is not None and with_depth.truth is not None
    # map z + origin height (the curvature is negligible at rest)
    h = with_depth.truth.n_p[::10, 2] - 100.0
    # the bias, the noise averaged
    np.testing.assert_allclose(np.mean(d.depth_m[:600] + h[:600]), 0.3, atol=0.02)


def test_cli_depth_topic(tmp_path: Path) -> None:
    log = dataclasses.replace(make_log(30.0), depth=_with_depth())
    write_log(tmp_path / "log.mcap", log)
    runner = CliRunner()
    ok = runner.invoke(
        app, ["info", str(tmp_path / "log.mcap"), "--depth-topic", "/depth/pressure"]
    )
    assert ok.exit_code == 0, ok.output
    bad = runner.invoke(app, ["info", str(tmp_path / "log.mcap"), "--depth-topic", "/nope"])
    assert bad.exit_code == 1 and "no depth topic /nope" in bad.output
