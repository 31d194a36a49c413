"""Sans-IO codec: the batch encoder is byte-identical to pymavlink; the decoder counts junk."""

from __future__ import annotations

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.codec import BatchEncoder, GenericEncoder, PeerDecoder
from vehicle_emulator.telemetry import DEFAULT_RATES_HZ


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
