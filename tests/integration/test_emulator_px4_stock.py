"""The px4 personality where stock clients notice (issue 28, item 5): health against arming,
GPS_RAW_INT, NAV_TAKEOFF above the takeoff altitude, RTL / DO_REPOSITION refused honestly.

Real ``vehicle-emu --id 1`` processes on 127.0.0.1, pymavlink and MAVSDK (4.x, its own
mavsdk_server library) as the clients. Figures come from PX4 v1.16.0 SIH
(../shared/data/sitl/px4/boot, modes_and_acks; docs/emulator.md).
"""

from __future__ import annotations

import asyncio
import math

import pytest

from benchmarks.bench_mavsdk_takeoff_land import EXAMPLE_SLEEP_S, takeoff_and_land
from tests.harness import (
    MavClient,
    free_udp_port,
    run_emulator,
    run_emulator_ready,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(150)]

ACCEPTED, TEMP_REJECTED, UNSUPPORTED = 0, 1, 3
GPS_BIT = 0x20  # MAV_SYS_STATUS_SENSOR_GPS
PREARM_BIT = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK
HOME_AMSL_M = 488.0  # the emulator's home (geodesy.HOME_ALT_M)
PX4_ALREADY_HIGHER = "Already higher than takeoff altitude"  # PX4 navigator takeoff.cpp


def _gps_ok(m) -> bool:
    """MAVSDK's is_global_position_ok: the GPS bit present, enabled and healthy."""
    return bool(m.onboard_control_sensors_present & m.onboard_control_sensors_enabled
                & m.onboard_control_sensors_health & GPS_BIT)


def test_mavsdk_takeoff_and_land_example_flies_from_the_ready_line(tmp_path):
    # GIVEN a fresh px4 vehicle, MAVSDK's takeoff_and_land steps started the moment it prints
    # ready (twice; benchmarks/bench_mavsdk_takeoff_land.py does the 10 starts)
    for start in range(2):
        port = free_udp_port()
        with run_emulator_ready(["--id", "1"], remote_port=port, log_dir=str(tmp_path)):
            out = asyncio.run(takeoff_and_land(port))
        # THEN health (global position and home) comes no earlier than arming is possible:
        # arm() is accepted at the first try, the vehicle climbs to MIS_TAKEOFF_ALT, lands
        assert out["arm_error"] is None, f"start {start + 1}: arm() failed: {out}"
        assert out["max_rel_alt_m"] > 2.0, f"start {start + 1}: no takeoff: {out}"
        assert out["land_s"] - out["takeoff_s"] >= EXAMPLE_SLEEP_S


def test_sys_status_gps_and_prearm_bits_come_with_arming(tmp_path):
    # GIVEN a px4 vehicle booting on the ground, pymavlink listening from its first packet
    port = free_udp_port()
    client = MavClient(port)
    with run_emulator(["--id", "1"], remote_port=port, log_dir=str(tmp_path)):
        client.wait("HEARTBEAT", 60)
        # WHEN SYS_STATUS is read until its GPS bit is present, enabled and healthy
        before = []
        first_ok = client.wait("SYS_STATUS", 10, lambda m: before.append(m) or _gps_ok(m))
        # THEN it was not before (PX4 SIH: 2.8 s after its first HEARTBEAT), the pre-arm bit
        # comes in the same message, and arming is accepted at once
        assert len(before) > 5 and not any(_gps_ok(m) for m in before[:-1])
        assert not any(m.onboard_control_sensors_health & PREARM_BIT for m in before[:-1])
        assert first_ok.onboard_control_sensors_health & PREARM_BIT
        assert client.command(400, 1) == ACCEPTED
    client.close()


def test_gps_raw_int_streams_from_boot_with_a_3d_fix_at_the_estimate(tmp_path):
    # GIVEN a px4 vehicle booting on the ground (PX4 SIH streams GPS_RAW_INT from its first
    # packet, 8 Hz of sim time: fix 3D, 10 satellites, eph 70, epv 110)
    port = free_udp_port()
    client = MavClient(port)
    with run_emulator(["--id", "1", "--param", "EMU_NOISE=0"], remote_port=port,
                      log_dir=str(tmp_path)):
        client.wait("HEARTBEAT", 60)
        msgs = client.collect(3.0, ("GPS_RAW_INT", "GLOBAL_POSITION_INT", "SYS_STATUS"))
    client.close()
    gps = [m for m in msgs if m.get_type() == "GPS_RAW_INT"]
    glob = [m for m in msgs if m.get_type() == "GLOBAL_POSITION_INT"]
    # THEN at ~8 Hz, before arming is possible, with PX4's fix and accuracy fields
    assert 20 <= len(gps) <= 28, f"{len(gps)} GPS_RAW_INT in 3 s"
    first_status = next(m for m in msgs if m.get_type() == "SYS_STATUS")
    assert not first_status.onboard_control_sensors_health & PREARM_BIT
    for m in gps:
        assert (m.fix_type, m.satellites_visible, m.eph, m.epv) == (3, 10, 70, 110)
        assert (m.h_acc, m.v_acc, m.vel_acc) == (900, 1780, 400)
        assert m.alt_ellipsoid == m.alt
    # AND at the position GLOBAL_POSITION_INT reports (the vehicle sits still on the ground)
    last_gps, last_glob = gps[-1], glob[-1]
    assert abs(last_gps.lat - last_glob.lat) <= 2 and abs(last_gps.lon - last_glob.lon) <= 2
    assert abs(last_gps.alt - last_glob.alt) <= 20  # mm
    assert abs(last_gps.alt / 1e3 - HOME_AMSL_M) < 0.5


