"""asyncio UDP endpoint: one local socket, its peer addresses, counters, bounded buffers."""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable
from dataclasses import dataclass, fields
from types import TracebackType

import numpy as np

from gcs.link.bulk import (
    MAX_BATCH_DATAGRAMS,
    Address,
    BatchCallback,
    BulkReader,
    bind_bulk_socket,
)

logger = logging.getLogger(__name__)

DatagramCallback = Callable[[bytes, Address], None]

#: Bytes the transport may hold unsent before send() drops (a healthy UDP socket holds none).
DEFAULT_MAX_WRITE_BUFFER_BYTES = 256 * 1024
DEFAULT_RX_QUEUE_SIZE = 1024


class LinkClosedError(RuntimeError):
    """The endpoint is not open."""


@dataclass(frozen=True, slots=True)
class UdpStats:
    """Counters of one endpoint since it opened."""

    bytes_in: int
    packets_in: int
    packets_in_foreign: int  # datagrams from an address other than the remote (still delivered)
    rx_dropped_queue_full: int  # oldest datagrams dropped because the receive queue was full
    bytes_out: int
    packets_out: int
    send_no_remote: int  # send() before the remote address was configured or learned
    send_dropped_backpressure: int  # send() while the transport's buffer was over its limit
    send_errors: int  # errors reported by the socket (e.g. ICMP port unreachable)
    callback_errors: int  # exceptions raised by on_datagram (logged with traceback)
    rx_truncated: int  # bulk mode: datagrams longer than a read slot, cut (gcs.link.mmsg)
    # bulk mode (Linux): datagrams the kernel dropped because the socket's receive buffer was
    # full: the ground station did not read them in time (SO_RXQ_OVFL)
    rx_dropped_kernel: int


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, owner: UdpEndpoint) -> None:
        self._owner = owner

    def datagram_received(self, data: bytes, addr: Address) -> None:  # type: ignore[override]
        self._owner._on_datagram(data, (addr[0], addr[1]))

    def error_received(self, exc: Exception) -> None:
        self._owner._on_error(exc)


