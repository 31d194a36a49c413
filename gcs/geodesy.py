"""One team frame for vehicles whose local frames start at different places. Pure.

A real vehicle's LOCAL_POSITION_NED is relative to its own EKF origin (GPS_GLOBAL_ORIGIN, set
where its estimator first had a position, normally where it booted). The team frame is the ENU
tangent frame at a geodetic point (the team file's `frame.origin`). Each vehicle's local frame
is tied to it by a `FrameTie`: the team-frame position of the vehicle's origin and the rotation
between the two tangent frames (the local frame's axes point along its own east, north and up;
50 m away they differ from the team's by 8 micro-radians, 1 km away by 0.16 milli-radians)::

    p_team = offset_enu_m + rotation @ p_local_enu

Geodetic -> ENU goes through ECEF on the WGS-84 ellipsoid with PROJ (pyproj's `cart` and
`topocentric` operations), not a flat-earth approximation. Altitudes are used as the vehicles
report them (GPS_GLOBAL_ORIGIN's altitude is AMSL on PX4 and ArduPilot): the team frame and
every origin use the same convention, and the geoid's slope between points a few hundred metres
apart is millimetres, so heights compare correctly. PX4's own local x/y is an azimuthal
equidistant map of latitude and longitude about the origin; for the distances of a formation
it agrees with the tangent frame to far below a millimetre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pyproj import Transformer

FloatArray = NDArray[np.float64]

#: PX4 SITL's default home (the bundled emulator's team-frame origin).
PX4_SITL_HOME = (47.397742, 8.545594, 488.0)


@dataclass(frozen=True, slots=True)
class Geodetic:
    """A WGS-84 point: latitude and longitude [deg], altitude [m] (see the module docstring)."""

    lat_deg: float
    lon_deg: float
    alt_m: float

    def __post_init__(self) -> None:
        for name in ("lat_deg", "lon_deg", "alt_m"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"{name}: expected a finite number, got {value}")
        if not -90.0 <= self.lat_deg <= 90.0:
            raise ValueError(f"lat_deg: expected -90..90, got {self.lat_deg}")
        if not -180.0 <= self.lon_deg <= 180.0:
            raise ValueError(f"lon_deg: expected -180..180, got {self.lon_deg}")
        if not -1000.0 <= self.alt_m <= 20000.0:
            raise ValueError(f"alt_m: expected -1000..20000 m, got {self.alt_m}")

    def __str__(self) -> str:
        return f"{self.lat_deg:.7f}, {self.lon_deg:.7f}, {self.alt_m:.2f} m"


def _enu_axes_in_ecef(point: Geodetic) -> FloatArray:
    """Rows: the east, north and up unit vectors at `point`, in ECEF (geodetic normal)."""
    lat, lon = math.radians(point.lat_deg), math.radians(point.lon_deg)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]])


@dataclass(frozen=True, slots=True)
class FrameTie:
    """How one vehicle's local frame (ENU axes at its origin) sits in the team frame."""

    origin: Geodetic
    offset_enu_m: FloatArray  # (3,) the vehicle's origin in the team frame
    rotation: FloatArray  # (3, 3) team ENU <- local ENU

    def team_from_local(self, p_local_enu_m: ArrayLike) -> FloatArray:
        """Positions (..., 3) in the vehicle's local ENU frame -> team frame [m]."""
        return self.offset_enu_m + np.asarray(p_local_enu_m, dtype=float) @ self.rotation.T

    def local_from_team(self, p_team_enu_m: ArrayLike) -> FloatArray:
        """Team-frame positions (..., 3) -> the vehicle's local ENU frame [m]."""
        return (np.asarray(p_team_enu_m, dtype=float) - self.offset_enu_m) @ self.rotation

    def vectors_team_from_local(self, v_local_enu: ArrayLike) -> FloatArray:
        """Free vectors (velocities, forces) (..., 3): local ENU axes -> team axes."""
        return np.asarray(v_local_enu, dtype=float) @ self.rotation.T

    def vectors_local_from_team(self, v_team_enu: ArrayLike) -> FloatArray:
        """Free vectors (..., 3): team axes -> the vehicle's local ENU axes."""
        return np.asarray(v_team_enu, dtype=float) @ self.rotation


@dataclass(frozen=True)
class TeamFrame:
    """The ENU tangent frame at `origin`; converts geodetic points and ties local frames."""

    origin: Geodetic
    _to_enu: Transformer = field(init=False, repr=False)

    def __post_init__(self) -> None:
        o = self.origin
        pipeline = (
            "+proj=pipeline +step +proj=cart +ellps=WGS84 "
            f"+step +proj=topocentric +ellps=WGS84 +lat_0={o.lat_deg!r} +lon_0={o.lon_deg!r} "
            f"+h_0={o.alt_m!r}"
        )
        object.__setattr__(self, "_to_enu", Transformer.from_pipeline(pipeline))

    def enu_from_geodetic(self, lat_deg: ArrayLike, lon_deg: ArrayLike,
                          alt_m: ArrayLike) -> FloatArray:
        """Geodetic points (arrays of one shape) -> team-frame ENU (..., 3) [m]."""
        lon, lat, alt = np.broadcast_arrays(np.asarray(lon_deg, dtype=float),
                                            np.asarray(lat_deg, dtype=float),
                                            np.asarray(alt_m, dtype=float))
        e, n, u = self._to_enu.transform(lon, lat, alt)
        return np.stack([np.asarray(e), np.asarray(n), np.asarray(u)], axis=-1)

    def geodetic_from_enu(self, p_enu_m: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Team-frame ENU (..., 3) [m] -> (lat deg, lon deg, alt m), each of shape (...)."""
        p = np.asarray(p_enu_m, dtype=float)
        lon, lat, alt = self._to_enu.transform(p[..., 0], p[..., 1], p[..., 2],
                                               direction="INVERSE")
        return np.asarray(lat), np.asarray(lon), np.asarray(alt)

    def tie(self, local_origin: Geodetic) -> FrameTie:
        """The tie of a vehicle whose local frame starts at `local_origin`."""
        offset = self.enu_from_geodetic(local_origin.lat_deg, local_origin.lon_deg,
                                        local_origin.alt_m)
        rotation = _enu_axes_in_ecef(self.origin) @ _enu_axes_in_ecef(local_origin).T
        return FrameTie(local_origin, np.asarray(offset, dtype=float).reshape(3), rotation)

    def shared_tie(self) -> FrameTie:
        """The tie of a vehicle whose local frame is the team frame (a shared origin)."""
        return FrameTie(self.origin, np.zeros(3), np.eye(3))
