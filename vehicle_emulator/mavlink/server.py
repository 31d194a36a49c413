"""asyncio UDP endpoint of one vehicle link: datagrams in/out, impairments, remote tracking.

Like PX4 SITL's UDP link, the endpoint sends to its configured remote (127.0.0.1:14540+i by
default) until a valid MAVLink message arrives, then to the address that last sent one. A
``connect``ed endpoint (ArduPilot SITL's ``udpclient``) binds an ephemeral port unless one is
given, sends only to its remote and receives only from it (a connected UDP socket). Link
impairments (loss window, seeded loss, latency, jitter, reordering: faults.py) apply to both
directions. Bytes are decoded by a per-link ``PeerDecoder`` (one parser per peer address) and
handed to a callback.

``LinkPoller`` reads many endpoints in bulk (a fleet's hundreds of sockets): one asyncio reader
(an epoll descriptor) for all of them; at each wake-up the ready sockets are drained (for at
most ``read_budget_s``, then the next wake-up reads on) and the datagrams are decoded together
(codec.HotDecoder: the setpoint streams without pymavlink's parser), then delivered in arrival
order, exactly as one callback per datagram would; before each, ``between`` lets a periodic tick
that fell due run first. Sends go straight to the socket (asyncio's transport only when its
buffer holds earlier data).

Latest wins: a setpoint (SET_ATTITUDE_TARGET, SET_POSITION_TARGET_LOCAL_NED) read in the same
wake-up as a newer one of the same type from the same peer to the same target is counted
(``UdpLink.superseded``) but not handled. Handled in turn they would all act at one simulated
instant, each replacing the one before, so the vehicle ends in the same state; what it saves is
the work, which is what lets a fleet that fell behind catch up. A real autopilot's receive
thread keeps up with its one link; a fleet process shares a core between hundreds, and without
this a backlog, once built, stayed: 240 vehicles flew setpoints up to 0.3 s (30 per socket)
old while every physics tick ran on time, and the formation diverged in its highest mode.
"""

from __future__ import annotations

import asyncio
import logging
import select
import socket
import time
from collections.abc import Callable
from typing import Any

from vehicle_emulator.config.faults import LinkImpairment
from vehicle_emulator.mavlink.codec import HotDecoder, PeerDecoder

log = logging.getLogger(__name__)

__all__ = ["LinkPoller", "UdpLink"]

MAX_DATAGRAM = 65536
# A wake-up reads in rounds: one datagram from each socket the epoll reports ready, then asks
# the epoll again (one system call for all sockets, where reading each socket until it fails
# costs a failed call and an exception per setpoint, ~2 us), until no socket is ready or the
# read budget is spent: a backlog is read at once and its superseded setpoints dropped (module
# docstring). The physics tick runs between rounds and between deliveries (``between``). The
# caps only bound one wake-up's memory: a fleet of 240 reads ~250 datagrams per 10 ms.
MAX_PER_SOCKET = 512
MAX_PER_WAKEUP = 16384
#: A wake-up starts no new round after this long [s] (``LinkPoller.read_budget_s``): what it read
#: is then delivered, and the next wake-up (at once: the epoll is level-triggered) reads on.
#: Without it, a wake-up that found data at every round never ended while the ground station
#: kept sending (240 vehicles: 24 setpoints a millisecond, the ticks between rounds taking half
#: the time): it read for up to 0.25 s (5,000 datagrams) with everything it read, TIMESYNC
#: requests among them, waiting, and the vehicles answered 0.3 s late while their telemetry
#: went out on time. 20 ms is two setpoint periods at 100 Hz: a backlog read within it is still
#: superseded at once (with 5 ms, a 240-vehicle fleet that fell behind handled more of its
#: setpoints one by one, and its deepest socket backlog grew to 73 datagrams).
READ_BUDGET_S = 0.02
#: Message ids of the setpoint streams where the newest of a wake-up's reads wins.
LATEST_WINS = frozenset({82, 84})  # SET_ATTITUDE_TARGET, SET_POSITION_TARGET_LOCAL_NED

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
        self.superseded = 0  # setpoints read but not handled: a newer one came with them
        self.send_errors = 0
        self.connected = False
        self.sock: socket.socket | None = None
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
        family, _, _, _, address = socket.getaddrinfo(bind[0], bind[1], type=socket.SOCK_DGRAM)[0]
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind(address)
            if connect:
                sock.connect(remote)
            sock.setblocking(False)
            _, proto = await loop.create_datagram_endpoint(
                lambda: cls(name, remote, impairment, now_s, on_messages,
                            follow_sender=not connect),
                sock=sock,
            )
        except BaseException:
            sock.close()
            raise
        proto._loop = loop
        proto.connected = connect
        proto.sock = sock
        return proto

    @property
    def local_address(self) -> Address | None:
        """(host, port) actually bound."""
        return None if self.transport is None else self.transport.get_extra_info("sockname")

    # --- asyncio callbacks ---------------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: Address) -> None:
        if self.admit_now(data, addr):
            self._deliver(data, addr)

    def admit_now(self, data: bytes, addr: Address) -> bool:
        """The link's impairment on one received datagram: True to deliver it now; False when
        it is lost or delayed (then delivered later by the event loop)."""
        delay = self.impairment.admit(self.now_s())
        if delay is None:
            return False
        if delay > 0.0 and self._loop is not None:
            self._loop.call_later(delay, self._deliver, data, addr)
            return False
        return True

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when nobody listens on the remote yet: normal for UDP
        self.send_errors += 1
        log.debug("%s: %s", self.name, exc)

    def _deliver(self, data: bytes, addr: Address) -> None:
        self._hand_over(self.decoder.feed(data, addr), addr)

    def _deliver_decoded(self, data: bytes, addr: Address, msgs: list[Any]) -> None:
        """A datagram ``LinkPoller`` decoded in batch (``msgs`` not empty)."""
        self.decoder.count_decoded(data, addr, len(msgs))
        self._hand_over(msgs, addr)

    def _hand_over(self, msgs: list[Any], addr: Address) -> None:
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
            sock = self.sock
            if sock is not None and not self.transport.get_write_buffer_size():
                try:  # straight to the socket: asyncio's sendto costs as much again
                    if self.connected:
                        sock.send(data)
                    else:
                        sock.sendto(data, target)
                    self.sent_datagrams += 1
                    return
                except (BlockingIOError, InterruptedError):
                    pass  # the socket buffer is full: asyncio's transport queues it
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


