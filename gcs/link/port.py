"""Shared GCS UDP port: one endpoint serving several vehicles, datagrams routed by MAVLink sysid.

mavlink-router, MAVProxy ``--out`` and several SITL instances told to send to one port all put
many vehicles behind one GCS port. A `MavlinkPort` owns that port's `UdpEndpoint` and hands each
datagram to the vehicle whose sysid its MAVLink header carries; the vehicle's proxy decodes it
(once, with its own parser) and tracks that vehicle's address. The routing reads the frame
headers only (start marker, length, sysid), no CRC and no decoding:

* every frame of a datagram from one sysid (the usual case): the datagram is delivered whole;
* frames of several sysids in one datagram: split at frame boundaries, each part to its vehicle
  (counted as ``split_datagrams``);
* bytes before the first frame go with that frame (its vehicle's codec counts them as garbage);
* a sysid no vehicle on the port has, or a datagram without any frame start (ArduPilot's
  plain-text boot banner): decoded by the port's own codec, counted (``unknown_sysid_frames``
  and ``unknown_sysids`` per sysid; ``codec`` for the bytes that were not MAVLink), logged once
  per sysid, written to the tlog, and otherwise ignored. A port with a single vehicle (the
  default, one port per vehicle) tells that vehicle's proxy about another vehicle's HEARTBEAT,
  which then refuses to fly it (a team-file mistake); a shared port does not (other systems on
  a router are normal).

TIMESYNC requests are the port's to ration: a request to one address reaches every vehicle behind
it, and each answers with the request's ts1. The port hands out at most one request per address
and period (:meth:`claim_timesync`) and remembers when each went out (:meth:`timesync_sent_s`),
so every vehicle's proxy can time the replies of a request another proxy sent.

Lifetime: ``async with MavlinkPort(port) as p:``; the proxies ``attach`` to it (see
`gcs.link.proxy.VehicleProxy`'s ``port`` argument) and ``detach`` when they close.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass, fields
from types import TracebackType
from typing import Protocol

import numpy as np

from gcs.link.codec import (
    CHECKSUM_LEN,
    HEADER_LEN_V1,
    HEADER_LEN_V2,
    IFLAG_SIGNED,
    SIGNATURE_LEN,
    STX_V1,
    STX_V2,
    CodecStats,
    MavlinkCodec,
    MAVLinkMessage,
)
from gcs.link.fastpath import (
    Datagrams,
    HotTable,
    Routing,
    crc_extra_table,
    kind_table,
    scan,
)
from gcs.link.tlog import TlogWriter
from gcs.link.udp import MAX_BATCH_DATAGRAMS, Address, UdpEndpoint, UdpStats

logger = logging.getLogger(__name__)

#: How often the hot path tells a proxy that its vehicle's messages arrived when nothing waits
#: for them [s] (its clock filter's feed; at 240 vehicles a call per vehicle per batch was a
#: tenth of the ground station's time). Each slot has its own phase in the period (slot k at
#: k / 8 of it, modulo), so a team's notices spread over the batches instead of all landing in
#: one (240 proxies' clock filters at once: ~1 ms in a single callback).
HOT_NOTICE_S = 0.05
NOTICE_PHASES = 8
#: TIMESYNC requests remembered for their replies (one per vehicle address per 0.5 s: 240
#: vehicles' last 8 s, one vehicle's last half hour).
TIMESYNC_REMEMBERED = 4096
#: The slow path's share of one event-loop callback [s]: frames the hot path hands back
#: (HEARTBEAT, COMMAND_ACK, STATUSTEXT, TIMESYNC replies) are decoded by pymavlink, ~10 us
#: each; past this budget the rest waits for the loop's next pass, so a burst
#: (240 vehicles' HEARTBEATs in one batch: ~2.5 ms) never holds the control tick back.
SLOW_BUDGET_S = 0.5e-3


class PortClient(Protocol):
    """What a port needs of a vehicle's proxy."""

    def _on_datagram(self, data: bytes, addr: Address, seq_counted: bool = False,
                     rx_s: float | None = None) -> None:
        """Bytes (whole MAVLink frames) from this vehicle's sysid, received from ``addr``;
        ``seq_counted``: the hot path accepted these frames and counted their sequence numbers;
        ``rx_s``: when they were received (None: now)."""

    def _on_hot(self) -> None:
        """The hot path stored new messages of this vehicle in the port's table (since its
        last call: the table's clock reduction covers them all)."""

    @property
    def hot_waiting(self) -> bool:
        """Something waits for this vehicle's next message: tell it at every batch."""

    def _on_foreign(self, msg: MAVLinkMessage, addr: Address) -> None:
        """A valid message from a sysid no vehicle on this port has (single-vehicle ports)."""


