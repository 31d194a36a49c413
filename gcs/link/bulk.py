"""Bulk reading of a UDP socket that serves many vehicles: batches, kernel times, drops.

A port serving hundreds of vehicles reads its socket itself (`loop.add_reader`): at each
wake-up `BulkReader.drain` takes up to MAX_BATCH_DATAGRAMS datagrams into one buffer and hands
them over in one call, each with the kernel's receive time where the OS gives it (Linux
SO_TIMESTAMPNS), so a stall of the event loop does not read as link delay. On Linux one
recvmmsg call reads them all (gcs.link.mmsg); elsewhere one recvmsg per datagram. Datagrams the
kernel dropped because the reader fell behind are counted from the socket's own drop count
(SO_RXQ_OVFL) and told.
"""

from __future__ import annotations

import contextlib
import logging
import math
import socket
import struct
import sys
import time
from collections.abc import Callable

import numpy as np

from gcs.link.mmsg import SLOT_BYTES as MULTI_SLOT_BYTES
from gcs.link.mmsg import SO_RXQ_OVFL, MultiReceiver
from gcs.link.mmsg import available as mmsg_available

logger = logging.getLogger("gcs.link.udp")  # the records of the endpoint it reads for

Address = tuple[str, int]
#: ``on_batch(buffer, offsets, lengths, sources, stamps)``: datagram d is
#: ``buffer[offsets[d]:offsets[d] + lengths[d]]`` (int64 arrays), from ``sources[d]``, received
#: by the kernel at ``stamps[d]`` (float array, Unix time in s; NaN where the kernel gave none);
#: the buffer is reused after the call returns.
BatchCallback = Callable[[bytearray, np.ndarray, np.ndarray, list[Address], np.ndarray], None]

#: At most this many datagrams per wake-up (the rest wait for the next one, so a flood cannot
#: hold the event loop), into a buffer of this many bytes.
MAX_BATCH_DATAGRAMS = 512
BATCH_BUFFER_BYTES = 1 << 20
MAX_DATAGRAM_BYTES = 65536
#: Kernel receive buffer asked for (hundreds of vehicles' telemetry between wake-ups).
BULK_RCVBUF_BYTES = 4 << 20
#: Linux SO_TIMESTAMPNS / SCM_TIMESTAMPNS (not in Python's socket module): the kernel's receive
#: time of each datagram as a struct timespec.
_SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@qq")
_DROPS = struct.Struct("@I")
_ANCILLARY_BYTES = socket.CMSG_SPACE(_TIMESPEC.size) + socket.CMSG_SPACE(_DROPS.size)
#: At most one warning per this many seconds about datagrams the kernel dropped.
DROP_WARNING_S = 5.0


def bind_bulk_socket(host: str, port: int) -> socket.socket:
    """A non-blocking UDP socket bound to ``host:port`` with a large receive buffer."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setblocking(False)
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, BULK_RCVBUF_BYTES)
        sock.bind((host, port))
    except OSError:
        sock.close()
        raise
    return sock


class BulkReader:
    """Reads bound non-blocking ``sock`` in batches for endpoint ``name``: each batch goes to
    ``hand_over`` (a `BatchCallback`); socket errors (a queued ICMP error) to ``on_error``;
    ``counts`` (the endpoint's) gets ``rx_dropped_kernel`` and ``rx_truncated``."""

    def __init__(self, sock: socket.socket, name: str, counts: dict[str, int],
                 on_error: Callable[[Exception], None], hand_over: BatchCallback) -> None:
        self.name = name
        self._sock = sock
        self._counts = counts
        self._on_error = on_error
        self._hand_over = hand_over
        self._batch_buf = bytearray(BATCH_BUFFER_BYTES)
        self._drops_warned = 0  # rx_dropped_kernel when the last warning went out
        self._drop_warning_s = -math.inf
        self._kernel_stamps = False  # each datagram's kernel receive time (Linux)
        if sys.platform == "linux":
            try:
                sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
                self._kernel_stamps = True
            except OSError:
                logger.debug("%s: no kernel receive times; stamped when read", name)
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        #: recvmmsg where the platform has it (gcs.link.mmsg); None: one datagram per call
        self.multi: MultiReceiver | None = MultiReceiver(sock) if mmsg_available(sock) else None

    def drain(self) -> None:
        """Read what the socket holds (bounded), hand it over in one call; returns at once."""
        sock, cb = self._sock, self._hand_over
        if self.multi is not None:
            self._drain_multi(self.multi, cb)
            return
        view = memoryview(self._batch_buf)
        limit = len(self._batch_buf) - MAX_DATAGRAM_BYTES
        offsets: list[int] = []
        lengths: list[int] = []
        sources: list[Address] = []
        stamps: list[float] = []
        total = 0
        kernel = self._kernel_stamps
        drops = -1
        while len(offsets) < MAX_BATCH_DATAGRAMS and total <= limit:
            stamp = math.nan
            try:
                if kernel:
                    nbytes, ancillary, _, addr = sock.recvmsg_into([view[total:]],
                                                                   _ANCILLARY_BYTES)
                    for level, kind, data in ancillary:
                        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS:
                            sec, nsec = _TIMESPEC.unpack_from(data)
                            stamp = sec + nsec * 1e-9
                        elif level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL:
                            drops = max(drops, _DROPS.unpack_from(data)[0])
                else:
                    nbytes, addr = sock.recvfrom_into(view[total:])
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # an ICMP error queued on the socket: counted, read on
                self._on_error(exc)
                continue
            offsets.append(total)
            lengths.append(nbytes)
            sources.append((addr[0], addr[1]))
            stamps.append(stamp)
            total += nbytes
        self._count_drops(drops)
        if not offsets:
            return
        cb(self._batch_buf, np.asarray(offsets, dtype=np.int64),
           np.asarray(lengths, dtype=np.int64), sources, np.asarray(stamps, dtype=np.float64))

    def _drain_multi(self, multi: MultiReceiver, cb: BatchCallback) -> None:
        for _ in range(2):  # an error the socket reports (ICMP) is read first, then the data
            try:
                n = multi.receive()
                break
            except OSError as exc:
                self._on_error(exc)
        else:
            return
        if n == 0:
            return
        self._count_drops(multi.drops(n))
        lengths = multi.lengths(n)
        truncated = int(multi.truncated(n).sum())
        if truncated:
            self._counts["rx_truncated"] += truncated
            logger.warning("%s: %d datagram(s) longer than %d bytes, cut", self.name, truncated,
                           MULTI_SLOT_BYTES)
        stamps = multi.stamps(n) if self._kernel_stamps else np.full(n, np.nan)
        cb(multi.buffer, multi.offsets[:n], lengths, multi.sources(n), stamps)

    def _count_drops(self, drops: int) -> None:
        """The socket's drop count as the datagrams just read carried it (-1: none did): kept,
        and told (at most every DROP_WARNING_S) when it grew. Those datagrams were sent and
        arrived; the vehicles' sequence numbers count them as lost, this says why."""
        counts = self._counts
        if drops <= counts["rx_dropped_kernel"]:
            return
        counts["rx_dropped_kernel"] = drops
        now_s = time.monotonic()
        if now_s - self._drop_warning_s >= DROP_WARNING_S:
            logger.warning("%s: the kernel dropped %d datagrams (%d in all) that arrived faster "
                           "than this ground station read them: it is short of CPU, and the "
                           "vehicles' telemetry has gaps", self.name, drops - self._drops_warned,
                           drops)
            self._drops_warned, self._drop_warning_s = drops, now_s
