"""In-process emulator (no sockets): telemetry rates, faults, parameters, noise, purity."""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import RecordingLink, run_until
from vehicle_emulator.config.faults import LinkImpairment
from vehicle_emulator.config.team import FaultSpec, default_vehicle
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.mavlink.codec import PeerDecoder
from vehicle_emulator.mavlink.telemetry import DEFAULT_RATES_HZ

ROOT = Path(__file__).resolve().parents[2]
GCS = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)


FakeLink = RecordingLink


def _emu(n=1, in_air=True, **kw) -> tuple[Emulator, list[FakeLink]]:
    emu = Emulator([default_vehicle(i + 1, on_ground=not in_air) for i in range(n)], **kw)
    links = []
    for node in emu.nodes:
        link = FakeLink()
        node.links.append(link)
        links.append(link)
    return emu, links


_run = run_until


def _send(emu: Emulator, i: int, msg, link) -> None:
    decoded = PeerDecoder().feed(msg.pack(GCS), "gcs")
    emu.on_messages(emu.nodes[i], link, decoded, ("127.0.0.1", 1))


def test_px4_telemetry_rates_over_ten_simulated_seconds():
    emu, (link,) = _emu()
    _run(emu, 10.0)
    counts = link.types()
    for name, hz in DEFAULT_RATES_HZ.items():
        assert counts[name] == pytest.approx(10.0 * hz, abs=1.01), name
    assert link.decoder.stats.rejected == 0


def test_set_message_interval_changes_one_vehicles_rate():
    emu, links = _emu(2)
    _send(
        emu,
        0,
        mavlink.MAVLink_command_long_message(1, 1, 511, 0, 30, 50_000, 0, 0, 0, 0, 0),
        links[0],
    )
    _run(emu, 2.0)
    assert links[0].types()["ATTITUDE"] == pytest.approx(40, abs=1)
    assert links[1].types()["ATTITUDE"] == pytest.approx(200, abs=1)
    ack = [m for m in links[0].msgs if m.get_type() == "COMMAND_ACK"]
    assert ack[0].result == 0 and ack[0].target_system == 245


def test_mass_drop_fires_on_the_fault_clock_at_the_first_tick_at_or_after_its_time():
    emu, (link,) = _emu(faults=[FaultSpec("mass_drop", 1, 3.0, fraction=0.3)])
    node = emu.nodes[0]
    assert node.params["EMU_MDROP_T"] == 3.0
    _run(emu, 5.0)
    assert emu.plant.mass_kg[0] == 0.85  # no OFFBOARD yet: the fault clock has not started
    node.autopilot.first_offboard_s = 5.0  # formation start
    _run(emu, 7.998)
    assert emu.plant.mass_kg[0] == 0.85
    _run(emu, 8.0)
    assert emu.plant.mass_kg[0] == pytest.approx(0.595)
    texts = [m.text for m in link.msgs if m.get_type() == "STATUSTEXT"]
    assert any(t.startswith("Fault: mass 0.850->0.595 kg at 3.000 s") for t in texts)


def test_a_late_wake_up_still_drops_the_mass_at_the_first_step_at_or_after_its_time():
    # GIVEN a mass drop at 3.0 s on the fault clock, started at 5.0 s (formation start)
    emu, (link,) = _emu(faults=[FaultSpec("mass_drop", 1, 3.0, fraction=0.3)])
    node = emu.nodes[0]
    _run(emu, 5.0)
    node.autopilot.first_offboard_s = 5.0
    _run(emu, 7.9)
    # WHEN a busy machine wakes the emulator 80 ms late and it catches up in one call
    emu.advance_to(7.98)
    assert emu.plant.mass_kg[0] == 0.85
    emu.advance_to(8.06)
    # THEN the mass dropped at the step at 8.0 s inside that catch-up, and the fault says it
    # happened at 3.000 s on its clock, not at the wake-up (3.060)
    assert emu.plant.mass_kg[0] == pytest.approx(0.595)
    texts = [m.text for m in link.msgs if m.get_type() == "STATUSTEXT"]
    assert any(t.startswith("Fault: mass 0.850->0.595 kg at 3.000 s") for t in texts), texts


def test_fault_clock_from_boot_option():
    emu, _ = _emu(
        faults=[FaultSpec("mass_drop", 1, 1.0, fraction=0.5)], param_overrides={"EMU_FLT_T0": 1}
    )
    _run(emu, 1.0)
    assert emu.plant.mass_kg[0] == pytest.approx(0.425)


