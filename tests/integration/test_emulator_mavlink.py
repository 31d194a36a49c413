"""vehicle-emu as a separate process over real UDP on 127.0.0.1, driven by pymavlink (issue 3)."""

from __future__ import annotations

import itertools
import math
import re
import textwrap
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import (
    PREARM_CHECK,
    MavClient,
    SetpointStreamer,
    custom_main_mode,
    custom_sub_mode,
    free_udp_port,
    hover_thrust,
    rates_setpoint,
    run_emulator,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

UAV1_MASS_KG, UAV1_FMAX_N = 0.85, 6.0  # Table I UAV 1, the default airframe of --id 1
OFFBOARD, POSCTL, AUTO = 6, 3, 4
OFFBOARD_MODE, LOITER_MODE, LAND_MODE = 6 << 16, (4 << 16) | (3 << 24), (4 << 16) | (6 << 24)
ACCEPTED, TEMP_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
# PX4 v1.16.0's STATUSTEXTs (recorded, ../shared/data/sitl/px4/modes_and_acks)
PX4_NO_OFFBOARD = "Switching to Offboard is currently not available"
PX4_ARMING_DENIED = "Arming denied: Resolve system health failures first"
PX4_FAILSAFE = "Failsafe activated"
PX4_TEXT = "%s\t"  # PX4 v1.16.0 ends every STATUSTEXT in a TAB (the px4 personality does)


def _start(args: list[str], tmp_path: Path):
    port = free_udp_port()
    client = MavClient(port)
    ctx = run_emulator(args, remote_port=port, log_dir=str(tmp_path))
    return client, ctx


@pytest.fixture
def ground_vehicle(tmp_path):
    """A vehicle booted on the ground, once its pre-arm checks pass (as a GCS waits for it)."""
    client, ctx = _start(["--id", "1"], tmp_path)
    with ctx as emu:
        client.wait("HEARTBEAT", 60)
        client.wait_ready_to_arm()
        yield client, emu
    client.close()


def test_arming_is_refused_until_the_vehicle_is_ready_after_boot(tmp_path):
    # PX4 v1.16.0 SIH: three TEMPORARILY_REJECTED with "Arming denied: Resolve system health
    # failures first", HEARTBEAT system_status UNINIT (0), then ACCEPTED 3.0 s after its first
    # HEARTBEAT, when SYS_STATUS shows the pre-arm check healthy and system_status STANDBY (3)
    client, ctx = _start(["--id", "1"], tmp_path)
    with ctx:
        first = client.wait("HEARTBEAT", 60)
        t_first = time.monotonic()
        assert first.system_status == 0
        assert client.command(400, 1) == TEMP_REJECTED
        assert client.wait_text(2, lambda t: t.startswith("Arming denied"))[1] == (
            "Arming denied: Resolve system health failures first\t"
        )
        status = client.wait("SYS_STATUS", 2)
        assert not status.onboard_control_sensors_health & PREARM_CHECK
        assert status.onboard_control_sensors_present & PREARM_CHECK
        client.wait_ready_to_arm(10)
        ready_after_s = time.monotonic() - t_first
        assert 2.0 < ready_after_s < 4.5
        assert client.wait("HEARTBEAT", 2).system_status == 3
        assert client.command(400, 1) == ACCEPTED
        assert client.wait("HEARTBEAT", 2, lambda m: m.base_mode & 128).system_status == 4
    client.close()


@pytest.fixture
def air_vehicle(tmp_path):
    client, ctx = _start(["--id", "1", "--in-air"], tmp_path)
    with ctx as emu:
        client.wait("HEARTBEAT", 60)
        yield client, emu
    client.close()


@pytest.fixture
def nominal_air_vehicle(tmp_path):
    """The paper's nominal model (stiff, noise-free inner loops) in the air; the calibrated
    px4 response is tested against the recordings in test_emulator_replay_udp.py."""
    client, ctx = _start(["--id", "1", "--in-air", "--autopilot", "nominal"], tmp_path)
    with ctx as emu:
        client.wait("HEARTBEAT", 60)
        yield client, emu
    client.close()


def _set_mode(client: MavClient, base_mode: int, main: int, sub: int = 0) -> int:
    """DO_SET_MODE as PX4 v1.16.0 answers it: ACCEPTED at once, then the result (returned)."""
    first, result = client.command_acks(176, base_mode, main, sub, count=2)
    assert first == ACCEPTED, "the first ACK (PX4's MAVLink receiver) is always ACCEPTED"
    return result


def _altitude_m(client: MavClient) -> float:
    return -client.wait("LOCAL_POSITION_NED", 2.0).z


def _hover_stream(client: MavClient, roll_rate=lambda: 0.0) -> SetpointStreamer:
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)
    return SetpointStreamer(client, lambda: rates_setpoint(1, roll_rate(), 0.0, 0.0, thrust))


