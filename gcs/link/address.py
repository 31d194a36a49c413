"""One vehicle's address: configured, or learned from its first message; strangers and foreigners.

`VehicleAddress` is the proxy's view of where its vehicle is: a fixed remote accepts the
vehicle's messages from any address; with ``learn_remote`` the source of the first valid message
with the vehicle's sysid/compid becomes its address (MAVProxy's ``udpin``), and later messages
with its ids from another address are counted (``stranger_address``), logged once per address
(up to `MAX_STRANGERS_LOGGED`) and dropped. It also counts valid messages of another sysid
(``foreign_sysid``) and reports a vehicle HEARTBEAT with another sysid as a sysid mismatch. Logs
as the proxy. No I/O.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from gcs.link.codec import MAVLinkMessage
from gcs.link.enums import MavType
from gcs.link.udp import Address

logger = logging.getLogger("gcs.link.proxy")  # the records of the proxy this serves

#: Stranger addresses logged per vehicle (all are counted); a flood does not flood the log.
MAX_STRANGERS_LOGGED = 8
#: The counters `VehicleAddress.counts` returns (fields of the proxy's ProxyCounters).
ADDRESS_COUNTERS = ("foreign_sysid", "stranger_address")


class VehicleAddress:
    """Where vehicle ``name`` (``sysid``) is. ``remote``: the configured address (None: not
    known yet); ``learn_remote``: take the source of its first valid message as its address;
    ``on_learn`` is called with the address once it is learned."""

    def __init__(self, name: str, sysid: int, remote: Address | None, *, learn_remote: bool,
                 on_learn: Callable[[Address], None] | None = None) -> None:
        self._name = name
        self._sysid = sysid
        self._remote = remote
        self._learn_remote = learn_remote
        self._on_learn = on_learn
        self._learned = False
        self._strangers: set[Address] = set()
        self._mismatch: int | None = None
        self._n = dict.fromkeys(ADDRESS_COUNTERS, 0)

    @property
    def remote(self) -> Address | None:
        """Where packets for the vehicle go (None until learned on a link without a fixed one)."""
        return self._remote

    @property
    def learned(self) -> bool:
        return self._learned

    @property
    def mismatch(self) -> int | None:
        """The sysid of the latest foreign vehicle HEARTBEAT `foreign` saw (None: none)."""
        return self._mismatch

    def counts(self) -> dict[str, int]:
        """The counters of `ADDRESS_COUNTERS`, by name."""
        return dict(self._n)

    def accepts(self, addr: Address) -> bool:
        """A valid message with the vehicle's sysid/compid came from ``addr``: learn ``addr``
        if it is the first (with ``learn_remote``); False, counted and logged, if the address
        is learned and ``addr`` is another."""
        if self._learned:
            if addr != self._remote:
                self._stranger(addr)
                return False
        elif self._learn_remote:
            self._learn(addr)
        return True

    def foreign(self, msg: MAVLinkMessage, addr: Address) -> None:
        """A valid message of another sysid from ``addr``: counted (``foreign_sysid``); a
        vehicle's HEARTBEAT (not a ground station's) is reported as a sysid mismatch."""
        self._n["foreign_sysid"] += 1
        if msg.get_type() == "HEARTBEAT" and msg.type != MavType.GCS:
            self._report_mismatch(msg.get_srcSystem(), msg.get_srcComponent(), addr)

    def _learn(self, addr: Address) -> None:
        same = " (the configured one)" if addr == self._remote else ""
        logger.info("%s: address learned from its first message: %s:%d%s", self._name, *addr,
                    same)
        self._remote = addr
        self._learned = True
        if self._on_learn is not None:
            self._on_learn(addr)

    def _stranger(self, addr: Address) -> None:
        self._n["stranger_address"] += 1
        if addr not in self._strangers and len(self._strangers) < MAX_STRANGERS_LOGGED:
            self._strangers.add(addr)
            assert self._remote is not None
            logger.warning(
                "%s: messages with its sysid %d from %s:%d, but its address is %s:%d (learned "
                "from its first message); ignored and counted (stranger_address)", self._name,
                self._sysid, addr[0], addr[1], self._remote[0], self._remote[1])

    def _report_mismatch(self, src_sys: int, src_comp: int, addr: Address) -> None:
        if self._mismatch != src_sys:
            logger.error(
                "%s: HEARTBEAT from sysid %d (compid %d) at %s:%d, expected sysid %d; check the "
                "team file. Messages from sysid %d are ignored.", self._name, src_sys, src_comp,
                addr[0], addr[1], self._sysid, src_sys)
        self._mismatch = src_sys
