"""The live view: a Foxglove WebSocket client subscribes to the pose and calibration
channels while a short simulated log is replayed as fast as possible; the decoded messages are the online
estimator's per-epoch estimates (its NavResult and timeline) to 1e-9, and the port is free afterwards.

The client speaks the Foxglove WebSocket protocol (v1; subprotocol foxglove.sdk.v1 for foxglove-sdk's server):
JSON "advertise" lists the channels, the client sends "subscribe", the server sends binary frames (opcode 1,
uint32 subscription id, uint64 log time in ns, payload). ROS 2 payloads are decoded with the independent rosbags
library.
"""

from __future__ import annotations

import json
import math
import struct
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pytest

# foxglove-sdk, websockets and rosbags are in the test extra (pyproject.toml): imported, not skipped, so that a
# missing one fails the suite instead of hiding the live view's test
import websockets.sync.client as websockets_sync
from rosbags import typesys
from websockets.exceptions import ConnectionClosed, ConnectionClosedOK

from gtsam_dvl.app import live
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.core.types import DvlData, ImuData, LogData, TruthData
from gtsam_dvl.estimators.online import OnlineEstimator
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

T_END_S = 220.0  # paper-3d-short cut here: 120 s static, then surge and the start of the descent
# foxglove-sdk's server speaks the v1 protocol under the name foxglove.sdk.v1 (and refuses a handshake without
# it); foxglove.websocket.v1 is the name of the same protocol in the ws-protocol specification
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]
SUBSCRIBED = ("odometry", "tf", "scale", "misalignment", "imu_bias", "truth", "status")


def _cut(log: LogData, t_end: float) -> LogData:
    i, d = log.imu.t <= t_end, log.dvl.t <= t_end
    tr = log.truth
    assert tr is not None
    k = tr.t <= t_end
    return replace(
        log,
        imu=ImuData(log.imu.t[i], log.imu.b_omega[i], log.imu.b_f[i]),
        dvl=DvlData(log.dvl.t[d], log.dvl.d_v[d], log.dvl.d_cov[d], log.dvl.valid[d], None),
        truth=TruthData(tr.t[k], tr.n_p[k], tr.n_q_b[k], tr.n_v[k], tr.b_omega[k]),
    )


@dataclass
class Received:
    """What the client got: per topic, (log time ns, payload) in arrival order."""

    advertised: dict[str, dict[str, Any]] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)
    error: BaseException | None = None
    closed: ConnectionClosed | None = None  # how the server ended the connection
    after_final: int = 0  # frames received after the final epoch's status


def _reader(ws: Any, subs: dict[int, str], out: Received, done: threading.Event) -> None:
    """Collect binary message frames until the server closes the connection (or 20 s without a frame)."""
    final_seen = False
    try:
        while not done.is_set():
            try:
                frame = ws.recv(timeout=20.0)
            except TimeoutError:
                break
            except ConnectionClosed as closed:
                out.closed = closed
                break
            out.after_final += final_seen
            if isinstance(frame, str):
                continue
            if frame[0] != 1:  # 2 = time, others not subscribed
                continue
            sub_id, log_ns = struct.unpack_from("<IQ", frame, 1)
            topic = subs[sub_id]
            payload = bytes(frame[13:])
            out.messages.setdefault(topic, []).append((log_ns, payload))
            final_seen = final_seen or (
                topic == live.TOPICS["status"] and json.loads(payload)["final"]
            )
    except BaseException as exc:  # surfaced by the test
        out.error = exc