def test_heartbeat_identifies_px4_quadrotor_with_custom_mode(ground_vehicle):
    # GIVEN a vehicle on the ground WHEN its heartbeat arrives THEN it is a PX4 quadrotor in Hold
    client, _ = ground_vehicle
    hb = client.wait("HEARTBEAT", 3)
    assert (hb.autopilot, hb.type) == (12, 2)
    assert hb.base_mode & 1 and not hb.base_mode & 128
    assert (custom_main_mode(hb.custom_mode), custom_sub_mode(hb.custom_mode)) == (AUTO, 3)
    # WHEN switched to Position mode THEN custom_mode reads main mode 3 (3 << 16)
    assert _set_mode(client, 1, POSCTL) == ACCEPTED
    hb = client.wait("HEARTBEAT", 3, lambda m: m.custom_mode == POSCTL << 16)
    assert hb.base_mode == 1 | 64 | 16  # PX4 v1.16.0: 209 armed, so 81 disarmed
    # and manual modes are refused without RC
    assert _set_mode(client, 1, 1) == DENIED


def test_arming_acks_and_command_rules(ground_vehicle):
    client, _ = ground_vehicle
    assert client.command(400, 1) == ACCEPTED
    client.wait("HEARTBEAT", 3, lambda m: m.base_mode & 128)
    assert client.command(400, 0) == ACCEPTED
    client.wait("HEARTBEAT", 3, lambda m: not m.base_mode & 128)
    assert client.command(400, 7) == DENIED  # nonsense param1
    assert client.command(31000) == UNSUPPORTED  # every COMMAND_LONG gets an ACK
    # a command for another system gets no ACK
    client.send(mavlink.MAVLink_command_long_message(7, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    with pytest.raises(TimeoutError):
        client.wait("COMMAND_ACK", 1.0)


@pytest.mark.parametrize("where", ["ground-disarmed", "ground-armed", "in-air"])
def test_one_setpoint_then_offboard_is_accepted_at_once(request, where):
    # GIVEN a vehicle that never saw a setpoint WHEN one SET_ATTITUDE_TARGET is followed at once
    # by DO_SET_MODE OFFBOARD THEN it is ACCEPTED (PX4 SITL entered OFFBOARD 2-4 ms later)
    client, _ = request.getfixturevalue("air_vehicle" if where == "in-air" else "ground_vehicle")
    armed = where != "ground-disarmed"
    if where == "ground-armed":
        assert client.command(400, 1) == ACCEPTED
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)
    client.send(rates_setpoint(1, 0.0, 0.0, 0.0, thrust))
    sent = time.monotonic()
    assert _set_mode(client, 1 | (128 if armed else 0), OFFBOARD) == ACCEPTED
    assert time.monotonic() - sent < 0.2
    with _hover_stream(client):  # keep it in OFFBOARD (no setpoint loss) while we look
        hb = client.wait("HEARTBEAT", 3, lambda m: m.custom_mode == 393216)
        assert bool(hb.base_mode & 128) is armed


def test_offboard_without_a_recent_setpoint_is_temporarily_rejected(air_vehicle):
    client, _ = air_vehicle
    # GIVEN armed, no setpoint ever WHEN OFFBOARD is requested THEN ACCEPTED (PX4's MAVLink
    # receiver) then TEMPORARILY_REJECTED + PX4's text (its commander), as PX4 v1.16.0 at 30.74 s
    sent = time.monotonic()
    assert client.command_acks(176, 1 | 128, OFFBOARD, 0, count=2) == [ACCEPTED, TEMP_REJECTED]
    assert time.monotonic() - sent < 0.2
    text = client.wait("STATUSTEXT", 2, lambda m: "Offboard" in m.text)
    assert text.text == PX4_TEXT % PX4_NO_OFFBOARD and text.severity == 2  # MAV_SEVERITY_CRITICAL
    hb = client.wait("HEARTBEAT", 3)
    assert (custom_main_mode(hb.custom_mode), custom_sub_mode(hb.custom_mode)) == (AUTO, 3)
    # GIVEN one setpoint older than COM_OF_LOSS_T (1 s) THEN still refused
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)
    client.send(rates_setpoint(1, 0.0, 0.0, 0.0, thrust))
    client.collect(1.3)
    assert _set_mode(client, 1 | 128, OFFBOARD) == TEMP_REJECTED
    # and a fresh one is enough again
    client.send(rates_setpoint(1, 0.0, 0.0, 0.0, thrust))
    assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED


