"""gcs.geodesy: the team frame and the ties of vehicles' local frames, against closed forms, the
emulator's own ECEF implementation (an independent one) and the rigid-motion property."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.geodesy import PX4_SITL_HOME, FrameTie, Geodetic, TeamFrame
from vehicle_emulator.physics import geodesy as emu_geodesy

HOME = Geodetic(*PX4_SITL_HOME)
A, F = 6378137.0, 1.0 / 298.257223563
E2 = F * (2.0 - F)

offsets = st.lists(st.floats(-2000.0, 2000.0), min_size=3, max_size=3)


def test_small_offsets_are_the_ellipsoids_radii_of_curvature_times_the_angles():
    frame = TeamFrame(HOME)
    lat = math.radians(HOME.lat_deg)
    m = A * (1 - E2) / (1 - E2 * math.sin(lat) ** 2) ** 1.5  # meridian radius
    n = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)  # prime vertical radius
    d = 1e-4  # deg: about 11 m north, 7.5 m east
    east = frame.enu_from_geodetic(HOME.lat_deg, HOME.lon_deg + d, HOME.alt_m)
    north = frame.enu_from_geodetic(HOME.lat_deg + d, HOME.lon_deg, HOME.alt_m)
    assert east[0] == pytest.approx((n + HOME.alt_m) * math.cos(lat) * math.radians(d), abs=1e-5)
    assert north[1] == pytest.approx((m + HOME.alt_m) * math.radians(d), abs=1e-4)
    # the tangent plane falls away from the ellipsoid: ~d^2 / 2R below it
    assert east[2] == pytest.approx(-east[0] ** 2 / (2 * n), rel=0.02)
    np.testing.assert_allclose(frame.enu_from_geodetic(*PX4_SITL_HOME), 0.0, atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(offsets)
def test_geodetic_round_trip_and_agreement_with_the_emulators_implementation(p):
    frame = TeamFrame(HOME)
    lat, lon, alt = frame.geodetic_from_enu(np.array(p))
    np.testing.assert_allclose(frame.enu_from_geodetic(lat, lon, alt), p, atol=1e-6)
    # the emulator converts with its own ECEF code: both agree to well under a millimetre
    elat, elon, ealt = emu_geodesy.enu_to_geodetic(np.array(p), *PX4_SITL_HOME)
    np.testing.assert_allclose(frame.enu_from_geodetic(elat, elon, ealt), p, atol=1e-5)


@settings(max_examples=50, deadline=None)
@given(offsets, offsets)
def test_a_tie_is_the_rigid_motion_between_the_two_tangent_frames(origin_enu, point_enu):
    # GIVEN a vehicle whose origin is somewhere within 2 km of the team origin and a point P
    team = TeamFrame(HOME)
    o_lat, o_lon, o_alt = team.geodetic_from_enu(np.array(origin_enu) * [1, 1, 0.05])
    origin = Geodetic(float(o_lat), float(o_lon), float(o_alt))
    tie = team.tie(origin)
    local = TeamFrame(origin)
    p_lat, p_lon, p_alt = team.geodetic_from_enu(np.array(point_enu))
    p_local = local.enu_from_geodetic(p_lat, p_lon, p_alt)
    # THEN P in the vehicle's local frame, tied, is P in the team frame (sub-millimetre), the
    # rotation is proper, and the inverse takes it back
    np.testing.assert_allclose(tie.team_from_local(p_local), point_enu, atol=1e-5)
    np.testing.assert_allclose(tie.local_from_team(point_enu), p_local, atol=1e-5)
    np.testing.assert_allclose(tie.rotation @ tie.rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(tie.rotation) == pytest.approx(1.0)


def test_ties_are_vectorised_and_the_shared_tie_is_the_identity():
    team = TeamFrame(HOME)
    lat, lon, alt = team.geodetic_from_enu(np.array([50.0, 0.0, 0.0]))
    tie = team.tie(Geodetic(float(lat), float(lon), float(alt)))
    pts = np.array([[0.0, 0.0, 10.0], [1.0, 2.0, 3.0]])
    out = tie.team_from_local(pts)
    assert out.shape == (2, 3)
    np.testing.assert_allclose(out[0], [50.0, 0.0, 10.0], atol=1e-3)
    # free vectors turn by the rotation only: 50 m east, 8 micro-radians
    v = tie.vectors_team_from_local([0.0, 0.0, 1.0])
    assert abs(v[0]) == pytest.approx(50.0 / 6.39e6, rel=0.01)
    np.testing.assert_allclose(tie.vectors_local_from_team(v), [0.0, 0.0, 1.0], atol=1e-12)
    shared = team.shared_tie()
    assert isinstance(shared, FrameTie)
    np.testing.assert_array_equal(shared.team_from_local(pts), pts)


@pytest.mark.parametrize("args, message", [
    ((91.0, 8.0, 0.0), "lat_deg: expected -90..90, got 91.0"),
    ((47.0, 181.0, 0.0), "lon_deg: expected -180..180, got 181.0"),
    ((47.0, 8.0, math.nan), "alt_m: expected a finite number, got nan"),
    ((47.0, 8.0, 1e6), "alt_m: expected -1000..20000 m"),
])
def test_bad_geodetic_points_are_refused_with_the_value(args, message):
    with pytest.raises(ValueError, match=message.replace(".", r"\.")):
        Geodetic(*args)
