"""The ROS 2 node end to end, three processes on this machine's DDS (a domain of their own, discovery on localhost):
`gtsam-dvl play` publishes a short simulated log (165 s of 100 Hz IMU and 2 Hz DVL whose DVL topic stops for 20 s)
at 20x real time, `gtsam-dvl node` estimates, and this test's rclpy subscriber receives the Odometry and the
diagnostics. The final Odometry must agree with `smooth --mode online` on the same log (estimators/run.py, what
the command runs) within 0.1 sigma, and so must every Odometry of a state; the diagnostics go from ok to degraded
while the DVL is silent and back. SIGINT ends the node: it finishes, publishes its final estimate and writes the
calibration file and its timings.

rclpy, the message packages and Fast DDS come from the test extra (pyproject.toml): imported here (rclpy by the
Listener, tests/support/node.py), not skipped, so that a missing wheel fails the suite.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from std_msgs.msg import Float64MultiArray

from gtsam_dvl.app.node.core import CALIBRATION_ROWS
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.estimators.run import run_estimator
from gtsam_dvl.io.calibration_file import read_calibration
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.ros2.cdr import stamps_ns
from gtsam_dvl.io.ros2.decode import MessageDecoder
from gtsam_dvl.io.writer import write_log
from tests.support.node import (
    GAP_S,
    Listener,
    cli,
    config_toml,
    gap_log,
    params_yaml,
    ros_env,
    sigma_distance,
)

# one worker runs the module's tests: its fixture (a simulated log, the processes) is made once
pytestmark = pytest.mark.xdist_group(name="ros2_node")

RATE = 20.0  # times real time
# the node's reorder window as long in wall time as its default (0.05 s) at real time: it is there for the delivery's
# jitter between topics, a wall-time matter, and is given in sensor time, which runs RATE times faster here
REORDER_WINDOW_S = 0.05 * RATE


_odometry = MessageDecoder("/gtsam_dvl/odometry", "nav_msgs/msg/Odometry")


@pytest.fixture(scope="module")
def node_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The three processes run once: what the subscriber received, the reference run and the files."""
    tmp = tmp_path_factory.mktemp("node")
    log = gap_log()
    mcap = tmp / "gap.mcap"
    write_log(mcap, log)
    (tmp / "cfg.toml").write_text(config_toml(log))
    (tmp / "params.yaml").write_text(
        params_yaml(
            imu_topic="/imu/data_raw",
            dvl_topic="/dvl/twist",
            pressure_topic="",
            gnss_topic="",
            diagnostics_period_s=0.2,
            calibration_out=str(tmp / "vehicle.toml"),
            vehicle="auv-test",
            stats_file=str(tmp / "stats.json"),
            qos_inputs={"reliability": "reliable", "depth": 100000},
            reorder_window_s=REORDER_WINDOW_S,
        )
    )
    env = ros_env()
    listener = Listener("gtsam_dvl_test_subscriber", env)
    try:
        odometry = listener.record(Odometry, "/gtsam_dvl/odometry", raw=True)
        diagnostics = listener.record(DiagnosticArray, "/diagnostics")
        calibration = listener.record(Float64MultiArray, "/gtsam_dvl/calibration")
        node_code, played = _run_node_and_player(listener, odometry, tmp, mcap, env)
    finally:
        listener.close()
    cfg = EstimatorConfig.load(tmp / "cfg.toml")
    reference = run_estimator(read_log(mcap, dvl_topic="/dvl/twist"), "online", cfg)
    return {
        "tmp": tmp,
        "log": log,
        "odometry": odometry,
        "diagnostics": diagnostics,
        "calibration": [m for _, m in calibration],
        "reference": reference,
        "played": played,
        "node_log": (tmp / "node.log").read_text(),
        "node_code": node_code,
    }