def test_rates_and_thrust_hold_hover_and_track_a_body_rate(nominal_air_vehicle):
    client, _ = nominal_air_vehicle
    cmd = {"roll": 0.0}
    with _hover_stream(client, lambda: cmd["roll"]):
        client.collect(1.3)
        assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
        z0 = _altitude_m(client)
        # hover: 2 s at hover thrust and zero rates keeps the altitude
        pos = client.collect(2.0, "LOCAL_POSITION_NED")
        assert len(pos) > 40
        assert max(abs(-p.z - z0) for p in pos) < 0.1
        assert max(abs(p.vz) for p in pos) < 0.1
        # a commanded roll rate of 0.5 rad/s is tracked (ATTITUDE.rollspeed, FRD)
        cmd["roll"] = 0.5
        client.collect(0.3)
        att = client.collect(0.3, "ATTITUDE")
        cmd["roll"] = -0.5
        client.collect(0.3)
        back = client.collect(0.3, "ATTITUDE")
        cmd["roll"] = 0.0
        assert att and back
        assert all(abs(a.rollspeed - 0.5) < 0.05 for a in att)
        assert all(abs(a.rollspeed + 0.5) < 0.05 for a in back)


@pytest.mark.parametrize("action, expect_mode", [(0, POSCTL << 16), (4, (AUTO << 16) | (6 << 24))])
def test_setpoint_loss_runs_the_loss_action_in_time(air_vehicle, action, expect_mode):
    client, _ = air_vehicle
    assert client.set_param("COM_OBL_RC_ACT", action, ptype=6).param_type == 6
    stream = _hover_stream(client)
    with stream:
        client.collect(1.3)
        assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
        client.wait("HEARTBEAT", 3, lambda m: m.custom_mode == 393216)
        z0 = _altitude_m(client)
    t_stop = time.monotonic()
    # WHEN the stream stops THEN the loss action starts within COM_OF_LOSS_T (1 s) + 0.5 s, with
    # PX4's STATUSTEXT (severity CRITICAL; PX4 v1.16.0: 1.12 s after the last setpoint)
    text = client.wait("STATUSTEXT", 3, lambda m: m.text == PX4_TEXT % PX4_FAILSAFE)
    assert time.monotonic() - t_stop < 1.5 and text.severity == 2
    hb = client.wait("HEARTBEAT", 3)
    assert hb.custom_mode == expect_mode, text.text
    # base_mode: POSCTL 209 armed as PX4 v1.16.0; AUTO modes 157 (AUTO | GUIDED | STABILIZE)
    assert hb.base_mode == (209 if action == 0 else 157)
    assert hb.system_status == 5  # CRITICAL while the failsafe holds the mode, as recorded
    pos = client.collect(2.0, "LOCAL_POSITION_NED")
    if action == 0:
        # Position with no manual control (COM_RC_IN_MODE 4): the stick reads full down, so it
        # descends at MPC_Z_VEL_MAX_DN (PX4 v1.16.0 recorded 1.04 m/s) while holding x, y
        assert 0.8 < pos[-1].vz < 1.2 and -pos[-1].z < z0 - 0.5
    else:
        # land: a gentle descent (MPC_LAND_SPEED 0.7 m/s) to the ground, then disarm
        assert 0.5 < pos[-1].vz < 0.9
    client.wait("EXTENDED_SYS_STATE", 30, lambda m: m.landed_state == 1)
    client.wait("HEARTBEAT", 10, lambda m: not m.base_mode & 128)