@dataclass(frozen=True, slots=True)
class PortStats:
    """Counters of one port since it opened (the endpoint's and the port codec's are separate)."""

    datagrams_routed: int  # delivered whole to one vehicle
    split_datagrams: int  # carried frames of several sysids, split between them
    unknown_sysid_frames: int  # frames from a sysid no vehicle on the port has (ignored)
    unframed_datagrams: int  # no MAVLink start marker at all (e.g. a plain-text banner)
    after_detach: int  # datagrams (or parts) of a vehicle whose proxy has closed (dropped)
    slow_deferred: int  # times the slow path's budget ran out and the rest waited a loop pass


def frame_sysids(data: bytes | bytearray) -> list[tuple[int, int, int | None]]:
    """Split a datagram into runs of consecutive frames of one sysid, reading headers only.

    Returns ``(start, end, sysid)`` byte ranges covering ``data`` in order; bytes before a frame
    start belong to the run of the frame after them, a frame cut off at the end to its run.
    ``sysid`` is None for a datagram without any frame start. Pure; MAVLink 1 and 2 frames.
    """
    n = len(data)
    runs: list[tuple[int, int, int | None]] = []
    run_start, current = 0, None
    pos = 0
    while pos < n:
        stx = data[pos]
        if stx == STX_V2:
            if n - pos < HEADER_LEN_V2:
                break
            sysid = data[pos + 5]
            size = (HEADER_LEN_V2 + data[pos + 1] + CHECKSUM_LEN
                    + (SIGNATURE_LEN if data[pos + 2] & IFLAG_SIGNED else 0))
        elif stx == STX_V1:
            if n - pos < HEADER_LEN_V1:
                break
            sysid = data[pos + 3]
            size = HEADER_LEN_V1 + data[pos + 1] + CHECKSUM_LEN
        else:
            pos += 1
            continue
        if current is None:
            current = sysid
        elif sysid != current:
            runs.append((run_start, pos, current))
            run_start, current = pos, sysid
        pos += size
    runs.append((run_start, n, current))
    return runs


