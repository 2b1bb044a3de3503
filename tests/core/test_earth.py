"""WGS84 model against published values and closed forms (gtsam_dvl/core/earth.py)."""

from __future__ import annotations

import numpy as np

from gtsam_dvl.core import earth

A = 6378137.0
F = 1.0 / 298.257223563
E2 = F * (2.0 - F)


def test_normal_gravity_matches_wgs84_published_values() -> None:
    # NIMA TR8350.2 table 3.4: normal gravity at the equator and at the poles on the ellipsoid
    g_eq = float(earth.normal_gravity(0.0, 0.0))
    g_pole = float(earth.normal_gravity(np.pi / 2, 0.0))
    g_south = float(earth.normal_gravity(-np.pi / 2, 0.0))
    print(
        f"gamma_e error {g_eq - 9.7803253359:.3e}, gamma_p error {g_pole - 9.8321849378:.3e} m/s^2"
    )
    assert abs(g_eq - 9.7803253359) < 1e-9
    assert abs(g_pole - 9.8321849378) < 1e-9
    assert abs(g_south - g_pole) < 1e-12
    # free-air gradient near the surface is about -3.086e-6 s^-2
    grad = float(earth.normal_gravity(0.5, 100.0) - earth.normal_gravity(0.5, 0.0)) / 100.0
    print(f"free-air gradient at 28.6 deg: {grad:.4e} 1/s^2")
    assert abs(grad + 3.086e-6) < 0.01e-6


def test_radii_of_curvature_closed_forms() -> None:
    r_n0, r_e0 = earth.radii_of_curvature(0.0)
    r_n90, r_e90 = earth.radii_of_curvature(np.pi / 2)
    b = A * (1.0 - F)
    print(f"R_N(0) {float(r_n0):.4f}  R_E(0) {float(r_e0):.4f}  R(90) {float(r_n90):.4f} m")
    assert abs(r_n0 - A * (1.0 - E2)) < 1e-6  # b^2 / a
    assert abs(r_n0 - b * b / A) < 1e-6
    assert abs(r_e0 - A) < 1e-6
    assert abs(r_n90 - A * A / b) < 1e-6  # both radii equal a^2 / b at the pole
    assert abs(r_e90 - A * A / b) < 1e-6


def test_ecef_geodetic_round_trip_including_poles() -> None:
    rng = np.random.default_rng(1)
    lat = np.concatenate(
        [rng.uniform(-np.pi / 2, np.pi / 2, 2000), [np.pi / 2, -np.pi / 2, 0.0, 1e-9]]
    )
    lon = rng.uniform(-np.pi, np.pi, lat.size)
    h = rng.uniform(-6000.0, 20000.0, lat.size)
    e_p = earth.geodetic_to_ecef(lat, lon, h)
    lat2, lon2, h2 = earth.ecef_to_geodetic(e_p)
    away = np.abs(np.cos(lat)) > 1e-6  # longitude is undefined on the polar axis
    err_lat = np.max(np.abs(lat2 - lat))
    err_lon = np.max(np.abs(np.angle(np.exp(1j * (lon2 - lon)))[away]))
    err_h = np.max(np.abs(h2 - h))
    print(f"round trip: lat {err_lat:.2e} rad, lon {err_lon:.2e} rad, h {err_h:.2e} m")
    assert err_lat < 1e-14 and err_lon < 1e-14 and err_h < 1e-8
    # a point on the polar axis (the textbook h = rho/cos(lat) - R_E divides by zero there)
    lat_p, _, h_p = earth.ecef_to_geodetic(np.array([0.0, 0.0, A * (1 - F) + 123.0]))
    assert abs(lat_p - np.pi / 2) < 1e-15 and abs(h_p - 123.0) < 1e-8


def test_map_geodetic_round_trip_and_axes() -> None:
    frame = earth.LocalFrame(30.0, 114.0, -100.0)
    rng = np.random.default_rng(2)
    n_p = rng.uniform(-50e3, 50e3, (1000, 3)) * np.array([1.0, 1.0, 0.01])
    lat, lon, h = frame.map_to_geodetic(n_p)
    back = frame.geodetic_to_map(lat, lon, h)
    err = np.max(np.abs(back - n_p))
    print(f"map -> geodetic -> map: {err:.2e} m")
    assert err < 1e-8
    # the origin is at zero, and small steps along the map axes are east, north, up
    assert np.max(np.abs(frame.geodetic_to_map(frame.lat0, frame.lon0, -100.0))) < 1e-9
    r_n, r_e = earth.radii_of_curvature(frame.lat0)
    d = 1e-7
    north = frame.geodetic_to_map(frame.lat0 + d, frame.lon0, -100.0) / (d * (r_n - 100.0))
    east = frame.geodetic_to_map(frame.lat0, frame.lon0 + d, -100.0) / (
        d * (r_e - 100.0) * np.cos(frame.lat0)
    )
    up = frame.geodetic_to_map(frame.lat0, frame.lon0, -99.0)
    print(f"north {north}, east {east}, up {up}")
    np.testing.assert_allclose(north, [0, 1, 0], atol=1e-6)
    np.testing.assert_allclose(east, [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-9)


def test_gravity_and_earth_rate_in_map_frame() -> None:
    frame = earth.LocalFrame(30.0, 114.0, -100.0)
    g0 = frame.n_gravity(np.zeros(3))
    gamma = float(earth.normal_gravity(np.radians(30.0), -100.0))
    np.testing.assert_allclose(g0, [0.0, 0.0, -gamma], atol=1e-12)
    # 10 km north the local up leans towards map north by ~10 km / R_N (1.57e-3 rad)
    g_n = frame.n_gravity(np.array([0.0, 10e3, -7.85]))
    tilt = np.arctan2(-g_n[1], -g_n[2])
    print(f"gravity tilt 10 km north: {tilt:.6e} rad")
    assert abs(tilt - 10e3 / float(earth.radii_of_curvature(frame.lat0)[0])) < 1e-7
    w = frame.n_omega_ie
    assert abs(np.linalg.norm(w) - 7.292115e-5) < 1e-18
    np.testing.assert_allclose(w / 7.292115e-5, [0, np.cos(np.radians(30)), 0.5], atol=1e-15)
