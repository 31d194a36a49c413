"""LinkPoller on real UDP sockets: bulk reads deliver what one callback per datagram would, in
order, through the batch decoder or pymavlink's parser."""

from __future__ import annotations

import asyncio
import math
import socket
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from tests.harness import run_bounded, wait_until
from vehicle_emulator.config.faults import LinkImpairment
from vehicle_emulator.mavlink.server import LinkPoller, UdpLink

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


def test_a_tick_that_falls_due_during_a_batch_runs_before_the_rest_of_it():
    """The fleet's tick comes first: a burst of datagrams (a 240-vehicle setpoint burst is ~3 ms
    of work) is delivered with the ticks that fall due meanwhile run between its datagrams, not
    after the whole batch with the telemetry that late."""
    from vehicle_emulator.config.team import parse_team
    from vehicle_emulator.fleet.runner import Emulator, LinkPlan, RunStats, _Pace

    class SteppedClock:  # simulated time: 1 ms passes for every message the vehicle handles
        t_s = 0.0

        def now_s(self) -> float:
            return self.t_s

        async def sleep_until(self, t_s: float) -> None:
            self.t_s = max(self.t_s, t_s)

    async def scenario(tick_first: bool) -> tuple[list[int], int]:
        team = parse_team({"vehicles": [{"id": 1, "initial": {"position_enu_m": [0, 0, 10]}}]})
        emu = Emulator(list(team.vehicles), tick_s=0.002)
        clock = SteppedClock()
        await emu.open_links([LinkPlan(("127.0.0.1", 0), ("127.0.0.1", 9), None, None)], clock)
        handled = [0]
        ticks_at: list[int] = []  # messages handled before each tick
        on_messages, advance_to = emu.on_messages, emu.advance_to

        def handle(node, link, msgs, addr):
            on_messages(node, link, msgs, addr)
            handled[0] += len(msgs)
            clock.t_s += 1e-3 * len(msgs)

        def tick(t_s):
            ticks_at.append(handled[0])
            return advance_to(t_s)

        emu.on_messages, emu.advance_to = handle, tick  # type: ignore[method-assign]
        pace = _Pace(emu, clock, RunStats())
        assert emu.poller is not None
        emu.poller.between = pace.tick_if_due if tick_first else None
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            port = emu.links[0].local_address[1]
            pace.tick_if_due()  # the tick at t = 0
            # GIVEN 40 messages waiting in the vehicle's socket (HEARTBEATs: each is handled;
            # a burst of setpoints would be one, the newest)
            for _ in range(40):
                gcs.sendto(_frame(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)),
                           ("127.0.0.1", port))
            await asyncio.sleep(0.05)
            # WHEN the poller reads and delivers them
            for _ in range(40):
                if handled[0] >= 40:
                    break
                emu.poller._ready()
            pace.tick_if_due()  # and the loop's own tick comes after
            return ticks_at, handled[0]
        finally:
            gcs.close()
            emu.close_links()

    ticks_at, handled = run_bounded(scenario(True), 20.0)
    # THEN all 40 were handled, and a tick ran every 2 ms of it, between the datagrams
    assert handled == 40
    assert ticks_at[0] == 0 and len(ticks_at) == 21
    assert all(b - a == 2 for a, b in zip(ticks_at[1:], ticks_at[2:], strict=False))
    # while without the hook no tick ran until the poller had delivered everything
    ticks_at, handled = run_bounded(scenario(False), 20.0)
    assert handled == 40 and ticks_at == [0, 40]


