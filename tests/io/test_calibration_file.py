"""The calibration file: written and read back bit for bit, bad files refused in one line, inflation."""

from __future__ import annotations

import numpy as np
import pytest

from gtsam_dvl.core.calibration import SourceLog, VehicleCalibration
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import rpy_deg_to_matrix
from gtsam_dvl.io.calibration_file import read_calibration, write_calibration


def _calibration() -> VehicleCalibration:
    rng = np.random.default_rng(3)
    A = rng.normal(size=(5, 5)) * np.array([2e-4, 1e-3, 1e-3, 3e-3, 1e-2])
    cov = A @ A.T + np.diag([1e-8, 1e-7, 1e-7, 1e-6, 1e-4])
    values = {
        "scale": np.array([1.0009]),
        "misalignment": rpy_deg_to_matrix([0.1, -0.2, 0.5]),
        "time_offset": np.array([0.012]),
    }
    return VehicleCalibration(
        "auv-1",
        "2026-11-02T10:15:00Z",
        ("scale", "misalignment", "time_offset"),
        values,
        cov,
        (SourceLog("dive 1.mcap", "ab" * 32),),
        "0123456789abcdef",
        "smooth",
    )


def test_round_trip_is_exact(tmp_path):
    cal = _calibration()
    path = write_calibration(tmp_path / "calib.toml", cal)
    back = read_calibration(path)
    assert back.vehicle == "auv-1" and back.date == cal.date and back.states == cal.states
    assert back.sources == cal.sources and back.config_hash == cal.config_hash
    np.testing.assert_array_equal(back.cov, cal.cov)  # repr() of a float reads back exactly
    for name in cal.states:
        np.testing.assert_array_equal(back.values[name], cal.values[name])
    text = path.read_text()
    # the summary a person reads: (1.0009 - 1) in ppm, the mounting in degrees
    assert "scale_ppm = 900.0\n" in text and "misalignment_rpy_deg = [0.1, -0.2, 0.5]" in text
    np.testing.assert_allclose(back.sigma("scale"), np.sqrt(cal.cov[0, 0]))


def test_inflation_and_days():
    cal = _calibration()
    assert cal.days_before("2026-11-12T10:15:00Z") == pytest.approx(10.0)
    grown = cal.inflated(10.0, 0.05)
    np.testing.assert_allclose(grown.cov, cal.cov * 1.5)
    # dated after the dive: unchanged
    np.testing.assert_array_equal(cal.inflated(-3.0, 0.05).cov, cal.cov)


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda t: t.replace("format = 1", "format = 7"), "not a gtsam_dvl calibration file"),
        (lambda t: t.replace("[covariance]", "[other]"), "has no 'covariance'"),
        (lambda t: t.replace("date =", "dated ="), "has no 'date'"),
        (lambda t: t + "\n[[[", "not a calibration file"),
    ],
)
def test_bad_files_are_one_line_errors(tmp_path, edit, words):
    path = write_calibration(tmp_path / "calib.toml", _calibration())
    path.write_text(edit(path.read_text()))
    with pytest.raises(GtsamDvlError, match=words) as info:
        read_calibration(path)
    assert "\n" not in str(info.value)


def test_checks_on_construction():
    cal = _calibration()
    with pytest.raises(GtsamDvlError, match="covariance is"):
        VehicleCalibration("v", cal.date, cal.states, cal.values, cal.cov[:4, :4])
    with pytest.raises(GtsamDvlError, match="not positive definite"):
        VehicleCalibration("v", cal.date, cal.states, cal.values, -cal.cov)
    with pytest.raises(GtsamDvlError, match="no such calibration file"):
        read_calibration("/nonexistent/calib.toml")
