"""The ROS 2 node end to end, three processes on this machine's DDS (a domain of their own, discovery on localhost):
`gtsam-dvl play` publishes a short simulated log (165 s of 100 Hz IMU and 2 Hz DVL whose DVL topic stops for 20 s)
at 20x real time, `gtsam-dvl node` estimates, and this test's rclpy subscriber receives the Odometry and the
diagnostics. The final Odometry must agree with `smooth --mode online` on the same log (estimators/run.py, what
the command runs) within 0.1 sigma, and so must every Odometry of a state; the diagnostics go from ok to degraded
while the DVL is silent and back. SIGINT ends the node: it finishes, publishes its final estimate and writes the
calibration file and its timings. A node killed (SIGKILL) mid-run leaves a whole calibration file, written while
it ran.

A vehicle computer is a loaded computer: two busy processes run beside the node's (busy_cpus), and no wait is a
deadline such a machine misses. The test waits for conditions (the player done, every message it published received
by the node, the node's exit), each with LIMIT_S as a safety net only.

rclpy, the message packages and Fast DDS come from the test extra (pyproject.toml): imported here (rclpy by the
Listener, tests/support/node.py), not skipped, so that a missing wheel fails the suite.
"""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import Odometry
from std_msgs.msg import Float64MultiArray

from gtsam_dvl.app.node.core import CALIBRATION_ROWS
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.rotations import rpy_deg_to_matrix, so3_log
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

# one worker runs the module's tests: its fixtures (a simulated log, the processes) are made once
pytestmark = pytest.mark.xdist_group(name="ros2_node")

RATE = 20.0  # times real time
# the node's reorder window as long in wall time as its default (0.05 s) at real time: it is there for the delivery's
# jitter between topics, a wall-time matter, and is given in sensor time, which runs RATE times faster here
REORDER_WINDOW_S = 0.05 * RATE
# the same for the two settings judged as messages arrive: the stamp distance from the IMU's beyond which a message is
# on another clock (default 30 s) and a stamp jump (1 s). A node behind its inputs (a loaded machine) takes the few
# pings queued before the many IMU samples queued with them: at 20x, pings came 30 s of stamps ahead of the IMU
CLOCK_SKEW_S = 30.0 * RATE
STAMP_JUMP_S = 1.0 * RATE
# every wait's safety net: a run takes 20-40 s on a loaded 2-core machine; a broken one fails here, not a slow one
LIMIT_S = 300.0
BUSY = 2  # busy processes beside the node's
# the history of the node's inputs and outputs and of the listener's subscriptions: every message of a run
DEPTH = 100_000
# the diagnostics' counts of the messages the node took on an input (core.py key_values)
TAKEN = "received|other_clock|undecodable"


_odometry = MessageDecoder("/gtsam_dvl/odometry", "nav_msgs/msg/Odometry")


@pytest.fixture(scope="module")
def busy_cpus() -> Iterator[None]:
    """BUSY processes spinning beside the node's while the module's tests run; always ended."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(BUSY)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


@pytest.fixture(scope="module")
def recorded_log(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The test log (tests/support/node.py gap_log) written, with the node's estimator configuration."""
    tmp = tmp_path_factory.mktemp("node")
    log = gap_log()
    write_log(tmp / "gap.mcap", log)
    (tmp / "cfg.toml").write_text(config_toml(log))
    return {"tmp": tmp, "log": log, "mcap": tmp / "gap.mcap", "cfg": tmp / "cfg.toml"}


def _params(path: Path, **settings: Any) -> Path:
    """The node's parameter file with the test's topics, QoS and window, and these settings."""
    path.write_text(
        params_yaml(
            imu_topic="/imu/data_raw",
            dvl_topic="/dvl/twist",
            pressure_topic="",
            gnss_topic="",
            diagnostics_period_s=0.2,
            qos_inputs={"reliability": "reliable", "depth": DEPTH},
            # every message kept until the listener acknowledged it: starved of CPU, it fell 1.2 s behind once
            qos_outputs={"reliability": "reliable", "depth": DEPTH},
            reorder_window_s=REORDER_WINDOW_S,
            clock_skew_s=CLOCK_SKEW_S,
            stamp_jump_s=STAMP_JUMP_S,
            **settings,
        )
    )
    return path


@pytest.fixture(scope="module")
def node_run(recorded_log: dict[str, Any], busy_cpus: None) -> dict[str, Any]:
    """The three processes run once: what the subscriber received, the reference run and the files."""
    tmp, mcap = recorded_log["tmp"], recorded_log["mcap"]
    params = _params(
        tmp / "params.yaml",
        calibration_out=str(tmp / "vehicle.toml"),
        vehicle="auv-test",
        stats_file=str(tmp / "stats.json"),
    )
    env = ros_env()
    listener = Listener("gtsam_dvl_test_subscriber", env)
    try:
        odometry = listener.record(Odometry, "/gtsam_dvl/odometry", DEPTH, raw=True)
        diagnostics = listener.record(DiagnosticArray, "/diagnostics", DEPTH)
        calibration = listener.record(Float64MultiArray, "/gtsam_dvl/calibration", DEPTH)
        node_code, played = _run_node_and_player(
            listener, odometry, diagnostics, tmp, recorded_log["cfg"], params, mcap, env
        )
    finally:
        listener.close()
    cfg = EstimatorConfig.load(recorded_log["cfg"])
    reference = run_estimator(read_log(mcap, dvl_topic="/dvl/twist"), "online", cfg)
    return {
        "tmp": tmp,
        "log": recorded_log["log"],
        "odometry": odometry,
        "diagnostics": diagnostics,
        "calibration": [m for _, m in calibration],
        "reference": reference,
        "played": played,
        "node_log": (tmp / "node.log").read_text(),
        "node_code": node_code,
    }