def test_takeoff_and_land_then_disarm(ground_vehicle):
    client, _ = ground_vehicle
    assert client.command(400, 1) == ACCEPTED
    assert client.command(22, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + 3.0) == ACCEPTED
    client.wait("EXTENDED_SYS_STATE", 3, lambda m: m.landed_state in (2, 3))
    client.wait("LOCAL_POSITION_NED", 10, lambda m: m.z < -2.8)
    client.wait("HEARTBEAT", 5, lambda m: custom_sub_mode(m.custom_mode) == 3)  # Hold
    assert abs(_altitude_m(client) - 3.0) < 0.3
    assert client.command(21) == ACCEPTED
    fast = client.collect(1.5, "LOCAL_POSITION_NED")
    assert all(p.vz < 1.0 for p in fast)
    client.wait("EXTENDED_SYS_STATE", 15, lambda m: m.landed_state == 1)
    client.wait("STATUSTEXT", 5, lambda m: m.text == PX4_TEXT % "Disarmed by landing")
    # PX4 v1.16.0 (2026-12-04 recordings): Land never becomes the mode after disarming, so the
    # disarm returns to the last armable mode selected, here Hold (docs/emulator.md)
    hb = client.wait("HEARTBEAT", 3, lambda m: not m.base_mode & 128)
    assert custom_sub_mode(hb.custom_mode) == 3 and hb.custom_mode != LAND_MODE  # Hold


def test_parameters_list_read_set_and_refuse_unknown(ground_vehicle):
    client, _ = ground_vehicle
    client.send(mavlink.MAVLink_param_request_list_message(1, 1))
    first = client.wait("PARAM_VALUE", 5)
    values = {first.param_id: first} | {m.param_id: m for m in client.collect(1.0, "PARAM_VALUE")}
    assert len(values) == first.param_count
    assert values["COM_OF_LOSS_T"].param_value == pytest.approx(1.0)
    assert client.get_param("COM_OF_LOSS_T").param_value == pytest.approx(1.0)
    assert client.set_param("COM_OF_LOSS_T", 2.5).param_value == pytest.approx(2.5)
    assert client.get_param("COM_OF_LOSS_T").param_value == pytest.approx(2.5)
    # out of range: refused, the old value is echoed
    assert client.set_param("COM_OF_LOSS_T", 1e6).param_value == pytest.approx(2.5)
    # unknown: refused with a STATUSTEXT, no PARAM_VALUE
    client.send(mavlink.MAVLink_param_set_message(1, 1, b"NO_SUCH_PARAM", 1.0, 9))
    client.wait("STATUSTEXT", 3, lambda m: "NO_SUCH_PARAM" in m.text)


