"""Sans-IO codec: literal packets, corrupted/truncated/garbage input counted, signing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.codec import CodecStats, MavlinkCodec, SeqBlock, signing_timestamp_10us

# HEARTBEAT from sysid 1 / compid 1, seq 0: QUADROTOR, PX4, base_mode 129 (armed + custom),
# custom_mode 393216 (PX4 OFFBOARD), MAV_STATE_ACTIVE, MAVLink 2 (pymavlink-independent literal).
HEARTBEAT_V2 = bytes.fromhex("fd09000000010100000000000600020c810403d291")
HEARTBEAT_V1 = bytes.fromhex("fe090001010000000600020c8104034852")
# The same HEARTBEAT signed with key bytes(range(32)), link_id 7, timestamp 1000 (10 us units).
HEARTBEAT_SIGNED = bytes.fromhex(
    "fd09010000010100000000000600020c810403356907e80300000000953cc209d379")
KEY = bytes(range(32))
# A well-framed message with id 0xFFFFF0, which the common dialect does not define.
UNKNOWN_ID = bytes.fromhex("fd010000000101f0ffff2a0000")


def count(stats: CodecStats, **expected: int) -> None:
    got = {k: getattr(stats, k) for k in expected}
    assert got == expected


def assert_offboard_heartbeat(msg: mavlink.MAVLink_message) -> None:
    assert msg.get_type() == "HEARTBEAT"
    assert (msg.get_srcSystem(), msg.get_srcComponent(), msg.get_seq()) == (1, 1, 0)
    assert (msg.type, msg.autopilot, msg.base_mode) == (2, 12, 129)
    assert (msg.custom_mode, msg.system_status) == (393216, 4)


def test_decodes_literal_mavlink2_heartbeat() -> None:
    codec = MavlinkCodec()
    msgs = codec.feed(HEARTBEAT_V2)
    assert len(msgs) == 1
    assert_offboard_heartbeat(msgs[0])
    count(codec.stats(), bytes_in=21, messages_in=1, bad_crc=0, truncated=0, garbage_bytes=0)


def test_decodes_literal_mavlink1_heartbeat() -> None:
    codec = MavlinkCodec()
    (msg,) = codec.feed(HEARTBEAT_V1)
    assert_offboard_heartbeat(msg)


def test_encode_produces_the_literal_bytes_and_advances_seq() -> None:
    # GIVEN a codec posing as sysid 1 / compid 1
    codec = MavlinkCodec(1, 1)
    hb = codec.mav.heartbeat_encode(2, 12, 129, 393216, 4)
    # WHEN encoding twice THEN the first packet is the literal and the second has seq 1
    assert codec.encode(hb) == HEARTBEAT_V2
    second = codec.encode(hb)
    assert second[4] == 1
    assert codec.stats().messages_out == 2


def test_codecs_sharing_a_seq_block_keep_their_own_sequences() -> None:
    block = SeqBlock(2)
    a, b = MavlinkCodec(seqs=block, seq_row=0), MavlinkCodec(seqs=block, seq_row=1)
    reader = mavlink.MAVLink(None)
    hb = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
    seqs_a = [reader.decode(bytearray(a.encode(hb))).get_seq() for _ in range(3)]
    assert seqs_a == [0, 1, 2]
    assert a.take_seq() == 3  # a frame packed elsewhere takes the next one
    assert list(block.take(np.array([1, 0]))) == [0, 4]  # the team's take, row by row
    assert reader.decode(bytearray(b.encode(hb))).get_seq() == 1
    assert (a.stats().messages_out, b.stats().messages_out) == (5, 2)
    block.seq[0] = 255
    assert a.take_seq() == 255 and a.take_seq() == 0  # wraps like pymavlink's own


def test_gcs_defaults_are_sysid_255_compid_190() -> None:
    gcs = MavlinkCodec()
    data = gcs.encode(gcs.mav.heartbeat_encode(6, 8, 0, 0, 4))
    (msg,) = MavlinkCodec(1, 1).feed(data)
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (255, 190)


@pytest.mark.parametrize("index", [-1, -2, 12, 14])  # both CRC bytes, the payload, the type
def test_corrupted_byte_is_counted_as_bad_crc_and_the_next_packet_survives(index: int) -> None:
    bad = bytearray(HEARTBEAT_V2)
    bad[index] ^= 0x55
    codec = MavlinkCodec()
    msgs = codec.feed(bytes(bad) + HEARTBEAT_V2)
    assert len(msgs) == 1
    count(codec.stats(), bad_crc=1, messages_in=1, truncated=0, garbage_bytes=0)
    assert codec.stats().errors == 1


def test_truncated_frame_is_counted_and_does_not_poison_the_next_datagram() -> None:
    codec = MavlinkCodec()
    assert codec.feed(HEARTBEAT_V2[:15]) == []
    assert codec.feed(HEARTBEAT_V2[:2]) == []  # shorter than the length field
    (msg,) = codec.feed(HEARTBEAT_V2)
    assert_offboard_heartbeat(msg)
    count(codec.stats(), truncated=2, bad_crc=0, messages_in=1)


def test_stream_mode_reassembles_a_frame_split_across_feeds() -> None:
    codec = MavlinkCodec(datagram_mode=False)
    assert codec.feed(HEARTBEAT_V2[:7]) == []
    assert codec.feed(HEARTBEAT_V2[7:18]) == []
    (msg,) = codec.feed(HEARTBEAT_V2[18:] + HEARTBEAT_V2[:3])
    assert_offboard_heartbeat(msg)
    assert len(codec.feed(HEARTBEAT_V2[3:])) == 1
    count(codec.stats(), truncated=0, messages_in=2)


def test_garbage_is_skipped_and_counted() -> None:
    codec = MavlinkCodec()
    msgs = codec.feed(b"hello\x00\x01" + HEARTBEAT_V2 + b"xyz" + HEARTBEAT_V2)
    assert len(msgs) == 2
    count(codec.stats(), garbage_bytes=10, garbage_runs=2, messages_in=2, bad_crc=0)


def test_unknown_message_id_is_counted_not_returned() -> None:
    codec = MavlinkCodec()
    assert codec.feed(UNKNOWN_ID) == []
    count(codec.stats(), unknown_id=1, bad_crc=0, truncated=0)


def test_a_newer_definitions_extension_fields_are_read_past_not_refused() -> None:
    # GIVEN PX4 v1.16.0's reply to a TIMESYNC request, as recorded (data/sitl px4/timing): an
    # 18-byte payload whose last two bytes are the target fields of MAVLink's newer TIMESYNC
    # (unset by PX4: b8 34), two more than the common dialect here defines
    reply = bytes.fromhex("fd1200008301016f0000007f559a0900000000d7ff426515ed18b834a918")
    codec = MavlinkCodec()
    # WHEN it is fed THEN it decodes to the fields this dialect knows, counted as newer
    (msg,) = codec.feed(reply)
    assert msg.get_type() == "TIMESYNC" and (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1)
    assert (msg.tc1, msg.ts1) == (int.from_bytes(reply[10:18], "little"),
                                  int.from_bytes(reply[18:26], "little"))
    count(codec.stats(), newer_fields=1, bad_length=0, bad_crc=0, messages_in=1)


def test_a_longer_payload_must_still_pass_its_crc_and_mavlink1_has_no_extensions() -> None:
    # GIVEN a MAVLink 2 HEARTBEAT claiming 20 payload bytes with a zero CRC, and a MAVLink 1
    # HEARTBEAT claiming 20 bytes (MAVLink 1 frames have no extension fields)
    v2 = bytearray(HEARTBEAT_V2[:10]) + bytes(20) + b"\x00\x00"
    v2[1] = 20
    v1 = bytearray(HEARTBEAT_V1[:6]) + bytes(20) + b"\x00\x00"
    v1[1] = 20
    codec = MavlinkCodec()
    # WHEN fed before a good HEARTBEAT THEN both are refused and the good one is still read
    assert len(codec.feed(bytes(v2) + HEARTBEAT_V2)) == 1
    assert len(codec.feed(bytes(v1) + HEARTBEAT_V2)) == 1
    count(codec.stats(), bad_crc=1, bad_length=1, newer_fields=0, messages_in=2)


def test_unknown_incompat_flag_is_rejected() -> None:
    frame = bytearray(HEARTBEAT_V2)
    frame[2] = 0x02
    codec = MavlinkCodec()
    assert codec.feed(bytes(frame)) == []
    count(codec.stats(), bad_length=1)


@settings(max_examples=200)
@given(st.binary(max_size=300), st.booleans())
def test_arbitrary_bytes_never_raise(data: bytes, datagram_mode: bool) -> None:
    codec = MavlinkCodec(datagram_mode=datagram_mode)
    codec.feed(data)
    codec.feed(data[::-1])
    assert codec.stats().bytes_in == 2 * len(data)


@given(st.binary(max_size=50).filter(lambda b: 0xFD not in b and 0xFE not in b))
def test_valid_packet_is_found_after_any_marker_free_garbage(garbage: bytes) -> None:
    codec = MavlinkCodec()
    (msg,) = codec.feed(garbage + HEARTBEAT_V2)
    assert_offboard_heartbeat(msg)
    assert codec.stats().garbage_bytes == len(garbage)


# --- signing -------------------------------------------------------------------------------------


def signed_codec(**kwargs: bool) -> MavlinkCodec:
    codec = MavlinkCodec(wall_clock_s=lambda: 0.0)
    codec.setup_signing(KEY, initial_timestamp_10us=0, **kwargs)
    return codec


def test_signed_literal_is_accepted_with_the_right_key() -> None:
    codec = signed_codec()
    (msg,) = codec.feed(HEARTBEAT_SIGNED)
    assert_offboard_heartbeat(msg)
    assert msg._signed and msg._link_id == 7


def test_encode_signs_like_the_literal() -> None:
    vehicle = MavlinkCodec(1, 1, wall_clock_s=lambda: 0.0)
    vehicle.setup_signing(KEY, link_id=7, initial_timestamp_10us=1000)
    assert vehicle.encode(vehicle.mav.heartbeat_encode(2, 12, 129, 393216, 4)) == HEARTBEAT_SIGNED


def test_wrong_key_is_a_bad_signature() -> None:
    codec = MavlinkCodec()
    codec.setup_signing(bytes(32), initial_timestamp_10us=0)
    assert codec.feed(HEARTBEAT_SIGNED) == []
    count(codec.stats(), bad_signature=1, messages_in=0)


def test_unsigned_is_rejected_unless_allowed() -> None:
    strict = signed_codec()
    assert strict.feed(HEARTBEAT_V2) == []
    count(strict.stats(), unsigned_rejected=1)
    lenient = signed_codec(allow_unsigned=True)
    assert len(lenient.feed(HEARTBEAT_V2)) == 1
    # allow_unsigned does not let a badly signed frame through
    bad = bytearray(HEARTBEAT_SIGNED)
    bad[-1] ^= 1
    assert lenient.feed(bytes(bad)) == []
    count(lenient.stats(), bad_signature=1, unsigned_rejected=0)


def test_replayed_packet_is_stale() -> None:
    codec = signed_codec()
    assert len(codec.feed(HEARTBEAT_SIGNED)) == 1
    assert codec.feed(HEARTBEAT_SIGNED) == []
    count(codec.stats(), stale_signature=1, messages_in=1)


def test_new_stream_more_than_a_minute_behind_is_stale() -> None:
    codec = MavlinkCodec()
    codec.setup_signing(KEY, initial_timestamp_10us=1000 + 6_000_001)
    assert codec.feed(HEARTBEAT_SIGNED) == []
    count(codec.stats(), stale_signature=1)


def test_forged_future_timestamp_does_not_lock_out_the_real_stream() -> None:
    # GIVEN a forged copy of the packet with a far-future timestamp and a wrong signature
    forged = bytearray(HEARTBEAT_SIGNED)
    forged[-12:-6] = (10**12).to_bytes(6, "little")
    codec = signed_codec()
    # WHEN it arrives before the genuine packet THEN it is rejected and the genuine one accepted
    assert codec.feed(bytes(forged)) == []
    assert len(codec.feed(HEARTBEAT_SIGNED)) == 1
    count(codec.stats(), bad_signature=1, stale_signature=0, messages_in=1)


def test_signed_traffic_interoperates_with_a_plain_pymavlink_parser() -> None:
    # GIVEN our signing GCS codec and a pymavlink parser holding the same key
    gcs = MavlinkCodec()
    gcs.setup_signing(KEY, link_id=3)
    peer = mavlink.MAVLink(None, 1, 1)
    peer.signing.secret_key = KEY
    # WHEN the GCS encodes two commands
    for _ in range(2):
        data = gcs.encode(gcs.mav.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        # THEN each is signed (flag, 13 extra bytes) and pymavlink verifies it
        assert data[2] == 1
        msgs = peer.parse_buffer(data)
        assert msgs is not None and msgs[0].get_type() == "COMMAND_LONG" and msgs[0]._signed
    assert peer.signing.goodsig_count == 2


def test_outgoing_timestamp_tracks_the_wall_clock() -> None:
    now_s = [1.7e9]
    codec = MavlinkCodec(wall_clock_s=lambda: now_s[0])
    codec.setup_signing(KEY)
    codec.encode(codec.mav.heartbeat_encode(6, 8, 0, 0, 4))
    now_s[0] += 10.0
    data = codec.encode(codec.mav.heartbeat_encode(6, 8, 0, 0, 4))
    stamp = int.from_bytes(data[-12:-6], "little")
    assert stamp == signing_timestamp_10us(now_s[0])


def test_signing_key_must_be_32_bytes() -> None:
    with pytest.raises(ValueError, match="signing secret_key: expected 32 bytes, got 16"):
        MavlinkCodec().setup_signing(bytes(16))
