"""estimators/inputs/prepare.py: what each estimator supports, read from the shared-state registry, refused once
by the one runner with one line naming every request it does not meet and the estimators that do; the
combinations no estimator does; the configuration resolved for the log and kept as given."""

from __future__ import annotations

import pytest

from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.states import STATES
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.inputs.prepare import (
    TRAJECTORY_MODES,
    prepare,
    supports_state,
    unsupported,
)
from gtsam_dvl.estimators.run import MODES, run_estimator
from tests.support.calibration import calibration_at_truth
from tests.support.water import with_water_track


def _config(**updates: dict[str, object]) -> EstimatorConfig:
    cfg = EstimatorConfig()
    return cfg.model_copy(
        update={k: getattr(cfg, k).model_copy(update=v) for k, v in updates.items()}
    )


LEVER_AND_WATER_SCALE = _config(
    dvl={"estimate_lever_arm": True},
    current={"water_track": "use", "water_track_scale": True},
)


def test_supports_follow_the_shared_state_registry() -> None:
    """A state the EKF's error state lacks is refused by the EKF, one without an iSAM2 threshold by both
    online modes; the batch smoother estimates every state."""
    assert set(TRAJECTORY_MODES) | {"io-dvlc"} == set(MODES)
    for s in STATES:
        assert supports_state("batch", s)
        assert supports_state("ekf", s) == s.ekf
        assert supports_state("online", s) == supports_state("online-full", s)
        assert supports_state("online", s) == (s.relinearization is not None)


def test_every_request_an_estimator_does_not_meet_is_named_with_who_does() -> None:
    cal = object()  # only its presence is read
    assert unsupported("batch", LEVER_AND_WATER_SCALE, None) == []
    assert unsupported("online", LEVER_AND_WATER_SCALE, None) == [
        "[dvl] estimate_lever_arm is batch only"
    ]
    assert unsupported("ekf", LEVER_AND_WATER_SCALE, cal) == [  # type: ignore[arg-type]
        "[dvl] estimate_lever_arm is batch only",
        "[current] water_track_scale is batch and online only",
    ]
    assert unsupported("io-dvlc", EstimatorConfig(), cal) == [  # type: ignore[arg-type]
        "a vehicle calibration as the prior is batch, online and ekf only"
    ]
    assert unsupported("ekf", EstimatorConfig(), cal) == []  # type: ignore[arg-type]


@pytest.mark.parametrize("mode", ["online", "online-full", "ekf"])
def test_the_runner_refuses_once_before_any_work(mode: str, sim_paper3d_short: LogData) -> None:
    with pytest.raises(GtsamDvlError) as err:
        run_estimator(sim_paper3d_short, mode, LEVER_AND_WATER_SCALE)
    line = str(err.value)
    assert "\n" not in line and line.endswith(f"not --mode {mode}"), line
    assert "[dvl] estimate_lever_arm is batch only" in line
    assert ("water_track_scale" in line) == (mode == "ekf")


def test_io_dvlc_refuses_a_calibration_prior(sim_paper3d_short: LogData) -> None:
    cal = calibration_at_truth(sim_paper3d_short)
    with pytest.raises(
        GtsamDvlError, match="calibration as the prior is batch, online and ekf only"
    ):
        run_estimator(sim_paper3d_short, "io-dvlc", None, calibration=cal)


def test_combinations_no_estimator_does(sim_paper3d_short: LogData) -> None:
    beams_offset = _config(dvl={"use_beams": True, "estimate_time_offset": True})
    for mode in TRAJECTORY_MODES:
        with pytest.raises(GtsamDvlError, match="3-D velocity only, not with use_beams"):
            prepare(sim_paper3d_short, beams_offset, mode)
    water = with_water_track(sim_paper3d_short)
    beams = _config(dvl={"use_beams": True, "estimate_time_offset": False})
    with pytest.raises(GtsamDvlError, match="use_beams with water-track pings"):
        prepare(water, beams, "batch")
    # refused water track: the beams are fine
    refused = _config(
        dvl={"use_beams": True, "estimate_time_offset": False}, current={"water_track": "refuse"}
    )
    assert prepare(water, refused, "batch").config.current.water_track == "refuse"


def test_water_track_resolved_and_the_configuration_kept_as_given(
    sim_paper3d_short: LogData,
) -> None:
    stated = EstimatorConfig()
    assert stated.current.water_track == "auto"
    dry = prepare(sim_paper3d_short, stated, "batch")
    wet = prepare(with_water_track(sim_paper3d_short), stated, "batch")
    assert dry.config.current.water_track == "refuse" and wet.config.current.water_track == "use"
    assert dry.stated is stated and wet.stated is stated