def test_scheduled_mass_drop_happens_at_its_time(tmp_path):
    team = tmp_path / "team.yaml"
    team.write_text(
        textwrap.dedent("""
        vehicles:
          - id: 1
            sysid: 1
            initial: {position_enu_m: [0.0, 0.0, 5.0]}
            airframe: {arm_length_m: 0.2, anti_torque_m: 0.016, rotor_thrust_max_n: 6.0}
            plant: {mass_kg: 0.85, inertia_kgm2: [0.04856, 0.04856, 0.08801]}
        faults:
          - {kind: mass_drop, vehicle: 1, at_s: 2.0, fraction: 0.3}
    """)
    )
    client, ctx = _start(["--id", "1", "--team", str(team)], tmp_path)
    with ctx:
        client.wait("HEARTBEAT", 60)
        assert client.get_param("EMU_MDROP_T").param_value == pytest.approx(2.0)
        assert client.get_param("EMU_FLT_CLK").param_value == -1.0  # not started before OFFBOARD
        with _hover_stream(client):
            client.collect(1.3)
            assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
            client.wait("STATUSTEXT", 3, lambda m: "Fault clock started" in m.text)
            text = client.wait("STATUSTEXT", 5, lambda m: m.text.startswith("Fault: mass"))
            at_s = float(re.search(r"at ([0-9.]+) s", text.text).group(1))
            assert 2.0 <= at_s <= 2.0 + 0.003  # the first tick (2 ms) at or after 2.0 s
            assert client.get_param("EMU_MASS_KG").param_value == pytest.approx(0.595, abs=1e-4)
            # same thrust, 30 % less mass: it now climbs
            client.wait("LOCAL_POSITION_NED", 3, lambda m: m.vz < -0.5)
    client.close()