def _read_param(emu: Emulator, link, name: str) -> float:
    _send(emu, 0, mavlink.MAVLink_param_request_read_message(1, 1, name.encode(), -1), link)
    values = [m for m in link.msgs if m.get_type() == "PARAM_VALUE" and m.param_id == name]
    return values[-1].param_value


def test_the_fault_clock_parameter_reads_the_clock_when_asked():
    # GIVEN a vehicle whose fault clock does not start before OFFBOARD, and one that starts it
    # at boot
    waiting, (w_link,) = _emu()
    running, (r_link,) = _emu(param_overrides={"EMU_FLT_T0": 1})
    # WHEN 1.5 simulated seconds pass and EMU_FLT_CLK is read, then 0.5 s more
    _run(waiting, 1.5)
    _run(running, 1.5)
    # THEN it reads -1 while the clock has not started, and the clock's time when read
    assert _read_param(waiting, w_link, "EMU_FLT_CLK") == -1.0
    assert _read_param(running, r_link, "EMU_FLT_CLK") == pytest.approx(1.5, abs=1e-6)
    _run(running, 2.0)
    assert _read_param(running, r_link, "EMU_FLT_CLK") == pytest.approx(2.0, abs=1e-6)


def test_link_loss_and_motor_efficiency_faults():
    emu, (link,) = _emu(
        faults=[
            FaultSpec("link_loss", 1, 1.0, duration_s=2.0),
            FaultSpec("motor_efficiency", 1, 1.0, motor=2, efficiency=0.6),
        ],
        param_overrides={"EMU_FLT_T0": 1},
    )
    _run(emu, 1.1)
    n_before = len(link.msgs)
    assert emu.plant.rotor_efficiency[0, 1] == 0.6 and emu.nodes[0].params["EMU_MOT2_EFF"] == 0.6
    _run(emu, 2.9)
    assert len(link.msgs) - n_before < 5  # silent (only STATUSTEXT sent before the loss)
    _run(emu, 3.5)
    assert link.types()["ATTITUDE"] > 0 and len(link.msgs) - n_before > 30


def test_seeded_packet_loss_is_reproducible():
    def drops(seed):
        imp = LinkImpairment(np.random.default_rng(seed), loss_probability=0.3)
        return [imp.admit(0.0) is None for _ in range(2000)]

    a, b = drops(5), drops(5)
    assert a == b and 0.25 < sum(a) / len(a) < 0.35


def test_parameter_side_effects_and_run_time_triggers():
    emu, (link,) = _emu()
    for name, value in [("EMU_MOT3_EFF", 0.5), ("EMU_NOISE", 1), ("EMU_MASS_DROP", 0.2)]:
        _send(emu, 0, mavlink.MAVLink_param_set_message(1, 1, name.encode(), value, 9), link)
    assert emu.plant.rotor_efficiency[0, 2] == 0.5
    # px4 (the default personality): EMU_NOISE drives its sensor model, not telemetry noise
    assert emu.plant.onboard.noise_on[0] and not emu.status.noise[0]
    assert emu.plant.mass_kg[0] == pytest.approx(0.68)
    echoed = {m.param_id: m.param_value for m in link.msgs if m.get_type() == "PARAM_VALUE"}
    assert echoed["EMU_MOT3_EFF"] == 0.5


@pytest.mark.parametrize("autopilot", ["nominal", "px4", "ardupilot"])
def test_noise_defaults_per_personality_and_is_seeded_when_on(autopilot):
    def first_positions(seed, **overrides):
        spec = replace(default_vehicle(1, on_ground=False), autopilot=autopilot)
        emu = Emulator([spec], seed=seed, param_overrides=overrides or None)
        link = FakeLink()
        emu.nodes[0].links.append(link)
        emu.telemetry.set_interval(0, 32, 20_000, 0.0)  # ArduPilot streams only when asked
        _run(emu, 0.5)
        default = emu.nodes[0].params.get_int("EMU_NOISE")
        return default, [(m.x, m.y, m.z) for m in link.msgs if m.get_type() == "LOCAL_POSITION_NED"]

    # GIVEN the personality's default THEN nominal is noise-free, px4 and ardupilot are noisy
    default, _ = first_positions(1)
    assert default == (0 if autopilot == "nominal" else 1)
    # WHEN noise is off THEN the hold is exact; WHEN on THEN seeded, reproducible, small
    _, clean = first_positions(1, EMU_NOISE=0)
    assert clean and all(p == (0.0, 0.0, -10.0) for p in clean)
    _, noisy = first_positions(1, EMU_NOISE=1)
    assert noisy == first_positions(1, EMU_NOISE=1)[1] and noisy != clean
    assert noisy != first_positions(2, EMU_NOISE=1)[1]
    assert max(abs(p[2] + 10.0) for p in noisy) < 0.1


