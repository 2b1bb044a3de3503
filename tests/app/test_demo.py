"""`gtsam-dvl demo` end to end (the path `make demo` takes): reports, the paper's figures, and the paper's
findings holding on both runs for the batch smoother, the online estimator and the EKF."""

from __future__ import annotations

from pathlib import Path

import pytest

from gtsam_dvl.app.demo import run_demo

pytestmark = pytest.mark.slow


def test_demo_writes_reports_figures_and_reproduces_the_findings(tmp_path: Path) -> None:
    runs = run_demo(tmp_path, seed=7)
    assert (tmp_path / "report.md").exists()
    for run in runs:
        figs = {p.name for p in (tmp_path / run["run"] / "figures").glob("*.png")}
        wanted = (
            {
                "fig01_trajectory.png",
                "fig02_dvl_output.png",
                "fig03_imu_output.png",
                "fig04_iodvlc_scale.png",
                "fig05_iodvlc_misalignment.png",
                "fig06_scale.png",
                "fig07_misalignment.png",
                "fig08_gyro_bias.png",
                "fig09_accel_bias.png",
                "fig10_attitude_error.png",
                "fig11_position_error.png",
                "fig12_normalised_sigmas.png",
            }
            if run["run"] == "paper-3d"
            else {
                "fig13_scale.png",
                "fig14_misalignment.png",
                "fig15_attitude_error.png",
                "fig16_position_error.png",
            }
        )
        assert wanted <= figs, wanted - figs
        assert {"batch", "online", "ekf"} <= set(run["findings"])
        for estimator, findings in run["findings"].items():
            for f in findings:
                print(
                    f"{run['run']} {estimator}: {'yes' if f.held else 'NO'}: {f.text} ({f.evidence})"
                )
                assert f.held, f"{run['run']} {estimator}: {f.text} ({f.evidence})"
    # the deep descent: water track used against refused, on the same log (app/demo.py deep_run)
    import json

    deep = tmp_path / "deep-descent"
    used, refused = (
        json.loads((deep / name).read_text()) for name in ("summary.json", "summary-refused.json")
    )
    e_used, e_ref = used["errors"], refused["errors"]
    assert used["health"]["status"] == "ok", used["health"]["warnings"]
    # within 3 sigma: the final horizontal position and every calibration state
    assert e_used["final_horizontal_position_m"] < 3 * used["final_horizontal_position_sigma_m"]
    assert (
        abs(e_used["scale_nsigma"]) < 3 and max(abs(v) for v in e_used["misalignment_nsigma"]) < 3
    )
    # the final horizontal error at least 2x smaller than with water track refused; the thrust-axis (roll)
    # misalignment better determined (the descent's change of specific force, seen through the water track)
    assert 2 * e_used["final_horizontal_position_m"] < e_ref["final_horizontal_position_m"], (
        e_used,
        e_ref,
    )
    assert used["misalignment_deg"]["sigma"][0] < refused["misalignment_deg"]["sigma"][0]
    assert (
        used["water_current"]["determined_share"] > 0.9
        and used["water_current"]["errors"]["rms_m_s"] < 0.05
    )
    assert (deep / "evaluation" / "water_current.png").exists()
