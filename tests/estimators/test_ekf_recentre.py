"""The EKF's time offset prior centred at its warm-up window's estimate ([ekf] recentre_time_offset): on
straight-transect (DVL stamped 1.0 s early, two prior sigmas) the filter, linearised at the offset the data show,
keeps the calibration and the position within 3 sigma, with the prior's centre found within 0.1 s."""

from __future__ import annotations

import numpy as np
import pytest

from gtsam_dvl.app.campaign.montecarlo import STATES, run_errors
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.estimators.ekf.filter import run_ekf
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

NAMES = [name for name, _ in STATES]


def _z(recentre: bool) -> tuple[np.ndarray, dict]:
    sc = load_scenario("straight-transect")
    log = simulate(sc, 1)
    d = sc.estimator_configuration().to_dict()
    d["ekf"] = {**d["ekf"], "recentre_time_offset": recentre}
    # the filtered calibration itself (the nominal check holds it at nominal on this straight log: tested apart)
    d["priors"] = {**d["priors"], "nominal_check": False}
    r = run_ekf(log, EstimatorConfig.from_dict(d))
    e = run_errors(r, log)
    return np.array(e["error"]) / np.array(e["sigma"]), r.info


@pytest.mark.slow
def test_recentred_time_offset_keeps_the_ekf_consistent() -> None:
    z_on, info = _z(True)
    z_off, _ = _z(False)
    print("recentred", dict(zip(NAMES, np.round(z_on, 2), strict=True)))
    print("at the prior", dict(zip(NAMES, np.round(z_off, 2), strict=True)))
    assert info["time_offset_prior"]["centre_s"] == pytest.approx(1.0, abs=0.1)
    assert "warm-up window" in info["time_offset_prior"]["why"]
    calibration = [NAMES.index(n) for n in NAMES if n == "scale" or n.startswith("misalignment")]
    position = [NAMES.index("final_position_east"), NAMES.index("final_position_north")]
    # measured, seed 1: recentred scale -0.6, pitch -1.0, yaw 0.6, east/north -0.1/0.7 sigma; at the prior's 0: scale
    # -1.0, the rest within 0.3 sigma of the recentred (before the EKF's underway-start fix, estimators/ekf/filter.py,
    # the run at the prior was 2.0 sigma off in pitch and recentring brought it closer; since, both are consistent)
    assert np.all(np.abs(z_on[calibration + position]) < 3.0)
    assert np.all(np.abs(z_off[calibration + position]) < 3.0)
