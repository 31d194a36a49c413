"""UDP endpoint on real 127.0.0.1 sockets, against pymavlink's own UDP connection as the peer."""

from __future__ import annotations

import asyncio
import logging
import socket

import pytest
from pymavlink import mavutil

from gcs.link.codec import MavlinkCodec
from gcs.link.udp import Address, LinkClosedError, UdpEndpoint
from tests.harness import run_bounded as run
from tests.harness import wait_until

pytestmark = pytest.mark.integration


def test_exchanges_mavlink_with_a_pymavlink_udpin_peer() -> None:
    # GIVEN a pymavlink vehicle-side connection listening on an ephemeral port
    peer = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=1, source_component=1)
    peer_port = peer.port.getsockname()[1]
    codec = MavlinkCodec()

    async def scenario() -> None:
        async with UdpEndpoint(0, ("127.0.0.1", peer_port)) as ep:
            # WHEN the endpoint sends a GCS HEARTBEAT
            assert ep.send(codec.encode(codec.mav.heartbeat_encode(6, 8, 0, 0, 4)))
            # THEN pymavlink receives it from sysid 255 / compid 190
            hb = await asyncio.to_thread(peer.recv_match, type="HEARTBEAT", blocking=True,
                                         timeout=3)
            assert hb is not None and (hb.get_srcSystem(), hb.get_srcComponent()) == (255, 190)
            assert (hb.type, hb.autopilot) == (6, 8)
            # AND WHEN pymavlink answers (to the address it learned)
            peer.mav.heartbeat_send(2, 12, 81, 0, 3)
            data, addr = await ep.recv(timeout_s=3.0)
            # THEN the endpoint delivers the datagram from the peer's address
            assert addr == ("127.0.0.1", peer_port)
            (msg,) = codec.feed(data)
            assert msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == 1
            stats = ep.stats()
            assert (stats.packets_out, stats.packets_in, stats.packets_in_foreign) == (1, 1, 0)
            assert stats.bytes_out == 21 and stats.bytes_in == len(data)

    try:
        run(scenario())
    finally:
        peer.close()


def send_raw(port: int, payloads: list[bytes]) -> Address:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        for p in payloads:
            s.sendto(p, ("127.0.0.1", port))
        host, src_port = s.getsockname()
        return (host, src_port)


def test_bounded_receive_queue_drops_oldest_and_counts() -> None:
    async def scenario() -> None:
        async with UdpEndpoint(0, learn_remote=True, rx_queue_size=2) as ep:
            send_raw(ep.local_address[1], [b"1", b"2", b"3", b"4", b"5"])
            await wait_until(lambda: ep.stats().packets_in == 5)
            assert [(await ep.recv(1.0))[0] for _ in range(2)] == [b"4", b"5"]
            assert ep.stats().rx_dropped_queue_full == 3

    run(scenario())


def test_send_before_the_remote_is_known_is_counted_then_works() -> None:
    async def scenario() -> None:
        got: list[tuple[bytes, Address]] = []
        def collect(data: bytes, addr: Address) -> None:
            got.append((data, addr))

        async with UdpEndpoint(0, learn_remote=True, on_datagram=collect) as peer, \
                UdpEndpoint(0, learn_remote=True) as ep:
            assert ep.remote is None and not ep.send(b"x")
            assert ep.stats().send_no_remote == 1
            ep.set_remote(peer.local_address)
            assert ep.send(b"hello")
            await wait_until(lambda: len(got) == 1)
            assert got == [(b"hello", ep.local_address)]

    run(scenario())


def test_foreign_sources_are_counted_and_callback_errors_do_not_kill_the_socket(
        caplog: pytest.LogCaptureFixture) -> None:
    calls: list[bytes] = []

    def flaky(data: bytes, addr: Address) -> None:
        calls.append(data)
        if data == b"boom":
            raise RuntimeError("handler bug")

    async def scenario() -> None:
        async with UdpEndpoint(0, ("127.0.0.1", 9), on_datagram=flaky, name="vehicle 0") as ep:
            send_raw(ep.local_address[1], [b"boom", b"ok"])
            await wait_until(lambda: len(calls) == 2)
            stats = ep.stats()
            assert (stats.callback_errors, stats.packets_in_foreign) == (1, 2)

    with caplog.at_level(logging.ERROR):
        run(scenario())
    assert "vehicle 0: on_datagram callback failed" in caplog.text


def test_closed_endpoint_and_bad_arguments() -> None:
    ep = UdpEndpoint(0, ("127.0.0.1", 14580), name="vehicle 3")
    with pytest.raises(LinkClosedError, match="vehicle 3: send on a closed endpoint"):
        ep.send(b"x")
    with pytest.raises(ValueError, match="vehicle 1: no remote address and learn_remote is False"):
        UdpEndpoint(0, name="vehicle 1")
    with pytest.raises(ValueError, match="local_port: expected 0..65535, got 70000"):
        UdpEndpoint(70000, ("127.0.0.1", 1))
