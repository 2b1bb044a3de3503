"""WGS84 Earth model: radii of curvature, normal gravity, Earth rate, and the local `map` frame.

The `map` frame (n) is the East-North-Up tangent frame at a fixed geodetic origin, Earth-fixed
(docs/conventions.md). In it the Earth-rate vector is constant and gravity's direction turns with the
vehicle's position. The local-level frame (l) is the East-North-Up frame at the vehicle's current
position; it differs from `map` by the small rotation n_R_l(lat, lon).

Everything here is plain numpy, independent of GTSAM, so it can serve as the reference for tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WGS84_A = 6378137.0  # semi-major axis, m
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_B = WGS84_A * (1.0 - WGS84_F)  # semi-minor axis, m
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
WGS84_GM = 3.986004418e14  # m^3/s^2
OMEGA_IE = 7.292115e-5  # Earth rate, rad/s
GAMMA_E = 9.7803253359  # normal gravity at the equator, m/s^2
SOMIGLIANA_K = 0.00193185265241  # Somigliana constant
M_RATIO = OMEGA_IE**2 * WGS84_A**2 * WGS84_B / WGS84_GM  # m = w^2 a^2 b / GM


def radii_of_curvature(lat: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """(R_N meridian, R_E transverse/prime-vertical) radii of curvature in metres at latitude lat (rad)."""
    s2 = np.sin(lat) ** 2
    w = np.sqrt(1.0 - WGS84_E2 * s2)
    r_e = WGS84_A / w
    r_n = WGS84_A * (1.0 - WGS84_E2) / w**3
    return r_n, r_e


def normal_gravity(lat: np.ndarray | float, h: np.ndarray | float) -> np.ndarray:
    """Magnitude of normal gravity (gravitation + centrifugal) in m/s^2 at latitude lat (rad), height h (m).

    Somigliana's closed formula on the ellipsoid with the second-order free-air height correction
    (NIMA TR8350.2 eq. 4-1 and 4-3).
    """
    s2 = np.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + SOMIGLIANA_K * s2) / np.sqrt(1.0 - WGS84_E2 * s2)
    h = np.asarray(h, dtype=float)
    corr = (
        1.0
        - 2.0 / WGS84_A * (1.0 + WGS84_F + M_RATIO - 2.0 * WGS84_F * s2) * h
        + 3.0 * h**2 / WGS84_A**2
    )
    return np.asarray(g0 * corr)


def geodetic_to_ecef(
    lat: np.ndarray | float, lon: np.ndarray | float, h: np.ndarray | float
) -> np.ndarray:
    """ECEF position (..., 3) in metres of geodetic lat, lon (rad) and ellipsoidal height h (m)."""
    _, r_e = radii_of_curvature(lat)
    cl, sl = np.cos(lat), np.sin(lat)
    x = (r_e + h) * cl * np.cos(lon)
    y = (r_e + h) * cl * np.sin(lon)
    z = (r_e * (1.0 - WGS84_E2) + h) * sl
    return np.stack(np.broadcast_arrays(x, y, z), axis=-1)


def ecef_to_geodetic(e_p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lat, lon, h) in rad, rad, m of ECEF positions (..., 3). Fixed-point iteration, exact to 1e-12 rad."""
    e_p = np.asarray(e_p, dtype=float)
    x, y, z = e_p[..., 0], e_p[..., 1], e_p[..., 2]
    lon = np.arctan2(y, x)
    rho = np.hypot(x, y)
    lat = np.arctan2(z, rho * (1.0 - WGS84_E2))
    for _ in range(8):
        _, r_e = radii_of_curvature(lat)
        h = _height_above(rho, z, lat)
        lat = np.arctan2(z, rho * (1.0 - WGS84_E2 * r_e / (r_e + h)))
    return lat, lon, _height_above(rho, z, lat)


