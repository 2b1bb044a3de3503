"""The simulated water: the current's truth against its profile formula, bottom lock decided on the altitude against
the DVL's bottom-track range, water-track pings against the model computed independently from the truth
(k b_R_d^T (n_R_b^T (n_v - n_c) + b_omega x b_l), with scipy's rotations), their own noise, and scenarios without
the new tables unchanged."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gtsam_dvl.core.earth import LocalFrame
from gtsam_dvl.core.errors import GtsamDvlError
from gtsam_dvl.core.types import LogData
from gtsam_dvl.sim import simulate
from gtsam_dvl.sim.scenario import load_scenario, scenario_from_dict
from tests.support.scenarios import WATER_DIVE, water_dive_raw

CURRENT, LEVER_M, MIS_DEG, RANGE_M, SCALE, SEAFLOOR_M = (
    WATER_DIVE[k]
    for k in ("current", "lever_m", "misalignment_deg", "bottom_range_m", "scale", "seafloor_m")
)


@pytest.fixture(scope="module")
def clean() -> LogData:
    return simulate(scenario_from_dict(water_dive_raw(), "water"), 3, white_noise=False)


def _at_pings(log: LogData) -> dict[str, np.ndarray]:
    """The truth at the DVL stamps (both on the same 0.1 s grid; the stamps are the measurement times)."""
    assert log.truth is not None and log.truth.n_c is not None
    i = np.searchsorted(log.truth.t, log.dvl.t - 1e-9)
    assert np.allclose(log.truth.t[i], log.dvl.t, atol=1e-9)
    t = log.truth
    return {
        "n_p": t.n_p[i],
        "n_R_b": Rotation.from_quat(t.n_q_b[i]).as_matrix(),
        "n_v": t.n_v[i],
        "n_c": t.n_c[i],
        "b_omega": t.b_omega[i],
        "t": t.t[i],
    }


def _model(log: LogData, water: bool) -> np.ndarray:
    """k b_R_d^T (n_R_b^T (n_v - n_c) + b_omega x b_l) at the pings (n_c left out for bottom track)."""
    x = _at_pings(log)
    b_R_d0 = Rotation.from_euler("x", 180.0, degrees=True).as_matrix()
    R_c = Rotation.from_euler("ZYX", [MIS_DEG[2], MIS_DEG[1], MIS_DEG[0]], degrees=True).as_matrix()
    b_R_d = R_c @ b_R_d0
    n_rel = x["n_v"] - x["n_c"] if water else x["n_v"]
    b_v = np.einsum("kji,kj->ki", x["n_R_b"], n_rel) + np.cross(x["b_omega"], LEVER_M)
    return SCALE * np.einsum("ji,kj->ki", b_R_d, b_v)


def _dvl_depth(log: LogData) -> np.ndarray:
    x = _at_pings(log)
    return -(x["n_p"][:, 2] + np.einsum("kij,j->ki", x["n_R_b"], LEVER_M)[:, 2])


def test_current_truth_is_the_profile(clean: LogData) -> None:
    truth = clean.truth
    assert truth is not None and truth.n_c is not None
    # the map's origin at the surface
    assert clean.origin is not None and clean.origin.height_m == 0.0
    depth = -LocalFrame(clean.origin.lat_deg, clean.origin.lon_deg, 0.0).map_to_geodetic(truth.n_p)[
        2
    ]
    assert depth.max() > 18.0
    s, r = np.array(CURRENT["surface_m_s"]), np.array(CURRENT["reference_m_s"])
    w = np.minimum(np.maximum(depth, 0.0) / CURRENT["reference_depth_m"], 1.0)
    tide = np.outer(
        np.sin(2 * np.pi * truth.t / CURRENT["variation_period_s"]), CURRENT["variation_m_s"]
    )
    expected = (1 - w)[:, None] * s + w[:, None] * r + tide
    assert np.abs(truth.n_c[:, :2] - expected).max() < 1e-9  # the geodetic round trip's nanometres
    assert np.all(truth.n_c[:, 2] == 0.0)
    # constant in depth below the reference depth
    deep = depth > CURRENT["reference_depth_m"] + 0.01
    assert deep.sum() > 50 and np.allclose(truth.n_c[deep, :2] - tide[deep], r, atol=1e-12)


def test_lock_is_lost_exactly_beyond_the_range(clean: LogData) -> None:
    dvl = clean.dvl
    assert dvl.water_track is not None and dvl.altitude is not None
    altitude = SEAFLOOR_M - _dvl_depth(clean)
    sure = np.abs(altitude - RANGE_M) > 0.01
    assert np.array_equal(dvl.water_track[sure], altitude[sure] > RANGE_M)
    # water track at the start and the end, bottom lock between: lost and reacquired once each
    changes = np.flatnonzero(np.diff(dvl.water_track.astype(int)))
    assert dvl.water_track[0] and dvl.water_track[-1] and len(changes) == 2
    lock = ~dvl.water_track
    assert np.all(np.isnan(dvl.altitude[dvl.water_track])) and np.all(dvl.altitude[lock] <= RANGE_M)
    assert np.abs(dvl.altitude[lock] - altitude[lock]).max() < 0.01
    # valid means velocity over ground: bottom-track pings only; water-track pings keep their velocity and beams
    assert np.array_equal(dvl.valid, lock) and np.isfinite(dvl.d_v).all()
    assert dvl.beams is not None and not dvl.beams.valid[dvl.water_track].any()
    assert np.isnan(dvl.beams.range[dvl.water_track]).all() and np.isfinite(dvl.beams.v).all()


def test_pings_are_the_model_computed_from_the_truth(clean: LogData) -> None:
    wt = clean.dvl.water_track
    assert wt is not None and 40 < wt.sum() < len(wt) - 40
    err_water = clean.dvl.d_v[wt] - _model(clean, True)[wt]
    err_bottom = clean.dvl.d_v[~wt] - _model(clean, False)[~wt]
    print(np.abs(err_water).max(), np.abs(err_bottom).max())
    assert np.abs(err_water).max() < 1e-5 and np.abs(err_bottom).max() < 1e-5
    # the current matters: the water-track pings are not the velocity over ground
    assert np.linalg.norm(clean.dvl.d_v[wt] - _model(clean, False)[wt], axis=1).min() > 0.05
    beams = clean.dvl.beams
    assert beams is not None
    assert np.abs(np.einsum("kbi,ki->kb", beams.d_u, clean.dvl.d_v) - beams.v).max() < 1e-12


@pytest.mark.parametrize("noise_model", ["velocity", "beam"])
def test_water_track_noise_is_its_own(noise_model: str) -> None:
    """Water-track pings carry water_track_noise_m_s (here 3 cm/s, the bottom track's 2 cm/s) and say so in their
    covariance; the bottom-track pings keep theirs."""
    raw = water_dive_raw(noise_model, water_track_noise_m_s=0.03, noise_m_s=0.02)
    log = simulate(scenario_from_dict(raw, "water"), 5)
    wt = log.dvl.water_track
    assert wt is not None
    for mask, water, sigma in ((wt, True, 0.03), (~wt, False, 0.02)):
        err = log.dvl.d_v[mask] - _model(log, water)[mask]
        # the per-axis sigma the covariance states, whitened: unit variance within the sample's spread
        z = err / np.sqrt(np.einsum("kii->ki", log.dvl.d_cov[mask]))
        n = z.size
        print(
            noise_model,
            water,
            n,
            z.std(),
            np.sqrt(np.einsum("kii->ki", log.dvl.d_cov[mask])).mean(),
        )
        assert abs(z.std() - 1.0) < 4.0 / np.sqrt(2 * n) and abs(z.mean()) < 4.0 / np.sqrt(n)
        if noise_model == "velocity":
            assert np.allclose(log.dvl.d_cov[mask], sigma**2 * np.eye(3))


def test_without_seafloor_the_dvl_is_as_before() -> None:
    """A current without [seafloor] is truth only: the DVL's arrays are those of the scenario without it, bit for
    bit, no water track, no altitude."""
    raw = water_dive_raw()
    raw.pop("seafloor")
    with_current = simulate(scenario_from_dict(raw, "a"), 2)
    raw.pop("current")
    plain = simulate(scenario_from_dict(raw, "a"), 2)
    assert with_current.truth is not None and with_current.truth.n_c is not None
    assert plain.truth is not None and plain.truth.n_c is None and plain.dvl.water_track is None
    assert with_current.dvl.water_track is None and with_current.dvl.altitude is None
    assert np.array_equal(with_current.dvl.d_v, plain.dvl.d_v, equal_nan=True)
    assert "current" in with_current.metadata["truth"] and "current" not in plain.metadata["truth"]
    assert "bottom_range_m" not in plain.metadata["sensors"]["dvl"]


@pytest.mark.parametrize(
    ("table", "value", "key"),
    [
        ("current", {"surface_m_s": [0.1, 0.2, 0.0]}, "current.surface_m_s"),
        ("current", {"reference_depth_m": 0.0}, "current.reference_depth_m"),
        ("current", {"speed": 1.0}, "current.speed"),
        ("seafloor", {}, "seafloor.depth_m"),
        ("seafloor", {"depth_m": -5.0}, "seafloor.depth_m"),
    ],
)
def test_bad_tables_fail_in_one_line(table: str, value: dict[str, Any], key: str) -> None:
    raw = water_dive_raw()
    raw[table] = value
    with pytest.raises(GtsamDvlError, match=f"key '{key}'") as exc:
        scenario_from_dict(raw)
    assert "\n" not in str(exc.value)


def test_bottom_range_defaults_to_the_presets_altitude() -> None:
    raw = water_dive_raw()
    del raw["dvl"]["bottom_range_m"]
    raw["dvl"].pop("max_range_m", None)
    raw["dvl"]["model"] = "teledyne-workhorse-navigator-300"
    sc = scenario_from_dict(raw)
    from gtsam_dvl.core.config.presets import DVL_PRESETS

    assert (
        sc.dvl.bottom_range_m
        == DVL_PRESETS["teledyne-workhorse-navigator-300"].max_altitude_m
        == sc.dvl.max_range_m
    )


def test_deep_descent_timeline() -> None:
    """deep-descent as its comments state: 25-35 min from the surface with GNSS fixes, 300 m down in water track
    through a 0.2-0.5 m/s current, lock near 295 m, lost again on the way up, fixes at the end."""
    sc = load_scenario("deep-descent")
    assert 25 * 60 <= sc.duration_s <= 35 * 60 and sc.origin.height_m == 0.0 and sc.gnss is not None
    log = simulate(sc, 1, white_noise=False)
    truth, dvl, gnss = log.truth, log.dvl, log.gnss
    assert (
        truth is not None
        and truth.n_c is not None
        and dvl.water_track is not None
        and gnss is not None
    )
    depth_m = -truth.n_p[:, 2]  # within 0.4 m of the depth (the map's curvature over 2 km)
    assert abs(depth_m[0]) < 1e-9 and abs(depth_m[-1]) < 0.5 and 299.5 < depth_m.max() < 300.5
    speed = np.linalg.norm(truth.n_c, axis=1)
    assert 0.2 <= speed.min() and speed.max() <= 0.5
    changes = dvl.t[1:][np.diff(dvl.water_track.astype(int)) != 0]
    assert len(changes) == 2 and dvl.water_track[0] and dvl.water_track[-1]
    descent, ascent = (s for s in sc.segments if s.kind in ("descent", "ascent"))
    assert (
        descent.start_s < changes[0] < descent.end_s and ascent.start_s < changes[1] < ascent.end_s
    )
    depth = np.interp(changes, truth.t, depth_m)
    assert np.all(np.abs(depth - (sc.seafloor.depth_m - sc.dvl.bottom_range_m)) < 1.0)  # type: ignore[union-attr]
    assert (
        gnss.t[0] == 0.0
        and gnss.t[-1] == sc.duration_s
        and not np.any((gnss.t > 300) & (gnss.t < 1800))
    )
    print(
        f"lock {changes[0]:.0f}-{changes[1]:.0f} s at {depth.round(1)} m; {dvl.water_track.sum()} water pings"
    )
