"""The surfacing error (analysis/surfacing.py through analysis/evaluate.py): on a dive that starts and ends at
the surface, read back from MCAP without its origin and without its truth (as a real log), the reported error
at the first fix of the final surfacing, in metres and in % of the distance travelled, equals an independent
computation from the result's arrays and the fix; the printed lines say it, and say so when no fix is held
out."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.analysis.evaluate import evaluate_result
from gtsam_dvl.analysis.metrics import build_summary
from gtsam_dvl.app.report import gnss_lines
from gtsam_dvl.core.config import EstimatorConfig
from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.result import NavResult, StoredResult
from gtsam_dvl.core.types import LogData
from gtsam_dvl.estimators.batch.smoother import smooth_batch
from gtsam_dvl.io.reader import read_log
from gtsam_dvl.io.writer import write_log
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import surface_dive_raw

LEVER = [0.2, 0.0, 0.6]


def _raw() -> dict[str, Any]:
    """60 s static at the surface, away, a 24 m dive with one banked turn, up and 40 s on at the surface."""
    return surface_dive_raw(
        [
            {"kind": "static", "duration_s": 60.0},
            {"kind": "level", "duration_s": 20.0, "speed_end_m_s": 2.0},
            {"kind": "descent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "turn", "duration_s": 60.0, "heading_change_deg": 120.0, "bank_deg": 15.0},
            {"kind": "straight", "duration_s": 60.0},
            {"kind": "ascent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "straight", "duration_s": 40.0},
        ],
        gnss={"rate_hz": 1.0, "antenna_lever_arm_m": LEVER, "origin_in_log": False},
    )


@pytest.fixture(scope="module")
def real_log(tmp_path_factory: pytest.TempPathFactory) -> LogData:
    """The dive as a real vehicle's log: no origin, no truth."""
    log = simulate(scenario_from_dict(_raw(), name="surfacing"), 11)
    log.truth = None
    path = Path(tmp_path_factory.mktemp("surfacing")) / "dive.mcap"
    write_log(path, log)
    back = read_log(path)
    assert back.truth is None and back.origin is not None
    return back


def _stored(res: NavResult, log: LogData) -> StoredResult:
    return StoredResult(res, build_summary(res, log), "memory")


def test_surfacing_error_equals_an_independent_computation(real_log: LogData) -> None:
    res = smooth_batch(real_log, EstimatorConfig())
    ev = evaluate_result(_stored(res, real_log), real_log)
    m = ev.metrics["gnss"]
    s = m["surfacing_error"]
    # independently: the first fix after the longest gap between fixes (the dive), in map at the first fix
    g = real_log.gnss
    assert g is not None and real_log.origin is not None
    k = int(np.argmax(np.diff(g.t))) + 1
    frame = LocalFrame(real_log.origin.lat_deg, real_log.origin.lon_deg, real_log.origin.height_m)
    fix = frame.geodetic_to_map(np.radians(g.lat_deg[k]), np.radians(g.lon_deg[k]), g.height_m[k])
    i = int(np.argmin(np.abs(res.t - g.t[k])))
    assert abs(res.t[i] - g.t[k]) < 1e-6  # 1 Hz fixes on the 1 Hz pings
    antenna = res.n_p[i] + res.n_R_b[i] @ np.asarray(LEVER)
    e = antenna - fix
    travelled = float(np.sum(np.linalg.norm(np.diff(res.n_p[: i + 1], axis=0), axis=1)))
    h = float(np.hypot(e[0], e[1]))
    print(
        f"\nsurfacing at {g.t[k]:.0f} s: horizontal {h:.3f} m, {100 * h / travelled:.4f} % of {travelled:.1f} m, "
        f"vertical {e[2]:+.3f} m; reported {s['horizontal_error_m']:.3f} m, {s['horizontal_error_pct']:.4f} %, "
        f"{s['vertical_error_m']:+.3f} m; estimate sigma {s['estimate_sigma_h_m']:.3f} m, nis {s['nis']:.2f}"
    )
    assert s["t_s"] == pytest.approx(g.t[k])
    assert s["horizontal_error_m"] == pytest.approx(h, rel=1e-9, abs=1e-9)
    assert s["vertical_error_m"] == pytest.approx(e[2], rel=1e-9, abs=1e-9)
    assert s["distance_m"] == pytest.approx(travelled, rel=1e-9)
    assert s["horizontal_error_pct"] == pytest.approx(100 * h / travelled, rel=1e-9)
    assert s["fix_sigma_h_m"] == pytest.approx(np.sqrt(8.0), rel=1e-6) and s[
        "fix_sigma_v_m"
    ] == pytest.approx(4.0)
    # the estimate's sigma from the marginal covariance: between the start's fixes' 0.25 m and the fix's 2.8 m
    assert 0.2 < s["estimate_sigma_h_m"] < 2.0
    # the error is the fix's noise and the drift: consistent with both sigmas (chi^2, 3 dof, 99.9 %: 16.3)
    assert s["nis"] < 16.3
    assert m["held_out_evaluated"] == m["counters"]["gnss_held_out"] >= 40
    assert m["counters"]["gnss_used"] >= 60 and m["surface_intervals"] == 2
    lines = gnss_lines(m)
    print("\n".join(lines))
    assert any(
        f"{s['horizontal_error_m']:.2f} m = {s['horizontal_error_pct']:.3f} %" in line
        for line in lines
    )
    assert "truth" not in ev.metrics
    # the mean over the last surfacing's fixes: every fix from k on, each against the antenna at its own state
    errs = []
    for kk in range(k, len(g.t)):
        fk = frame.geodetic_to_map(
            np.radians(g.lat_deg[kk]), np.radians(g.lon_deg[kk]), g.height_m[kk]
        )
        ik = int(np.argmin(np.abs(res.t - g.t[kk])))
        errs.append(res.n_p[ik] + res.n_R_b[ik] @ np.asarray(LEVER) - fk)
    e_mean = np.mean(errs, axis=0)
    mm = m["surfacing_error_mean"]
    print(
        f"mean over {len(errs)} fixes: horizontal {np.hypot(*e_mean[:2]):.3f} m; reported "
        f"{mm['horizontal_error_m']:.3f} m +- {mm['fix_sigma_h_m']:.3f} m (fixes' mean), nis {mm['nis']:.2f}"
    )
    assert m["surfacing_fixes"] == len(errs) >= 40
    assert mm["horizontal_error_m"] == pytest.approx(
        np.hypot(e_mean[0], e_mean[1]), rel=1e-9, abs=1e-9
    )
    assert mm["fix_sigma_h_m"] == pytest.approx(np.sqrt(8.0 / len(errs)), rel=1e-6)
    assert mm["nis"] < 16.3
    assert any("mean over the" in line for line in lines)


def test_no_held_out_fixes_is_said(real_log: LogData) -> None:
    cfg = EstimatorConfig()
    cfg.gnss.use = "all"
    ev = evaluate_result(_stored(smooth_batch(real_log, cfg), real_log), real_log)
    m = ev.metrics["gnss"]
    assert m["surfacing_error"] is None and m["held_out_evaluated"] == 0
    lines = gnss_lines(m)
    print("\n".join(lines))
    assert any("no held-out fixes" in line for line in lines)
    assert gnss_lines(None) == []
