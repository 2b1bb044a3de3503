"""The summary's model (core/summary.py): its JSON Schema kept in docs/summary-schema.json, summaries written before
schema version 8 read into it (the old calibration_hold shapes migrated), one that does not fit is one error line,
and the console lines of every reason a calibration is held."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from gtsam_dvl.core.config.schema import SCHEMA_VERSION
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.summary import (
    DIRECTION_NAMES,
    CalibrationHold,
    Summary,
    hold_in_one_shape,
    parse_summary,
    schema_text,
)

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_DOC = ROOT / "docs" / "summary-schema.json"
# summaries written at version 7 (main at 8a98d19) of realistic-straight (seed 1, 400 s) with the defaults
V7 = Path(__file__).parent / "summaries_v7"

NOMINAL_PAYS_NOT = {"chi2_gain": 0.6, "chi2_limit": 9.49, "level": 0.95, "pays": False}


def _v7(mode: str) -> dict[str, Any]:
    return json.loads((V7 / f"realistic-straight-{mode}.json").read_text())


def test_schema_doc_is_current() -> None:
    """docs/summary-schema.json is the model's JSON Schema as this code generates it."""
    regenerate = (
        "python -c 'from gtsam_dvl.core.summary import schema_text; print(schema_text(), end=\"\")' "
        "> docs/summary-schema.json"
    )
    assert SCHEMA_DOC.read_text() == schema_text(), f"the summary's model changed: {regenerate}"
    schema = json.loads(SCHEMA_DOC.read_text())
    assert schema["anyOf"] == [{"$ref": "#/$defs/Summary"}, {"$ref": "#/$defs/IoDvlcSummary"}]
    hold = schema["$defs"]["CalibrationHold"]
    assert hold["additionalProperties"] is False and {"reason", "why", "held"} <= set(
        hold["required"]
    )


def test_ekf_summary_of_version_7_reads() -> None:
    """The EKF's nominal hold named its states (["scale", "misalignment"]): read as the four directions they stand
    for, their information and direction unknown (None), the reason nominal_check, its words kept."""
    old = _v7("ekf")
    assert "schema_version" not in old and old["calibration_hold"]["held"] == [
        "scale",
        "misalignment",
    ]
    s = parse_summary(old, "v7 ekf")
    assert isinstance(s, Summary) and s.schema_version == SCHEMA_VERSION
    hold = s.calibration_hold
    assert hold is not None and hold.reason == "nominal_check"
    assert [h.mostly for h in hold.held] == list(DIRECTION_NAMES)
    assert all(h.information is None and h.direction is None for h in hold.held)
    assert hold.why == old["calibration_hold"]["why"]
    assert hold.lines() == [
        "  held at the nominal calibration: scale, misalignment roll, misalignment pitch, misalignment yaw",
        f"    why: {hold.why}",
    ]
    # everything else as written
    assert s.errors is not None and s.errors.scale_ppm == old["errors"]["scale_ppm"]
    assert s.health is not None and s.health.warnings == old["health"]["warnings"]


@pytest.mark.parametrize("mode", ["batch", "online"])
def test_batch_and_online_summaries_of_version_7_read(mode: str) -> None:
    """Their held directions were objects already; the reason is filled in, and the online estimator's words,
    which it did not write."""
    old = _v7(mode)
    s = parse_summary(old, f"v7 {mode}")
    assert isinstance(s, Summary)
    hold = s.calibration_hold
    assert hold is not None and hold.reason == "nominal_check" and len(hold.held) == 4
    assert [h.information for h in hold.held] == [
        h["information"] for h in old["calibration_hold"]["held"]
    ]
    assert hold.why.startswith("held at the nominal calibration")
    if mode == "batch":
        assert hold.why == old["calibration_hold"]["why"] and hold.consistent is True
    # written back: the file's keys, plus schema_version and the hold's new keys
    back = s.to_json_dict()
    assert set(back) == set(old) | {"schema_version"}
    assert back["info"] == old["info"]


def test_old_hold_shapes_in_one_shape() -> None:
    """Each shape calibration_hold had before version 8, by estimator and outcome."""
    ekf_paid = hold_in_one_shape({"nominal": {**NOMINAL_PAYS_NOT, "pays": True}, "held": []})
    assert (
        ekf_paid["reason"] == "none"
        and ekf_paid["held"] == []
        and "nothing held" in ekf_paid["why"]
    )
    direction = dict.fromkeys(DIRECTION_NAMES, 0.0)
    weak = {"information": 0.05, "mostly": "misalignment yaw", "direction": direction}
    released = hold_in_one_shape(
        {
            "threshold": 0.25,
            "information": [0.05, 2.0, 3.0, 4.0],
            "held": [],
            "released": [weak],
            "chi2_increase": 9.0,
            "chi2_limit_99": 6.6,
            "consistent": False,
            "why": "not held: pinning cost chi^2 9.0 > 6.6 (99 %)",
        }
    )
    assert released["reason"] == "none" and released["released"] == [weak]
    online_weak = hold_in_one_shape(
        {
            "threshold": 0.25,
            "information": [0.05, 2.0, 3.0, 4.0],
            "held": [weak],
            "nominal": {**NOMINAL_PAYS_NOT, "pays": True},
        }
    )
    assert online_weak["reason"] == "weak_directions"
    assert online_weak["why"] == (
        "held at the prior: the run informs misalignment yaw less than 0.25 of their prior's information "
        "([priors] hold_weak_information)"
    )
    for hold in (ekf_paid, released, online_weak):
        CalibrationHold.model_validate(hold)
        assert hold_in_one_shape(hold) == hold  # a hold in the one shape is left as it is


def test_console_lines_of_every_reason() -> None:
    direction = dict.fromkeys(DIRECTION_NAMES, 0.0)
    yaw = {"information": 0.05, "mostly": "misalignment yaw", "direction": direction}
    weak = CalibrationHold.model_validate(
        {"reason": "weak_directions", "why": "held at the prior: ...", "held": [yaw]}
    )
    assert weak.lines() == [
        "  held at the prior (the run informs them little) (the data's information along each direction, in "
        "units of its prior's): misalignment yaw 0.05",
        "    why: held at the prior: ...",
    ]
    released = CalibrationHold.model_validate(
        {"reason": "none", "why": "not held: ...", "held": [], "released": [yaw]}
    )
    assert released.lines()[0].startswith("  released (estimated, not held)")
    assert CalibrationHold(reason="none", why="nothing held", held=[]).lines() == []


def test_newer_summary_is_one_line() -> None:
    with pytest.raises(GtsamDvlError) as err:
        parse_summary({**_v7("ekf"), "schema_version": SCHEMA_VERSION + 1}, "s.json")
    assert str(err.value).startswith(
        f"s.json: summary: schema_version {SCHEMA_VERSION + 1} is newer"
    )


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"states": "many"}, "s.json: the summary's states: input should be a valid integer"),
        ({"colour": "red"}, "s.json: the summary's colour: extra inputs are not permitted"),
        ({"scale": None}, "s.json: the summary's scale: input should be a valid dictionary"),
    ],
)
def test_summary_that_does_not_fit_is_one_line(change: dict[str, Any], message: str) -> None:
    with pytest.raises(GtsamDvlError) as err:
        parse_summary({**_v7("batch"), **change}, "s.json")
    text = str(err.value)
    assert text.startswith(message) and text.endswith("; smooth the log again") and "\n" not in text