def test_message_interval_and_timesync(ground_vehicle):
    client, _ = ground_vehicle
    assert client.command(511, 30, 100_000) == ACCEPTED  # ATTITUDE at 10 Hz
    client.collect(0.2)
    stamps = [m.time_boot_ms for m in client.collect(2.0, "ATTITUDE")]
    # paced on the vehicle's own clock: a loaded host that stops it for a while costs messages
    # in the 2 s (as PX4, it sends one late, never the backlog), not the 100 ms spacing
    gaps = sorted(b - a for a, b in itertools.pairwise(stamps))
    assert 10 <= len(stamps) <= 23
    assert gaps[len(gaps) // 2] == pytest.approx(100, abs=4)
    assert client.command(511, 30, -1) == ACCEPTED  # off
    client.collect(0.2)
    assert client.collect(0.5, "ATTITUDE") == []
    assert client.command(511, 9999, 1000) == UNSUPPORTED
    client.send(mavlink.MAVLink_timesync_message(0, 123456789))
    reply = client.wait("TIMESYNC", 3, lambda m: m.ts1 == 123456789)
    assert reply.tc1 > 0


def test_heartbeat_stays_at_1_hz_whatever_is_requested(ground_vehicle):
    # GIVEN PX4 v1.16.0: SET_MESSAGE_INTERVAL HEARTBEAT 5 Hz -> FAILED; GET -> 1000000 us; 1.00 Hz
    client, _ = ground_vehicle
    assert client.command(511, 0, 200_000) == FAILED
    client.send(mavlink.MAVLink_command_long_message(1, 1, 510, 0, 0, 0, 0, 0, 0, 0, 0))
    reply = client.wait("MESSAGE_INTERVAL", 3, lambda m: m.message_id == 0)
    assert reply.interval_us == 1_000_000
    assert client.wait("COMMAND_ACK", 3, lambda m: m.command == 510).result == ACCEPTED
    beats = client.collect(4.0, "HEARTBEAT")
    assert 3 <= len(beats) <= 5  # 1 Hz (at 5 Hz: 20)


def test_do_set_mode_is_acked_twice_other_commands_once_and_emu_ack_twice_0_once(air_vehicle):
    client, _ = air_vehicle
    # GIVEN the default (PX4 v1.16.0) WHEN armed THEN one ACK (recorded: one for arming)
    assert client.command(400, 1) == ACCEPTED
    with pytest.raises(TimeoutError):
        client.wait("COMMAND_ACK", 0.5)
    # WHEN DO_SET_MODE THEN exactly two ACKs, both within 0.2 s (recorded: 0.4-3 ms, 4-11 ms)
    sent = time.monotonic()
    assert client.command_acks(176, 1 | 128, POSCTL, 0, count=2) == [ACCEPTED, ACCEPTED]
    assert time.monotonic() - sent < 0.2
    with pytest.raises(TimeoutError):
        client.wait("COMMAND_ACK", 0.5)
    # GIVEN EMU_ACK_TWICE = 0 WHEN OFFBOARD without a setpoint THEN one ACK, the real result
    assert client.set_param("EMU_ACK_TWICE", 0, ptype=6).param_value == 0.0
    assert client.command(176, 1 | 128, OFFBOARD, 0) == TEMP_REJECTED
    assert client.command(176, 1 | 128, AUTO, 3) == ACCEPTED
    with pytest.raises(TimeoutError):
        client.wait("COMMAND_ACK", 0.5)


def test_disarmed_offboard_without_a_setpoint_is_accepted_and_arming_there_refused(
    ground_vehicle,
):
    # PX4 v1.16.0, modes_and_acks 6.44-12.51 s
    client, _ = ground_vehicle
    # GIVEN disarmed, no setpoint ever WHEN OFFBOARD THEN ACCEPTED twice, HEARTBEAT 393216 base 1
    assert client.command_acks(176, 1, OFFBOARD, 0, count=2) == [ACCEPTED, ACCEPTED]
    hb = client.wait("HEARTBEAT", 3, lambda m: m.custom_mode == OFFBOARD_MODE)
    assert hb.base_mode == 1
    # AND no failsafe while disarmed: still OFFBOARD after more than COM_OF_LOSS_T (1 s)
    client.collect(1.2)
    hb = client.wait("HEARTBEAT", 3)
    assert (hb.custom_mode, hb.base_mode) == (OFFBOARD_MODE, 1)
    # WHEN armed THEN TEMPORARILY_REJECTED with PX4's text (CRITICAL), still disarmed OFFBOARD
    assert client.command(400, 1) == TEMP_REJECTED
    text = client.wait_text(2, lambda t: t.startswith("Arming"))
    assert text == (2, PX4_TEXT % PX4_ARMING_DENIED)  # CRITICAL, in two chunks as PX4 sends it
    hb = client.wait("HEARTBEAT", 3)
    assert (hb.custom_mode, hb.base_mode) == (OFFBOARD_MODE, 1)
    # WHEN switched to AUTO_LOITER THEN arming is ACCEPTED
    assert _set_mode(client, 1, AUTO, 3) == ACCEPTED
    assert client.command(400, 1) == ACCEPTED
    client.wait("STATUSTEXT", 2, lambda m: m.text == PX4_TEXT % "Armed by external command")
    hb = client.wait("HEARTBEAT", 3, lambda m: m.base_mode & 128)
    assert (hb.custom_mode, hb.base_mode) == (LOITER_MODE, 157)
    assert client.command(400, 0) == ACCEPTED


FAST_LAND = ["--param", "MPC_LAND_SPEED=2.5"]  # 10 m in 4 s


def test_after_an_offboard_loss_landing_it_is_back_in_offboard_and_refuses_to_arm(tmp_path):
    # PX4 v1.16.0, modes_and_acks 35.75-59.01 s: the default loss action (Position, with no
    # manual control) sinks to the ground; MPC_Z_VEL_MAX_DN 2.5 m/s makes 10 m last 4 s
    client, ctx = _start(
        ["--id", "1", "--in-air", "--param", "MPC_Z_VEL_MAX_DN=2.5"], tmp_path
    )
    with ctx:
        client.wait("HEARTBEAT", 60)
        # GIVEN one setpoint then OFFBOARD at once, and nothing more
        client.send(rates_setpoint(1, 0.0, 0.0, 0.0, hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)))
        assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
        # THEN "Failsafe activated" (CRITICAL), Position (CRITICAL), it sinks, lands and
        # "Disarmed by landing"
        text = client.wait("STATUSTEXT", 3, lambda m: m.text == PX4_TEXT % PX4_FAILSAFE)
        assert text.severity == 2
        hb = client.wait("HEARTBEAT", 3, lambda m: m.custom_mode == POSCTL << 16)
        assert (hb.base_mode, hb.system_status) == (209, 5)
        client.wait("STATUSTEXT", 15, lambda m: m.text == PX4_TEXT % "Landing detected")
        client.wait("STATUSTEXT", 5, lambda m: m.text == PX4_TEXT % "Disarmed by landing")
        # AND the HEARTBEAT is back in the intended OFFBOARD, disarmed, base_mode 1
        hb = client.wait("HEARTBEAT", 3, lambda m: not m.base_mode & 128)
        assert (hb.custom_mode, hb.base_mode) == (OFFBOARD_MODE, 1)
        # WHEN armed THEN TEMPORARILY_REJECTED with PX4's text
        assert client.command(400, 1) == TEMP_REJECTED
        text = client.wait_text(2, lambda t: t.startswith("Arming"))
        assert text == (2, PX4_TEXT % PX4_ARMING_DENIED)  # CRITICAL, in two chunks as PX4 sends it
        # AND after AUTO_LOITER is selected arming is ACCEPTED
        assert _set_mode(client, 1, AUTO, 3) == ACCEPTED
        assert client.command(400, 1) == ACCEPTED
        hb = client.wait("HEARTBEAT", 3, lambda m: m.base_mode & 128)
        assert hb.custom_mode == LOITER_MODE
    client.close()