@pytest.fixture(scope="module")
def session() -> dict[str, Any]:
    log = _cut(simulate(load_scenario("paper-3d-short"), 3), T_END_S)
    view = live.LiveView(port=0, t0_ns=log.t0_ns, mounting=log.mounting)
    port = view.port
    out = Received()
    # no HTTP proxy for localhost
    connect = websockets_sync.connect(
        view.url, subprotocols=SUBPROTOCOLS, open_timeout=10, max_size=None, proxy=None
    )
    try:
        with connect as ws:
            wanted = {live.TOPICS[k] for k in SUBSCRIBED}
            deadline = time.monotonic() + 10
            while not wanted <= out.advertised.keys() and time.monotonic() < deadline:
                msg = json.loads(ws.recv(timeout=10))
                if msg.get("op") == "advertise":
                    out.advertised.update({c["topic"]: c for c in msg["channels"]})
            assert wanted <= out.advertised.keys(), (
                f"not advertised: {wanted - out.advertised.keys()}"
            )
            subs = {i + 1: topic for i, topic in enumerate(sorted(wanted))}
            ws.send(
                json.dumps(
                    {
                        "op": "subscribe",
                        "subscriptions": [
                            {"id": i, "channelId": out.advertised[t]["id"]} for i, t in subs.items()
                        ],
                    }
                )
            )
            assert view.wait_for_subscribers(sorted(wanted), timeout_s=10)
            done = threading.Event()
            reader = threading.Thread(target=_reader, args=(ws, subs, out, done), daemon=True)
            reader.start()
            estimator = OnlineEstimator.for_log(log, EstimatorConfig.paper())
            t0 = time.perf_counter()
            outcome = live.replay_log(log, view, estimator, speed=math.inf)
            replay_s = time.perf_counter() - t0
            view.close()  # at once, as `live --exit-when-done` does: the client still gets everything, then a close
            reader.join(timeout=20)
            done.set()
    finally:
        view.close()
    return {
        "log": log,
        "out": out,
        "outcome": outcome,
        "result": estimator.result(log.t0_ns),
        "port": port,
        "replay_s": replay_s,
    }


def _index(result: Any, t0_ns: int, log_ns: int) -> int:
    """The epoch of the result whose stamp is log_ns (stamps are t0_ns + round(t * 1e9))."""
    i = int(np.argmin(np.abs(result.t - (log_ns - t0_ns) * 1e-9)))
    assert t0_ns + round(result.t[i] * 1e9) == log_ns
    return i


def test_channels_are_advertised_with_their_schemas(session: dict[str, Any]) -> None:
    adv = session["out"].advertised
    assert adv[live.TOPICS["odometry"]]["schemaName"] == "nav_msgs/msg/Odometry"
    assert adv[live.TOPICS["odometry"]]["encoding"] == "cdr"
    assert adv[live.TOPICS["tf"]]["schemaName"] == "tf2_msgs/msg/TFMessage"
    scale = adv[live.TOPICS["scale"]]
    assert (
        scale["encoding"] == "json"
        and json.loads(scale["schema"])["properties"]["sigma"]["type"][0] == "number"
    )


def test_pose_messages_are_the_estimators_epochs(session: dict[str, Any]) -> None:
    out, result, log = session["out"], session["result"], session["log"]
    assert out.error is None, out.error
    store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
    odom = out.messages[live.TOPICS["odometry"]]
    published = session["outcome"].epochs_published
    print(
        f"replay {session['replay_s']:.2f} s of {T_END_S:.0f} s log; {published} epochs published, "
        f"{len(odom)} odometry messages received; result has {len(result.t)} epochs"
    )
    assert len(odom) >= 0.9 * published and len(odom) >= 50
    worst = {"p": 0.0, "q": 0.0, "cov": 0.0}
    for log_ns, payload in odom[:-1]:  # the last is the final estimate (after finish)
        m = store.deserialize_cdr(payload, "nav_msgs/msg/Odometry")
        assert m.header.frame_id == "map" and m.child_frame_id == "base_link"
        assert m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec == log_ns
        i = _index(result, log.t0_ns, log_ns)
        pose = m.pose.pose
        p = np.array([pose.position.x, pose.position.y, pose.position.z])
        q = np.array(
            [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w]
        )
        R = result.n_R_b[i]
        worst["p"] = max(worst["p"], float(np.abs(p - result.n_p[i]).max()))
        worst["q"] = max(worst["q"], float(np.abs(quat_xyzw_to_matrix(q) - R).max()))
        # ROS order (x, y, z, rot x, rot y, rot z) in map axes; GTSAM's pose tangent is [rot, trans] in body axes
        C = np.asarray(m.pose.covariance).reshape(6, 6)
        P = result.pose_cov[i]
        expected = np.block(
            [[R @ P[3:, 3:] @ R.T, R @ P[3:, :3] @ R.T], [R @ P[:3, 3:] @ R.T, R @ P[:3, :3] @ R.T]]
        )
        worst["cov"] = max(worst["cov"], float(np.abs(C - expected).max() / np.abs(expected).max()))
    print(
        f"worst differences: position {worst['p']:.1e} m, rotation {worst['q']:.1e}, covariance "
        f"{worst['cov']:.1e} (relative)"
    )
    assert worst["p"] < 1e-9 and worst["q"] < 1e-9 and worst["cov"] < 1e-9
    for log_ns, payload in out.messages[live.TOPICS["tf"]][:5]:
        tf = store.deserialize_cdr(payload, "tf2_msgs/msg/TFMessage").transforms[0]
        assert (tf.header.frame_id, tf.child_frame_id) == ("map", "base_link")
        i = _index(result, log.t0_ns, log_ns)
        tr = tf.transform.translation
        assert np.abs(np.array([tr.x, tr.y, tr.z]) - result.n_p[i]).max() < 1e-9


