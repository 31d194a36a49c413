"""WGS-84 geodetic <-> local ENU (tangent plane at a reference point), vectorised. Pure.

The team frame is the ENU tangent plane at the team's home (PX4 SITL's default home unless
configured); GLOBAL_POSITION_INT, HOME_POSITION and GPS_GLOBAL_ORIGIN carry geodetic
coordinates of points given in that frame. The conversion goes through ECEF exactly (no
flat-earth approximation), so a ground station that converts back with any proper library
(pymap3d, GeographicLib) recovers the team-frame positions to well under a millimetre.

geodetic -> ECEF: x = (N + h) cos(lat) cos(lon), y = (N + h) cos(lat) sin(lon),
z = (N (1 - e^2) + h) sin(lat), N = a / sqrt(1 - e^2 sin^2(lat)). ECEF -> geodetic: Bowring's
initial latitude, then two Newton-style refinements (sub-micrometre at aircraft altitudes).
The team frame's default origin (``DEFAULT_ORIGIN_LLA``) and the NED form telemetry uses
(``geodetic_of_ned``) are here too.
"""

from __future__ import annotations

import numpy as np

__all__ = ["WGS84_A_M", "WGS84_F", "enu_to_geodetic", "geodetic_to_enu"]

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
_E2 = WGS84_F * (2.0 - WGS84_F)
_B_M = WGS84_A_M * (1.0 - WGS84_F)
_EP2 = _E2 / (1.0 - _E2)


def _ecef(lat: np.ndarray, lon: np.ndarray, h: np.ndarray) -> np.ndarray:
    sl, cl = np.sin(lat), np.cos(lat)
    n = WGS84_A_M / np.sqrt(1.0 - _E2 * sl * sl)
    return np.stack(
        ((n + h) * cl * np.cos(lon), (n + h) * cl * np.sin(lon), (n * (1.0 - _E2) + h) * sl),
        axis=-1,
    )


def _rotation(lat0: float, lon0: float) -> np.ndarray:
    """Rows: east, north, up unit vectors at (lat0, lon0) in ECEF."""
    sl, cl, so, co = np.sin(lat0), np.cos(lat0), np.sin(lon0), np.cos(lon0)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


def enu_to_geodetic(
    enu_m: np.ndarray, lat0_deg: float, lon0_deg: float, h0_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 3) ENU metres about the reference -> (lat deg, lon deg, ellipsoid height m)."""
    lat0, lon0 = np.radians(lat0_deg), np.radians(lon0_deg)
    ref = _ecef(np.asarray(lat0), np.asarray(lon0), np.asarray(float(h0_m)))
    xyz = ref + np.asarray(enu_m, dtype=float) @ _rotation(lat0, lon0)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    p = np.hypot(x, y)
    theta = np.arctan2(z * WGS84_A_M, p * _B_M)
    lat = np.arctan2(
        z + _EP2 * _B_M * np.sin(theta) ** 3, p - _E2 * WGS84_A_M * np.cos(theta) ** 3
    )
    for _ in range(2):
        sl = np.sin(lat)
        n = WGS84_A_M / np.sqrt(1.0 - _E2 * sl * sl)
        h = p / np.cos(lat) - n
        lat = np.arctan2(z, p * (1.0 - _E2 * n / (n + h)))
    sl = np.sin(lat)
    n = WGS84_A_M / np.sqrt(1.0 - _E2 * sl * sl)
    h = p / np.cos(lat) - n
    return np.degrees(lat), np.degrees(np.arctan2(y, x)), h


def geodetic_to_enu(
    lat_deg: np.ndarray, lon_deg: np.ndarray, h_m: np.ndarray,
    lat0_deg: float, lon0_deg: float, h0_m: float,
) -> np.ndarray:
    """Geodetic points -> (..., 3) ENU metres about the reference."""
    lat0, lon0 = np.radians(lat0_deg), np.radians(lon0_deg)
    ref = _ecef(np.asarray(lat0), np.asarray(lon0), np.asarray(float(h0_m)))
    xyz = _ecef(np.radians(lat_deg), np.radians(lon_deg), np.asarray(h_m, dtype=float))
    return (xyz - ref) @ _rotation(lat0, lon0).T


# The team frame's origin on the globe when the team file states none (its `frame.origin`):
# PX4 SITL's default home (Zurich). Geodetic coordinates (GLOBAL_POSITION_INT, HOME_POSITION,
# GPS_GLOBAL_ORIGIN) are exact WGS-84 (geodesy.py).
HOME_LAT_DEG = 47.397742
HOME_LON_DEG = 8.545594
HOME_ALT_M = 488.0
DEFAULT_ORIGIN_LLA = (HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M)


def geodetic_of_ned(
    ned_m: np.ndarray, origin_lla: tuple[float, float, float] = DEFAULT_ORIGIN_LLA
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Team-frame NED points (..., 3) -> (lat deg, lon deg, altitude m) on the WGS-84
    ellipsoid (the emulator reports ellipsoid heights as AMSL: no geoid model); the team
    frame's origin is ``origin_lla`` (lat deg, lon deg, alt m)."""
    ned = np.asarray(ned_m, dtype=float)
    enu = np.stack((ned[..., 1], ned[..., 0], -ned[..., 2]), axis=-1)
    return enu_to_geodetic(enu, *origin_lla)