def _run_node_and_player(
    listener: Listener,
    odometry: list[tuple[float, Any]],
    tmp: Path,
    mcap: Path,
    env: dict[str, str],
) -> tuple[int, str]:
    """`gtsam-dvl node` and `gtsam-dvl play` in their processes, the listener receiving meanwhile; SIGINT ends the
    node once its Odometry has gone quiet after the player's end. Returns the node's exit code and what the player
    printed."""
    deadline = time.monotonic() + 120
    with open(tmp / "node.log", "w") as out:
        node = subprocess.Popen(
            cli("node", "-c", tmp / "cfg.toml", "--params", tmp / "params.yaml"),
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
        try:
            player = subprocess.Popen(
                cli(
                    "play",
                    mcap,
                    "--rate",
                    str(RATE),
                    "--wait",
                    "60",
                    "--topic",
                    "/imu/data_raw",
                    "--topic",
                    "/dvl/twist",
                ),
                env=env,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            listener.spin_until(lambda: player.poll() is not None, deadline)
            played = player.communicate(timeout=10)[0]
            # the node may still be working through its queue (a loaded machine runs it slower than RATE):
            # interrupted only once its odometry has gone quiet
            listener.spin_until(_quiet_for(odometry, 3.0), deadline)
            node.send_signal(signal.SIGINT)
            listener.spin_until(lambda: node.poll() is not None, deadline)
            # the last messages in flight
            listener.spin_until(lambda: False, time.monotonic() + 0.5)
        finally:
            if node.poll() is None:
                node.kill()
            node.wait(timeout=10)
    return node.returncode, played


def _quiet_for(received: list[Any], seconds: float) -> Callable[[], bool]:
    """A done() for Listener.spin_until: True once nothing was appended to received for `seconds`."""
    seen = {"count": len(received), "at": time.monotonic()}

    def done() -> bool:
        if len(received) != seen["count"]:
            seen.update(count=len(received), at=time.monotonic())
        return time.monotonic() - seen["at"] >= seconds

    return done


def test_node_odometry_agrees_with_smooth_online(node_run: dict[str, Any]) -> None:
    ref = node_run["reference"]
    assert node_run["odometry"], node_run["node_log"] + node_run["played"]
    assert node_run["node_code"] == 0, node_run["node_log"]
    rows = [_odometry(b) for _, b in node_run["odometry"]]
    stamps = np.array([int(stamps_ns(r)[0]) for r in rows])
    # the reader's time origin, which the node takes the same way
    t = (stamps - int(ref.t0_ns)) / 1e9
    final = rows[-1]
    # the node's final estimate: the last state's
    assert abs(t[-1] - ref.t[-1]) < 1e-6, (t[-1], ref.t[-1], node_run["node_log"])
    d_final = sigma_distance(final["position"][0], ref.n_p[-1], ref.n_R_b[-1], ref.pose_cov[-1])
    # every Odometry of a state (the others are predictions at pings between keyframes) against the reference's
    # filtering estimate of that state
    k = np.searchsorted(ref.t, t)
    matched = [
        (i, int(j)) for i, j in enumerate(k) if j < len(ref.t) and abs(ref.t[j] - t[i]) < 1e-6
    ]
    worst = max(
        sigma_distance(rows[i]["position"][0], ref.n_p[j], ref.n_R_b[j], ref.pose_cov[j])
        for i, j in matched
    )
    print(
        f"\nnode vs smooth --mode online: final position {d_final:.2e} sigma, worst of {len(matched)} states "
        f"{worst:.2e} sigma; {len(rows)} Odometry messages"
    )
    assert d_final < 0.1
    # the states made at the alignment come at once (one Odometry, the newest); after it, one per state but where
    # one message completes two epochs (a state without a ping and the next ping's)
    after = int(np.sum(ref.t >= t[0]))
    assert len({j for _, j in matched}) >= 0.95 * after and worst < 0.1
    # covariances in ROS order (io/ros2/covariance.py): the final pose's position sigmas are the reference's
    pose_cov = final["pose_covariance"][0].reshape(6, 6)
    assert np.all(np.diag(pose_cov)[:3] > 0)
    np.testing.assert_allclose(
        final["position"][0], ref.n_p[-1], atol=0.1 * np.sqrt(np.diag(pose_cov)[:3]).min()
    )
    assert final["frame_id"][0] in ("map", b"map") and final["child_frame_id"][0] in (
        "base_link",
        b"base_link",
    )


def test_node_diagnostics_turn_degraded_when_the_dvl_stops(node_run: dict[str, Any]) -> None:
    seen = []  # (sensor time of the verdict, status, message)
    for _, msg in node_run["diagnostics"]:
        (status,) = msg.status
        values = {kv.key: kv.value for kv in status.values}
        if "t_s" in values:  # (after the first estimate)
            seen.append(
                (float(values["sensor_t_s"]), values["status"], status.message, status.level)
            )
    assert seen, node_run["node_log"]
    start, stop = GAP_S
    dvl_t = node_run["log"].dvl.t
    last_ping = float(dvl_t[dvl_t < start].max())  # the DVL's silence starts here
    ok_before = [s for s in seen if s[0] < start and s[1] == "ok"]
    degraded = [s for s in seen if start <= s[0] <= stop + 1.0 and s[1] == "degraded"]
    ok_after = [s for s in seen if s[0] > stop + 2.0 and s[1] == "ok"]
    assert ok_before, seen[:20]
    assert degraded, [s[:2] for s in seen if s[0] > start - 1]
    assert "DVL topic /dvl/twist silent" in degraded[0][2] and degraded[0][3] == b"\x02"  # ERROR
    assert not [s for s in seen if s[0] < last_ping + 10.0 and s[1] == "degraded"]
    # dvl_silent_degraded_s (10 s) after the last ping, seen within CHECK_EVERY_S of sensor time (and the window)
    assert 9.99 <= degraded[0][0] - last_ping <= 10.6, [s[:2] for s in seen if start < s[0] < stop]
    assert ok_after, [s[:2] for s in seen if s[0] > start]


def test_node_calibration_topic_and_file(node_run: dict[str, Any]) -> None:
    ref = node_run["reference"]
    msgs = node_run["calibration"]
    assert msgs
    last = msgs[-1]
    dims = last.layout.dim
    assert dims[0].label.split(",") == list(CALIBRATION_ROWS) and dims[1].label == "value,sigma"
    rows = np.asarray(last.data).reshape(dims[0].size, dims[1].size)
    scale, scale_sigma = rows[CALIBRATION_ROWS.index("scale")]
    assert abs(scale - ref.scale) < 0.1 * ref.scale_sigma and scale_sigma == pytest.approx(
        ref.scale_sigma, rel=1e-3
    )
    # written at shutdown (calibration_out)
    cal = read_calibration(node_run["tmp"] / "vehicle.toml")
    assert cal.vehicle == "auv-test" and "scale" in cal.states
    assert abs(float(cal.values["scale"][0]) - ref.scale) < 0.1 * ref.scale_sigma
    stats = json.loads((node_run["tmp"] / "stats.json").read_text())
    published = [r for r in stats["timings"] if not math.isnan(r["published"])]
    assert len(published) > 100
