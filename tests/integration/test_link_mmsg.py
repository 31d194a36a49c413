"""recvmmsg reads (gcs/link/mmsg.py) over real sockets on 127.0.0.1, and the bulk endpoint on
top of them: what the one-at-a-time path would have read, truncation counted."""

from __future__ import annotations

import asyncio
import socket
import sys
import time

import numpy as np
import pytest

from gcs.link.mmsg import SLOT_BYTES, VLEN, MultiReceiver, available
from gcs.link.udp import UdpEndpoint

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="recvmmsg is Linux's")


def _socket() -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    return s


def test_a_call_reads_many_datagrams_with_their_sources_and_kernel_times():
    rx = _socket()
    rx.setblocking(False)
    rx.setsockopt(socket.SOL_SOCKET, 35, 1)  # SO_TIMESTAMPNS
    assert available(rx)
    senders = [_socket() for _ in range(3)]
    multi = MultiReceiver(rx)
    assert multi.receive() == 0  # nothing there: no error, nothing read
    before = time.time()
    sent = []
    for k in range(10):
        s = senders[k % 3]
        data = bytes([k]) * (1 + 37 * k)
        s.sendto(data, rx.getsockname())
        sent.append((data, s.getsockname()))
    big = bytes(range(256)) * (SLOT_BYTES // 256 + 4)  # longer than a slot
    senders[0].sendto(big, rx.getsockname())
    n = multi.receive()
    assert n == 11
    lengths, offsets = multi.lengths(n), multi.offsets[:n]
    got = [bytes(multi.buffer[o:o + size]) for o, size in zip(offsets, lengths, strict=True)]
    assert got[:10] == [d for d, _ in sent]
    assert multi.sources(n)[:10] == [a for _, a in sent]
    assert got[10] == big[:SLOT_BYTES] and multi.truncated(n).tolist() == [False] * 10 + [True]
    stamps = multi.stamps(n)
    assert np.all((stamps >= before - 1e-3) & (stamps <= time.time() + 1e-3))
    for s in (rx, *senders):
        s.close()


def test_more_than_a_call_holds_waits_for_the_next_call():
    rx = _socket()
    rx.setblocking(False)
    tx = _socket()
    for k in range(VLEN + 5):
        tx.sendto(k.to_bytes(2, "big"), rx.getsockname())
    multi = MultiReceiver(rx)
    first = multi.receive()
    order = [int.from_bytes(bytes(multi.buffer[o:o + 2]), "big") for o in multi.offsets[:first]]
    second = multi.receive()
    order += [int.from_bytes(bytes(multi.buffer[o:o + 2]), "big")
              for o in multi.offsets[:second]]
    assert (first, second) == (VLEN, 5) and order == list(range(VLEN + 5))
    assert np.isnan(multi.stamps(second)).all()  # no SO_TIMESTAMPNS asked: no kernel times
    rx.close()
    tx.close()


def test_the_bulk_endpoint_counts_a_cut_datagram_and_delivers_the_rest():
    asyncio.run(asyncio.wait_for(_bulk(), 10.0))


async def _bulk() -> None:
    batches = []

    def on_batch(buffer, offsets, lengths, sources, stamps) -> None:  # noqa: ANN001
        batches.extend(bytes(buffer[o:o + size]) for o, size in zip(offsets, lengths,
                                                                     strict=True))

    async with UdpEndpoint(0, None, learn_remote=True, on_batch=on_batch) as ep:
        tx = _socket()
        tx.sendto(b"a" * (SLOT_BYTES + 1), ep.local_address)
        tx.sendto(b"small", ep.local_address)
        for _ in range(100):
            await asyncio.sleep(0.01)
            if len(batches) == 2:
                break
        assert batches == [b"a" * SLOT_BYTES, b"small"]
        stats = ep.stats()
        assert (stats.rx_truncated, stats.packets_in) == (1, 2)
        tx.close()


@pytest.mark.parametrize("bulk_read", ["recvmmsg", "one at a time"])
def test_datagrams_the_kernel_dropped_while_the_ground_station_was_busy_are_counted_and_told(
        bulk_read: str, caplog: pytest.LogCaptureFixture) -> None:
    asyncio.run(asyncio.wait_for(_overflow(bulk_read, caplog), 20.0))


async def _overflow(bulk_read: str, caplog: pytest.LogCaptureFixture) -> None:
    got = [0]

    def on_batch(buffer, offsets, lengths, sources, stamps) -> None:  # noqa: ANN001
        got[0] += len(offsets)

    async with UdpEndpoint(0, None, learn_remote=True, on_batch=on_batch, name="gcs port") as ep:
        if bulk_read == "one at a time":
            ep._reader.multi = None  # the path of a platform without recvmmsg
        tx = _socket()
        # GIVEN a ground station that reads nothing for a while (the loop is blocked) as a
        # fleet's telemetry keeps coming: more datagrams than its socket's buffer holds
        sent = 0
        for _ in range(40_000):
            try:
                tx.sendto(b"x" * 40, ep.local_address)
                sent += 1
            except BlockingIOError:
                time.sleep(1e-3)
        # WHEN it reads again, and the stream goes on (the kernel tells a socket's drop count
        # with the datagrams queued after the drops)
        for _ in range(500):
            await asyncio.sleep(0.002)
            if ep.stats().packets_in + ep.stats().rx_dropped_kernel >= sent:
                break
            tx.sendto(b"y" * 40, ep.local_address)
            sent += 1
        # THEN every datagram is either read or counted as dropped by the kernel, and the
        # operator is told why the telemetry has gaps
        stats = ep.stats()
        assert stats.rx_dropped_kernel > 0
        assert stats.packets_in == got[0]
        assert stats.packets_in + stats.rx_dropped_kernel == sent
        assert any("gcs port: the kernel dropped" in r.getMessage() and "short of CPU" in
                   r.getMessage() for r in caplog.records)
        tx.close()
