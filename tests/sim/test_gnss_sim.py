"""Simulated GNSS fixes (sim/gnss.py, the scenario's [gnss] table): the fixes against the truth antenna position
(mean and spread of the errors against the stated sigmas), none while submerged, the seed's streams, a log
without its origin (truth in the first fix's frame), and the table's validation. Each test prints what it
measured."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pytest

from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.rotations import quat_xyzw_to_matrix
from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import scenario_from_dict
from tests.support.scenarios import scenario_raw

LEVER = [0.3, -0.2, 0.6]


def _raw(gnss: dict[str, Any] | None = None) -> dict[str, Any]:
    """At the surface (origin height 0) 60 s static, then away at 2 m/s, a dive to about 24 m, up again and on
    at the surface: 360 s."""
    return scenario_raw(
        origin={"height_m": 0.0},
        gnss=gnss,
        segments=[
            {"kind": "static", "duration_s": 60.0},
            {"kind": "level", "duration_s": 20.0, "speed_end_m_s": 2.0},
            {"kind": "descent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "turn", "duration_s": 60.0, "heading_change_deg": 90.0, "bank_deg": 10.0},
            {"kind": "ascent", "duration_s": 60.0, "peak_vertical_speed_m_s": 0.8},
            {"kind": "straight", "duration_s": 100.0},
        ],
    )


@functools.cache
def _log(
    seed: int, rate_hz: float = 10.0, origin_in_log: bool = True, white_noise: bool = True
) -> LogData:
    gnss = {
        "rate_hz": rate_hz,
        "horizontal_sigma_m": 1.5,
        "vertical_sigma_m": 3.0,
        "antenna_lever_arm_m": LEVER,
        "origin_in_log": origin_in_log,
    }
    return simulate(scenario_from_dict(_raw(gnss), name="gnss-sim"), seed, white_noise=white_noise)


def _truth_antenna(log: LogData, t: np.ndarray) -> np.ndarray:
    """Truth antenna position in map at the truth stamps t (the fixes are on the 10 Hz truth grid)."""
    assert log.truth is not None
    k = np.searchsorted(log.truth.t, t)
    np.testing.assert_allclose(log.truth.t[k], t, atol=1e-9)
    R = quat_xyzw_to_matrix(log.truth.n_q_b[k])
    return np.asarray(log.truth.n_p[k] + R @ np.asarray(LEVER))


def _fixes_in_map(log: LogData, frame: LocalFrame) -> np.ndarray:
    g = log.gnss
    assert g is not None
    return np.asarray(
        frame.geodetic_to_map(np.radians(g.lat_deg), np.radians(g.lon_deg), g.height_m)
    )


def test_fixes_match_the_antenna_within_the_stated_sigmas() -> None:
    log = _log(3)
    g = log.gnss
    assert g is not None and log.origin is not None
    frame = LocalFrame(log.origin.lat_deg, log.origin.lon_deg, log.origin.height_m)
    err = _fixes_in_map(log, frame) - _truth_antenna(log, g.t)
    n = len(g)
    mean, std = err.mean(axis=0), err.std(axis=0, ddof=1)
    print(
        f"\n{n} fixes; error mean {np.round(mean, 3)} m, std {np.round(std, 3)} m (stated 1.5, 1.5, 3.0)"
    )
    sig = np.array([1.5, 1.5, 3.0])
    assert n > 1500
    assert np.all(np.abs(mean) < 4 * sig / np.sqrt(n))
    assert np.all(np.abs(std / sig - 1) < 5 / np.sqrt(2 * n))  # 5 sigma of the sample std
    assert np.corrcoef(err.T)[0, 1] == pytest.approx(0.0, abs=5 / np.sqrt(n))
    np.testing.assert_allclose(g.cov_enu_m2, np.broadcast_to(np.diag(sig**2), (n, 3, 3)))
    assert np.all(g.status == 0) and g.frame_id == "gnss_link"
    np.testing.assert_array_equal(g.b_p_antenna, LEVER)
    # without white noise the fix is the antenna to a millimetre (the lever arm turned by the attitude)
    clean = _log(3, white_noise=False)
    assert clean.gnss is not None
    e0 = _fixes_in_map(clean, frame) - _truth_antenna(clean, clean.gnss.t)
    print(f"noise-free: max |error| {np.abs(e0).max() * 1e3:.3f} mm")
    assert np.abs(e0).max() < 1e-3


def test_no_fixes_while_submerged() -> None:
    log = _log(3)
    g, tr = log.gnss, log.truth
    assert g is not None and tr is not None
    depth = -tr.n_p[:, 2]  # base_link below the surface (origin at height 0)
    at_fix = np.interp(g.t, tr.t, depth)
    surfaced = tr.t[depth < 0.5 - 1e-6]
    print(
        f"\nfixes {len(g)} at depths up to {at_fix.max():.3f} m; truth deepest {depth.max():.1f} m; "
        f"fix times {g.t[0]:.1f}-{g.t[-1]:.1f} s"
    )
    assert at_fix.max() < 0.5 and depth.max() > 20.0
    # every surfaced 0.1 s has its fix
    assert np.isin(np.round(surfaced * 10), np.round(g.t * 10)).all()
    gap = np.diff(g.t).max()
    assert gap > 100.0  # the dive
    # a window: only fixes in [start_s, end_s]
    raw = _raw({"rate_hz": 1.0, "start_s": 300.0, "end_s": 330.0})
    w = simulate(scenario_from_dict(raw), 1).gnss
    assert w is not None and w.t.tolist() == [float(t) for t in range(300, 331)]


def test_same_seed_same_fixes_and_other_sensors_unchanged() -> None:
    a, b = (
        _log(5),
        simulate(
            scenario_from_dict(
                _raw(
                    {
                        "rate_hz": 10.0,
                        "horizontal_sigma_m": 1.5,
                        "vertical_sigma_m": 3.0,
                        "antenna_lever_arm_m": LEVER,
                    }
                )
            ),
            5,
        ),
    )
    assert a.gnss is not None and b.gnss is not None
    for name in ("t", "lat_deg", "lon_deg", "height_m", "cov_enu_m2", "status"):
        np.testing.assert_array_equal(getattr(a.gnss, name), getattr(b.gnss, name))
    other = _log(6)
    assert other.gnss is not None and not np.array_equal(other.gnss.lat_deg, a.gnss.lat_deg)
    plain = simulate(scenario_from_dict(_raw()), 5)  # no [gnss]: the same IMU and DVL bytes
    assert plain.gnss is None
    np.testing.assert_array_equal(plain.imu.b_omega, a.imu.b_omega)
    np.testing.assert_array_equal(plain.imu.b_f, a.imu.b_f)
    np.testing.assert_array_equal(plain.dvl.d_v, a.dvl.d_v)


def test_log_without_origin_has_its_truth_in_the_first_fix_frame() -> None:
    with_origin, without = _log(3), _log(3, origin_in_log=False)
    assert without.origin is None and "origin" not in without.metadata
    assert (
        with_origin.origin is not None
        and without.gnss is not None
        and with_origin.truth is not None
    )
    assert without.truth is not None
    g = without.gnss
    fix_frame = LocalFrame(float(g.lat_deg[0]), float(g.lon_deg[0]), float(g.height_m[0]))
    assert without.metadata["truth"]["map_origin"]["lat_deg"] == fix_frame.lat_deg
    sc_frame = LocalFrame(
        with_origin.origin.lat_deg, with_origin.origin.lon_deg, with_origin.origin.height_m
    )
    # the same geodetic truth in both frames
    lat0, lon0, h0 = sc_frame.map_to_geodetic(with_origin.truth.n_p)
    lat1, lon1, h1 = fix_frame.map_to_geodetic(without.truth.n_p)
    np.testing.assert_allclose(np.degrees(lat1), np.degrees(lat0), atol=1e-11)
    np.testing.assert_allclose(np.degrees(lon1), np.degrees(lon0), atol=1e-11)
    np.testing.assert_allclose(h1, h0, atol=1e-6)
    # the first fix is the origin of the new frame; the truth antenna is off it by that fix's noise only
    e = -_truth_antenna(without, g.t[:1])[0]
    offset = without.truth.n_p[0] - with_origin.truth.n_p[0]
    print(f"\nfirst fix's error {np.round(e, 3)} m; truth moved by {np.round(offset, 3)} m")
    assert np.all(np.abs(e) < 5 * np.array([1.5, 1.5, 3.0])) and np.linalg.norm(offset) > 0.01
    # attitudes turn by the frames' micro-radian rotation, velocities likewise
    R0, R1 = quat_xyzw_to_matrix(with_origin.truth.n_q_b), quat_xyzw_to_matrix(without.truth.n_q_b)
    assert np.abs(R1 - R0).max() < 1e-5
    np.testing.assert_allclose(without.truth.n_v, with_origin.truth.n_v, atol=1e-5)


@pytest.mark.parametrize(
    "table, key",
    [
        ({"rate_hz": 3.0}, "gnss.rate_hz"),
        ({"rate_hz": 0.0}, "gnss.rate_hz"),
        ({"sigma_m": 1.0}, "gnss.sigma_m"),
        ({"origin_in_log": "no"}, "gnss.origin_in_log"),
        ({"antenna_lever_arm_m": [0, 1]}, "gnss.antenna_lever_arm_m"),
        ({"start_s": 10.0, "end_s": 5.0}, "gnss.end_s"),
        ({"vertical_sigma_m": -1.0}, "gnss.vertical_sigma_m"),
    ],
)
def test_bad_gnss_table_names_the_key(table: dict[str, Any], key: str) -> None:
    with pytest.raises(GtsamDvlError, match=key.replace(".", r"\.")):
        scenario_from_dict(_raw(table))


def test_origin_from_fixes_needs_a_fix() -> None:
    raw = _raw({"origin_in_log": False})
    raw["origin"]["height_m"] = -50.0  # never at the surface
    with pytest.raises(GtsamDvlError, match="origin_in_log"):
        simulate(scenario_from_dict(raw), 1)