def test_commands_for_other_systems_are_ignored_and_counted():
    emu, (link,) = _emu()
    _send(emu, 0, mavlink.MAVLink_command_long_message(9, 1, 400, 0, 0, 0, 0, 0, 0, 0, 0), link)
    assert not [m for m in link.msgs if m.get_type() == "COMMAND_ACK"]
    assert emu.nodes[0].counters.other_target == 1


def _acks(link: FakeLink) -> list[tuple[int, int]]:
    return [(m.command, m.result) for m in link.msgs if m.get_type() == "COMMAND_ACK"]


def _set_offboard(target_system=1, base_mode=1 | 128):
    return mavlink.MAVLink_command_long_message(
        target_system, 1, 176, 0, base_mode, 6, 0, 0, 0, 0, 0
    )


@pytest.mark.parametrize(
    "in_air, result", [(True, 1), (False, 0)], ids=["armed-no-setpoint", "disarmed"]
)
def test_do_set_mode_gets_accepted_at_once_then_the_commanders_result_on_the_next_tick(
    in_air, result
):
    # GIVEN PX4 v1.16.0's double ACK (EMU_ACK_TWICE = 1, the default) and no setpoint ever
    emu, (link,) = _emu(in_air=in_air)
    assert emu.nodes[0].params["EMU_ACK_TWICE"] == 1
    _run(emu, 0.1)
    link.msgs.clear()
    # WHEN DO_SET_MODE OFFBOARD arrives THEN ACCEPTED goes out at once (the MAVLink receiver)
    _send(emu, 0, _set_offboard(base_mode=1 | (128 if in_air else 0)), link)
    assert _acks(link) == [(176, 0)]
    assert link.types()["STATUSTEXT"] == 0
    # AND on the next tick the real result: armed TEMPORARILY_REJECTED then PX4's STATUSTEXT
    # (in that order, as recorded), disarmed ACCEPTED
    emu.advance_to(emu.now_s + emu.tick_s)
    assert _acks(link) == [(176, 0), (176, result)]
    ack = [m for m in link.msgs if m.get_type() == "COMMAND_ACK"][1]
    assert (ack.target_system, ack.target_component) == (245, 190)
    kinds = [m.get_type() for m in link.msgs if m.get_type() in ("COMMAND_ACK", "STATUSTEXT")]
    texts = [m.text for m in link.msgs if m.get_type() == "STATUSTEXT"]
    if in_air:
        assert kinds[:3] == ["COMMAND_ACK", "COMMAND_ACK", "STATUSTEXT"]
        assert "Switching to Offboard is currently not available\t" in texts  # PX4: a TAB
    # AND nothing more
    _run(emu, emu.now_s + 1.0)
    assert len(_acks(link)) == 2
    assert emu.nodes[0].autopilot.custom_mode == (393216 if not in_air else (4 << 16) | (3 << 24))


def test_emu_ack_twice_0_answers_do_set_mode_once_with_the_result():
    emu, (link,) = _emu(param_overrides={"EMU_ACK_TWICE": 0})
    _send(emu, 0, _set_offboard(), link)
    assert _acks(link) == [(176, 1)]  # TEMPORARILY_REJECTED at once, nothing later
    _run(emu, 0.5)
    assert _acks(link) == [(176, 1)]


def test_only_do_set_mode_commands_are_acked_twice():
    emu, (link,) = _emu(in_air=False)
    _run(emu, 3.1)  # past PX4's arming readiness after boot
    # COMMAND_INT 176 goes through the same PX4 receiver path: twice
    _send(
        emu, 0, mavlink.MAVLink_command_int_message(1, 1, 0, 176, 0, 0, 1, 3, 0, 0, 0, 0, 0), link
    )
    _run(emu, emu.now_s + 0.01)
    assert _acks(link) == [(176, 0), (176, 0)]
    # SET_MODE (the message) is PX4's commander alone: one ACK; arming: one ACK
    link.msgs.clear()
    _send(emu, 0, mavlink.MAVLink_set_mode_message(1, 1, (4 << 16) | (3 << 24)), link)
    _send(emu, 0, mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0), link)
    _run(emu, emu.now_s + 0.1)
    assert _acks(link) == [(176, 0), (400, 0)]