def test_calibration_messages_match_the_timeline_and_final_estimate(
    session: dict[str, Any],
) -> None:
    out, result, log = session["out"], session["result"], session["log"]
    tl = result.timeline
    scale = [(ns, json.loads(b)) for ns, b in out.messages[live.TOPICS["scale"]]]
    mis = [(ns, json.loads(b)) for ns, b in out.messages[live.TOPICS["misalignment"]]]
    bias = [(ns, json.loads(b)) for ns, b in out.messages[live.TOPICS["imu_bias"]]]
    assert scale[-1][1]["final"] and not any(m["final"] for _, m in scale[:-1])
    for ns, m in scale[:-1]:
        i = _index(result, log.t0_ns, ns)
        assert m["value"] == pytest.approx(tl.scale[i], abs=1e-9)
        assert m["sigma"] == pytest.approx(tl.scale_sigma[i], abs=1e-9)
        assert m["lower"] == pytest.approx(tl.scale[i] - tl.scale_sigma[i], abs=1e-9)
        assert m["upper"] == pytest.approx(tl.scale[i] + tl.scale_sigma[i], abs=1e-9)
    for ns, m in mis[:-1]:
        i = _index(result, log.t0_ns, ns)
        got = np.array([[m[a]["value"], m[a]["sigma"]] for a in ("roll", "pitch", "yaw")])
        assert np.abs(got[:, 0] - tl.misalignment_deg[i]).max() < 1e-9
        assert np.abs(got[:, 1] - tl.misalignment_sigma_deg[i]).max() < 1e-9
    for ns, m in bias[:-1]:
        i = _index(result, log.t0_ns, ns)
        acc = np.array([m["accel_ug"][a]["value"] for a in "xyz"])
        gyro_sigma = np.array([m["gyro_deg_per_h"][a]["sigma"] for a in "xyz"])
        assert np.abs(acc - tl.accel_bias_ug[i]).max() < 1e-9
        assert np.abs(gyro_sigma - tl.gyro_bias_sigma_deg_per_h[i]).max() < 1e-9
    final = scale[-1][1]
    assert final["value"] == pytest.approx(result.scale, abs=1e-9)
    assert final["sigma"] == pytest.approx(result.scale_sigma, abs=1e-9)
    # the run is 100 s of motion: the scale has left its prior (0.8 +- 0.5) for the truth, within 3 sigma
    true_k = log.true_calibration.scale if log.true_calibration is not None else 0.9998
    print(
        f"final scale {final['value']:.5f} +- {final['sigma']:.5f} (truth {true_k}); {len(scale)} scale messages"
    )
    assert abs(final["value"] - true_k) < 3 * final["sigma"] and final["sigma"] < 0.05


def test_truth_and_status(session: dict[str, Any]) -> None:
    out, log = session["out"], session["log"]
    store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
    truth = log.truth
    assert truth is not None
    for ns, payload in out.messages[live.TOPICS["truth"]][:10]:
        m = store.deserialize_cdr(payload, "nav_msgs/msg/Odometry")
        k = int(np.argmin(np.abs(truth.t - (ns - log.t0_ns) * 1e-9)))
        p = m.pose.pose.position
        assert np.abs(np.array([p.x, p.y, p.z]) - truth.n_p[k]).max() < 1e-9
    last = json.loads(out.messages[live.TOPICS["status"]][-1][1])
    assert last["final"] and last["counters"] == session["result"].info["counters"]


