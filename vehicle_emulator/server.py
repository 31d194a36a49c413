"""asyncio UDP endpoint of one vehicle link: datagrams in/out, impairments, remote tracking.

Like PX4 SITL's UDP link, the endpoint sends to its configured remote (127.0.0.1:14540+i by
default) until a valid MAVLink message arrives, then to the address that last sent one. A
``connect``ed endpoint (ArduPilot SITL's ``udpclient``) binds an ephemeral port unless one is
given, sends only to its remote and receives only from it (a connected UDP socket). Link
impairments (loss window, seeded loss, latency, jitter, reordering: faults.py) apply to both
directions. Bytes are decoded by a per-link ``PeerDecoder`` (one parser per peer address) and
handed to a callback.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from vehicle_emulator.codec import PeerDecoder
from vehicle_emulator.faults import LinkImpairment

log = logging.getLogger(__name__)

__all__ = ["UdpLink"]

Address = tuple[str, int]


class UdpLink(asyncio.DatagramProtocol):
    """One UDP endpoint. ``on_messages(link, messages, addr)`` receives decoded messages."""

    def __init__(
        self,
        name: str,
        remote: Address,
        impairment: LinkImpairment,
        now_s: Callable[[], float],
        on_messages: Callable[[UdpLink, list[Any], Address], None],
        follow_sender: bool = True,
    ) -> None:
        self.name = name
        self.remote = remote
        self.impairment = impairment
        self.now_s = now_s
        self.on_messages = on_messages
        self.follow_sender = follow_sender
        self.decoder = PeerDecoder()
        self.transport: asyncio.DatagramTransport | None = None
        self.sent_datagrams = 0
        self.send_errors = 0
        self.connected = False
        self._loop: asyncio.AbstractEventLoop | None = None

    @classmethod
    async def open(
        cls,
        bind: Address,
        remote: Address,
        impairment: LinkImpairment,
        now_s: Callable[[], float],
        on_messages: Callable[[UdpLink, list[Any], Address], None],
        name: str = "link",
        connect: bool = False,
    ) -> UdpLink:
        """Bind ``bind`` (port 0: an ephemeral one) and return the endpoint (OSError if the port
        is taken); ``connect``: a connected socket to ``remote`` (see the module docstring)."""
        loop = asyncio.get_running_loop()
        _, proto = await loop.create_datagram_endpoint(
            lambda: cls(name, remote, impairment, now_s, on_messages, follow_sender=not connect),
            local_addr=bind,
            remote_addr=remote if connect else None,
        )
        proto._loop = loop
        proto.connected = connect
        return proto

    @property
    def local_address(self) -> Address | None:
        """(host, port) actually bound."""
        return None if self.transport is None else self.transport.get_extra_info("sockname")

    # --- asyncio callbacks ---------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: Address) -> None:
        delay = self.impairment.admit(self.now_s())
        if delay is None:
            return
        if delay > 0.0 and self._loop is not None:
            self._loop.call_later(delay, self._deliver, data, addr)
        else:
            self._deliver(data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when nobody listens on the remote yet: normal for UDP
        self.send_errors += 1
        log.debug("%s: %s", self.name, exc)

    def _deliver(self, data: bytes, addr: Address) -> None:
        msgs = self.decoder.feed(data, addr)
        if not msgs:
            return
        if self.follow_sender and addr != self.remote:
            log.info("%s: remote is now %s:%d", self.name, addr[0], addr[1])
            self.remote = addr
        self.on_messages(self, msgs, addr)

    # --- output --------------------------------------------------------------------------------

    def send(self, data: bytes, addr: Address | None = None) -> None:
        """Send ``data`` (after impairments) to ``addr`` or the current remote; never blocks."""
        if self.transport is None or self.transport.is_closing():
            return
        delay = self.impairment.admit(self.now_s())
        if delay is None:
            return
        target = addr or self.remote
        if delay > 0.0 and self._loop is not None:
            self._loop.call_later(delay, self._sendto, data, target)
        else:
            self._sendto(data, target)

    def _sendto(self, data: bytes, target: Address) -> None:
        if self.transport is None or self.transport.is_closing():
            return
        try:
            if self.connected:  # the connected peer only
                self.transport.sendto(data)
            else:
                self.transport.sendto(data, target)
            self.sent_datagrams += 1
        except OSError as exc:
            self.send_errors += 1
            log.debug("%s: send to %s failed: %s", self.name, target, exc)

    def close(self) -> None:
        """Close the socket."""
        if self.transport is not None:
            self.transport.close()