class LinkPoller:
    """Bulk reader of many ``UdpLink``s (module docstring). ``attach`` each link after it
    opened; ``close`` before closing the links. ``batches`` and ``datagrams`` count the
    wake-ups and what they read."""

    def __init__(self, loop: asyncio.AbstractEventLoop | None = None) -> None:
        self._loop = loop or asyncio.get_running_loop()
        self._epoll = select.epoll()
        self._links: dict[int, UdpLink] = {}
        self._hot = HotDecoder()
        self.batches = 0
        self.datagrams = 0
        #: the most rounds one wake-up read (a socket's deepest backlog, in datagrams)
        self.deepest = 0
        #: called before each datagram of a batch is delivered (the fleet's real-time tick,
        #: which runs there when it is due: Emulator.run)
        self.between: Callable[[], None] | None = None
        #: how long one wake-up reads before it delivers (READ_BUDGET_S)
        self.read_budget_s = READ_BUDGET_S
        #: wake-ups that stopped reading at the budget (the rest waits for the next)
        self.budget_stops = 0
        self._loop.add_reader(self._epoll.fileno(), self._ready)

    def attach(self, link: UdpLink) -> None:
        """Read ``link`` here instead of through its asyncio transport."""
        if link.sock is None or link.transport is None:
            raise ValueError(f"{link.name}: not open")
        link.transport.pause_reading()
        fd = link.sock.fileno()
        self._links[fd] = link
        self._epoll.register(fd, select.EPOLLIN)

    def close(self) -> None:
        """Stop reading (idempotent)."""
        if self._epoll.closed:
            return
        self._loop.remove_reader(self._epoll.fileno())
        self._epoll.close()

    def _ready(self) -> None:
        items: list[tuple[UdpLink, bytes, Address]] = []
        room = MAX_PER_WAKEUP
        between = self.between
        depth = 0
        stop_s = time.monotonic() + self.read_budget_s
        for _ in range(MAX_PER_SOCKET):  # rounds of one datagram from each ready socket
            if depth and time.monotonic() >= stop_s:
                self.budget_stops += 1
                break
            ready = self._epoll.poll(0, room)
            if not ready:
                break
            depth += 1
            for fd, _events in ready:
                link = self._links.get(fd)
                if link is not None:
                    self._read_one(link, items)
            room = MAX_PER_WAKEUP - len(items)
            if room <= 0:
                break
            if between is not None:
                between()
        if not items:
            return
        self.batches += 1
        self.datagrams += len(items)
        self.deepest = max(self.deepest, depth)
        decoded = self._hot.decode([data for _, data, _ in items])
        # one round reads at most one datagram per socket: nothing to supersede
        stale = _superseded(items, decoded) if depth > 1 else None
        for k, ((link, data, addr), msgs) in enumerate(zip(items, decoded, strict=True)):
            hot = msgs is not None and link.decoder.idle(addr)
            if hot and stale is not None and stale[k]:
                link.decoder.count_decoded(data, addr, len(msgs))
                link.superseded += 1
                continue
            if between is not None:
                between()
            if hot:
                link._deliver_decoded(data, addr, msgs)
            else:
                link._deliver(data, addr)

    @staticmethod
    def _read_one(link: UdpLink, items: list[tuple[UdpLink, bytes, Address]]) -> None:
        """One datagram from ``link``'s socket (epoll said it is readable), through its
        impairments."""
        sock = link.sock
        assert sock is not None
        try:
            data, addr = sock.recvfrom(MAX_DATAGRAM)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:  # e.g. ICMP port unreachable on a connected socket
            link.error_received(exc)
            return
        if link.admit_now(data, addr):
            items.append((link, data, addr))


def _superseded(items: list[tuple[UdpLink, bytes, Address]],
                decoded: list[list[Any] | None]) -> list[bool]:
    """Per datagram, whether it is one setpoint of a LATEST_WINS stream that a later datagram
    of the same read replaces (same link, peer, message id and target)."""
    out = [False] * len(items)
    newest: set[tuple[int, Address, int, int, int]] = set()
    for k in range(len(items) - 1, -1, -1):
        msgs = decoded[k]
        if msgs is None or len(msgs) != 1:
            continue
        msg = msgs[0]
        msgid = msg.get_msgId()
        if msgid not in LATEST_WINS:
            continue
        link, _, addr = items[k]
        key = (id(link), addr, msgid, msg.target_system, msg.target_component)
        if key in newest:
            out[k] = True
        else:
            newest.add(key)
    return out