def test_a_backlog_of_setpoints_is_read_at_once_and_only_the_newest_handled():
    """Latest wins: setpoints that queued up in a socket (a fleet that fell behind) are read in
    one wake-up; each stream's newest is handled, the ones it replaces only counted, and every
    other message is handled in order."""
    async def scenario() -> None:
        got: list[tuple[str, float]] = []

        def on_messages(link, msgs, addr):
            got.extend((m.get_type(), getattr(m, "thrust", getattr(m, "x", 0.0))) for m in msgs)

        loop = asyncio.get_running_loop()
        link = await UdpLink.open(("127.0.0.1", 0), ("127.0.0.1", 9),
                                  LinkImpairment(np.random.default_rng(0)), loop.time,
                                  on_messages, name="v1")
        poller = LinkPoller()
        poller.attach(link)
        # the loop may wake the poller itself during the wait below: with the time to read all
        poller.read_budget_s = 10.0
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        gcs.bind(("127.0.0.1", 0))
        try:
            where = ("127.0.0.1", link.local_address[1])

            def attitude(thrust, component=1):
                return _frame(mavlink.MAVLink_set_attitude_target_message(
                    0, 1, component, 128, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, thrust))

            def position(x):
                return _frame(mavlink.MAVLink_set_position_target_local_ned_message(
                    0, 1, 1, 1, 0b110111111000, x, 0.0, -10.0, 0, 0, 0, 0, 0, 0, 0, 0))

            hb = _frame(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3))
            # GIVEN 100 attitude setpoints (thrust 0.300 .. 0.399), a heartbeat among them,
            # two position targets, and one attitude setpoint to another component, all
            # waiting in the socket before the poller looks
            for k in range(100):
                gcs.sendto(attitude(0.3 + 0.001 * k), where)
                if k == 50:
                    gcs.sendto(hb, where)
                    gcs.sendto(position(1.0), where)
                    gcs.sendto(attitude(0.9, component=2), where)
            gcs.sendto(position(2.0), where)
            await asyncio.sleep(0.1)
            # WHEN the poller wakes up once (here, or during the wait)
            poller._ready()
            # THEN all 104 datagrams were read; the newest of each stream was handled, in
            # arrival order, with the heartbeat and the other component's setpoint
            assert poller.datagrams == 104 and poller.deepest == 104
            assert [kind for kind, _ in got] == ["HEARTBEAT", "SET_ATTITUDE_TARGET",
                                                "SET_ATTITUDE_TARGET",
                                                "SET_POSITION_TARGET_LOCAL_NED"]
            assert got[1][1] == pytest.approx(0.9)  # component 2's own
            assert got[2][1] == pytest.approx(0.399)  # the newest to component 1
            assert got[3][1] == pytest.approx(2.0)
            # AND the replaced ones were counted, not lost: 99 + 1 setpoints superseded
            assert link.superseded == 100
            assert link.decoder.stats.datagrams == 104 and link.decoder.stats.rejected == 0
        finally:
            gcs.close()
            poller.close()
            link.close()

    run_bounded(scenario(), 20.0)


def test_a_wake_up_delivers_what_it_read_within_its_budget_while_the_input_keeps_coming():
    """A ground station that keeps sending faster than a busy fleet reads (one datagram a round,
    the tick between rounds) must not hold what was read, a TIMESYNC request first of all,
    until it stops: the wake-up delivers after its read budget and the next one reads on."""
    async def scenario(budget_s: float) -> tuple[int, int, list[str]]:
        got: list[str] = []
        loop = asyncio.get_running_loop()
        link = await UdpLink.open(("127.0.0.1", 0), ("127.0.0.1", 9),
                                  LinkImpairment(np.random.default_rng(0)), loop.time,
                                  lambda lk, msgs, addr: got.extend(m.get_type() for m in msgs),
                                  name="v1")
        poller = LinkPoller()
        poller.attach(link)
        poller.read_budget_s = budget_s
        where = ("127.0.0.1", link.local_address[1])
        timesync = _frame(mavlink.MAVLink_timesync_message(0, 12345))
        setpoints = [_frame(mavlink.MAVLink_set_attitude_target_message(
            0, 1, 1, 128, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.5)) for _ in range(300)]
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        pending = iter(setpoints)

        def tick() -> None:
            # a fleet tick that takes 2 ms, during which the ground station sends two more
            # setpoints (one a millisecond): sent here, in step with the rounds, the input
            # outpaces the reads however busy the machine is (a loopback datagram is in the
            # socket when sendto returns)
            for data in (next(pending, None), next(pending, None)):
                if data is not None:
                    gcs.sendto(data, where)
            time.sleep(0.002)

        poller.between = tick
        try:
            # GIVEN the request, then the first two setpoints, waiting
            gcs.sendto(timesync, where)
            tick()
            assert poller._epoll.poll(5.0), "nothing arrived"
            # WHEN the poller wakes up once while the stream goes on
            poller._ready()
            return poller.datagrams, poller.budget_stops, list(got)
        finally:
            gcs.close()
            poller.close()
            link.close()

    # THEN, with the budget, it read a few datagrams, stopped at the budget and delivered them,
    # the TIMESYNC request first
    read, stops, got = run_bounded(scenario(0.005), 20.0)
    assert stops == 1 and 1 <= read <= 20
    assert got[0] == "TIMESYNC"
    # while a wake-up without one read on until the ground station stopped sending, holding
    # the request all that time
    read, stops, got = run_bounded(scenario(math.inf), 20.0)
    assert stops == 0 and read == 301
    assert got[0] == "TIMESYNC"
