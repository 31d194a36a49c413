"""The agents' state sample on the wire (gcs/agent/wire.py): literal bytes, round trips, every
refusal by its reason, and arbitrary bytes raising WireError only."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs.agent.wire import (
    BODY_BYTES,
    ECHO_BYTES,
    HEAD_BYTES,
    MAX_U32,
    SUPERVISOR_ID,
    Echo,
    StateSample,
    WireError,
    decode,
    encode,
)

SAMPLE = StateSample(
    vehicle_id=3, epoch=7, seq=258, taken_s=1.5, sent_s=2.25,
    position_enu_m=(1.0, 2.0, 3.0), velocity_enu_mps=(0.1, 0.2, 0.3),
    acceleration_enu_mps2=(0.0, 0.0, -9.81), attitude_wxyz=(1.0, 0.0, 0.0, 0.0),
    omega_flu_radps=(0.01, 0.02, 0.03), echoes=(Echo(1, 10.0, 0.5), Echo(SUPERVISOR_ID, 4.0, 0.0)))

# The head of SAMPLE as written by hand: magic, version 1, flags 0, 2 echoes, vehicle 3, epoch 7,
# seq 258, taken_s 1.5, sent_s 2.25 (little-endian)
HEAD = bytes.fromhex(
    "464d5354" "01" "00" "0200" "03000000" "07000000" "02010000"
    "000000000000f83f" "0000000000000240")


def test_the_head_is_the_documented_layout():
    data = encode(SAMPLE)
    assert data[:HEAD_BYTES] == HEAD
    assert len(data) == HEAD_BYTES + BODY_BYTES + 2 * ECHO_BYTES == 36 + 128 + 40
    # AND the first echo follows the 16 state values: peer 1, sent 10.0, held 0.5
    assert struct.unpack_from("<Idd", data, HEAD_BYTES + BODY_BYTES) == (1, 10.0, 0.5)


def test_a_sample_round_trips():
    assert decode(encode(SAMPLE)) == SAMPLE
    assert decode(bytearray(encode(SAMPLE)), ids={1, 3}) == SAMPLE
    bare = StateSample(1, 0, MAX_U32, -5.0, -4.0, (0.0,) * 3, (0.0,) * 3, (0.0,) * 3,
                       (0.5, 0.5, 0.5, 0.5), (0.0,) * 3)
    assert decode(memoryview(encode(bare))) == bare


def with_float(data: bytes, offset: int, value: float) -> bytes:
    return data[:offset] + struct.pack("<d", value) + data[offset + 8:]


GOOD = encode(SAMPLE)
REFUSED = [
    (b"", r"0 bytes, a sample has at least 164"),
    (GOOD[:163], r"163 bytes"),
    (b"XMST" + GOOD[4:], r"magic b'XMST', expected b'FMST'"),
    (GOOD[:4] + b"\x02" + GOOD[5:], r"version 2, this program reads 1"),
    (GOOD[:5] + b"\x01" + GOOD[6:], r"reserved flags 0x01 set"),
    (GOOD + b"\x00", r"205 bytes, a sample with 2 echoes has 204"),
    (GOOD[:-1], r"203 bytes, a sample with 2 echoes has 204"),
    (GOOD[:6] + b"\x01\x00" + GOOD[8:], r"204 bytes, a sample with 1 echoes has 184"),
    (GOOD[:6] + b"\xff\xff" + GOOD[8:], r"65535 echoes, at most 1024"),
    (GOOD[:8] + b"\x00\x00\x00\x00" + GOOD[12:], r"vehicle id 0 is outside 1\.\.4294967295"),
    (with_float(GOOD, 20, math.nan), r"taken_s is nan, expected a finite number"),
    (with_float(GOOD, 28, math.inf), r"sent_s is inf"),
    (with_float(GOOD, HEAD_BYTES + 8, -math.inf), r"position_enu_m\[1\] is -inf"),
    (with_float(GOOD, HEAD_BYTES + 9 * 8, math.nan), r"attitude_wxyz\[0\] is nan"),
    (with_float(GOOD, HEAD_BYTES + 15 * 8, math.nan), r"omega_flu_radps\[2\] is nan"),
    (with_float(GOOD, HEAD_BYTES + BODY_BYTES + 4, math.nan), r"echo sent_s is nan"),
    (with_float(GOOD, HEAD_BYTES + BODY_BYTES + 12, -0.5), r"echo held_s -0\.5 is negative"),
]


@pytest.mark.parametrize(("data", "match"), REFUSED)
def test_each_bad_sample_is_refused_with_its_reason(data, match):
    with pytest.raises(WireError, match=match) as info:
        decode(data)
    assert info.value.reason == str(info.value)


def test_the_team_ids_bound_the_sender_and_the_echoes():
    # GIVEN a team of vehicles 1 and 3: the sample decodes (peer 0 is the supervisor)
    assert decode(GOOD, ids=(1, 3)).vehicle_id == 3
    # THEN without vehicle 3, or without echo peer 1, it is refused naming the id
    with pytest.raises(WireError, match=r"^vehicle id 3 is no vehicle of the team$"):
        decode(GOOD, ids=(1, 2))
    with pytest.raises(WireError, match=r"^echo peer id 1 is no vehicle of the team$"):
        decode(GOOD, ids=(2, 3))


def replace(sample: StateSample, **changes) -> StateSample:
    fields = {name: getattr(sample, name) for name in StateSample.__slots__}
    return StateSample(**(fields | changes))


@pytest.mark.parametrize(("changes", "match"), [
    ({"vehicle_id": 0}, r"vehicle id 0 is outside"),
    ({"vehicle_id": 2**32}, r"vehicle id 4294967296 is outside"),
    ({"seq": -1}, r"seq -1 is outside 0\.\.4294967295"),
    ({"epoch": 2**32}, r"epoch 4294967296 is outside"),
    ({"taken_s": math.nan}, r"taken_s is nan"),
    ({"velocity_enu_mps": (0.0, math.inf, 0.0)}, r"velocity_enu_mps\[1\] is inf"),
    ({"attitude_wxyz": (1.0, 0.0, 0.0)}, r"expected 3 \+ 3 \+ 3 \+ 4 \+ 3 state values, got 15"),
    ({"echoes": (Echo(2, 1.0, -1.0),)}, r"echo held_s -1\.0 is negative"),
    ({"echoes": (Echo(-1, 1.0, 0.0),)}, r"echo peer id -1 is outside 0\.\.4294967295"),
    ({"echoes": (Echo(2, 1.0, 0.0),) * 1025}, r"1025 echoes, at most 1024"),
    ({"seq": 1.5}, r"cannot encode the sample of vehicle 3"),
])
def test_encode_refuses_what_the_layout_cannot_carry(changes, match):
    with pytest.raises(WireError, match=match):
        encode(replace(SAMPLE, **changes))


finite = st.floats(allow_nan=False, allow_infinity=False)
vec3 = st.tuples(finite, finite, finite)
samples = st.builds(
    StateSample, st.integers(1, MAX_U32), st.integers(0, MAX_U32), st.integers(0, MAX_U32),
    finite, finite, vec3, vec3, vec3, st.tuples(finite, finite, finite, finite), vec3,
    st.lists(st.builds(Echo, st.integers(0, MAX_U32), finite,
                       st.floats(0.0, 1e9, allow_nan=False)), max_size=5).map(tuple))


@settings(max_examples=300, deadline=None)
@given(samples)
def test_every_valid_sample_round_trips(sample):
    assert decode(encode(sample)) == sample


@settings(max_examples=1000, deadline=None)
@given(st.binary(max_size=400))
def test_arbitrary_bytes_raise_wire_error_only(data):
    try:
        sample = decode(data)
    except WireError as exc:
        assert exc.reason and "\n" not in exc.reason
    else:
        assert encode(sample) == data


@settings(max_examples=1000, deadline=None)
@given(st.integers(0, len(GOOD) - 1), st.integers(0, 255), st.integers(0, len(GOOD)))
def test_a_damaged_sample_decodes_to_a_valid_one_or_raises_wire_error(at, byte, cut):
    # GIVEN a valid sample with one byte changed and cut short (or not)
    data = (GOOD[:at] + bytes([byte]) + GOOD[at + 1:])[:cut or None]
    # THEN it decodes to a sample that encodes back to it, or raises WireError
    try:
        sample = decode(data, ids=(1, 3))
    except WireError as exc:
        assert exc.reason
    else:
        assert encode(sample) == data
