"""A synthetic log for the I/O tests: random but realistic streams of every kind the reader and writers handle,
built directly (not by the simulator), with a fixed first stamp."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.core.types import (
    BeamData,
    DvlCalibration,
    DvlData,
    GeoOrigin,
    ImuBiases,
    ImuData,
    LogData,
    Mounting,
    Segment,
    TruthData,
)

T0_NS = 1_700_000_123_000_000_000


def make_log(
    duration: float = 60.0, seed: int = 0, beams: bool = True, truth: bool = True
) -> LogData:
    """Random but realistic: 100 Hz IMU, 1 Hz DVL with 4 beams (some invalid pings/beams), 10 Hz truth."""
    rng = np.random.default_rng(seed)
    n, m, k = int(round(duration * 100)), int(duration), int(duration * 10)
    imu = ImuData(
        np.arange(1, n + 1) / 100.0,
        rng.normal(0, 1e-3, (n, 3)) + [0, 0, 7.29e-5],
        rng.normal([0.0, 0.0, 9.79], 1e-3, (n, 3)),
    )
    d_v = rng.normal([2.0, 0.1, -0.05], 0.05, (m, 3))
    valid = rng.random(m) > 0.15
    d_v[~valid] = np.nan
    sig = rng.uniform(0.01, 0.03, m)
    d_cov = np.einsum("k,ij->kij", sig**2, np.eye(3))
    d_cov[:, 0, 1] = d_cov[:, 1, 0] = 1e-5
    beam_data = None
    if beams:
        c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
        d_u = np.broadcast_to([[s, 0, c], [-s, 0, c], [0, s, c], [0, -s, c]], (m, 4, 3)).copy()
        v = np.einsum("kij,kj->ki", d_u, np.nan_to_num(d_v)) + rng.normal(0, 0.01, (m, 4))
        beam_data = BeamData(d_u, v, rng.uniform(10, 30, (m, 4)), rng.random((m, 4)) > 0.1)
    dvl = DvlData(np.arange(1, m + 1, dtype=float), d_v, d_cov, valid, beam_data)
    truth_data = None
    if truth:
        q = Rotation.from_rotvec(rng.normal(0, 0.3, (k, 3))).as_quat()
        truth_data = TruthData(
            np.arange(k) / 10.0,
            rng.normal(0, 100, (k, 3)),
            q,
            rng.normal(0, 2, (k, 3)),
            rng.normal(0, 0.05, (k, 3)),
        )
    mounting = Mounting(
        b_R_d0=rpy_deg_to_matrix([180.0, 0.0, 45.0]), b_p_dvl=np.array([0.5, 0.0, -0.3])
    )
    meta = {
        "scenario": "unit-test",
        "seed": seed,
        "sensors": {
            "imu": {"gyro_noise_density": 4.8e-7, "accel_noise_density": 9.8e-5},
            "dvl": {"sigma": 0.02},
        },
    }
    typed: dict[str, Any] = {}
    if truth:
        typed = {
            "origin": GeoOrigin(30.0, 114.0, -100.0),
            "true_calibration": DvlCalibration(0.9998, (-0.1, 0.2, -0.5)),
            "true_imu_bias": ImuBiases((4e-4, -3e-4, 2e-4), (5e-8, -4e-8, 3e-8)),
            "segments": [
                Segment(0.0, 10.0, "static"),
                Segment(10.0, 40.0, "level", "I"),
                Segment(40.0, 60.0, "turn", "II"),
            ],
        }
    return LogData(imu, dvl, mounting, truth_data, t0_ns=T0_NS, metadata=meta, **typed)