def test_a_gcs_nav_land_from_offboard_is_back_in_offboard_disarmed_after_the_landing(tmp_path):
    # PX4 v1.16.0 (the 2026-12-04 formation recordings): Land prevents arming, so it never
    # becomes the mode after disarming; "Disarmed by landing" returns to the last armable mode
    # selected, OFFBOARD here, where it stays disarmed (docs/emulator.md, "After a landing")
    client, ctx = _start(["--id", "1", "--in-air", *FAST_LAND], tmp_path)
    with ctx:
        client.wait("HEARTBEAT", 60)
        client.send(rates_setpoint(1, 0.0, 0.0, 0.0, hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)))
        with _hover_stream(client):
            assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
            client.wait("HEARTBEAT", 3, lambda m: m.custom_mode == OFFBOARD_MODE)
            assert client.command(21) == ACCEPTED
        texts: list[str] = []
        client.wait(
            "STATUSTEXT", 15, lambda m: texts.append(m.text) or m.text == PX4_TEXT % "Disarmed by landing"
        )
        assert PX4_TEXT % PX4_FAILSAFE not in texts
        beats = client.collect(2.5, "HEARTBEAT")
        assert beats and all((hb.custom_mode, hb.base_mode & 128) == (OFFBOARD_MODE, 0)
                             for hb in beats)
    client.close()


def test_actuator_control_target_flies_through_the_mixer(tmp_path):
    """The nominal personality honours SET_ACTUATOR_CONTROL_TARGET as PX4 <= 1.13 did."""
    client, ctx = _start(["--id", "1", "--in-air", "--autopilot", "nominal"], tmp_path)
    with ctx:
        client.wait("HEARTBEAT", 60)
        _fly_actuator_roll(client)
    client.close()


