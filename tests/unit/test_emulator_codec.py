"""Sans-IO codec: the batch encoder is byte-identical to pymavlink; the decoder counts junk."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.mavlink.codec import BatchEncoder, GenericEncoder, HotDecoder, PeerDecoder
from vehicle_emulator.mavlink.telemetry import DEFAULT_RATES_HZ


def test_heartbeat_literal_bytes():
    # GIVEN a PX4 quadrotor heartbeat in OFFBOARD, armed, sysid 1, seq 0
    enc = BatchEncoder(mavlink.MAVLink_heartbeat_message)
    rows = enc.empty(1)
    rows["custom_mode"], rows["type"], rows["autopilot"] = 393216, 2, 12
    rows["base_mode"], rows["system_status"], rows["mavlink_version"] = 157, 4, 3
    out, ln = enc.encode(rows, np.array([0]), np.array([1], np.uint8), np.zeros(1, np.uint8))
    frame = bytes(out[0, : ln[0]])
    ref = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    assert frame == mavlink.MAVLink_heartbeat_message(2, 12, 157, 393216, 4, 3).pack(ref)
    assert frame[:10] == bytes([0xFD, 9, 0, 0, 0, 1, 1, 0, 0, 0])
    assert frame[10:14] == (393216).to_bytes(4, "little")


@pytest.mark.parametrize("name", list(DEFAULT_RATES_HZ))
def test_batch_encoder_matches_pymavlink_for_every_telemetry_message(name):
    cls = getattr(mavlink, f"MAVLink_{name.lower()}_message")
    enc = BatchEncoder(cls)
    rng = np.random.default_rng(7)
    rows = enc.empty(5)
    for field in rows.dtype.names:
        kind = rows.dtype[field].base.kind
        shape = rows[field].shape
        if kind == "f":
            rows[field] = rng.normal(size=shape)
        elif kind in "ui":
            rows[field] = rng.integers(0, 100, size=shape)
    seq = np.array([3, 250, 7, 0, 255], np.uint8)
    sysid = np.array([1, 2, 3, 4, 5], np.uint8)
    out, ln = enc.encode(rows, np.arange(5), sysid, seq.copy())
    dec = PeerDecoder()
    for r in range(5):
        msgs = dec.feed(bytes(out[r, : ln[r]]), "peer")
        assert len(msgs) == 1 and msgs[0].get_type() == name
        ref = mavlink.MAVLink(None, srcSystem=int(sysid[r]), srcComponent=1)
        ref.seq = int(seq[r])
        assert bytes(out[r, : ln[r]]) == msgs[0].pack(ref)


def test_generic_encoder_shares_the_sequence_counter():
    seq = np.array([41], np.uint8)
    g = GenericEncoder(1, 1, seq, 0)
    data = g.pack(mavlink.MAVLink_statustext_message(6, b"hello", 0, 0))
    assert data[4] == 41 and seq[0] == 42


def test_decoder_counts_every_kind_of_junk_and_keeps_going():
    mav = mavlink.MAVLink(None, srcSystem=245, srcComponent=190)
    good = mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(mav)
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    unknown = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav)
    unknown = bytes([0xFD, 9, 0, 0, 1, 245, 190, 0x10, 0x27, 0]) + unknown[10:]  # msgid 10000
    dec = PeerDecoder()
    assert dec.feed(bytes(bad_crc), "a") == []
    assert dec.feed(b"\x00\x01garbage", "a") == []
    dec.feed(unknown, "a")
    out = dec.feed(good + good[:7], "a")  # one good frame, then a truncated one
    assert [m.get_type() for m in out] == ["COMMAND_LONG"]
    assert [m.get_type() for m in dec.feed(good[7:], "a")] == ["COMMAND_LONG"]
    st = dec.stats
    assert st.bad_crc >= 1 and st.messages == 2 and st.rejected >= 2


# SET_ATTITUDE_TARGET from 255/190, seq 7: time_boot_ms 1000, q (1, 0, 0, 0), rates (0.5, -0.25, 0),
# thrust 0.5, target 3/1, type_mask 128 (trailing zeros of the payload truncated)
SAT_FRAME = bytes.fromhex(
    "fd27000007ffbe520000e80300000000803f0000000000000000000000000000003f000080be0000000000"
    "00003f030180a203"
)
HB_FRAME = bytes.fromhex("fd09000000ffbe0000000000000006080004033d48")


def test_hot_decoder_reads_literal_frames_as_pymavlink_does():
    # GIVEN a datagram with a SET_ATTITUDE_TARGET and one with it and a HEARTBEAT
    # WHEN decoded in one batch
    out = HotDecoder().decode([SAT_FRAME, SAT_FRAME + HB_FRAME])
    # THEN the fields, the header and the types are pymavlink's
    (sat,), (sat2, hb) = out
    assert (sat.get_type(), sat.get_msgId(), sat.get_srcSystem(), sat.get_srcComponent(),
            sat.get_seq()) == ("SET_ATTITUDE_TARGET", 82, 255, 190, 7)
    assert sat.time_boot_ms == 1000 and sat.target_system == 3 and sat.target_component == 1
    assert sat.type_mask == 128 and sat.q == [1.0, 0.0, 0.0, 0.0]
    assert (sat.body_roll_rate, sat.body_pitch_rate, sat.body_yaw_rate, sat.thrust) == (
        0.5, -0.25, 0.0, 0.5)
    assert hb.get_type() == "HEARTBEAT" and (hb.type, hb.autopilot, hb.system_status) == (6, 8, 4)
    for ours, datagram in ((sat, SAT_FRAME), (hb, HB_FRAME)):
        (ref,) = PeerDecoder().feed(datagram)
        assert ours.to_dict() == ref.to_dict()
        for name in ref.get_fieldnames():
            assert type(getattr(ours, name)) is type(getattr(ref, name)), name


@pytest.mark.parametrize(
    "datagram",
    [
        pytest.param(SAT_FRAME[:-1] + bytes([SAT_FRAME[-1] ^ 1]), id="bad CRC"),
        pytest.param(SAT_FRAME[:-3], id="truncated"),
        pytest.param(SAT_FRAME[:2] + b"\x01" + SAT_FRAME[3:], id="signed flag"),
        pytest.param(SAT_FRAME + b"\x00", id="trailing byte"),
        pytest.param(b"", id="empty"),
        pytest.param(mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
                     .pack(mavlink.MAVLink(None, 255, 190)), id="not hot"),
        pytest.param(SAT_FRAME + mavlink.MAVLink_command_long_message(
            1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(mavlink.MAVLink(None, 255, 190)),
            id="hot and not hot"),
        pytest.param(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)
                     .pack(mavlink.MAVLink(None, 255, 190), force_mavlink1=True), id="MAVLink 1"),
    ],
)
def test_hot_decoder_leaves_everything_else_to_pymavlink(datagram):
    # GIVEN a datagram that is not only whole, good, unsigned MAVLink 2 hot frames
    # WHEN decoded in a batch beside a good one THEN it is left to the full parser (None)
    assert HotDecoder().decode([datagram, SAT_FRAME])[0] is None
    assert HotDecoder().decode([SAT_FRAME, datagram])[0] is not None


def test_peer_decoder_is_not_idle_while_it_holds_a_partial_frame():
    # GIVEN a parser that got half a frame from one peer
    dec = PeerDecoder()
    assert dec.idle("a")
    assert dec.feed(SAT_FRAME[:20], "a") == []
    # THEN that peer's next datagram must go to it (the fast path would lose the half frame)
    assert not dec.idle("a") and dec.idle("b")
    # AND a batch-decoded datagram is counted as feed counts one
    dec.count_decoded(SAT_FRAME, "b", 1)
    assert (dec.stats.datagrams, dec.stats.bytes, dec.stats.messages) == (
        2, 20 + len(SAT_FRAME), 1)
