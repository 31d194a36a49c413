"""`--streams requested`: HEARTBEAT only until the ground station asks (in-process, no sockets)."""

from __future__ import annotations

from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import RecordingLink, run_until
from vehicle_emulator.config.team import default_vehicle
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.mavlink.codec import PeerDecoder
from vehicle_emulator.mavlink.telemetry import DEFAULT_RATES_HZ

GCS = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)


def _emu(autopilot: str = "px4") -> tuple[Emulator, RecordingLink]:
    spec = replace(default_vehicle(1, on_ground=False), autopilot=autopilot)
    emu = Emulator([spec], streams="requested")
    link = RecordingLink()
    emu.nodes[0].links.append(link)
    return emu, link


def _command(emu: Emulator, link: RecordingLink, cmd: int, *p: float) -> None:
    p = (*p, *([0.0] * (7 - len(p))))
    msg = mavlink.MAVLink_command_long_message(1, 1, cmd, 0, *p)
    emu.on_messages(emu.nodes[0], link, PeerDecoder().feed(msg.pack(GCS), "gcs"),
                    ("127.0.0.1", 1))


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot", "nominal"])
def test_requested_mode_sends_heartbeat_only_until_asked(autopilot):
    # GIVEN a vehicle with --streams requested
    emu, link = _emu(autopilot)
    # WHEN five simulated seconds pass without a request
    run_until(emu, 5.0)
    # THEN it sent HEARTBEATs at its rate and no other stream (GPS_GLOBAL_ORIGIN, once after
    # boot, is an announcement, not a stream)
    counts = link.types()
    assert counts["HEARTBEAT"] == pytest.approx(5.0, abs=1.01)
    streamed = set(DEFAULT_RATES_HZ) - {"HEARTBEAT"}
    assert not streamed & set(counts), counts


def test_set_message_interval_and_request_message_turn_streams_on():
    # GIVEN a px4 vehicle in requested mode
    emu, link = _emu()
    run_until(emu, 1.0)
    # WHEN the ground station asks ATTITUDE_QUATERNION at 100 Hz, EXTENDED_SYS_STATE at the
    # default rate (interval 0) and SYS_STATUS once (REQUEST_MESSAGE)
    _command(emu, link, 511, 31, 10_000)
    _command(emu, link, 511, 245, 0)
    _command(emu, link, 512, 1)
    before = link.types()
    run_until(emu, 3.0)
    after = link.types()
    # THEN two seconds bring 200 ATTITUDE_QUATERNION, EXTENDED_SYS_STATE at PX4's 5 Hz, one
    # SYS_STATUS, and nothing else it was not asked for
    assert after["ATTITUDE_QUATERNION"] - before.get("ATTITUDE_QUATERNION", 0) == \
        pytest.approx(200, abs=2)
    assert after["EXTENDED_SYS_STATE"] - before.get("EXTENDED_SYS_STATE", 0) == \
        pytest.approx(2.0 * DEFAULT_RATES_HZ["EXTENDED_SYS_STATE"], abs=1.01)
    assert after["SYS_STATUS"] == 1
    assert "LOCAL_POSITION_NED" not in after and "HIGHRES_IMU" not in after


def test_unknown_streams_mode_is_refused():
    with pytest.raises(ValueError, match="streams: expected one of default, requested, got 'all'"):
        Emulator([default_vehicle(1)], streams="all")


class _CountingLink(RecordingLink):
    def __init__(self) -> None:
        super().__init__()
        self.datagrams = 0

    def send(self, data: bytes, addr=None) -> None:
        self.datagrams += 1
        super().send(data, addr)


def test_rates_set_one_command_at_a_time_keep_one_datagram_per_period():
    # GIVEN a vehicle in requested mode whose ground station sets three 100 Hz streams one
    # command at a time, each in a later tick (gcs fly awaits each ACK)
    emu = Emulator([default_vehicle(1, on_ground=False)], streams="requested")
    link = _CountingLink()
    emu.nodes[0].links.append(link)
    run_until(emu, 1.0)
    for msgid in (31, 32, 105):
        _command(emu, link, 511, msgid, 10_000)
        run_until(emu, emu.now_s + 0.006)
    # WHEN two seconds pass
    link.datagrams = 0
    before = link.types()
    run_until(emu, emu.now_s + 2.0)
    after = link.types()
    # THEN each stream runs at 100 Hz, and the three leave together: one datagram per 10 ms
    # (plus the HEARTBEATs' own ticks at most)
    for name in ("ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "HIGHRES_IMU"):
        assert after[name] - before[name] == pytest.approx(200, abs=1)
    assert 200 <= link.datagrams <= 203
