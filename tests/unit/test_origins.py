"""gcs.fly.origins: a vehicle's EKF origin from GPS_GLOBAL_ORIGIN or HOME_POSITION, the team's
ties, and the distance rule; checked against the emulator's own geodesy (an independent
implementation) and the tangent-frame closed forms of gcs.geodesy's tests."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from gcs.fly.origins import (
    WAITING,
    TeamTies,
    origin_from_gps_global_origin,
    origin_from_home_position,
)
from gcs.geodesy import PX4_SITL_HOME, Geodetic, TeamFrame
from gcs.link.samples import GpsGlobalOrigin, HomePosition
from vehicle_emulator.physics import geodesy as emu_geodesy

HOME = Geodetic(*PX4_SITL_HOME)


def _int_geodetic(enu_m):
    """An emulator-encoded geodetic point (1e-7 deg, mm) of a team-frame position."""
    lat, lon, alt = emu_geodesy.enu_to_geodetic(np.array(enu_m, dtype=float), *PX4_SITL_HOME)
    return int(round(float(lat) * 1e7)), int(round(float(lon) * 1e7)), int(round(float(alt) * 1e3))


def test_the_origin_from_home_position_is_the_origin_from_gps_global_origin():
    # GIVEN a vehicle whose EKF origin is at (40, -25, 0) m and whose home is 3 m east of it,
    # 0.2 m up (x, y, z NED of home relative to the origin)
    o_lat, o_lon, o_alt = _int_geodetic([40.0, -25.0, 0.0])
    h_lat, h_lon, h_alt = _int_geodetic([43.0, -25.0, 0.2])
    gpo = GpsGlobalOrigin.from_message(
        SimpleNamespace(latitude=o_lat, longitude=o_lon, altitude=o_alt), 0.0)
    home = HomePosition.from_message(SimpleNamespace(
        latitude=h_lat, longitude=h_lon, altitude=h_alt, x=0.0, y=3.0, z=-0.2), 0.0)
    # THEN both give the same origin, and the team frame puts it where it is (the 1e-7 deg
    # encoding is 1 cm)
    team = TeamFrame(HOME)
    a = team.tie(origin_from_gps_global_origin(gpo)).offset_enu_m
    b = team.tie(origin_from_home_position(home)).offset_enu_m
    np.testing.assert_allclose(a, [40.0, -25.0, 0.0], atol=0.02)
    np.testing.assert_allclose(b, a, atol=0.02)


def test_ties_offset_positions_and_refuse_far_origins():
    team = TeamFrame(HOME)
    names = ["vehicle 1 (sysid 1)", "vehicle 2 (sysid 2)"]
    ties = TeamTies(team, names, shared=False, max_origin_distance_m=1000.0)
    assert not ties.complete and ties.problems == [WAITING, WAITING]
    lat, lon, alt = team.geodetic_from_enu(np.array([50.0, 0.0, 0.0]))
    line = ties.tie(0, Geodetic(float(lat), float(lon), float(alt)), "GPS_GLOBAL_ORIGIN")
    assert line.startswith("vehicle 1 (sysid 1): origin ") and "(50.000, 0.000" in line
    np.testing.assert_allclose(ties.offsets_enu_m[0], [50.0, 0.0, 0.0], atol=1e-6)
    # a vehicle 1200 km away is refused, naming the distance and the key
    far = Geodetic(HOME.lat_deg + 10.8, HOME.lon_deg, HOME.alt_m)
    text = ties.tie(1, far, "GPS_GLOBAL_ORIGIN")
    assert ties.ties[1] is None and ties.problems[1] == text
    assert "more than frame.max_origin_distance_m 1000" in text and "set frame.origin" in text
    # attitudes go to each vehicle's local axes by its tie's rotation (the identity when shared)
    shared = TeamTies(team, names, shared=True, max_origin_distance_m=1000.0)
    assert shared.complete and shared.problems == [None, None]
    r = np.tile(np.eye(3), (2, 1, 1))
    np.testing.assert_array_equal(shared.rotations_to_local(r), r)
    turned = ties.rotations_to_local(r)
    np.testing.assert_allclose(turned[0], ties.ties[0].rotation.T, atol=1e-15)


def test_a_malformed_origin_message_is_a_problem_not_a_crash():
    bad = GpsGlobalOrigin.from_message(SimpleNamespace(latitude=10 ** 10, longitude=0,
                                                       altitude=0), 0.0)
    with pytest.raises(ValueError, match="lat_deg"):
        origin_from_gps_global_origin(bad)
    ties = TeamTies(TeamFrame(HOME), ["vehicle 1 (sysid 1)"], False, 1000.0)
    ties.refuse(0, "malformed origin: lat_deg: expected -90..90")
    assert ties.problems[0] == "vehicle 1 (sysid 1): malformed origin: lat_deg: expected -90..90"
