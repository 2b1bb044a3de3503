"""The realistic scenario (data/scenarios/field-survey.toml) with the default configuration, as
`make demo` runs it: a dive that starts underway at the surface (no static phase: the attitude is aligned in
motion), the origin only in the GNSS fixes (read back from MCAP), a 5 Hz z-down DVL whose stamps are 0.3 s early
with a lever arm, 200 Hz IMU, pressure, and a surfacing with fixes at the end that are held out.

Targets: calibration (scale, misalignment, time offset) within 3 sigma of the truth; final
horizontal error at surfacing below 0.1 % of the distance travelled; vertical error within 3 sigma.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gtsam_dvl.analysis.evaluate import evaluate_result
from gtsam_dvl.analysis.health import assess_health
from gtsam_dvl.analysis.metrics import build_summary, summary
from gtsam_dvl.core.result import NavResult, StoredResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario

pytestmark = pytest.mark.slow

SEED = 7


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[LogData, NavResult]:
    path = Path(tmp_path_factory.mktemp("field")) / "field-survey.mcap"
    write_log(path, simulate(load_scenario("field-survey"), SEED))
    log = read_log(path)
    return log, smooth_batch(log)  # no configuration: the scenario names none, so the defaults


def test_field_survey_meets_issue_11(run: tuple[LogData, NavResult]) -> None:
    log, res = run
    s = summary(res, log)
    e = s["errors"]
    # the origin came from the first fix
    assert log.metadata.get("origin") is None and log.origin is not None
    assert res.info["alignment"]["method"] == "in_motion"
    z = np.array([e["scale_nsigma"], *e["misalignment_nsigma"], e["dvl_time_offset_nsigma"]])
    # vertical error and sigma at the last state (the depth sensor holds it)
    assert log.truth is not None
    z_true = np.interp(res.t[-1], log.truth.t, log.truth.n_p[:, 2])
    R = res.n_R_b[-1]
    sig_up = float(np.sqrt((R @ res.pose_cov[-1, 3:, 3:] @ R.T)[2, 2]))
    up_err = float(res.n_p[-1, 2] - z_true)
    print(
        f"\nfield-survey seed {SEED}: scale/misalignment/offset errors {np.round(z, 2)} sigma; offset "
        f"{res.time_offset_s:.4f} +- {res.time_offset_sigma_s:.4f} s; final horizontal "
        f"{e['final_horizontal_position_m']:.2f} m ({e['final_horizontal_position_pct_distance']:.3f} %); "
        f"vertical {up_err:+.3f} m +- {sig_up:.3f} m; {len(res.t)} states, counters {res.info['counters']}"
    )
    assert np.all(np.abs(z) < 3)
    assert e["final_horizontal_position_pct_distance"] < 0.1
    assert abs(up_err) < 3 * sig_up
    assert res.time_offset_sigma_s < 0.03  # 5 Hz, 1 cm/s DVL: tens of ms at worst (measured 16 ms)
    assert res.info["counters"]["gnss_used"] > 50 and res.info["counters"]["gnss_held_out"] > 50
    # the self-diagnosis sees the model that was fitted (time offset and lever arm included): healthy
    health = assess_health(res, log)
    print("health", health.status, health.warnings)
    assert health.status == "ok"


def test_field_survey_surfacing_error(run: tuple[LogData, NavResult]) -> None:
    """Evaluation without truth: the held-out fixes of the final surfacing against the estimate."""
    log, res = run
    metrics = evaluate_result(StoredResult(res, build_summary(res, log), "memory"), log).metrics[
        "gnss"
    ]
    first, mean = metrics["surfacing_error"], metrics["surfacing_error_mean"]
    print(
        f"\nsurfacing: first fix {first['horizontal_error_m']:.2f} m ({first['horizontal_error_pct']:.3f} %), "
        f"mean of {metrics['surfacing_fixes']} fixes {mean['horizontal_error_m']:.2f} m "
        f"({mean['horizontal_error_pct']:.3f} %) +- {mean['fix_sigma_h_m']:.2f} m, nis {mean['nis']:.2f}"
    )
    assert metrics["surfacing_fixes"] > 50
    # 1.8 km: under 1.8 m, fix noise averaged down to 0.33 m
    assert mean["horizontal_error_pct"] < 0.1
    # chi^2 3 dof, 99.9 %: consistent with the sigmas of the fixes and the estimate
    assert mean["nis"] < 16.3