def _height_above(rho: np.ndarray, z: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Ellipsoidal height of the point (rho, z) whose geodetic latitude is lat.

    rho cos(lat) + z sin(lat) - a sqrt(1 - e^2 sin^2 lat) holds at every latitude; the textbook
    rho / cos(lat) - R_E loses precision near the poles and divides by zero on the polar axis.
    """
    return (
        rho * np.cos(lat) + z * np.sin(lat) - WGS84_A * np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    )


def e_R_l(lat: np.ndarray | float, lon: np.ndarray | float) -> np.ndarray:
    """Rotation (..., 3, 3) from the local East-North-Up frame at (lat, lon) to ECEF; columns are E, N, U."""
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    east = np.stack(np.broadcast_arrays(-so, co, 0.0 * so), axis=-1)
    north = np.stack(np.broadcast_arrays(-sl * co, -sl * so, cl), axis=-1)
    up = np.stack(np.broadcast_arrays(cl * co, cl * so, sl), axis=-1)
    return np.stack([east, north, up], axis=-1)


@dataclass(frozen=True)
class LocalFrame:
    """The `map` frame: ENU tangent frame at a geodetic origin (lat_deg, lon_deg, height_m on WGS84)."""

    lat_deg: float
    lon_deg: float
    height_m: float = 0.0

    @property
    def lat0(self) -> float:
        return float(np.radians(self.lat_deg))

    @property
    def lon0(self) -> float:
        return float(np.radians(self.lon_deg))

    @property
    def e_R_n(self) -> np.ndarray:
        return e_R_l(self.lat0, self.lon0)

    @property
    def e_p0(self) -> np.ndarray:
        return geodetic_to_ecef(self.lat0, self.lon0, self.height_m)

    @property
    def n_omega_ie(self) -> np.ndarray:
        """Earth rate in the map frame, rad/s (constant because map is Earth-fixed)."""
        return np.array([0.0, OMEGA_IE * np.cos(self.lat0), OMEGA_IE * np.sin(self.lat0)])

    def geodetic_to_map(self, lat: np.ndarray, lon: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Map-frame position n_p (..., 3) in metres of geodetic coordinates (rad, rad, m)."""
        return (geodetic_to_ecef(lat, lon, h) - self.e_p0) @ self.e_R_n

    def map_to_geodetic(self, n_p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lat, lon, h) in rad, rad, m of map-frame positions (..., 3)."""
        return ecef_to_geodetic(np.asarray(n_p) @ self.e_R_n.T + self.e_p0)

    def n_R_l(self, lat: np.ndarray | float, lon: np.ndarray | float) -> np.ndarray:
        """Rotation (..., 3, 3) from the local-level ENU frame at (lat, lon) to the map frame."""
        return self.e_R_n.T @ e_R_l(lat, lon)

    def n_gravity(self, n_p: np.ndarray) -> np.ndarray:
        """Normal gravity vector (..., 3) in m/s^2 at map positions n_p, expressed in the map frame.

        Along the downward ellipsoidal normal at the point, magnitude normal_gravity(lat, h).
        """
        lat, lon, h = self.map_to_geodetic(n_p)
        l_up = self.n_R_l(lat, lon)[..., :, 2]
        return -normal_gravity(lat, h)[..., None] * l_up


# Hydrostatics of the depth sensor (docs/conventions.md: /depth/pressure). The water surface is taken at
# ellipsoidal height 0, so a depth d is the height h = -d.
WATER_DENSITY_KG_M3 = 1025.0  # sea water
ATMOSPHERIC_PA = 101325.0  # standard atmosphere


def column_gravity(lat: np.ndarray | float, depth_m: np.ndarray | float) -> np.ndarray:
    """Mean normal gravity over a water column from the surface (h = 0) down to depth_m: gravity at its
    middle (normal gravity is linear in h to 1e-13 over a few km), m/s^2."""
    return normal_gravity(lat, -0.5 * np.asarray(depth_m, dtype=float))


def depth_to_pressure(
    depth_m: np.ndarray | float,
    lat: float,
    density_kg_m3: float = WATER_DENSITY_KG_M3,
    atmospheric_pa: float = ATMOSPHERIC_PA,
) -> np.ndarray:
    """Absolute pressure (Pa) at depth_m below the surface: p_atm + rho g_column d."""
    d = np.asarray(depth_m, dtype=float)
    return np.asarray(atmospheric_pa + density_kg_m3 * column_gravity(lat, d) * d)


def pressure_to_depth(
    pressure_pa: np.ndarray | float,
    lat: float,
    density_kg_m3: float = WATER_DENSITY_KG_M3,
    atmospheric_pa: float = ATMOSPHERIC_PA,
) -> tuple[np.ndarray, np.ndarray]:
    """Depth below the surface (m) of absolute pressure, the inverse of depth_to_pressure (fixed point on
    the column's gravity, exact to 1e-9 m after three passes), and dd/dp (m/Pa) for the variance."""
    dp = np.asarray(pressure_pa, dtype=float) - atmospheric_pa
    d = dp / (density_kg_m3 * normal_gravity(lat, 0.0))
    for _ in range(3):
        d = dp / (density_kg_m3 * column_gravity(lat, d))
    return np.asarray(d), np.asarray(1.0 / (density_kg_m3 * column_gravity(lat, d)))


def gaussian_radius(lat: float) -> float:
    """sqrt(R_N R_E) at lat (rad), m: the radius of the sphere that best fits the ellipsoid there. A map
    position (x, y, z) has the ellipsoidal height h0 + z + (x^2 + y^2) / (2 R) to a millimetre within 10 km."""
    r_n, r_e = radii_of_curvature(lat)
    return float(np.sqrt(r_n * r_e))


def gravity_gradient(frame: LocalFrame, n_p: np.ndarray, step_m: float = 10.0) -> np.ndarray:
    """(..., 3, 3) gradient d n_gravity / d n_p (1/s^2) at map positions, by central differences of
    LocalFrame.n_gravity (its curvature over step_m is 1e-12 of g: the differences are exact enough)."""
    n_p = np.asarray(n_p, dtype=float)
    G = np.empty(n_p.shape + (3,))
    for j in range(3):
        e = np.zeros(3)
        e[j] = step_m
        G[..., :, j] = (frame.n_gravity(n_p + e) - frame.n_gravity(n_p - e)) / (2.0 * step_m)
    return G