def test_heartbeat_interval_cannot_be_changed():
    # GIVEN PX4 v1.16.0: SET_MESSAGE_INTERVAL for HEARTBEAT (0) -> FAILED, GET -> 1000000 us
    emu, (link,) = _emu()
    for interval_us in (200_000, 0, -1):
        cmd = mavlink.MAVLink_command_long_message(1, 1, 511, 0, 0, interval_us, 0, 0, 0, 0, 0)
        _send(emu, 0, cmd, link)
    assert _acks(link) == [(511, 4)] * 3
    _send(emu, 0, mavlink.MAVLink_command_long_message(1, 1, 510, 0, 0, 0, 0, 0, 0, 0, 0), link)
    reply = [m for m in link.msgs if m.get_type() == "MESSAGE_INTERVAL"]
    assert [(m.message_id, m.interval_us) for m in reply] == [(0, 1_000_000)]
    assert _acks(link)[-1] == (510, 0)
    link.msgs.clear()
    _run(emu, 5.0)
    assert link.types()["HEARTBEAT"] == pytest.approx(5, abs=1)


def test_px4_statustexts_end_in_a_tab_as_recorded():
    # PX4 v1.16.0: "Arming denied: Resolve system health failures first" + TAB, in 2 chunks
    emu, (link,) = _emu(in_air=False)
    emu.nodes[0].statustext(2, "Arming denied: Resolve system health failures first")
    emu.nodes[0].statustext(6, "Armed by external command")
    msgs = [m for m in link.msgs if m.get_type() == "STATUSTEXT"]
    assert [(m.text, m.chunk_seq) for m in msgs] == [
        ("Arming denied: Resolve system health failures firs", 0), ("t\t", 1),
        ("Armed by external command\t", 0),
    ]


def test_a_statustext_longer_than_50_bytes_goes_in_mavlink2_chunks():
    # GIVEN PX4 v1.16.0's 51-character arming refusal (recorded: 2 chunks, one id), from a
    # personality that adds no ending
    emu = Emulator([dataclasses.replace(default_vehicle(1), autopilot="nominal")])
    link = RecordingLink()
    emu.nodes[0].links.append(link)
    node = emu.nodes[0]
    text = "Arming denied: Resolve system health failures first"
    node.statustext(2, "short one")
    node.statustext(2, text)
    node.statustext(2, "x" * 100)  # a multiple of 50: an empty chunk ends it
    msgs = [m for m in link.msgs if m.get_type() == "STATUSTEXT"]
    assert [(m.text, m.id, m.chunk_seq) for m in msgs] == [
        ("short one", 0, 0),
        (text[:50], 1, 0),
        ("t", 1, 1),
        ("x" * 50, 2, 0),
        ("x" * 50, 2, 1),
        ("", 2, 2),
    ]


def test_an_ardupilot_attitude_target_stops_being_flown_within_one_tick_of_guid_timeout():
    # GIVEN an ArduPilot vehicle in GUIDED_NOGPS that takes thrust as thrust (GUID_OPTIONS 8)
    spec = replace(default_vehicle(1, on_ground=False), autopilot="ardupilot")
    emu = Emulator([spec], param_overrides={"EMU_NOISE": 0, "GUID_OPTIONS": 8})
    link = FakeLink()
    emu.nodes[0].links.append(link)
    _run(emu, 1.0)
    _send(emu, 0, mavlink.MAVLink_set_mode_message(1, 1, 20), link)
    _run(emu, 1.006)  # off the 50 Hz autopilot grid
    # WHEN one setpoint arrives THEN its thrust is commanded for GUID_TIMEOUT (3 s), and stops at
    # the first emulator tick after it (ArduCopter checks at 400 Hz), not at the next 50 Hz tick
    _send(emu, 0, mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0,
                                                              0.4321), link)
    sent_s, flown = emu.now_s, []  # (time since the setpoint [s], its thrust commanded)
    while emu.now_s < sent_s + 3.05:
        emu.advance_to(emu.now_s + emu.tick_s)
        flown.append((emu.now_s - sent_s, abs(emu.plant.thrust_cmd_norm[0] - 0.4321) < 1e-6))
    last = max(t for t, used in flown if used)
    first_not = min(t for t, used in flown if not used)
    assert all(used for t, used in flown if t <= 3.0) and last <= 3.0 + 1e-9
    assert 3.0 < first_not <= 3.0 + 2 * emu.tick_s


