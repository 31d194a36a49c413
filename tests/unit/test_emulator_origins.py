"""Per-vehicle EKF origins: LOCAL_POSITION_NED relative to each vehicle's own origin, and the
geodetic messages (GPS_GLOBAL_ORIGIN, HOME_POSITION, GLOBAL_POSITION_INT) consistent with it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tests.harness import RecordingLink, run_until
from vehicle_emulator.config.team import TeamFileError, default_vehicle, parse_team
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.physics.geodesy import (
    HOME_ALT_M,
    HOME_LAT_DEG,
    HOME_LON_DEG,
    WGS84_A_M,
    WGS84_F,
    enu_to_geodetic,
    geodetic_to_enu,
)

E2 = WGS84_F * (2.0 - WGS84_F)


def test_geodetic_round_trip_is_exact_to_a_micrometre():
    rng = np.random.default_rng(1)
    enu = rng.uniform(-3000.0, 3000.0, (200, 3)) * np.array([1.0, 1.0, 0.05])
    lat, lon, h = enu_to_geodetic(enu, HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M)
    back = geodetic_to_enu(lat, lon, h, HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M)
    np.testing.assert_allclose(back, enu, atol=1e-6)


def test_a_kilometre_north_and_east_matches_the_ellipsoid_radii():
    # meridional radius M and prime-vertical radius N at the reference latitude
    phi = math.radians(HOME_LAT_DEG)
    w = math.sqrt(1.0 - E2 * math.sin(phi) ** 2)
    m_radius = WGS84_A_M * (1.0 - E2) / w**3
    n_radius = WGS84_A_M / w
    lat, lon, h = enu_to_geodetic(np.array([[0.0, 1000.0, 0.0], [1000.0, 0.0, 0.0]]),
                                  HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M)
    assert math.radians(lat[0] - HOME_LAT_DEG) * (m_radius + HOME_ALT_M) == pytest.approx(
        1000.0, abs=0.05
    )
    assert math.radians(lon[1] - HOME_LON_DEG) * (n_radius + HOME_ALT_M) * math.cos(
        phi
    ) == pytest.approx(1000.0, abs=0.05)
    # the tangent plane leaves the ellipsoid: 1 km away it is d^2 / 2R (~7.9 cm) above it
    assert h[1] - HOME_ALT_M == pytest.approx(1000.0**2 / (2.0 * n_radius), abs=0.005)


def _two(autopilot: str, **kw) -> tuple[Emulator, list[RecordingLink]]:
    specs = [
        dataclasses.replace(default_vehicle(1, on_ground=False), autopilot=autopilot,
                            position_enu_m=(0.0, 0.0, 10.0), **kw),
        dataclasses.replace(default_vehicle(2, on_ground=False), autopilot=autopilot,
                            position_enu_m=(40.0, -25.0, 12.0), **kw),
    ]
    # noise off: the origins' bookkeeping to the centimetre, not the personalities' estimate
    # wander (on by default for px4 and ardupilot, docs/emulator.md "Calibration")
    emu = Emulator(specs, param_overrides={"EMU_NOISE": 0})
    links = []
    for node in emu.nodes:
        link = RecordingLink()
        node.links.append(link)
        links.append(link)
    run_until(emu, 2.2)
    return emu, links


def _last(link: RecordingLink, mtype: str):
    return [m for m in link.msgs if m.get_type() == mtype][-1]


def _geo_to_team_enu(lat_e7: int, lon_e7: int, alt_mm: int) -> np.ndarray:
    return geodetic_to_enu(
        lat_e7 * 1e-7, lon_e7 * 1e-7, alt_mm * 1e-3, HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M
    )


def test_px4_vehicles_report_positions_from_their_own_boot_origin():
    emu, links = _two("px4")
    for spec, link in zip(emu.specs, links, strict=True):
        x, y, z = spec.position_enu_m
        lp = _last(link, "LOCAL_POSITION_NED")
        # own origin: the ground point below the boot position -> local (0, 0, -height)
        assert (lp.x, lp.y, lp.z) == pytest.approx((0.0, 0.0, -z), abs=0.02)
        origin = _last(link, "GPS_GLOBAL_ORIGIN")
        np.testing.assert_allclose(
            _geo_to_team_enu(origin.latitude, origin.longitude, origin.altitude),
            (x, y, 0.0), atol=0.01,
        )
        home = _last(link, "HOME_POSITION")
        np.testing.assert_allclose(
            _geo_to_team_enu(home.latitude, home.longitude, home.altitude), (x, y, 0.0),
            atol=0.01,
        )
        assert (home.x, home.y, home.z) == pytest.approx((0.0, 0.0, 0.0), abs=1e-6)
        gp = _last(link, "GLOBAL_POSITION_INT")
        np.testing.assert_allclose(
            _geo_to_team_enu(gp.lat, gp.lon, gp.alt), (x, y, z), atol=0.02
        )
        assert gp.relative_alt * 1e-3 == pytest.approx(z, abs=0.02)


def test_the_nominal_personality_and_origin_shared_report_the_team_frame():
    for emu, links in (_two("nominal"), _two("px4", origin_enu_m=(0.0, 0.0, 0.0))):
        for spec, link in zip(emu.specs, links, strict=True):
            x, y, z = spec.position_enu_m
            lp = _last(link, "LOCAL_POSITION_NED")
            assert (lp.x, lp.y, lp.z) == pytest.approx((y, x, -z), abs=0.02)
            origin = _last(link, "GPS_GLOBAL_ORIGIN")
            assert (origin.latitude, origin.longitude) == (
                round(HOME_LAT_DEG * 1e7), round(HOME_LON_DEG * 1e7)
            )


def test_a_configured_origin_is_where_local_position_is_zero():
    emu, links = _two("px4", origin_enu_m=(10.0, 5.0, 0.0))
    for spec, link in zip(emu.specs, links, strict=True):
        x, y, z = spec.position_enu_m
        lp = _last(link, "LOCAL_POSITION_NED")
        assert (lp.x, lp.y, lp.z) == pytest.approx((y - 5.0, x - 10.0, -z), abs=0.02)


def _team(**emulator) -> dict:
    v = {"id": 1, "initial": {"position_enu_m": [3.0, 4.0, 10.0]}}
    if emulator.get("vehicle"):
        v["emulator"] = emulator.pop("vehicle")
    return {"vehicles": [v, {"id": 2}], **({"emulator": emulator} if emulator else {})}


def test_team_file_keys_choose_personality_and_origin():
    team = parse_team(_team())
    assert [v.autopilot for v in team.vehicles] == ["px4", "px4"]
    assert team.vehicles[0].local_origin_enu_m(True) == (3.0, 4.0, 0.0)
    team = parse_team(_team(autopilot="nominal", origin="shared",
                            vehicle={"autopilot": "ardupilot"}))
    assert [v.autopilot for v in team.vehicles] == ["ardupilot", "nominal"]
    assert team.vehicles[0].local_origin_enu_m(True) == (0.0, 0.0, 0.0)
    team = parse_team(_team(vehicle={"origin_enu_m": [1.0, 2.0, 0.0]}))
    assert team.vehicles[0].local_origin_enu_m(True) == (1.0, 2.0, 0.0)


@pytest.mark.parametrize(
    ("emulator", "match"),
    [
        ({"autopilot": "px5"}, r"emulator\.autopilot: expected one of nominal, px4, ardupilot"),
        ({"origin": "mine"}, r"emulator\.origin: expected one of own, shared"),
        ({"vehicle": {"autopilot": 4}}, r"vehicles\[0\]\.emulator\.autopilot: expected one of"),
        ({"vehicle": {"origin_enu_m": [1.0]}}, r"vehicles\[0\]\.emulator\.origin_enu_m"),
    ],
)
def test_bad_emulator_keys_name_the_key(emulator, match):
    with pytest.raises(TeamFileError, match=match):
        parse_team(_team(**emulator))
