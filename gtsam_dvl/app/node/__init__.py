"""The ROS 2 node (`gtsam-dvl node`, extra `[ros2]`): the online estimator on live topics.

Modules: settings.py (NodeSettings, load_settings: the parameter file or -c TOML), reorder.py (ReorderBuffer:
messages in stamp order within a bounded window), core.py (NodeCore: decode, order, feed the estimator, make the
outputs; no ROS), ros.py (the rclpy node: subscriptions, publishers, the save service, timers), run.py (run_node:
the command; the one-line error without the extra) and player.py (play_log: a recorded log published on its
topics, for tests, benchmarks and vehicles without a ROS install). Nothing here imports rclpy at import time.
"""

from gtsam_dvl.app.node.settings import NodeSettings, load_settings

__all__ = ["NodeSettings", "load_settings"]
