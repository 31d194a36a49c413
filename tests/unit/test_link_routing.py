"""Shared-port routing: the header-only split of a datagram by sysid, on literal frames."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from gcs.link.codec import MavlinkCodec
from gcs.link.port import TIMESYNC_REMEMBERED, MavlinkPort, frame_sysids

# HEARTBEAT from sysid 1 / compid 1 (MAVLink 2, 21 bytes; the codec tests' literal)
HB_V2_SYS1 = bytes.fromhex("fd09000000010100000000000600020c810403d291")
HB_V1_SYS1 = bytes.fromhex("fe090001010000000600020c8104034852")
# The same HEARTBEAT signed (13 bytes of signature follow the checksum)
HB_SIGNED_SYS1 = bytes.fromhex(
    "fd09010000010100000000000600020c810403356907e80300000000953cc209d379")


def heartbeat(sysid: int) -> bytes:
    codec = MavlinkCodec(sysid, 1)
    return codec.encode(codec.mav.heartbeat_encode(2, 12, 129, 393216, 4))


def test_one_sender_is_one_run_whatever_the_frame_kind() -> None:
    # GIVEN MAVLink 2, MAVLink 1 and signed frames of sysid 1 in one datagram
    data = HB_V2_SYS1 + HB_V1_SYS1 + HB_SIGNED_SYS1
    # THEN it is one run of sysid 1 covering it all (delivered whole, not copied)
    assert frame_sysids(data) == [(0, len(data), 1)]


def test_frames_of_several_sysids_split_at_frame_boundaries() -> None:
    a, b = heartbeat(3), heartbeat(7)
    data = a + a + b + a
    assert frame_sysids(data) == [(0, 42, 3), (42, 63, 7), (63, 84, 3)]


def test_garbage_goes_with_the_next_frame_and_a_cut_frame_with_its_run() -> None:
    # GIVEN text before a frame of sysid 7, and a frame of sysid 3 cut off after 12 bytes
    data = b"Init ArduCopter\n" + heartbeat(7) + heartbeat(3)[:12]
    # THEN the text belongs to sysid 7's run (its codec counts it), the cut frame to sysid 3's
    assert frame_sysids(data) == [(0, 37, 7), (37, 49, 3)]


def test_a_datagram_without_a_frame_start_has_no_sysid() -> None:
    assert frame_sysids(b"Free RAM: 131072\n") == [(0, 17, None)]
    assert frame_sysids(b"") == [(0, 0, None)]
    # a start marker with less than a header after it is not a frame either
    assert frame_sysids(b"\xfd\x09\x00") == [(0, 3, None)]


@given(st.lists(st.integers(1, 254), min_size=1, max_size=8))
def test_runs_cover_the_datagram_in_order(sysids: list[int]) -> None:
    data = b"".join(heartbeat(s) for s in sysids)
    runs = frame_sysids(data)
    assert runs[0][0] == 0 and runs[-1][1] == len(data)
    assert all(r[1] == q[0] for r, q in zip(runs, runs[1:], strict=False))
    # consecutive equal sysids merge; the sequence of run sysids is the deduplicated input
    merged = [s for k, s in enumerate(sysids) if k == 0 or sysids[k - 1] != s]
    assert [r[2] for r in runs] == merged


def test_one_timesync_request_per_address_and_period_and_every_proxy_can_time_its_replies():
    port = MavlinkPort(0)  # never opened: the rationing needs no socket
    router, other = ("127.0.0.1", 14550), ("127.0.0.1", 14551)
    first = port.claim_timesync(router, 10.0, 0.5)
    # a second vehicle behind the same router asks in the same period: no second request
    assert first is not None and port.claim_timesync(router, 10.2, 0.5) is None
    assert port.claim_timesync(other, 10.2, 0.5) is not None
    assert port.claim_timesync(router, 10.5, 0.5) is not None
    # the replies echo ts1: any proxy on the port learns when that request went out
    assert port.timesync_sent_s(first) == 10.0
    assert port.timesync_sent_s(first + 12345) is None
    for k in range(TIMESYNC_REMEMBERED):
        port.claim_timesync(router, 20.0 + k, 0.5)
    assert port.timesync_sent_s(first) is None  # forgotten, not grown without bound