class UdpEndpoint:
    """A UDP socket bound to ``local_host:local_port`` exchanging datagrams with one remote.

    The remote is either given (``remote``) or, with ``learn_remote=True`` and none given, set by
    the layer above through :meth:`set_remote` once it has seen a valid packet (the endpoint itself
    cannot tell valid from invalid bytes). Received datagrams go to ``on_datagram`` (called on the
    event loop, must not block) if given, else to a bounded queue read with :meth:`recv` (when full,
    the oldest datagram is dropped and counted). Lifetime: ``async with UdpEndpoint(...) as ep:``.

    ``on_batch`` (bulk mode, for ports serving many vehicles): the endpoint reads its socket itself
    (``loop.add_reader``) and, at each wake-up, drains up to MAX_BATCH_DATAGRAMS datagrams into one
    buffer and hands them over in one call, each with the kernel's receive time where the OS
    gives it (Linux SO_TIMESTAMPNS): a stall of the event loop then does not read as delay.
    Sends go straight to the non-blocking socket; a full socket buffer drops the datagram
    (counted as ``send_dropped_backpressure``).
    """

    def __init__(
        self,
        local_port: int,
        remote: Address | None = None,
        *,
        local_host: str = "127.0.0.1",
        learn_remote: bool = False,
        on_datagram: DatagramCallback | None = None,
        on_batch: BatchCallback | None = None,
        rx_queue_size: int = DEFAULT_RX_QUEUE_SIZE,
        max_write_buffer_bytes: int = DEFAULT_MAX_WRITE_BUFFER_BYTES,
        name: str = "udp",
    ) -> None:
        if not 0 <= local_port <= 65535:
            raise ValueError(f"{name}: local_port: expected 0..65535, got {local_port}")
        if remote is not None and not 1 <= remote[1] <= 65535:
            raise ValueError(f"{name}: remote port: expected 1..65535, got {remote[1]}")
        if remote is None and not learn_remote:
            raise ValueError(f"{name}: no remote address and learn_remote is False")
        if on_datagram is not None and on_batch is not None:
            raise ValueError(f"{name}: on_datagram or on_batch, not both")
        if rx_queue_size < 1:
            raise ValueError(f"{name}: rx_queue_size: expected >= 1, got {rx_queue_size}")
        self.name = name
        self._local_host = local_host
        self._local_port = local_port
        self._remote = remote
        self._learn_remote = learn_remote
        self._on_datagram_cb = on_datagram
        self._on_batch_cb = on_batch
        self._sock: socket.socket | None = None  # bulk mode: the socket, read and written directly
        self._loop: asyncio.AbstractEventLoop | None = None
        self._bound: Address | None = None  # local_address, once asked while open
        self._reader: BulkReader | None = None  # bulk mode: reads the socket in batches
        self._rx_queue: asyncio.Queue[tuple[bytes, Address]] = asyncio.Queue(rx_queue_size)
        self._max_write_buffer_bytes = max_write_buffer_bytes
        self._transport: asyncio.DatagramTransport | None = None
        self._counts: dict[str, int] = {f.name: 0 for f in fields(UdpStats)}
        self._last_error: Exception | None = None

    # --- lifetime --------------------------------------------------------------------------------

    async def open(self) -> None:
        """Bind the socket; returns when bound (``local_address`` is then known)."""
        if self._transport is not None or self._sock is not None:
            raise RuntimeError(f"{self.name}: already open")
        loop = asyncio.get_running_loop()
        if self._on_batch_cb is not None:
            sock = bind_bulk_socket(self._local_host, self._local_port)
            self._sock, self._loop = sock, loop
            self._reader = BulkReader(sock, self.name, self._counts, self._on_error,
                                      self._hand_over)
            loop.add_reader(sock.fileno(), self._reader.drain)
            logger.debug("%s: bound %s (bulk), remote %s", self.name, self.local_address,
                         self._remote)
            return
        transport, _ = await loop.create_datagram_endpoint(
            lambda: _Protocol(self), local_addr=(self._local_host, self._local_port)
        )
        self._transport = transport
        logger.debug("%s: bound %s, remote %s", self.name, self.local_address, self._remote)

    def close(self) -> None:
        """Close the socket; returns immediately. Idempotent."""
        if self._sock is not None:
            if self._loop is not None and not self._loop.is_closed():
                self._loop.remove_reader(self._sock.fileno())
            self._sock.close()
            self._sock = None
            self._bound = None
        if self._transport is not None:
            self._transport.close()
            self._transport = None
            self._bound = None

    async def __aenter__(self) -> UdpEndpoint:
        await self.open()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # --- addresses -------------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        return self._transport is not None or self._sock is not None

    @property
    def local_address(self) -> Address:
        """(host, port) actually bound; the port is resolved when 0 was asked for."""
        if self._sock is None and self._transport is None:
            raise LinkClosedError(f"{self.name}: not open")
        if self._bound is None:
            host, port = (self._sock.getsockname() if self._sock is not None else
                          self._transport.get_extra_info("sockname"))[:2]  # type: ignore[union-attr]
            self._bound = (str(host), int(port))
        return self._bound

    @property
    def remote(self) -> Address | None:
        return self._remote

    @property
    def learn_remote(self) -> bool:
        return self._learn_remote

    def set_remote(self, remote: Address) -> None:
        """Set (learn) the remote address; returns immediately."""
        if self._remote != remote:
            logger.info("%s: remote set to %s:%d", self.name, remote[0], remote[1])
        self._remote = remote

    @property
    def last_error(self) -> Exception | None:
        return self._last_error

    def stats(self) -> UdpStats:
        """A snapshot of the counters."""
        return UdpStats(**self._counts)

    # --- I/O -------------------------------------------------------------------------------------

    def send(self, data: bytes) -> bool:
        """Queue one datagram to the remote; returns immediately, never blocks.

        Returns True if handed to the socket, False if dropped (no remote yet, or transport
        backlog over ``max_write_buffer_bytes``); every drop is counted. Raises
        :class:`LinkClosedError` if the endpoint is not open.
        """
        return self.send_to(data, self._remote)

    def send_to(self, data: bytes, addr: Address | None) -> bool:
        """Queue one datagram to ``addr`` (None: not known yet, dropped and counted as
        ``send_no_remote``); otherwise as :meth:`send`, which sends to the endpoint's remote.
        A port shared by several peers sends with this, each peer at its own address."""
        if self._sock is not None:
            return self._send_direct(data, addr)
        transport = self._transport
        if transport is None:
            raise LinkClosedError(f"{self.name}: send on a closed endpoint")
        if addr is None:
            self._counts["send_no_remote"] += 1
            return False
        if transport.get_write_buffer_size() > self._max_write_buffer_bytes:
            self._counts["send_dropped_backpressure"] += 1
            return False
        transport.sendto(data, addr)
        self._counts["packets_out"] += 1
        self._counts["bytes_out"] += len(data)
        return True

    def send_many(self, datagrams: list[bytes], addrs: list[Address | None]) -> int:
        """`send_to` for each pair (bulk mode: straight to the socket, counters once); returns
        how many were handed to the socket."""
        if self._sock is None:
            return sum(self.send_to(d, a) for d, a in zip(datagrams, addrs, strict=True))
        sendto, sent, nbytes = self._sock.sendto, 0, 0
        counts = self._counts
        for data, addr in zip(datagrams, addrs, strict=True):
            if addr is None:
                counts["send_no_remote"] += 1
                continue
            try:
                sendto(data, addr)
            except BlockingIOError:
                counts["send_dropped_backpressure"] += 1
                continue
            except OSError as exc:
                self._on_error(exc)
                continue
            sent += 1
            nbytes += len(data)
        counts["packets_out"] += sent
        counts["bytes_out"] += nbytes
        return sent

    def _send_direct(self, data: bytes, addr: Address | None) -> bool:
        if addr is None:
            self._counts["send_no_remote"] += 1
            return False
        assert self._sock is not None
        try:
            self._sock.sendto(data, addr)
        except BlockingIOError:
            self._counts["send_dropped_backpressure"] += 1
            return False
        except OSError as exc:  # e.g. ICMP port unreachable reported on a later call
            self._on_error(exc)
            return False
        self._counts["packets_out"] += 1
        self._counts["bytes_out"] += len(data)
        return True

    def _hand_over(self, buffer: bytearray, offsets: np.ndarray, lengths: np.ndarray,
                   sources: list[Address], stamps: np.ndarray) -> None:
        """Bulk mode: one batch read (`BulkReader`), counted, to ``on_batch``."""
        cb = self._on_batch_cb
        assert cb is not None
        counts = self._counts
        counts["packets_in"] += len(offsets)
        counts["bytes_in"] += int(lengths.sum())
        if self._remote is not None:
            counts["packets_in_foreign"] += sum(1 for a in sources if a != self._remote)
        try:
            cb(buffer, offsets, lengths, sources, stamps)
        except Exception:
            counts["callback_errors"] += 1
            logger.exception("%s: on_batch callback failed", self.name)

    async def recv(self, timeout_s: float) -> tuple[bytes, Address]:
        """Next received datagram and its source; returns when one is there, raises TimeoutError
        after ``timeout_s``. Only for endpoints created without ``on_datagram``."""
        if self._on_datagram_cb is not None:
            raise RuntimeError(f"{self.name}: recv() on an endpoint with an on_datagram callback")
        async with asyncio.timeout(timeout_s):
            return await self._rx_queue.get()

    def _on_datagram(self, data: bytes, addr: Address) -> None:
        self._counts["packets_in"] += 1
        self._counts["bytes_in"] += len(data)
        if self._remote is not None and addr != self._remote:
            self._counts["packets_in_foreign"] += 1
        if self._on_datagram_cb is not None:
            try:
                self._on_datagram_cb(data, addr)
            except Exception:
                self._counts["callback_errors"] += 1
                logger.exception("%s: on_datagram callback failed", self.name)
            return
        if self._rx_queue.full():
            self._rx_queue.get_nowait()
            self._counts["rx_dropped_queue_full"] += 1
        self._rx_queue.put_nowait((data, addr))

    def _on_error(self, exc: Exception) -> None:
        self._counts["send_errors"] += 1
        if self._last_error is None or type(exc) is not type(self._last_error):
            logger.warning("%s: socket error: %s", self.name, exc)
        self._last_error = exc


__all__ = ["MAX_BATCH_DATAGRAMS", "Address", "BatchCallback", "DatagramCallback",
           "LinkClosedError", "UdpEndpoint", "UdpStats"]
