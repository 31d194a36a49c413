"""LinkPoller on real UDP sockets: bulk reads deliver what one callback per datagram would, in
order, through the batch decoder or pymavlink's parser."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from vehicle_emulator.faults import LinkImpairment
from vehicle_emulator.server import LinkPoller, UdpLink
from vehicle_emulator.testing import run_bounded, wait_until

pytestmark = [pytest.mark.integration, pytest.mark.timeout(60)]

GCS = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)


def _frame(msg) -> bytes:
    data = msg.pack(GCS)
    GCS.seq = (GCS.seq + 1) & 0xFF
    return data


def test_poller_delivers_hot_and_other_datagrams_in_order_and_joins_split_frames():
    async def scenario() -> None:
        got: dict[str, list] = {"a": [], "b": []}

        def recorder(key):
            def on_messages(link, msgs, addr):
                got[key].extend(m.get_type() for m in msgs)
            return on_messages

        loop = asyncio.get_running_loop()
        links = {}
        for key in ("a", "b"):
            links[key] = await UdpLink.open(
                ("127.0.0.1", 0), ("127.0.0.1", 9), LinkImpairment(np.random.default_rng(0)),
                loop.time, recorder(key), name=key)
        poller = LinkPoller()
        for link in links.values():
            poller.attach(link)
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        gcs.bind(("127.0.0.1", 0))
        try:
            # GIVEN a ground station sending from one port to both links
            sat = _frame(mavlink.MAVLink_set_attitude_target_message(
                0, 1, 1, 128, [1.0, 0.0, 0.0, 0.0], 0.1, 0.2, 0.3, 0.5))
            cmd = _frame(mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
            hb = _frame(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            a, b = (("127.0.0.1", lk.local_address[1]) for lk in (links["a"], links["b"]))
            # WHEN a gets setpoint, command, setpoint + heartbeat, and b one frame split over
            # two datagrams, then a whole one
            for data, addr in ((sat, a), (cmd, a), (sat + hb, a), (sat[:15], b), (sat[15:], b),
                               (sat, b)):
                gcs.sendto(data, addr)
            await wait_until(lambda: len(got["a"]) == 4 and len(got["b"]) == 2, 5.0)
            # THEN each link got its messages in the order sent, the split one joined
            assert got["a"] == ["SET_ATTITUDE_TARGET", "COMMAND_LONG", "SET_ATTITUDE_TARGET",
                                "HEARTBEAT"]
            assert got["b"] == ["SET_ATTITUDE_TARGET", "SET_ATTITUDE_TARGET"]
            # AND counted as pymavlink's path counts, following the sender as PX4 does
            st = links["a"].decoder.stats
            assert (st.datagrams, st.messages, st.rejected) == (3, 4, 0)
            assert links["a"].remote == gcs.getsockname()
            # AND sends go straight out
            links["a"].send(b"hello")
            gcs.settimeout(2.0)
            assert gcs.recvfrom(100)[0] == b"hello"
        finally:
            gcs.close()
            poller.close()
            for link in links.values():
                link.close()

    run_bounded(scenario(), 20.0)
