"""Read a result MCAP written by gtsam_dvl.io.result_writer back into arrays (for `evaluate` and scripts)."""

from __future__ import annotations

import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import Timeline
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.io.reader import read_odometry
from gtsam_dvl.io.result_writer import TOPICS
from gtsam_dvl.io.storage.sources import open_source


@dataclass
class ResultFile:
    """An estimator's result as stored: states with ROS-convention covariances, summary, calibration."""

    path: Path
    estimator: str
    t: np.ndarray  # (N,) s relative to t0_ns
    t0_ns: int
    n_p: np.ndarray  # (N, 3) m
    n_R_b: np.ndarray  # (N, 3, 3)
    n_v: np.ndarray  # (N, 3) m/s
    pose_cov_ros: np.ndarray  # (N, 6, 6) [x, y, z, rot_x, rot_y, rot_z] in map axes
    twist_cov_ros: np.ndarray  # (N, 6, 6) [v (base_link), omega (base_link)]
    summary: dict[str, Any]
    calibration: dict[str, Any]  # calibration.json: calib_joint_cov, b_R_d, config, ...
    timeline: Timeline | None
    source_log: str

    @property
    def position_sigma_m(self) -> np.ndarray:
        return np.sqrt(np.einsum("nii->ni", self.pose_cov_ros[:, :3, :3]))

    @property
    def velocity_sigma_m_s(self) -> np.ndarray:
        """(N, 3) velocity sigmas in map axes (the stored twist covariance is in base_link)."""
        cov = self.n_R_b @ self.twist_cov_ros[:, :3, :3] @ np.transpose(self.n_R_b, (0, 2, 1))
        return np.sqrt(np.einsum("nii->ni", cov))

    @property
    def attitude_sigma_deg(self) -> np.ndarray:
        return np.degrees(np.sqrt(np.einsum("nii->ni", self.pose_cov_ros[:, 3:, 3:])))


def read_result(path: Path | str) -> ResultFile:
    """A result MCAP of `gtsam-dvl smooth`; GtsamDvlError if it is not one."""
    path = Path(path)
    if not path.exists():
        raise GtsamDvlError(f"{path}: no such file")
    src = open_source(path)
    if TOPICS["odometry"] not in src.topics or "summary.json" not in src.attachments:
        raise GtsamDvlError(f"{path}: not a gtsam_dvl result (no {TOPICS['odometry']} or summary.json); "
                            "write one with `gtsam-dvl smooth LOG -o RESULT.mcap`")
    t, n_p, n_q_b, b_v, _b_omega, pose_cov, twist_cov = read_odometry(path, TOPICS["odometry"])
    n_R_b = quat_xyzw_to_matrix(n_q_b)
    summary = json.loads(src.attachments["summary.json"][1])
    calibration = json.loads(src.attachments["calibration.json"][1]) if "calibration.json" in src.attachments else {}
    timeline = None
    if "timeline.npz" in src.attachments:
        with np.load(io.BytesIO(src.attachments["timeline.npz"][1])) as npz:
            timeline = Timeline.from_arrays({k: npz[k] for k in npz.files})
    t0 = src.metadata.get("gtsam_dvl_time", {}).get("t0_ns", "0")
    return ResultFile(path, str(summary.get("estimator", "?")), t, int(t0), n_p, n_R_b,
                      np.einsum("nij,nj->ni", n_R_b, b_v), pose_cov, twist_cov, summary, calibration, timeline,
                      str(src.metadata.get("gtsam_dvl_result", {}).get("source_log", "")))
