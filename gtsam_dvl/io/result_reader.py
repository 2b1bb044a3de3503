"""Read a result log written by gtsam_dvl.io.result_writer back into the NavResult that was written, with its
summary as its typed model (core/summary.py Summary; for `evaluate` and scripts). A result of an older version (no
schema_version: core/config/schema.py) reads as it was written, its summary migrated to this version's model; one
of a newer version than this code knows is refused with one line, and so is a summary that does not fit the
model."""

from __future__ import annotations

import io
import json
from pathlib import Path
from typing import Any

import numpy as np

from gtsam_dvl.core.config.schema import checked_version
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult, StoredResult, Timeline, WaterCurrentProfile
from gtsam_dvl.core.summary import read_summary
from gtsam_dvl.io.result_writer import OPTIONAL_STATE_ARRAYS, STATE_ARRAYS, TOPICS
from gtsam_dvl.io.storage.sources import open_source


def read_result(path: Path | str) -> StoredResult:
    """A result MCAP of `gtsam-dvl smooth`; GtsamDvlError if it is not one."""
    path = Path(path)
    if not path.exists():
        raise GtsamDvlError(f"{path}: no such file")
    src = open_source(path)
    if TOPICS["odometry"] not in src.topics or "summary.json" not in src.attachments:
        raise GtsamDvlError(
            f"{path}: not a gtsam_dvl result (no {TOPICS['odometry']} or summary.json); "
            "write one with `gtsam-dvl smooth LOG -o RESULT.mcap`"
        )
    if "states.npz" not in src.attachments:
        raise GtsamDvlError(
            f"{path}: a result of an older gtsam_dvl (no states.npz attachment); smooth the log again"
        )
    try:
        summary = json.loads(src.attachments["summary.json"][1])
        meta = (
            json.loads(src.attachments["result.json"][1])
            if "result.json" in src.attachments
            else {}
        )
        with np.load(io.BytesIO(src.attachments["states.npz"][1])) as npz:
            arrays = {k: npz[k] for k in npz.files}
        timeline = None
        if "timeline.npz" in src.attachments:
            with np.load(io.BytesIO(src.attachments["timeline.npz"][1])) as npz:
                timeline = Timeline.from_arrays({k: npz[k] for k in npz.files})
        stored_arrays: dict[str, Any] = {name: arrays[name] for name in STATE_ARRAYS}
        stored_arrays.update({name: arrays.get(name) for name in OPTIONAL_STATE_ARRAYS})
        if "time_offset_s" in arrays:
            stored_arrays["time_offset_s"] = float(arrays["time_offset_s"][0])
            stored_arrays["time_offset_sigma_s"] = float(arrays["time_offset_s"][1])
        info = dict(meta.get("info") or {})
        # the water current's profile, in the file's info (io/result_writer.py)
        profile = info.pop("water_current", None)
        result = NavResult(
            estimator=str(meta.get("estimator", summary.get("estimator", "?"))),
            **stored_arrays,
            scale=float(arrays["scale"][0]),
            scale_sigma=float(arrays["scale"][1]),
            t0_ns=int(arrays["t0_ns"][0]),
            timeline=timeline,
            timing_s=dict(meta.get("timing_s") or {}),
            info=info,
            water_current=None
            if not isinstance(profile, dict)
            else WaterCurrentProfile.from_dict(profile),
            config=dict(meta.get("config") or {}),
        )
    except (KeyError, ValueError, json.JSONDecodeError, OSError) as exc:
        raise GtsamDvlError(
            f"{path}: damaged result attachments ({type(exc).__name__}: {exc})"
        ) from None
    record = src.metadata.get("gtsam_dvl_result", {})
    _check_version(record, path)
    try:
        read_options = json.loads(record["read_options"]) if record.get("read_options") else {}
        origin = json.loads(record["source_origin"]) if record.get("source_origin") else None
    except json.JSONDecodeError:
        raise GtsamDvlError(
            f"{path}: damaged result metadata (read_options or source_origin is not JSON)"
        ) from None
    return StoredResult(
        result,
        read_summary(summary, str(path)),
        str(path),
        str(record.get("source_log", "")),
        str(record.get("source_log_relative", "")),
        dict(read_options) if isinstance(read_options, dict) else {},
        str(record.get("source_sha256", "")),
        origin if isinstance(origin, dict) else None,
    )


def _check_version(record: dict[str, str], path: Path) -> None:
    """The result's schema_version (a string in the metadata record; none before it was written) is one this code
    reads, else one GtsamDvlError line."""
    text = record.get("schema_version")
    if text is None:
        return
    version: object = int(text) if text.strip().isdigit() else text
    checked_version(version, f"{path}: result")