class MavlinkPort:
    """One GCS UDP port (``local_host:local_port``, 0: any free port) shared by the vehicles
    attached to it, each by its sysid. Sending is per datagram to an explicit address
    (:meth:`send_to`): each vehicle's proxy keeps its own vehicle's address.

    With a `HotTable` (``table``) the port reads its socket in bulk and runs the hot path
    (gcs.link.fastpath) on each batch: the attached vehicles' hot messages go straight into the
    table (row ``slot`` given at :meth:`attach`), everything else to the proxies as above.
    ``clock`` (monotonic seconds) stamps those batches; give the proxies' clock.
    """

    def __init__(self, local_port: int, *, local_host: str = "127.0.0.1",
                 tlog: TlogWriter | None = None, name: str | None = None,
                 table: HotTable | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.name = name or f"udp port {local_host}:{local_port}"
        self._table = table
        self._now_s = clock
        if table is None:
            self._endpoint = UdpEndpoint(local_port, None, local_host=local_host,
                                         learn_remote=True, on_datagram=self._route,
                                         name=self.name)
        else:
            self._endpoint = UdpEndpoint(local_port, None, local_host=local_host,
                                         learn_remote=True, on_batch=self._on_batch,
                                         name=self.name)
            self._slot_of_sysid = np.full(256, -1, dtype=np.int64)
            self._slot_clients: dict[int, PortClient] = {}
            # when each slot's proxy is next told of its hot messages (monotonic s; phases
            # set at attach)
            self._notice_due_s = np.full(table.n, -math.inf)
            self._addr_codes: dict[Address, int] = {}
            self._crc_extra = crc_extra_table()
            self._kinds = kind_table()
            self._slow = np.zeros((4 * MAX_BATCH_DATAGRAMS, 4), dtype=np.int64)
            self._tlog_buf = np.zeros(0, dtype=np.uint8)
            # slow frames not routed yet (data, source, seq counted, receive time), in order
            self._slow_queue: deque[tuple[bytes, Address, bool, float]] = deque()
            self._slow_pending = False  # a pass of _route_slow is scheduled
        self._codec = MavlinkCodec()  # frames no attached vehicle claims (counted, ignored)
        self._tlog = tlog
        self._clients: dict[int, PortClient] = {}
        self._n: dict[str, int] = {f.name: 0 for f in fields(PortStats)}
        self._unknown: dict[int, int] = {}
        self._detached: set[int] = set()  # vehicles whose proxies closed first (shutdown)
        self._most_clients = 0
        self._ts_sent: OrderedDict[int, float] = OrderedDict()  # ts1 [ns] -> sent at [s]
        self._ts_last: dict[Address, float] = {}  # address -> when its last request went out

    # --- lifetime --------------------------------------------------------------------------------

    async def open(self) -> None:
        """Bind the socket; returns when bound."""
        await self._endpoint.open()

    def close(self) -> None:
        """Close the socket; returns immediately. Idempotent."""
        self._endpoint.close()
        if self._table is not None:
            self._slow_queue.clear()  # nobody to hand them to

    async def __aenter__(self) -> MavlinkPort:
        await self.open()
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                        tb: TracebackType | None) -> None:
        self.close()

    @property
    def table(self) -> HotTable | None:
        """The hot path's table (None: every frame goes through the proxies' codecs)."""
        return self._table

    def attach(self, sysid: int, client: PortClient, slot: int | None = None) -> None:
        """Route this sysid's frames to ``client``; ValueError if another client has it.
        ``slot``: the client's row in the port's table (hot path); the client sets
        ``table.compid_of_slot``/``addr_of_slot`` for it (see `HotTable`)."""
        if sysid in self._clients and self._clients[sysid] is not client:
            raise ValueError(f"{self.name}: sysid {sysid} is already attached")
        self._clients[sysid] = client
        if self._table is not None and slot is not None:
            if not 0 <= slot < self._table.n:
                raise ValueError(f"{self.name}: slot {slot} outside the table "
                                 f"(0..{self._table.n - 1})")
            self._slot_of_sysid[sysid] = slot
            self._slot_clients[slot] = client
            self._notice_due_s[slot] = (self._now_s()
                                        + HOT_NOTICE_S * (slot % NOTICE_PHASES) / NOTICE_PHASES)
        self._detached.discard(sysid)
        self._most_clients = max(self._most_clients, len(self._clients))

    def detach(self, sysid: int) -> None:
        """Stop routing this sysid; its later frames are dropped (counted ``after_detach``),
        not taken for a stranger's."""
        if self._clients.pop(sysid, None) is not None:
            self._detached.add(sysid)
        if self._table is not None and self._slot_of_sysid[sysid] >= 0:
            self._slot_clients.pop(int(self._slot_of_sysid[sysid]), None)
            self._slot_of_sysid[sysid] = -1

    # --- state -----------------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        return self._endpoint.is_open

    @property
    def local_address(self) -> Address:
        """(host, port) actually bound (raises LinkClosedError when closed)."""
        return self._endpoint.local_address

    @property
    def shared(self) -> bool:
        """More than one vehicle has been attached (it stays shared while they detach)."""
        return self._most_clients > 1

    @property
    def sysids(self) -> tuple[int, ...]:
        return tuple(sorted(self._clients))

    def stats(self) -> PortStats:
        return PortStats(**self._n)

    def udp_stats(self) -> UdpStats:
        return self._endpoint.stats()

    def codec_stats(self) -> CodecStats:
        """What the port decoded itself: unknown sysids and bytes without a frame."""
        return self._codec.stats()

    def unknown_sysids(self) -> dict[int, int]:
        """Frames received per sysid that no attached vehicle has."""
        return dict(self._unknown)

    # --- I/O -------------------------------------------------------------------------------------

    def send_to(self, data: bytes, addr: Address | None) -> bool:
        """One datagram to ``addr``; returns immediately (see UdpEndpoint.send_to)."""
        return self._endpoint.send_to(data, addr)

    def send_many(self, datagrams: list[bytes], addrs: list[Address | None]) -> int:
        """Datagram k to ``addrs[k]``, in one call; returns how many were handed to the socket
        (see UdpEndpoint.send_to for what is dropped and counted)."""
        return self._endpoint.send_many(datagrams, addrs)

    def claim_timesync(self, addr: Address, now_s: float, period_s: float) -> int | None:
        """ts1 [ns] for a TIMESYNC request to ``addr`` now, or None if one went there less than
        ``period_s`` ago; the caller sends it. ts1 is ``now_s`` in ns (unique per port)."""
        if now_s - self._ts_last.get(addr, -float("inf")) < period_s * 0.999:
            return None
        ts1 = int(now_s * 1e9)
        while ts1 in self._ts_sent:
            ts1 += 1
        self._ts_last[addr] = now_s
        self._ts_sent[ts1] = now_s
        if len(self._ts_sent) > TIMESYNC_REMEMBERED:
            self._ts_sent.popitem(last=False)
        return ts1

    def timesync_sent_s(self, ts1: int) -> float | None:
        """When the request with this ts1 went out (None: not one of ours, or forgotten)."""
        return self._ts_sent.get(ts1)

    def address_code(self, addr: Address) -> int:
        """The hot path's number for a source address of this port (stable while open)."""
        code = self._addr_codes.get(addr)
        if code is None:
            code = self._addr_codes[addr] = len(self._addr_codes)
        return code

    def _on_batch(self, buffer: bytearray, offs: np.ndarray, lens: np.ndarray,
                  sources: list[Address], stamps: np.ndarray) -> None:
        table = self._table
        assert table is not None
        now_s = self._now_s()
        if self._now_s is time.monotonic:  # the kernel's receive times, on this clock
            shift = time.time() - now_s
            rx = np.where(np.isnan(stamps), now_s, np.minimum(now_s, stamps - shift))
        else:  # an injected clock (tests): when the batch is read
            rx = np.full(len(offs), now_s)
        codes = self._addr_codes
        addr_codes = np.array([codes[a] if a in codes else self.address_code(a)
                               for a in sources], dtype=np.int64)
        total = int(offs[-1] + lens[-1])
        size = int(lens.sum())  # the datagrams' bytes (they may lie apart in the buffer)
        if self._tlog_buf.shape[0] < 2 * size + 64:  # a record: 8 bytes + a frame of >= 12
            self._tlog_buf = np.zeros(4 * size + 64, dtype=np.uint8)
        if self._slow.shape[0] < size // 12 + len(offs):  # a row per frame at most
            self._slow = np.zeros((2 * (size // 12 + len(offs)), 4), dtype=np.int64)
        data = np.frombuffer(buffer, dtype=np.uint8, count=total)
        n_slow, t_len, n_hot = scan(
            Datagrams(data, offs, lens, addr_codes, rx, int(time.time() * 1e6)),
            Routing(self._slot_of_sysid, table.compid_of_slot, table.addr_of_slot,
                    self._crc_extra, self._kinds),
            table.arrays, self._tlog_buf, self._slow)
        if n_hot:
            if self._tlog is not None:
                self._tlog.write_records(self._tlog_buf[:t_len].tobytes(), n_hot)
            # each proxy hears of it about every HOT_NOTICE_S, at its own phase (their clock
            # filters take the batches' least-delayed and newest stamps, accumulated meanwhile
            # in the table), at once when it waits for a message
            touched = np.flatnonzero(table.touched)
            due_s = self._notice_due_s
            told = []
            for slot, due in zip(touched.tolist(), (due_s[touched] <= now_s).tolist(),
                                 strict=True):
                client = self._slot_clients.get(slot)
                if client is None or due or client.hot_waiting:
                    if client is not None:
                        client._on_hot()
                        # the next notice at the slot's phase, the first one after now (a
                        # stalled loop skips whole periods; it does not bunch the team up)
                        due_s[slot] += HOT_NOTICE_S * (
                            math.floor((now_s - due_s[slot]) / HOT_NOTICE_S) + 1
                            if due_s[slot] <= now_s else 1)
                    told.append(slot)
            table.touched[told] = 0
            table.clock[told, 4] = 0.0
        if n_slow:
            view = memoryview(buffer)
            queue = self._slow_queue
            for d, start, end, counted in self._slow[:n_slow].tolist():
                queue.append((bytes(view[start:end]), sources[d], bool(counted), float(rx[d])))
            self._route_slow()

    def _route_slow(self, scheduled: bool = False) -> None:
        """Route queued slow frames, oldest first, for at most SLOW_BUDGET_S; what is left goes
        on at the loop's next pass, after the I/O and the timers that came due meanwhile. Each
        frame keeps its kernel receive time, so waiting here is not counted as link delay."""
        if scheduled:
            self._slow_pending = False
        queue = self._slow_queue
        stop = time.perf_counter() + SLOW_BUDGET_S
        while queue:
            data, addr, counted, rx_s = queue.popleft()
            self._route(data, addr, seq_counted=counted, rx_s=rx_s)
            if queue and time.perf_counter() >= stop:
                break
        if queue and not self._slow_pending:
            try:
                loop = asyncio.get_running_loop()
            except RuntimeError:  # no loop (a direct call): finish now
                self._route_slow()
                return
            self._slow_pending = True
            self._n["slow_deferred"] += 1
            # as a timer due now, not call_soon: timers that came due first (the tick's wake-up)
            # run before it, where a call_soon would run ahead of them
            loop.call_at(loop.time(), self._route_slow, True)

    def _route(self, data: bytes, addr: Address, seq_counted: bool = False,
               rx_s: float | None = None) -> None:
        runs = frame_sysids(data)
        if len(runs) == 1:
            sysid = runs[0][2]
            client = self._clients.get(sysid) if sysid is not None else None
            if client is not None:
                self._n["datagrams_routed"] += 1
                client._on_datagram(data, addr, seq_counted, rx_s)
                return
            if sysid is None:
                self._n["unframed_datagrams"] += 1
            self._foreign(data, addr, sysid)
            return
        self._n["split_datagrams"] += 1
        for start, end, sysid in runs:
            part = data[start:end]
            client = self._clients.get(sysid) if sysid is not None else None
            if client is not None:
                client._on_datagram(part, addr, seq_counted, rx_s)
            else:
                self._foreign(part, addr, sysid)

    def _foreign(self, data: bytes, addr: Address, sysid: int | None) -> None:
        if sysid in self._detached:
            self._n["after_detach"] += 1
            return
        single: Callable[[MAVLinkMessage, Address], None] | None = None
        if not self.shared and self._clients:
            single = next(iter(self._clients.values()))._on_foreign
        for msg in self._codec.feed(data):
            if self._tlog is not None:
                self._tlog.write(bytes(msg.get_msgbuf()))
            src = msg.get_srcSystem()
            self._n["unknown_sysid_frames"] += 1
            seen = self._unknown.get(src, 0)
            self._unknown[src] = seen + 1
            if seen == 0 and single is None:
                logger.warning("%s: messages from sysid %d (compid %d) at %s:%d, which no vehicle "
                               "on this port has (vehicles: sysids %s); counted and ignored",
                               self.name, src, msg.get_srcComponent(), addr[0], addr[1],
                               ", ".join(str(s) for s in self.sysids) or "none")
            if single is not None:
                single(msg, addr)