def test_final_status_has_the_consoles_numbers(session: dict[str, Any]) -> None:
    """The last status message and the console's last line (ReplayOutcome.describe) are one computation: the same
    epochs, wall time, log time and real-time factor. The client connected and subscribed before the replay (as
    --wait does): that time is not in the wall time."""
    outcome = session["outcome"]
    statuses = [json.loads(b) for _, b in session["out"].messages[live.TOPICS["status"]]]
    last = statuses[-1]
    print(
        outcome.describe(),
        "| final status:",
        {k: last[k] for k in ("epochs", "wall_s", "log_s", "real_time_factor")},
    )
    # one status per epoch, none missed
    assert last["epochs"] == outcome.epochs_published == len(statuses)
    assert last["wall_s"] == outcome.wall_s and last["log_s"] == outcome.log_s
    assert (
        last["real_time_factor"]
        == outcome.real_time_factor
        == pytest.approx(outcome.log_s / outcome.wall_s)
    )
    # the replay only, not the client's connection before it
    assert outcome.wall_s <= session["replay_s"]
    log = session["log"]
    assert outcome.log_s == pytest.approx(
        float(log.imu.t[-1] - min(log.imu.t[0], log.dvl.t[0])), abs=1e-9
    )
    assert f"{outcome.real_time_factor:.1f}x real time" in outcome.describe()
    assert f"{last['epochs']} epochs published" in outcome.describe()


def test_the_server_closes_the_connection_normally_after_the_replay(
    session: dict[str, Any],
) -> None:
    """Closed at the end of the replay, the server sends a close frame and the closing handshake completes (not a
    dropped socket, 1006) after every message: the final epoch's status arrives before it. foxglove-sdk's server
    sends its close frame without a status code, which a client reports as 1005 (no status, a normal close)."""
    out = session["out"]
    closed = out.closed
    print(
        f"close: received {closed.rcvd if closed else None}, sent {closed.sent if closed else None}; "
        f"{out.after_final} frames after the final status"
    )
    # a clean closing handshake, not a dropped socket
    assert isinstance(closed, ConnectionClosedOK), closed
    assert closed.rcvd is not None and closed.rcvd.code in (
        1000,
        1005,
    )  # the server's close frame arrived
    assert json.loads(out.messages[live.TOPICS["status"]][-1][1])["final"]


def test_port_is_free_after_close(session: dict[str, Any]) -> None:
    port = session["port"]
    again = live.LiveView(port=port)
    try:
        assert again.port == port
    finally:
        again.close()


def test_layout_file_is_the_generated_one_and_names_published_topics() -> None:
    from importlib import resources

    # the file as the installed package holds it (package data), not a path into the repository
    installed = (
        resources.files("gtsam_dvl.app.live").joinpath("layout.json").read_text(encoding="utf-8")
    )
    assert installed == live.installed_layout()
    assert installed == live.layout_json(), (
        "regenerate: python -m gtsam_dvl.app.live --write-layout"
    )
    text = json.dumps(live.layout())
    topics = set(live.TOPICS.values())
    for series in (s for c in live.layout()["configById"].values() for s in c.get("paths", [])):
        assert series["value"].split(".")[0] in topics, series
    assert live.TOPICS["odometry"] in text and live.TOPICS["log"] in text


def test_without_foxglove_the_command_says_how_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    import sys

    from typer.testing import CliRunner

    from gtsam_dvl.app.cli import app

    monkeypatch.setitem(sys.modules, "foxglove", None)  # import foxglove raises ImportError
    with pytest.raises(GtsamDvlError, match="pip install"):
        live.import_foxglove()
    res = CliRunner().invoke(app, ["live", "missing.mcap"])
    assert res.exit_code == 1
    assert "pip install 'gtsam-dvl[live]'" in res.output and "Traceback" not in res.output


