"""The realistic scenarios (issue 31): realistic-straight, realistic-turn and realistic-turns."""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import json

import numpy as np

from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict
from tests.support.scenarios import scenario_raw

# -- existing logs unchanged -------------------------------------------------------------------------------------
# sha256 (first 16 hex digits) of every array, the metadata (without the generator's version) and the true
# calibration of logs made before the realistic scenarios' keys existed (commit 52e1b4d), on this project's x86-64
# machines. A change here means an older scenario's log changed: a new random draw took numbers from an existing
# stream, or a new key changed a default.
GOLDEN_CASES = ("straight-transect", "steady-turn", "beams-depth-gnss")


def golden_log(case: str) -> LogData:
    """60 s of the two underway scenarios (seed 3), and 45 s of paper-3d-short with the per-beam noise model,
    dropouts, outliers, depth and GNSS (seed 11): every random stream simulate() had."""
    if case == "beams-depth-gnss":
        raw = scenario_raw(rates={"dvl_hz": 2.0}, segments=[
            {"kind": "static", "duration_s": 5.0}, {"kind": "level", "duration_s": 20.0, "speed_end_m_s": 1.5},
            {"kind": "turn", "duration_s": 20.0, "heading_change_deg": 90.0, "bank_deg": 10.0}],
            depth={"rate_hz": 5.0, "noise_m": 0.05, "bias_m": 0.1},
            gnss={"rate_hz": 1.0, "max_depth_m": 1000.0})
        raw["dvl"].update(noise_model="beam", dropout_ping_prob=0.05, dropout_beam_prob=0.1, outlier_prob=0.05)
        return simulate(scenario_from_dict(raw, case), 11)
    raw = copy.deepcopy(load_scenario(case).raw)
    raw["segments"] = [{**raw["segments"][0], "duration_s": 60.0}]
    return simulate(scenario_from_dict(raw, case), 3)


def log_digest(log: LogData) -> str:
    arrays: dict[str, np.ndarray] = {}

    def put(prefix: str, obj: object) -> None:
        for f in dataclasses.fields(obj):  # type: ignore[arg-type]
            v = getattr(obj, f.name)
            if isinstance(v, np.ndarray):
                arrays[f"{prefix}.{f.name}"] = v
            elif dataclasses.is_dataclass(v):
                put(f"{prefix}.{f.name}", v)

    for name in ("imu", "dvl", "truth", "depth", "gnss", "mounting"):
        if getattr(log, name) is not None:
            put(name, getattr(log, name))
    h = hashlib.sha256()
    for key in sorted(arrays):
        h.update(key.encode())
        h.update(np.ascontiguousarray(arrays[key]).tobytes())
    metadata = {k: v for k, v in log.metadata.items() if k != "generator"}
    h.update(json.dumps(metadata, sort_keys=True, default=str).encode())
    h.update(repr(log.true_calibration).encode())
    return h.hexdigest()[:16]
