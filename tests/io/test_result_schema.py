"""A result states its schema_version (core/config/schema.py): in its "gtsam_dvl_result" metadata record and its
config.json, which `-c` reads back; a result of an older version (no schema_version) still reads; one of a newer
version than this code knows is one error line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.metrics import summary
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.config.schema import SCHEMA_VERSION
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.result import NavResult
from gtsam_dvl.core.summary import Summary
from gtsam_dvl.io import result_writer
from gtsam_dvl.io.mcap.writer import McapLogWriter
from gtsam_dvl.io.read_options import ReadOptions
from gtsam_dvl.io.result_reader import read_result
from gtsam_dvl.io.storage.sources import open_source
from tests.support.synthetic_log import make_log

ROOT = Path(__file__).resolve().parents[2]


def _write(path: Path, written_summary: dict | None = None) -> Path:
    """A small result (three states) of a synthetic log, its configuration a non-default one; written_summary: the
    summary written instead of the result's."""
    n = 3
    cfg = EstimatorConfig(dvl={"huber_k": 2.0})
    result = NavResult(
        "batch",
        np.arange(n, dtype=float),
        np.zeros((n, 3)),
        np.tile(np.eye(3), (n, 1, 1)),
        np.zeros((n, 3)),
        np.tile(np.eye(6) * 1e-4, (n, 1, 1)),
        np.tile(np.eye(3) * 1e-4, (n, 1, 1)),
        b_R_d0=np.eye(3),
        accel_bias=np.zeros(3),
        gyro_bias=np.zeros(3),
        bias_cov=np.eye(6) * 1e-8,
        scale=1.0,
        scale_sigma=1e-3,
        b_R_d=np.eye(3),
        b_R_d_cov=np.eye(3) * 1e-6,
        config=cfg.to_dict(),
    )
    log = make_log(5.0, seed=1)
    return result_writer.write_result_log(
        path, result, log, written_summary or summary(result, log), ReadOptions(repair=True)
    )


def test_result_states_its_schema_version_and_its_config_reads_back(tmp_path: Path) -> None:
    path = _write(tmp_path / "result.mcap")
    src = open_source(path)
    assert src.metadata["gtsam_dvl_result"]["schema_version"] == str(SCHEMA_VERSION)
    config_json = json.loads(src.attachments["config.json"][1])
    assert config_json["schema_version"] == SCHEMA_VERSION
    (tmp_path / "config.json").write_bytes(src.attachments["config.json"][1])
    assert EstimatorConfig.load(tmp_path / "config.json") == EstimatorConfig(dvl={"huber_k": 2.0})
    stored = read_result(path)
    assert stored.read_options["repair"] is True


def test_result_of_an_older_version_reads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Written as before schema_version existed (no such key in the record): it reads as written."""
    add_metadata = McapLogWriter.add_metadata

    def without_version(self: McapLogWriter, name: str, data: dict[str, str]) -> None:
        add_metadata(self, name, {k: v for k, v in data.items() if k != "schema_version"})

    monkeypatch.setattr(McapLogWriter, "add_metadata", without_version)
    path = _write(tmp_path / "old.mcap")
    monkeypatch.undo()
    assert "schema_version" not in open_source(path).metadata["gtsam_dvl_result"]
    stored = read_result(path)
    assert stored.result.estimator == "batch" and len(stored.result.t) == 3


def test_result_of_a_newer_version_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(result_writer, "SCHEMA_VERSION", SCHEMA_VERSION + 1)
    path = _write(tmp_path / "new.mcap")
    with pytest.raises(GtsamDvlError) as err:
        read_result(path)
    assert str(err.value) == (
        f"{path}: result: schema_version {SCHEMA_VERSION + 1} is newer than this gtsam_dvl reads (at most "
        f"{SCHEMA_VERSION}): written by a newer version; upgrade gtsam_dvl to read it"
    )


def test_result_with_a_summary_of_version_7_reads_into_the_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A result written at version 7 (no schema_version in its record or summary) whose summary has the EKF's
    calibration_hold of then (the names ["scale", "misalignment"]): read_result gives it as the typed Summary,
    the hold in the one shape (core/summary.py)."""
    old = json.loads((ROOT / "tests/core/summaries_v7/realistic-straight-ekf.json").read_text())
    add_metadata = McapLogWriter.add_metadata

    def as_version_7(self: McapLogWriter, name: str, data: dict[str, str]) -> None:
        add_metadata(self, name, {k: v for k, v in data.items() if k != "schema_version"})

    monkeypatch.setattr(McapLogWriter, "add_metadata", as_version_7)
    # (this version's writer checks the summary against the model: not so then)
    monkeypatch.setattr(result_writer.Summary, "model_validate", lambda data: data)
    path = _write(tmp_path / "v7.mcap", old)
    monkeypatch.undo()
    stored = read_result(path)
    assert isinstance(stored.summary, Summary) and stored.summary.estimator == "ekf"
    hold = stored.summary.calibration_hold
    assert hold is not None and hold.reason == "nominal_check" and len(hold.held) == 4
    assert hold.why == old["calibration_hold"]["why"]


def test_result_whose_summary_does_not_fit_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(result_writer.Summary, "model_validate", lambda data: data)
    path = _write(tmp_path / "bad.mcap", {"estimator": "batch", "schema_version": SCHEMA_VERSION})
    monkeypatch.undo()
    with pytest.raises(GtsamDvlError) as err:
        read_result(path)
    assert str(err.value) == f"{path}: the summary's scale: field required; smooth the log again"
