"""The fleet's 100 Hz streams framed in one compiled pass (vehicle_emulator/mavlink/hotstreams.py)
against the general path every other stream takes (`Telemetry.fused = False`): the same
vehicles, seed and schedule must send the same messages with the same values, in datagrams
whose sequence numbers run in order."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.config.team import default_vehicle
from vehicle_emulator.fleet.runner import Emulator
from vehicle_emulator.mavlink import hotstreams
from vehicle_emulator.mavlink.codec import PeerDecoder

# what `gcs fly` asks for (msgid: Hz), the three hot streams among slower ones
GCS_RATES_HZ = {31: 100.0, 32: 100.0, 105: 100.0, 245: 5.0, 83: 10.0, 33: 5.0}
HOT_IDS = {int(m) for m in hotstreams.MSGIDS}


class RawLink:
    """Keeps every datagram a vehicle sends, as bytes."""

    name = "raw"

    def __init__(self) -> None:
        self.datagrams: list[bytes] = []

    def send(self, data: bytes, addr: Any = None) -> None:
        self.datagrams.append(data)


def _fleet(fused: bool) -> tuple[Emulator, list[RawLink]]:
    specs = []
    for i, autopilot in enumerate(["px4", "px4", "ardupilot", "nominal", "px4", "ardupilot"]):
        spec = replace(default_vehicle(i + 1, on_ground=i in (1, 2)), autopilot=autopilot)
        specs.append(spec)
    # noise on everywhere but the nominal vehicle (its default: off)
    emu = Emulator(specs, seed=7, streams="requested")
    emu.telemetry.fused = fused
    links = []
    for node in emu.nodes:
        link = RawLink()
        node.links.append(link)
        links.append(link)
        for msgid, hz in GCS_RATES_HZ.items():
            emu.telemetry.set_interval(node.index, msgid, 1e6 / hz, 0.0)
    return emu, links


def _fly(emu: Emulator, until_s: float) -> None:
    t = emu.now_s
    while t < until_s - 1e-9:
        t += 0.025 if abs(t - 1.0) < 1e-9 else 0.002  # one late wake-up: 25 ms at once
        if abs(t - 0.5) < 1e-9:  # vehicle 5's link goes down for 0.3 s
            emu.nodes[4].impairment.down_until_s = 0.8
        emu.advance_to(t)


def _messages(data: bytes) -> list[Any]:
    return PeerDecoder().feed(data, "emu")


def _frames_seq(data: bytes) -> list[int]:
    seqs, at = [], 0
    while at < len(data):
        assert data[at] == 0xFD
        seqs.append(data[at + 4])
        at += 12 + data[at + 1]
    return seqs


def test_fused_hot_streams_send_what_the_general_path_sends():
    # GIVEN two identical fleets (px4 with its sensor model, ArduPilot, nominal; two booting on
    # the ground, so LOCAL_POSITION_NED waits for their estimators; noise on) streaming what
    # `gcs fly` asks for, one through the compiled pass and one through the general path
    fused, fused_links = _fleet(True)
    general, general_links = _fleet(False)
    # WHEN both fly 1.5 simulated seconds, one vehicle's link down for 0.3 s and one
    # wake-up 23 ms late (the schedules skip what it missed)
    _fly(fused, 1.5)
    _fly(general, 1.5)
    # THEN the schedules and counts agree
    np.testing.assert_array_equal(fused.telemetry.next_due_s, general.telemetry.next_due_s)
    np.testing.assert_array_equal(fused.telemetry.sent, general.telemetry.sent)
    hot_sent = sum(int(fused.telemetry.sent[fused.telemetry.index[nm]]) for nm in hotstreams.NAMES)
    assert hot_sent > 3 * 6 * 100  # most of 150 periods of three streams for six vehicles
    for i, (a, b) in enumerate(zip(fused_links, general_links, strict=True)):
        assert len(a.datagrams) == len(b.datagrams), i
        last = None
        kinds = set()
        for da, db in zip(a.datagrams, b.datagrams, strict=True):
            ma, mb = _messages(da), _messages(db)
            # AND every datagram holds the same messages with the same values
            assert sorted(m.get_msgId() for m in ma) == sorted(m.get_msgId() for m in mb)
            key = lambda m: m.get_msgId()  # noqa: E731
            for x, y in zip(sorted(ma, key=key), sorted(mb, key=key), strict=True):
                assert x.to_dict() == y.to_dict(), (i, x, y)
            kinds.update(m.get_type() for m in ma)
            # AND the hot frames come first, their sequence numbers in order with the rest's
            ids = [m.get_msgId() for m in ma]
            hot = [k in HOT_IDS for k in ids]
            assert hot == sorted(hot, reverse=True), ids
            for s in _frames_seq(da):
                assert last is None or s == (last + 1) & 0xFF, (i, last, s)
                last = s
        # (the ArduPilot vehicle on the ground has no EKF position yet within the 1.5 s)
        expected = set(hotstreams.NAMES) - ({"LOCAL_POSITION_NED"} if i == 2 else set())
        assert expected <= kinds, (i, kinds)


def test_a_vehicle_without_an_estimated_position_gets_no_local_position():
    # GIVEN an ArduPilot vehicle booting on the ground (its EKF has no position for a while)
    emu, links = _fleet(True)
    # WHEN the first 0.1 s pass
    _fly(emu, 0.1)
    # THEN it sent attitude and IMU but no LOCAL_POSITION_NED before its position came,
    # while a vehicle in the air sent all three
    on_ground = [m.get_type() for d in links[2].datagrams for m in _messages(d)]
    in_air = [m.get_type() for d in links[0].datagrams for m in _messages(d)]
    from_ms = int(emu.status.position_from_ms[2])
    assert from_ms > 100, from_ms
    assert "ATTITUDE_QUATERNION" in on_ground and "LOCAL_POSITION_NED" not in on_ground
    assert {"ATTITUDE_QUATERNION", "LOCAL_POSITION_NED", "HIGHRES_IMU"} <= set(in_air)


def test_hot_frames_decode_with_the_values_pymavlink_packs():
    # GIVEN one frame of each hot stream from the compiled pass
    emu, links = _fleet(True)
    _fly(emu, 0.05)
    frames = {m.get_type(): m for d in links[0].datagrams for m in _messages(d)}
    # THEN repacking the decoded values with pymavlink gives the same payload (CRC and all)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    for name in hotstreams.NAMES:
        m = frames[name]
        mav.seq = m.get_seq()
        assert m.pack(mav) == m.get_msgbuf(), name