def test_nav_takeoff_below_the_current_altitude_keeps_it(tmp_path):
    # GIVEN a px4 vehicle holding at 10 m
    port = free_udp_port()
    client = MavClient(port)
    with run_emulator(["--id", "1", "--in-air", "--param", "EMU_NOISE=0"], remote_port=port,
                      log_dir=str(tmp_path)):
        start = client.wait("GLOBAL_POSITION_INT", 60)
        assert abs(start.relative_alt / 1e3 - 10.0) < 0.1
        # WHEN NAV_TAKEOFF asks for 2.5 m above home (param7 AMSL, as MAVSDK sends it)
        assert client.command(22, 0, 0, 0, math.nan, math.nan, math.nan,
                              HOME_AMSL_M + 2.5) == ACCEPTED
        # THEN PX4's navigator says so and keeps its altitude (it never descends to it)
        severity, _ = client.wait_text(3, lambda t: t.startswith(PX4_ALREADY_HIGHER))
        assert severity == 2  # CRITICAL, as PX4's mavlink_log_critical
        track = client.collect(4.0, "GLOBAL_POSITION_INT")
    client.close()
    alts = [m.relative_alt / 1e3 for m in track]
    assert min(alts) > 9.7, f"descended to {min(alts):.2f} m"


def test_rtl_and_reposition_are_refused_with_one_unsupported_ack(tmp_path):
    # GIVEN a px4 vehicle holding at 10 m (Hold)
    port = free_udp_port()
    client = MavClient(port)
    with run_emulator(["--id", "1", "--in-air"], remote_port=port, log_dir=str(tmp_path)):
        client.wait("HEARTBEAT", 60)
        # WHEN a client selects Return (DO_SET_MODE AUTO 4 / RTL 5, as MAVSDK's
        # return_to_launch), NAV_RETURN_TO_LAUNCH or DO_REPOSITION
        rtl_mode = client.command(176, 1 | 128, 4, 5)
        late = client.collect(1.0, "COMMAND_ACK")
        rtl_cmd = client.command(20)
        reposition = client.command(192, -1, 1, 0, math.nan, 47.3978, 8.5456, HOME_AMSL_M + 10)
        # and AUTOPILOT_VERSION says what is emulated (sent just before its ACK)
        assert client.command(512, 148) == ACCEPTED
        (version,) = client.seen("AUTOPILOT_VERSION")
        hb = client.wait("HEARTBEAT", 2)
    client.close()
    # THEN each gets one ACK, UNSUPPORTED (no ACCEPTED a client could take for success), and
    # the vehicle stays in Hold
    assert rtl_mode == UNSUPPORTED and not [m for m in late if m.command == 176]
    assert rtl_cmd == UNSUPPORTED and reposition == UNSUPPORTED
    assert hb.custom_mode == (4 << 16) | (3 << 24)
    caps = version.capabilities
    assert caps & 0x80 and caps & 0x40 and caps & 0x8  # position/attitude targets, COMMAND_INT
    assert not caps & (0x1 | 0x4 | 0x20 | 0x100)  # no missions, FTP, global position targets


def test_mavsdk_return_to_launch_reports_the_refusal(tmp_path):
    # GIVEN a px4 vehicle holding at 10 m, MAVSDK connected
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.plugins.action import ActionError, ActionResult

    async def rtl(port: int) -> ActionError | None:
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await mavsdk.first_autopilot(timeout_s=60.0)
            assert system is not None
            try:
                await ActionAsync(system).return_to_launch()
            except ActionError as err:
                return err
        return None

    port = free_udp_port()
    with run_emulator(["--id", "1", "--in-air"], remote_port=port, log_dir=str(tmp_path)):
        err = asyncio.run(rtl(port))
    # THEN return_to_launch() raises instead of "succeeding" while the vehicle stays in Hold
    assert err is not None, "return_to_launch() reported success; the vehicle does not return"
    assert err.result == ActionResult.UNSUPPORTED
