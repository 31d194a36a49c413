"""PX4 OFFBOARD position setpoints (SET_POSITION_TARGET_LOCAL_NED) over real UDP: vehicle-emu
as a subprocess, pymavlink as the ground station."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import MavClient, SetpointStreamer, free_udp_port, run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

OFFBOARD_MODE = 6 << 16
ACCEPTED, TEMP_REJECTED = 0, 1
POSITION_ONLY = 8 | 16 | 32 | 64 | 128 | 256 | 2048  # x, y, z, yaw
ALL_IGNORED = 1 | 2 | 4 | 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048
PX4_TEXT = "%s\t"  # PX4 v1.16.0 ends every STATUSTEXT in a TAB (its mavlink_log_critical texts)


def position_target(x: float, y: float, z: float, yaw: float, mask: int = POSITION_ONLY):
    """Local NED target of vehicle 1 (its LOCAL_POSITION_NED frame)."""
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, 1, mask, x, y, z, 0, 0, 0, 0, 0, 0, yaw, 0)


@pytest.fixture
def px4_in_air(tmp_path: Path):
    port = free_udp_port()
    client = MavClient(port)
    # (noise off: the hold wander, 0.35 m RMS, is test_emulator_hold_estimate's subject)
    with run_emulator(["--id", "1", "--in-air", "--autopilot", "px4", "--param", "EMU_NOISE=0"],
                      remote_port=port, log_dir=str(tmp_path)):
        client.wait("HEARTBEAT", 60)
        yield client
    client.close()


def test_position_setpoints_fly_offboard_and_count_for_the_loss_timeout(px4_in_air):
    client = px4_in_air
    # GIVEN a PX4 vehicle holding at 10 m WHEN one position target, then OFFBOARD at once
    # THEN it is accepted: a position setpoint is an offboard setpoint like the attitude ones
    client.send(position_target(3.0, -2.0, -12.0, math.pi / 2))
    assert client.command_acks(176, 1 | 128, 6, 0, count=2) == [ACCEPTED, ACCEPTED]
    # AND while streamed, it flies there (3 m north, 2 m west, 12 m up) and turns east
    with SetpointStreamer(client, lambda: position_target(3.0, -2.0, -12.0, math.pi / 2), 20):
        p = client.wait("LOCAL_POSITION_NED", 20, lambda m: math.dist(
            (m.x, m.y, m.z), (3.0, -2.0, -12.0)) < 0.15 and math.hypot(m.vx, m.vy, m.vz) < 0.1)
        att = client.wait("ATTITUDE", 2)
        assert att.yaw == pytest.approx(math.pi / 2, abs=0.05)
        assert client.wait("HEARTBEAT", 2).custom_mode == OFFBOARD_MODE
    # WHEN the stream stops THEN COM_OF_LOSS_T (1 s) later PX4's failsafe leaves OFFBOARD
    stopped = time.monotonic()
    client.wait_text(5, lambda t: t == PX4_TEXT % "Failsafe activated")
    assert 0.9 < time.monotonic() - stopped < 1.5
    assert client.wait("HEARTBEAT", 3).custom_mode != OFFBOARD_MODE
    assert p.z == pytest.approx(-12.0, abs=0.15)


def test_an_invalid_position_target_is_reported_and_is_no_setpoint(px4_in_air):
    client = px4_in_air
    # GIVEN a target that ignores everything THEN PX4's text, and OFFBOARD stays unavailable
    client.send(position_target(0, 0, 0, 0, mask=ALL_IGNORED))
    severity, _ = client.wait_text(
        3, lambda t: t == PX4_TEXT % "SET_POSITION_TARGET_LOCAL_NED invalid")
    assert severity == 2  # MAV_SEVERITY_CRITICAL
    assert client.command_acks(176, 1 | 128, 6, 0, count=2) == [ACCEPTED, TEMP_REJECTED]