def _start(
    tmp: Path, cfg: Path, params: Path, mcap: Path, env: dict[str, str]
) -> tuple[subprocess.Popen[bytes], subprocess.Popen[str]]:
    """`gtsam-dvl node` (its output in tmp/node.log) and `gtsam-dvl play` (waiting for the node's subscriptions),
    each in its process."""
    with open(tmp / "node.log", "w") as out:
        node = subprocess.Popen(
            cli("node", "-c", cfg, "--params", params),
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
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
    return node, player


def _run_node_and_player(
    listener: Listener,
    odometry: list[tuple[float, Any]],
    diagnostics: list[tuple[float, Any]],
    tmp: Path,
    cfg: Path,
    params: Path,
    mcap: Path,
    env: dict[str, str],
) -> tuple[int, str]:
    """The node and the player, the listener receiving meanwhile; SIGINT ends the node once it received every
    message the player published (a loaded machine runs it slower than RATE: it may still be working through its
    queue when the player is done). Returns the node's exit code and what the player printed."""
    node, player = _start(tmp, cfg, params, mcap, env)
    try:
        listener.spin_until(lambda: player.poll() is not None, time.monotonic() + LIMIT_S)
        played = player.communicate(timeout=LIMIT_S)[0]
        published = re.search(r"published (\d+) messages", played)
        assert published, played
        listener.spin_until(
            lambda: _diagnosed(diagnostics, TAKEN) >= int(published[1]) or node.poll() is not None,
            time.monotonic() + LIMIT_S,
        )
        node.send_signal(signal.SIGINT)
        listener.spin_until(lambda: node.poll() is not None, time.monotonic() + LIMIT_S)
        # the final messages: acknowledged by the listener's DDS before the node exited, taken here
        listener.spin_until(_quiet_for(odometry, 1.0), time.monotonic() + LIMIT_S)
    finally:
        for p in (node, player):
            if p.poll() is None:
                p.kill()
            p.wait()
    return node.returncode, played


def _diagnosed(diagnostics: list[tuple[float, Any]], what: str) -> int:
    """From the newest diagnostics, the counts named by the pattern what, summed (TAKEN: the messages the node took
    on its inputs; "written": the writes of calibration_out); 0 before there is any."""
    if not diagnostics:
        return 0
    (status,) = diagnostics[-1][1].status
    pattern = re.compile(rf"\b(?:{what}) (\d+)")
    return sum(int(m[1]) for kv in status.values for m in pattern.finditer(kv.value))


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
    # written while running too (core.py): at least once before the shutdown's write
    assert len(stats["calibration_writes"]) > 1


def test_a_node_killed_leaves_its_calibration_file_whole(
    recorded_log: dict[str, Any], busy_cpus: None, tmp_path: Path
) -> None:
    """SIGKILL mid-run, once the node said it wrote calibration_out WRITES times: the file is whole, and its
    calibration agrees with the log's truth within its sigmas."""
    kept = tmp_path / "kept.toml"
    params = _params(tmp_path / "params.yaml", calibration_out=str(kept), vehicle="auv-test")
    env = ros_env()
    listener = Listener("gtsam_dvl_test_killer", env)
    diagnostics = listener.record(DiagnosticArray, "/diagnostics")
    node, player = _start(tmp_path, recorded_log["cfg"], params, recorded_log["mcap"], env)
    try:
        listener.spin_until(
            lambda: _diagnosed(diagnostics, "written") >= 10 or node.poll() is not None,
            time.monotonic() + LIMIT_S,
        )
        assert node.poll() is None, (tmp_path / "node.log").read_text()
        node.send_signal(signal.SIGKILL)
    finally:
        for p in (node, player):
            if p.poll() is None:
                p.kill()
            p.wait()
        listener.close()
    assert node.returncode == -signal.SIGKILL
    cal = read_calibration(kept)
    assert cal.vehicle == "auv-test" and cal.states == ("scale", "misalignment")
    truth = recorded_log["log"].true_calibration
    scale_sigma, mis_sigma = cal.sigma("scale"), cal.sigma("misalignment")
    assert np.all(np.isfinite(cal.cov)) and 0 < scale_sigma[0] < 0.1 and np.all(mis_sigma < 0.1)
    # b_R_d0 is the identity here: the misalignment's value is R_c
    d_mis = so3_log(rpy_deg_to_matrix(truth.misalignment_deg).T @ cal.values["misalignment"])
    d_scale = float(cal.values["scale"][0]) - truth.scale
    print(
        f"\nkilled after {_diagnosed(diagnostics, 'written')} writes: scale {d_scale / scale_sigma[0]:+.2f} "
        f"sigma, misalignment {np.round(d_mis / mis_sigma, 2)} sigma from the truth"
    )
    assert abs(d_scale) < 4 * scale_sigma[0] and np.all(np.abs(d_mis) < 4 * mis_sigma)