def test_px4_personality_ignores_actuator_setpoints(air_vehicle):
    """PX4 v1.16.0 drops SET_ACTUATOR_CONTROL_TARGET: no setpoint counts, so an armed OFFBOARD
    request is refused (the first ACK is still ACCEPTED), and AUTOPILOT_VERSION says 1.16.0
    without the SET_ACTUATOR_TARGET capability."""
    client, _ = air_vehicle
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)

    def make():
        return mavlink.MAVLink_set_actuator_control_target_message(
            0, 0, 1, 1, [0.0, 0.0, 0.0, thrust, 0, 0, 0, 0]
        )

    with SetpointStreamer(client, make, rate_hz=100):
        client.collect(0.5)
        assert _set_mode(client, 1 | 128, OFFBOARD) == TEMP_REJECTED
    beats = client.collect(1.5, "HEARTBEAT")
    assert beats and all(hb.custom_mode != OFFBOARD_MODE for hb in beats)
    client.send(mavlink.MAVLink_command_long_message(1, 1, 512, 0, 148, 0, 0, 0, 0, 0, 0))
    version = client.wait("AUTOPILOT_VERSION", 2)
    assert version.flight_sw_version >> 8 == (1 << 16) | (16 << 8) | 0
    assert not version.capabilities & 0x400


def _fly_actuator_roll(client: MavClient) -> None:
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)
    cmd = {"roll": 0.0}

    def make():
        return mavlink.MAVLink_set_actuator_control_target_message(
            0, 0, 1, 1, [cmd["roll"], 0.0, 0.0, thrust, 0, 0, 0, 0]
        )

    with SetpointStreamer(client, make, rate_hz=100):
        client.collect(1.3)
        assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
        z0 = _altitude_m(client)
        pos = client.collect(1.0, "LOCAL_POSITION_NED")
        assert max(abs(-p.z - z0) for p in pos) < 0.1
        # a small positive roll torque (FRD) spins the vehicle up about +x
        cmd["roll"] = 0.01
        client.wait("ATTITUDE", 2, lambda m: m.rollspeed > 0.2)
        cmd["roll"] = 0.0


def test_attitude_branch_wins_over_rates(air_vehicle):
    client, _ = air_vehicle
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)
    # type_mask 0: attitude AND rates given; PX4 flies the attitude (level), rates only as yaw ff
    make = lambda: rates_setpoint(1, 2.0, 2.0, 0.0, thrust, type_mask=0)  # noqa: E731
    with SetpointStreamer(client, make):
        client.collect(1.3)
        assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
        att = client.collect(1.0, "ATTITUDE")
        # level within 0.1 rad: px4 comes from a hold on its wandering estimates, tilted as PX4
        # SIH was in AUTO_LOITER (recorded 1.1 deg mean, 2.8 deg max), with a noisy rate loop;
        # 2 rad/s of rates would turn it by 2 rad
        assert max(abs(a.roll) + abs(a.pitch) for a in att) < 0.1
        targets = client.collect(0.5, "ATTITUDE_TARGET")
        assert targets and all(abs(t.thrust - thrust) < 1e-6 for t in targets)


def test_lockstep_advances_one_tick_per_setpoint(tmp_path):
    client, ctx = _start(["--id", "1", "--in-air", "--lockstep", "--tick-ms", "2"], tmp_path)
    thrust = hover_thrust(UAV1_MASS_KG, UAV1_FMAX_N)
    with ctx:
        client.wait("HEARTBEAT", 60)
        with SetpointStreamer(client, lambda: rates_setpoint(1, 0.0, 0.0, 0.0, thrust)):
            client.collect(1.3)  # not in OFFBOARD yet: real time
            assert _set_mode(client, 1 | 128, OFFBOARD) == ACCEPTED
            client.collect(0.2)
            t0 = client.wait("ATTITUDE", 2).time_boot_ms
            sent0 = time.monotonic()
            client.collect(2.0)
            t1 = client.wait("ATTITUDE", 2).time_boot_ms
            wall_ms = 1e3 * (time.monotonic() - sent0)
        # GIVEN setpoints at 50 Hz (20 ms apart) THEN simulated time runs at 2 ms per setpoint,
        # a tenth of wall time
        assert 0.05 * wall_ms < t1 - t0 < 0.2 * wall_ms
        # WHEN the GCS goes silent THEN time follows the clock again and the failsafe holds
        client.wait("STATUSTEXT", 5, lambda m: m.text == PX4_TEXT % PX4_FAILSAFE)
    client.close()