def test_layout_option_writes_a_copy_and_never_overwrites(tmp_path: Any) -> None:
    from typer.testing import CliRunner

    from gtsam_dvl.app.cli import app

    out = tmp_path / "my_layout.json"
    # no LOG: only the layout, no foxglove needed
    res = CliRunner().invoke(app, ["live", "--layout", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_text(encoding="utf-8") == live.installed_layout() and str(out) in res.output
    json.loads(out.read_text(encoding="utf-8"))  # a JSON file Foxglove can import
    out.write_text("mine")
    again = CliRunner().invoke(app, ["live", "--layout", str(out)])
    assert (
        again.exit_code == 1
        and "does not overwrite" in again.output
        and len(again.output.splitlines()) == 1
    )
    assert out.read_text() == "mine"
    missing = CliRunner().invoke(app, ["live", "--layout", str(tmp_path / "no" / "layout.json")])
    assert (
        missing.exit_code == 1
        and "create it first" in missing.output
        and not (tmp_path / "no").exists()
    )
    neither = CliRunner().invoke(app, ["live"])
    assert (
        neither.exit_code == 1
        and "--layout" in neither.output
        and "Traceback" not in neither.output
    )


def test_every_interface_prints_addresses_a_client_can_open() -> None:
    """Served on 0.0.0.0, the view names ws://127.0.0.1:PORT (a client connects to it) and this machine's name and
    network address, never ws://0.0.0.0, which a browser cannot open."""
    import socket

    from gtsam_dvl.app.live.server import reachable_urls

    assert reachable_urls("127.0.0.1", 8765) == ["ws://127.0.0.1:8765"]
    assert reachable_urls("::1", 8765) == ["ws://[::1]:8765"]
    assert reachable_urls("::", 8765)[0] == "ws://[::1]:8765"
    with live.LiveView(port=0, host="0.0.0.0") as view:
        urls = view.urls
        print(urls)
        assert view.url == urls[0] == f"ws://127.0.0.1:{view.port}"
        assert f"ws://{socket.gethostname()}:{view.port}" in urls
        assert not any("0.0.0.0" in u for u in urls) and all(
            u.endswith(f":{view.port}") for u in urls
        )
        with websockets_sync.connect(
            view.url, subprotocols=SUBPROTOCOLS, open_timeout=5, proxy=None
        ) as ws:
            assert json.loads(ws.recv(timeout=5))["op"] == "serverInfo"


def test_speed_option() -> None:
    assert live.parse_speed("max") == math.inf and live.parse_speed("0") == math.inf
    assert live.parse_speed("2.5") == 2.5
    with pytest.raises(GtsamDvlError, match="--speed"):
        live.parse_speed("-1")
    with pytest.raises(GtsamDvlError, match="--speed"):
        live.parse_speed("fast")


def test_live_command_replays_a_log_file(session: dict[str, Any], tmp_path: Any) -> None:
    from typer.testing import CliRunner

    from gtsam_dvl.app.cli import app
    from gtsam_dvl.io.writer import write_log

    path = tmp_path / "short.mcap"
    write_log(path, session["log"])
    t0 = time.perf_counter()
    res = CliRunner().invoke(
        app,
        [
            "live",
            str(path),
            "--speed",
            "max",
            "--port",
            "0",
            "--exit-when-done",
            "-c",
            "paper",
            "--host",
            "0.0.0.0",
        ],
    )
    print(res.output, f"({time.perf_counter() - t0:.1f} s)")
    assert res.exit_code == 0, res.output
    assert "live view on ws://127.0.0.1:" in res.output and "health:" in res.output
    # served on 0.0.0.0
    assert "from other machines: ws://" in res.output and "ws://0.0.0.0" not in res.output
    published = int(res.output.split(" epochs published")[0].rsplit(" ", 1)[1])
    # the file replays as the in-memory log does
    assert published == session["outcome"].epochs_published


def test_example_attaches_the_view_in_a_users_loop() -> None:
    import subprocess
    import sys
    from pathlib import Path

    example = Path(__file__).resolve().parents[2] / "examples" / "live_view.py"
    proc = subprocess.run(
        [sys.executable, str(example), "--speed", "0", "--port", "0", "--duration-s", "150"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "live view on ws://127.0.0.1:" in proc.stdout and "final scale" in proc.stdout


def test_replay_is_paced_at_the_requested_speed(session: dict[str, Any]) -> None:
    """With a fake clock that only sleeps advance: the replay ends when the wall clock reaches the log's span
    divided by the speed (each IMU piece and ping pushed when its stamp is due)."""
    log = _cut(session["log"], 150.0)
    now = [0.0]
    sleeps: list[float] = []

    def sleep(s: float) -> None:
        sleeps.append(s)
        now[0] += s

    with live.LiveView(port=0, t0_ns=log.t0_ns) as view:
        # the view waited 100 s for a client (--wait): not part of the replay's wall time
        now[0] = 100.0
        out = live.replay_log(
            log,
            view,
            OnlineEstimator.for_log(log, EstimatorConfig.paper()),
            speed=25.0,
            health=False,
            clock=lambda: now[0],
            sleep=sleep,
        )
    span = float(log.imu.t[-1] - log.imu.t[0])
    print(f"{len(sleeps)} sleeps, fake wall {out.wall_s:.3f} s for {span:.0f} s of log at 25x")
    assert out.wall_s == pytest.approx(span / 25.0, abs=0.1 / 25.0)
    assert (
        out.real_time_factor == pytest.approx(25.0, rel=0.01)
        and "25.0x real time" in out.describe()
    )
    assert len(sleeps) > span / 0.1 * 0.9  # the IMU in pieces of about 0.1 s