def test_a_late_wake_up_does_not_fly_an_expired_guided_target_through_its_catch_up():
    # GIVEN an ArduPilot vehicle flying one attitude target's thrust in GUIDED_NOGPS, with
    # ATTITUDE_TARGET streamed at 500 Hz (every emulator tick)
    spec = replace(default_vehicle(1, on_ground=False), autopilot="ardupilot")
    emu = Emulator([spec], param_overrides={"EMU_NOISE": 0, "GUID_OPTIONS": 8})
    link = FakeLink()
    emu.nodes[0].links.append(link)
    _send(emu, 0, mavlink.MAVLink_command_long_message(1, 1, 511, 0, 83, 2000, 0, 0, 0, 0, 0), link)
    _run(emu, 1.0)
    _send(emu, 0, mavlink.MAVLink_set_mode_message(1, 1, 20), link)
    _run(emu, 1.1)
    _send(emu, 0, mavlink.MAVLink_set_attitude_target_message(0, 1, 1, 7, [1, 0, 0, 0], 0, 0, 0,
                                                              0.4321), link)
    sent_s = emu.now_s
    _run(emu, sent_s + 2.99)
    assert emu.plant.thrust_sp_norm[0] == pytest.approx(0.4321, abs=1e-6)
    # WHEN the emulator wakes 30 ms late, across GUID_TIMEOUT (3 s), and catches up at once
    link.msgs.clear()
    emu.advance_to(sent_s + 3.02)
    # THEN the target stopped at its deadline inside the catch-up: what the attitude loop flies
    # and echoes at the end is the level hold, not the expired thrust
    assert emu.plant.thrust_sp_norm[0] != pytest.approx(0.4321, abs=1e-6)
    echoed = [m.thrust for m in link.msgs if m.get_type() == "ATTITUDE_TARGET"]
    assert echoed and all(t != pytest.approx(0.4321, abs=1e-6) for t in echoed)


def test_the_fleet_tick_observes_and_refreshes_every_vehicle_as_each_node_would_alone():
    # GIVEN a fleet of every personality, in the air and on the ground, one of them armed and
    # climbing through takeoff (its battery draining, its landed state changing) for 3 s
    specs = [replace(default_vehicle(k + 1, on_ground=k % 2 == 0), autopilot=name)
             for k, name in enumerate(["px4", "ardupilot", "nominal", "px4", "ardupilot",
                                       "nominal"])]
    emu = Emulator(specs)
    for node in emu.nodes:
        node.links.append(FakeLink())
    _run(emu, 5.0)  # past the pre-arm checks
    link = emu.nodes[0].links[0]
    _send(emu, 0, mavlink.MAVLink_command_long_message(1, 1, 22, 0, 0, 0, 0, 0, 0, 0, 5.0), link)
    _send(emu, 0, mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0), link)
    _run(emu, 8.0)
    emu.advance_to(emu._next_autopilot_s)  # ends on an autopilot tick: the rows were written now
    assert emu.status.armed[0] and emu.status.battery_remaining[0] < 1.0
    assert emu.status.landed_state[0] in (2, 3)  # in the air, or taking off
    # WHEN the fleet's observations and status rows are set beside each node's own
    gathered = emu.observe_fleet()
    own = [node.observe() for node in emu.nodes]
    columns = (*emu.status.ROW_COLUMNS, "battery_remaining", "battery_voltage_v",
               "battery_current_a")
    fleet_status = {name: getattr(emu.status, name).copy() for name in columns}
    for node in emu.nodes:
        node.refresh_status(emu.now_s)
    # THEN they are the same, value for value (types included: a copter's has its tilt)
    assert gathered == own
    assert [type(o) for o in gathered] == [type(o) for o in own]
    for name, values in fleet_status.items():
        np.testing.assert_array_equal(values, getattr(emu.status, name), err_msg=name)
