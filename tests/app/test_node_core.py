"""The ROS 2 node without ROS: the reorder buffer, the settings, the live verdict, and NodeCore fed a recorded log's
own message bodies (out of order within the window) against `smooth --mode online` on the log, to the last bit;
an exception inside the estimator stops nothing; without the extra, `gtsam-dvl node` is one line and exit code 1."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.live_health import LiveState, LiveThresholds, StreamState, assess_live
from gtsam_dvl.app.node.core import NodeCore, moved
from gtsam_dvl.app.node.reorder import ReorderBuffer
from gtsam_dvl.app.node.settings import load_settings
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import so3_exp
from gtsam_dvl.core.states import Estimate
from gtsam_dvl.estimators.run import run_estimator
from gtsam_dvl.io.calibration_file import read_calibration
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.storage.sources import open_source
from gtsam_dvl.io.writer import write_log
from tests.support.node import config_toml, gap_log

# one worker runs the module's tests: its fixture (a simulated log, the processes) is made once
pytestmark = pytest.mark.xdist_group(name="ros2_node_core")

MS = 1_000_000


def test_reorder_puts_messages_in_stamp_order_within_the_window() -> None:
    buf = ReorderBuffer(window_ns=50 * MS, jump_ns=1000 * MS)
    out: list[tuple[str, int]] = []
    arrivals = [
        ("imu", 10),
        ("imu", 30),
        ("imu", 20),
        ("dvl", 30),
        ("imu", 40),
        ("imu", 100),
        ("imu", 120),
    ]
    for k, (kind, ms) in enumerate(arrivals):
        buf.push(kind, ms * MS, None, wall=k * 0.01)
        out += [(m.kind, m.stamp_ns // MS) for m in buf.ready()]
    # the IMU sample stamped like the ping before it; nothing within 50 ms of the newest IMU stamp (120 ms)
    assert out == [("imu", 10), ("imu", 20), ("imu", 30), ("dvl", 30), ("imu", 40)]
    assert buf.push("imu", 35 * MS, None, wall=0.1) is False and buf.streams["imu"].late == 1
    assert buf.push("imu", 40 * MS, None, wall=0.1) is False and buf.streams["imu"].duplicates == 1
    assert [(m.kind, m.stamp_ns // MS) for m in buf.flush()] == [("imu", 100), ("imu", 120)]


def test_a_silent_stream_that_comes_back_is_no_stamp_jump_but_a_clock_step_is() -> None:
    buf = ReorderBuffer(window_ns=0, jump_ns=1000 * MS)
    # 3 s of 100 Hz IMU, a ping at 0 and one at 2.5 s (silent in between); 10x real time
    for k in range(301):
        buf.push("imu", k * 10 * MS, None, wall=k * 0.001)
        if k in (0, 250):
            buf.push("dvl", k * 10 * MS, None, wall=k * 0.001)
    assert buf.streams["dvl"].jumps == 0 and buf.streams["imu"].jumps == 0
    # 6.5 s after its last, while the IMU's stamps moved 0.5 s
    buf.push("dvl", 9000 * MS, None, wall=0.301)
    buf.push("imu", 5000 * MS, None, wall=0.302)  # the IMU's 2 s ahead of the wall clock
    assert buf.streams["dvl"].jumps == 1 and buf.streams["dvl"].largest_jump_s == pytest.approx(
        6.0, abs=0.01
    )
    assert buf.streams["imu"].jumps == 1


def test_settings_from_toml_and_parameters(tmp_path: Path) -> None:
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(
        'preset = "paper"\n[online]\nalign_s = 35.0\n[node]\nimu_topic = "/imu/raw"\nreorder_window_s = '
        "0.1\n"
    )
    params = {
        "reorder_window_s": 0.02,
        "qos_inputs.reliability": "reliable",
        "estimator.dvl.noise_m_s": 0.03,
        "use_sim_time": False,
        "start_type_description_service": True,
    }
    settings, config = load_settings(cfg, params)
    # the parameter wins
    assert settings.imu_topic == "/imu/raw" and settings.reorder_window_s == 0.02
    assert settings.qos_inputs.reliability == "reliable" and settings.qos_inputs.depth == 1000
    assert (
        config.online.align_s == 35.0
        and config.dvl.noise_m_s == 0.03
        and config.priors.scale_initial == 0.8
    )
    with pytest.raises(GtsamDvlError, match=r"reorder_window_s must be a number >= 0, got -1"):
        load_settings(cfg, {"reorder_window_s": -1.0}, source="node.yaml")
    with pytest.raises(GtsamDvlError, match="unknown key 'imu_topik'"):
        load_settings(None, {"imu_topik": "/x"}, source="node.yaml")


def test_live_verdict_follows_the_dvl() -> None:
    lim = LiveThresholds(
        dvl_silent_warn_s=2.0, dvl_silent_degraded_s=10.0, bottom_lock_degraded_s=60.0
    )

    def verdict(silent_s: float, no_lock_s: float = 0.0, **state: Any) -> str:
        streams = {
            "imu": StreamState("/imu", received=100, silent_s=0.0),
            "dvl": StreamState("/dvl", received=10, silent_s=silent_s),
        }
        return assess_live(
            LiveState(phase="running", streams=streams, no_lock_s=no_lock_s, **state), lim
        ).status

    assert [verdict(s) for s in (0.5, 3.0, 12.0)] == ["ok", "warn", "degraded"]
    assert [verdict(0.2, n) for n in (1.0, 5.0, 61.0)] == ["ok", "warn", "degraded"]
    assert verdict(0.2, imu_wall_silent_s=2.0) == "failed"
    assert verdict(0.2, stop_error="RuntimeError: boom", since_stop_s=100.0) == "failed"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("node_core")
    log = gap_log()
    write_log(tmp / "gap.mcap", log)
    (tmp / "cfg.toml").write_text(config_toml(log))
    src = open_source(tmp / "gap.mcap")
    kinds = {"/imu/data_raw": "imu", "/dvl/twist": "dvl"}
    raw = src.read(list(kinds))
    msgs = sorted(
        (
            (int(ns), kinds[t], b)
            for t in kinds
            for ns, b in zip(raw[t].log_time, raw[t].items(), strict=True)
        ),
        key=lambda m: m[0],
    )
    return {"tmp": tmp, "msgs": msgs}


def test_node_core_on_a_logs_messages_out_of_order_equals_smooth_online(
    recorded: dict[str, Any],
) -> None:
    tmp, msgs = recorded["tmp"], list(recorded["msgs"])
    rng = np.random.default_rng(5)
    # arrival order: each message up to 20 ms late (the window is 50 ms), so that stamps cross within and across
    # topics; the wall clock is the log's
    late = rng.uniform(0.0, 0.02, len(msgs))
    order = np.argsort(
        [ns * 1e-9 + d for (ns, _, _), d in zip(msgs, late, strict=True)], kind="stable"
    )
    assert (np.diff(order) < 0).sum() > 1000  # really out of order
    settings, config = load_settings(
        tmp / "cfg.toml", {"imu_topic": "/imu/data_raw", "reorder_window_s": 0.05}
    )
    core = NodeCore(settings, config)
    states = {}
    for i in order:
        ns, kind, body = msgs[i]
        for e in core.receive(kind, body, wall=ns * 1e-9 + late[i]):
            if np.isnan(e.predicted_from_t):
                states[round(e.t, 9)] = e
    final = core.finish()
    ref = run_estimator(
        read_log(tmp / "gap.mcap", dvl_topic="/dvl/twist"),
        "online",
        EstimatorConfig.load(tmp / "cfg.toml"),
    )
    assert final is not None and final.t == ref.t[-1]
    np.testing.assert_array_equal(final.n_p, ref.n_p[-1])
    matched = [k for k, t in enumerate(ref.t) if round(t, 9) in states]
    assert len(matched) > 100
    for k in matched:
        np.testing.assert_array_equal(states[round(ref.t[k], 9)].n_p, ref.n_p[k])
    assert core.buffer.streams["imu"].late == 0 and core.buffer.streams["dvl"].late == 0
    last_wall = msgs[int(np.argmax([m[0] for m in msgs]))][0] * 1e-9 + 0.02
    assert core.health(wall=last_wall + 0.1).status == "ok"
    # the IMU silent in wall time: no estimate
    assert core.health(wall=last_wall + 5.0).status == "failed"
    rows = core.calibration_rows(final)
    assert rows[1, 0] == ref.scale and rows[1, 1] == pytest.approx(ref.scale_sigma, rel=1e-12)


def test_an_exception_in_the_estimator_is_one_line_and_a_stop(recorded: dict[str, Any]) -> None:
    tmp, msgs = recorded["tmp"], recorded["msgs"]
    settings, config = load_settings(tmp / "cfg.toml", {"imu_topic": "/imu/data_raw"})
    lines: list[tuple[str, str]] = []
    core = NodeCore(settings, config, log=lambda level, text: lines.append((level, text)))
    n = len(msgs)
    for k, (ns, kind, body) in enumerate(msgs):
        if k == n // 2:  # a fault inside the estimator, halfway

            def boom(*args: Any, **kwargs: Any) -> int:
                raise RuntimeError("injected fault")

            assert core.estimator is not None
            core.estimator.push_dvl = boom  # type: ignore[method-assign]
        core.receive(kind, body, wall=ns * 1e-9)
        if k == n // 2 + 400:
            health = core.health(wall=ns * 1e-9)
            assert health.status == "failed" and "injected fault" in health.warnings[0]
    errors = [text for level, text in lines if level == "error"]
    assert len(errors) == 1 and "injected fault" in errors[0] and core.stops == 1
    assert core.estimator is None and core.health().status == "failed"  # said, and nothing more fed


def test_a_move_is_counted_in_sigmas_of_each_component() -> None:
    scale = Estimate(np.array([1.0]), np.array([[1e-4]]))  # sigma 0.01
    mis = Estimate(np.eye(3), np.diag([1e-4, 1e-4, 4e-4]))  # sigmas 0.01, 0.01, 0.02 rad
    before = {"scale": scale, "misalignment": mis}
    assert not moved(before, before, 0.1)
    assert moved(before, {**before, "scale": Estimate(np.array([1.0011]), scale.cov)}, 0.1)
    assert not moved(before, {**before, "scale": Estimate(np.array([1.0009]), scale.cov)}, 0.1)
    # about z (sigma 0.02): 0.0015 rad is 0.075 sigma; about x (sigma 0.01) 0.15 sigma
    turned = so3_exp(np.array([0.0, 0.0, 0.0015]))
    assert not moved(before, {**before, "misalignment": Estimate(turned, mis.cov)}, 0.1)
    tilted = so3_exp(np.array([0.0015, 0.0, 0.0]))
    assert moved(before, {**before, "misalignment": Estimate(tilted, mis.cov)}, 0.1)
    assert moved({"scale": scale}, before, 0.1)  # a state new


def test_calibration_out_is_written_while_running(recorded: dict[str, Any], tmp_path: Path) -> None:
    """calibration_out while running (core.py): at the first estimate, then when a vehicle state moved by more than
    0.1 of its sigma since the last write, and calibration_out_period_s of sensor time after it at the latest."""
    tmp, msgs = recorded["tmp"], recorded["msgs"]
    path, period = tmp_path / "vehicle.toml", 5.0
    settings, config = load_settings(
        tmp / "cfg.toml",
        {
            "imu_topic": "/imu/data_raw",
            "calibration_out": str(path),
            "calibration_out_period_s": period,
        },
    )
    core = NodeCore(settings, config)
    states: dict[float, dict[str, Estimate]] = {}  # each estimate's vehicle states by its time
    for ns, kind, body in msgs:
        for e in core.receive(kind, body, wall=ns * 1e-9):
            if not states:  # the first estimate: written at once
                assert path.exists() and core.calibration_writes[0][0] == e.t
            states[e.t] = {n: e.calibration[n] for n in ("scale", "misalignment")}
    t = np.array(list(states))
    writes = np.array([w for w, _ in core.calibration_writes])
    assert 10 < len(writes) < len(t) / 2  # a write when due, not at every estimate
    last = writes[
        np.searchsorted(writes, t, side="right") - 1
    ]  # the last write at or before each estimate
    assert np.all(t - last < period)
    for k in range(1, len(t)):
        previous = last[k - 1]  # the last write before this estimate
        if t[k] in writes:  # due, or moved
            assert t[k] - previous >= period or moved(states[previous], states[t[k]], 0.1)
        else:
            assert not moved(states[previous], states[t[k]], 0.1)
    cal = read_calibration(path)
    assert float(cal.values["scale"][0]) == float(states[writes[-1]]["scale"].value[0])
    # the per-epoch timeline is left out of the node's result (NodeEstimator): a write stays short
    assert core.estimator is not None and len(core.estimator.timeline().t) == 0


def test_a_calibration_out_that_cannot_be_written_is_one_line(
    recorded: dict[str, Any], tmp_path: Path
) -> None:
    (tmp_path / "a-file").write_text("")
    lines: list[tuple[str, str]] = []
    settings, config = load_settings(
        recorded["tmp"] / "cfg.toml",
        {"imu_topic": "/imu/data_raw", "calibration_out": str(tmp_path / "a-file" / "v.toml")},
    )
    core = NodeCore(settings, config, log=lambda level, text: lines.append((level, text)))
    n = 0
    for ns, kind, body in recorded["msgs"][: len(recorded["msgs"]) * 2 // 3]:
        n += len(core.receive(kind, body, wall=ns * 1e-9))
    errors = [text for level, text in lines if level == "error"]
    assert n > 50 and len(errors) == 1 and errors[0].startswith("calibration_out: "), errors
    assert "a-file" in core.key_values()["calibration_out"]


def test_node_without_the_extra_is_one_line_and_exit_code_1() -> None:
    code = (
        "import sys; sys.modules['rclpy'] = None\n"  # as if the ros2 extra were not installed
        "from gtsam_dvl.app.cli import main; sys.argv = ['gtsam-dvl', 'node']; main()"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run.returncode == 1, run.stderr
    assert run.stderr.strip().splitlines() == [
        "gtsam-dvl: error: gtsam-dvl node needs ROS 2's rclpy and message packages (wheels from PyPI, no system "
        "ROS): pip install 'gtsam-dvl[ros2]' (rclpy is missing)"
    ]


def test_the_example_parameter_file_loads() -> None:
    """examples/node.yaml as rcl hands it to the node: its nested keys flattened to dotted names."""
    import yaml  # PyYAML comes with rclpy (the test extra)

    def flat(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
        out: dict[str, Any] = {}
        for k, v in d.items():
            out.update(flat(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
        return out

    path = Path(__file__).resolve().parents[2] / "examples" / "node.yaml"
    params = flat(yaml.safe_load(path.read_text())["/**"]["ros__parameters"])
    settings, config = load_settings(None, params, source=str(path))
    assert settings.dvl_rpy_deg == (180.0, 0.0, 0.0) and settings.gnss_topic == "/gnss/fix"
    assert config.dvl.estimate_time_offset and config.imu.model == "kvh-1750"
