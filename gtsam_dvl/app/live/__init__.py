"""Live view in Foxglove: the online estimator's state served on a Foxglove WebSocket as it is computed.

`LiveView` starts a Foxglove WebSocket server (the foxglove-sdk package, an optional extra: `pip install
gtsam-dvl[live]`) and publishes what an `OnlineEstimator` gives after each DVL epoch; `replay_log` drives a log
through the estimator at X times real time and publishes as it goes (`gtsam-dvl live LOG`). A user's own loop
attaches the view the same way (examples/live_view.py):

    view = LiveView(port=8765)                      # ws://127.0.0.1:8765, open in Foxglove
    if estimator.push_dvl(t, d_v, d_cov):           # an epoch was completed
        view.publish_epoch(estimator.estimate(), counters=estimator.counters)
    view.close()

Topics (log time = the log's t0_ns + t; the same frames as the result MCAP, docs/conventions.md):

- `/tf` (cdr, tf2_msgs/msg/TFMessage): map -> base_link, the estimated pose. `/tf_static`: base_link -> imu_link,
  dvl_link (the nominal mounting), re-sent with the path (a client may connect late).
- `/gtsam_dvl/odometry` (cdr, nav_msgs/msg/Odometry): the pose with its marginal covariance (ROS order, map axes)
  and the body velocity with its covariance; `/gtsam_dvl/path` (cdr, nav_msgs/msg/Path): the path so far, each
  state as estimated when it was processed.
- `/gtsam_dvl/live/scale`, `.../misalignment_deg` (roll, pitch, yaw of R_c, deg, body FLU, ZYX),
  `.../time_offset_s` (dt_d; estimated = false: held at 0), `.../imu_bias` (accelerometer micro-g, gyro deg/h per
  axis, imu_link): JSON, each value as {value, sigma, lower = value - sigma, upper = value + sigma}.
- `/gtsam_dvl/live/status` (JSON): epochs published, the estimator's counters, the last epoch's latency, wall time,
  real-time factor. `/gtsam_dvl/live/log` (foxglove.Log): the health warnings and notes (the log's checks at the
  start, the run's at the end), dropped messages, each counter when it first appears.
- `/raw/imu` (gyro rad/s, specific force m/s^2, imu_link), `/raw/dvl` (d_v m/s in dvl_link, its sigmas, valid),
  `/raw/depth` (m below the surface, pressure Pa): JSON, the input messages as pushed.
- `/ground_truth/odometry`, `/ground_truth/path` (cdr): the simulated truth at the epochs, when the log has it.

Every JSON value is in SI or the unit its name says; a value without a sigma (not estimated, no covariance) is
null, so the Plot panel leaves a gap instead of drawing a wrong band. The path is re-sent at most once per
`path_period_s` of wall time, thinned to at most `MAX_PATH_POSES` poses. Raw messages are encoded only while a
client subscribes to them.

The layout file `layout.json` of this package (written by `layout()`, installed as package data; `gtsam-dvl live
--layout PATH` writes a copy of it) shows these topics: a 3-D panel following
base_link in map with the path, the odometry's covariance and the truth; Plot panels of the calibration and the
biases with their sigma bands; a Log panel and a Raw Messages panel of the status.

Modules: server.py (LiveView, the Foxglove WebSocket server), replay.py (replay_log, serve_log), schemas.py (the
topics and the JSON schemas), layout.py (the Foxglove layout).
"""

from gtsam_dvl.app.live.layout import copy_layout, installed_layout, layout, layout_json
from gtsam_dvl.app.live.replay import ReplayOutcome, parse_speed, replay_log, serve_log
from gtsam_dvl.app.live.schemas import SCHEMAS, TOPICS, band
from gtsam_dvl.app.live.server import (
    BACKLOG_MESSAGES,
    DEFAULT_PORT,
    INSTALL_HINT,
    MAX_PATH_POSES,
    LiveView,
    import_foxglove,
)

__all__ = [
    "BACKLOG_MESSAGES",
    "DEFAULT_PORT",
    "INSTALL_HINT",
    "MAX_PATH_POSES",
    "SCHEMAS",
    "TOPICS",
    "LiveView",
    "ReplayOutcome",
    "band",
    "copy_layout",
    "import_foxglove",
    "installed_layout",
    "layout",
    "layout_json",
    "parse_speed",
    "replay_log",
    "serve_log",
]
