"""The agents' bus on real Zenoh sessions over TCP (and UDP) on 127.0.0.1, on free ports picked per test:
samples cross with their values and times, the latest wins, losses and corrupt bytes are
counted, a non-neighbour's key is never subscribed, sessions meet only by their endpoints,
clock offsets, the supervisor's side, and an agent in another process.

Every wait is a condition with a deadline (generous: a busy 2-core machine), never a sleep."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest
import zenoh

from gcs.agent.bus import STATE_LANES, NeighbourBus
from gcs.agent.control import Abort
from gcs.agent.session import BusError, Endpoints, zenoh_config
from gcs.agent.supervisor import SupervisorBus
from gcs.agent.table import CHECK_EXCHANGES
from gcs.agent.wire import SUPERVISOR_ID, StateSample, encode
from gcs.config.modes import ClockMode, FlyAction, NetworkMode
from gcs.config.network_schema import AgentNetwork, NetworkConfig, SupervisorNetwork
from tests.harness import run_bounded, wait_until

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
TEAM, IDS = "ring", (1, 2, 3, 4)
NEIGHBOURS = {1: {2, 4}, 2: {1, 3}, 3: {2, 4}, 4: {3, 1}}  # the ring 1-2-3-4-1
WAIT_S = 30.0  # any one condition
TEST_S = 120.0  # a whole test
STATE = {"position_enu_m": (1.0, 2.0, 3.0), "velocity_enu_mps": (0.1, 0.2, 0.3),
         "acceleration_enu_mps2": (0.0, 0.0, 0.5), "attitude_wxyz": (0.5, 0.5, 0.5, 0.5),
         "omega_flu_radps": (0.01, 0.02, 0.03)}


def free_ports(n: int, kind: socket.SocketKind = socket.SOCK_STREAM) -> list[int]:
    """n distinct TCP (`kind` SOCK_DGRAM: UDP) ports free on 127.0.0.1 now (held open
    together while picked)."""
    with contextlib.ExitStack() as stack:
        socks = [stack.enter_context(socket.socket(socket.AF_INET, kind)) for _ in range(n)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]


def tcp(port: int) -> str:
    return f"tcp/127.0.0.1:{port}"


def mixed_udp(port: int) -> str:
    """A UDP endpoint carrying reliable messages on QUIC streams and best-effort ones as
    datagrams (Zenoh's `rel=1;mixed_rel=1` link metadata)."""
    return f"udp/127.0.0.1:{port}?rel=1;mixed_rel=1"


def ring_network(endpoint: Callable[[int], str] = tcp, **changes: object) -> NetworkConfig:
    """The ring's network on free ports (`endpoint` of a port), under a key prefix of its
    own."""
    ports = free_ports(len(IDS) + 1, socket.SOCK_STREAM if endpoint is tcp
                       else socket.SOCK_DGRAM)
    fields = {"key_prefix": f"test/{uuid.uuid4().hex[:12]}",
              "agents": tuple(AgentNetwork(vid, (endpoint(ports[vid]),)) for vid in IDS),
              "supervisor": SupervisorNetwork((endpoint(ports[0]),))}
    return NetworkConfig(**(fields | changes))


def agent(network: NetworkConfig, vid: int, **kwargs: object) -> NeighbourBus:
    return NeighbourBus(network, TEAM, IDS, [vid], NEIGHBOURS[vid], **kwargs)


@contextlib.asynccontextmanager
async def raw_session(connect: list[str], listen: tuple[str, ...] = ()
                      ) -> AsyncIterator[zenoh.Session]:
    """A bare Zenoh session (the test's own peer, no bus) meeting only `connect`."""
    config = zenoh_config(Endpoints(NetworkMode.PEER, listen, tuple(connect), False))
    session = await asyncio.to_thread(zenoh.open, config)
    try:
        yield session
    finally:
        await asyncio.to_thread(session.close)


@contextlib.asynccontextmanager
async def publishing(publish: Callable[[], object], period_s: float = 0.01
                     ) -> AsyncIterator[None]:
    """Call `publish` every `period_s` while the block runs."""
    async def loop() -> None:
        while True:
            publish()
            await asyncio.sleep(period_s)

    task = asyncio.create_task(loop())
    try:
        yield
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


def sample(vid: int, seq: int, x: float = 0.0) -> bytes:
    return encode(StateSample(vid, 1, seq, 0.0, 0.0, (x, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3,
                              (1.0, 0.0, 0.0, 0.0), (0.0,) * 3))


def test_a_sample_crosses_with_its_values_and_its_time():
    async def scenario() -> None:
        network = ring_network()
        async with agent(network, 1) as one, agent(network, 2) as two:
            # WHEN both publish their state (each echoes the other's: the clock offsets),
            # vehicle 2's taken 5 ms before each send
            def send() -> None:
                one.publish(1, time.monotonic(), **STATE)
                two.publish(2, time.monotonic() - 0.005, **STATE)

            async with publishing(send):
                await wait_until(lambda: one.rows([2], time.monotonic()).finite[0], WAIT_S)
            # THEN vehicle 1 has it, in its own clock, with an echo-measured offset
            now = time.monotonic()
            rows = one.rows([2, 4], now)
            assert rows.finite.tolist() == [True, False]
            assert rows.position_enu_m[0].tolist() == [1.0, 2.0, 3.0]
            assert rows.velocity_enu_mps[0].tolist() == [0.1, 0.2, 0.3]
            assert rows.acceleration_enu_mps2[0].tolist() == [0.0, 0.0, 0.5]
            assert rows.attitude_wxyz[0].tolist() == [0.5, 0.5, 0.5, 0.5]
            assert rows.omega_flu_radps[0].tolist() == [0.01, 0.02, 0.03]
            latest = one.table.latest(2)
            assert rows.taken_local_s[0] == pytest.approx(latest.taken_s - one.offset(2))
            assert latest.sent_s - latest.taken_s == pytest.approx(0.005, abs=1e-3)
            assert 0.0 < rows.age_s[0] < 5.0 and rows.received_s[0] <= now
            assert rows.received_s[0] - latest.sent_s < 5.0
            # AND the stats name both neighbours; nothing was corrupt
            stats = one.stats()
            assert set(stats) == {2, 4} and stats[2].received >= 1 and stats[2].corrupt == 0
            assert stats[4].received == 0 and one.publisher_matched(1)

    run_bounded(scenario(), TEST_S)


def test_the_latest_wins_and_gaps_duplicates_and_corrupt_bytes_are_counted():
    async def scenario() -> None:
        network = ring_network()
        async with agent(network, 1) as one, raw_session(list(network.agent_listen(1))) as raw:
            pub = raw.declare_publisher(one.keys.state(2))
            # GIVEN the test's session knows vehicle 1 subscribes to vehicle 2's key
            await wait_until(lambda: pub.matching_status.matching, WAIT_S)
            # WHEN it sends seq 10, 11, 15, 12 (older), 15 (again), garbage, a sample with a
            # wrong magic, one of vehicle 4 on 2's key, then 16
            for data in (sample(2, 10), sample(2, 11), sample(2, 15, x=15.0), sample(2, 12),
                         sample(2, 15), b"garbage", b"XMST" + sample(2, 17)[4:], sample(4, 18),
                         sample(2, 16, x=16.0)):
                pub.put(data)
            await wait_until(lambda: one.table.latest(2) is not None
                             and one.table.latest(2).seq == 16, WAIT_S)
            # THEN 16 is held, 4 + 3 lost between 11 and 15 (the first sets the count going),
            # 2 duplicates, 3 corrupt with the last reason; nothing raised
            f = one.stats()[2]
            assert one.table.latest(2).position_enu_m[0] == 16.0
            assert (f.received, f.lost, f.duplicates, f.corrupt) == (4, 3, 2, 3)
            assert f.corrupt_reason == "vehicle id 4 on the key of vehicle 2"
            assert f.loss_fraction == pytest.approx(3 / 7)

    run_bounded(scenario(), TEST_S)


def test_a_non_neighbours_key_is_never_subscribed():
    async def scenario() -> None:
        network = ring_network()
        async with agent(network, 1) as one, raw_session(list(network.agent_listen(1))) as raw:
            to_2 = raw.declare_publisher(one.keys.state(2))
            to_3 = raw.declare_publisher(one.keys.state(3))
            # GIVEN the test's session learnt vehicle 1's subscriptions (2 matches) ...
            await wait_until(lambda: to_2.matching_status.matching, WAIT_S)
            # ... WHEN it sends vehicle 2's and vehicle 3's samples until 2's have arrived
            seq = iter(range(10**6))

            def send() -> None:
                k = next(seq)
                to_2.put(sample(2, k))
                to_3.put(sample(3, k))

            async with publishing(send):
                await wait_until(lambda: one.stats()[2].received >= 20, WAIT_S)
            # THEN nobody subscribes to 3's key, and vehicle 1 knows no vehicle 3
            assert not to_3.matching_status.matching
            assert set(one.stats()) == {2, 4} and 3 not in one.table.senders
            with pytest.raises(KeyError, match="vehicle 3 is not heard here"):
                one.rows([3], time.monotonic())

    run_bounded(scenario(), TEST_S)


def test_without_endpoints_or_multicast_two_sessions_never_meet():
    async def scenario() -> None:
        p1, p2 = (tcp(p) for p in free_ports(2))
        key = f"test/{uuid.uuid4().hex[:12]}/state/1"
        heard: dict[str, set[bytes]] = {"a": set(), "b": set(), "c": set()}

        def recorder(name: str) -> Callable[[zenoh.Sample], None]:
            return lambda s: heard[name].add(s.payload.to_bytes())

        # GIVEN two peers, each listening on its own port, connecting to nothing, no scouting
        async with raw_session([], (p1,)) as a, raw_session([], (p2,)) as b:
            a.declare_subscriber(key, recorder("a"))
            b.declare_subscriber(key, recorder("b"))
            pa, pb = a.declare_publisher(key), b.declare_publisher(key)
            # AND a third that connects to the first (the control: meeting is possible)
            async with raw_session([p1]) as c:
                c.declare_subscriber(key, recorder("c"))
                # WHEN the first two publish until the third has heard the first
                async with publishing(lambda: (pa.put(b"from a"), pb.put(b"from b"))):
                    await wait_until(lambda: b"from a" in heard["c"], WAIT_S)
                    # THEN the first two are not connected; the first and third are
                    assert not b.info.peers_zid()
                    assert [str(z) for z in a.info.peers_zid()] == [str(c.zid())]
        # AND each of the first two heard only itself (Zenoh's local delivery), the third only
        # the first
        assert heard == {"a": {b"from a"}, "b": {b"from b"}, "c": {b"from a"}}

    run_bounded(scenario(), TEST_S)


async def exchange_until(one: NeighbourBus, two: NeighbourBus, exchanges: int) -> None:
    """Vehicles 1 and 2 publish every 10 ms until each has `exchanges` clock exchanges with
    the other in its window."""
    def send() -> None:
        one.publish(1, one.clock(), **STATE)
        two.publish(2, two.clock(), **STATE)

    async with publishing(send):
        await wait_until(lambda: one.table.clock(2).samples >= exchanges
                         and two.table.clock(1).samples >= exchanges, WAIT_S)


def test_clock_offsets_on_one_machine_and_between_shifted_clocks():
    async def scenario() -> None:
        network = ring_network()
        # GIVEN two agents on this machine's monotonic clock
        async with agent(network, 1) as one, agent(network, 2) as two:
            await exchange_until(one, two, 40)
            # THEN each measures the other's offset as 0 within 2 ms, inside its uncertainty
            for bus, peer in ((one, 2), (two, 1)):
                f = bus.stats()[peer]
                assert abs(f.offset_s) < 0.002, f
                assert abs(f.offset_s) <= f.uncertainty_s + 1e-9, f
        # GIVEN vehicle 2's clock 7.5 s ahead of vehicle 1's (another host's)
        network = ring_network()
        shifted = lambda: time.monotonic() + 7.5  # noqa: E731
        async with agent(network, 1) as one, agent(network, 2, clock=shifted) as two:
            await exchange_until(one, two, 40)
            # THEN 1 measures +7.5 s, 2 measures -7.5 s, and 2's sample times land on 1's clock
            assert one.offset(2) == pytest.approx(7.5, abs=0.002)
            assert two.offset(1) == pytest.approx(-7.5, abs=0.002)
            rows = one.rows([2], time.monotonic())
            assert rows.taken_local_s[0] == pytest.approx(one.table.latest(2).taken_s - 7.5,
                                                          abs=0.002)
            assert 0.0 <= rows.age_s[0] < 5.0
        # AND with clocks one-host the same shift goes uncorrected
        network = ring_network(clocks=ClockMode.ONE_HOST)
        async with agent(network, 1) as one, agent(network, 2, clock=shifted) as two:
            await exchange_until(one, two, 5)
            f = one.stats()[2]
            assert one.offset(2) == 0.0 and abs(f.offset_s - 7.5) <= f.uncertainty_s + 1e-9
            assert one.rows([2], time.monotonic()).age_s[0] < -7.0

    run_bounded(scenario(), TEST_S)


def test_disciplined_clocks_carry_the_system_clock_and_a_skewed_one_is_refused():
    async def scenario() -> None:
        # GIVEN vehicle 2's monotonic clock 7.5 s ahead of vehicle 1's (another host's boot)
        # and both hosts' system clocks disciplined: the one system clock of this machine
        shifted = lambda: time.monotonic() + 7.5  # noqa: E731
        network = ring_network(clocks=ClockMode.DISCIPLINED)
        async with agent(network, 1) as one, agent(network, 2, clock=shifted) as two:
            await exchange_until(one, two, CHECK_EXCHANGES)
            # THEN 2's sample times land on 1's monotonic clock through the system clocks,
            # with no offset estimated for it, and the echoes find the clocks within 2 ms
            assert one.offset(2) == 0.0 and one.table.clock_known(2)
            assert abs(one.table.clock(2).median_offset_s) < 0.002
            latest = one.table.latest(2)
            rows = one.rows([2], time.monotonic())
            assert rows.taken_local_s[0] == pytest.approx(
                latest.taken_s - (time.time() - time.monotonic()), abs=0.002)
            assert 0.0 <= rows.age_s[0] < 1.0
        # GIVEN vehicle 2's system clock 40 ms ahead though clocks are called disciplined
        network = ring_network(clocks=ClockMode.DISCIPLINED)
        skewed = lambda: time.time() + 0.040  # noqa: E731
        async with agent(network, 1) as one, agent(network, 2, system_clock=skewed) as two:
            await exchange_until(one, two, CHECK_EXCHANGES)
            # THEN each names the other's clock, and neither gives the other's samples a time
            assert "vehicle 2's clock is at least 3" in one.table.clock_problem(2)
            assert "ahead of ours" in one.table.clock_problem(2)
            assert "vehicle 1's clock is at least 3" in two.table.clock_problem(1)
            assert "behind ours" in two.table.clock_problem(1)
            assert one.offset(2) is None and not one.rows([2], time.monotonic()).finite[0]

    run_bounded(scenario(), TEST_S)


def test_the_supervisor_hears_every_vehicle_and_steers_the_agents():
    async def scenario() -> None:
        network = ring_network()
        sup = SupervisorBus(network, TEAM, IDS)
        async with sup, agent(network, 1) as one, agent(network, 2) as two, \
                raw_session(list(network.supervisor_listen())) as raw, asyncio.TaskGroup() as tg:
            beat = tg.create_task(sup.beat(0.05))

            def send() -> None:
                one.publish(1, time.monotonic(), **STATE)
                two.publish(2, time.monotonic(), **STATE)

            async with publishing(send):
                # WHEN the agents publish and the supervisor beats THEN it has both rows on its
                # clock (offsets from the heartbeats' echoes), and the agents its offset
                await wait_until(lambda: sup.rows([1, 2], time.monotonic()).finite.all()
                                 and one.offset(SUPERVISOR_ID) is not None, WAIT_S)
                rows = sup.rows(list(IDS), time.monotonic())
                assert rows.finite.tolist() == [True, True, False, False]
                assert rows.fresh(network.stale_after_s).tolist() == [True, True, False, False]
                # (one clock: each offset is 0 within its uncertainty, which early on, with few
                # exchanges on a busy machine, can be several ms)
                for bus, peer in ((sup, 1), (sup, 2), (one, SUPERVISOR_ID)):
                    clock = bus.table.clock(peer)
                    assert abs(clock.offset_s) <= clock.uncertainty_s + 1e-9, (peer, clock.best)
                assert not one.supervisor_lost(time.monotonic())
                # AND a status reaches it with the agent's edge figures
                one.publish_status(1, "hold", waiting_gate="formation")
                await wait_until(lambda: 1 in sup.statuses, WAIT_S)
                status = sup.statuses[1]
                assert (status.phase, status.waiting_gate, status.outcome) == (
                    "hold", "formation", None)
                assert [e.neighbour_id for e in status.edges] == [2, 4]
                assert status.edges[0].received >= 1 and (await sup.status_updates.get()) == status
                # WHEN the supervisor opens a gate THEN each agent gets it once, though every
                # heartbeat repeats it
                gate = sup.open_gate("formation")
                assert await asyncio.wait_for(one.control.get(), WAIT_S) == gate
                later = time.monotonic() + 0.3
                await wait_until(lambda: one.table.last_heard_s(SUPERVISOR_ID) > later, WAIT_S)
                assert one.control.empty() and one.gates == {"formation": gate.opened_s}
                assert two.gates == {"formation": gate.opened_s}
                # AND an abort reaches both, once, after the gate
                sent = sup.abort("operator", FlyAction.HOLD)
                assert await asyncio.wait_for(two.control.get(), WAIT_S) == gate
                for bus in (one, two):
                    order = await asyncio.wait_for(bus.control.get(), WAIT_S)
                    assert isinstance(order, Abort) and order == sent
                later = time.monotonic() + 0.3
                await wait_until(lambda: two.table.last_heard_s(SUPERVISOR_ID) > later, WAIT_S)
                assert one.control.empty() and two.control.empty()
                assert two.abort_order == sent and sup.heartbeat().abort_reason == "operator"
            # AND bytes on the team's keys from no vehicle, or no status, are counted
            raw.put(sup.keys.state(99), sample(99, 0))
            raw.put(sup.keys.status(1), b"{not json")
            await wait_until(lambda: sup.strangers >= 1 and sup.status_corrupt[1] >= 1, WAIT_S)
            assert sup.stranger_key == sup.keys.state(99)
            assert sup.status_corrupt_reason[1].startswith("not a JSON object")
            beat.cancel()

    run_bounded(scenario(), TEST_S)


def test_over_a_mixed_udp_link_states_go_best_effort_and_control_reliable():
    async def scenario() -> None:
        # GIVEN the ring over UDP endpoints with mixed reliability
        network = ring_network(mixed_udp)
        sup = SupervisorBus(network, TEAM, IDS)
        async with sup, agent(network, 1) as one, agent(network, 2) as two, \
                asyncio.TaskGroup() as tg:
            beat = tg.create_task(sup.beat(0.05))
            # THEN each own state is published best effort (a lost one is never resent ahead
            # of the next), every status and heartbeat reliably
            assert one.reliabilities() == {one.keys.state(1): zenoh.Reliability.BEST_EFFORT,
                                           one.keys.status(1): zenoh.Reliability.RELIABLE}
            assert sup.reliabilities() == {sup.keys.supervisor: zenoh.Reliability.RELIABLE}

            def send() -> None:
                one.publish(1, time.monotonic(), **STATE)
                two.publish(2, time.monotonic(), **STATE)

            # AND samples, statuses and gates cross the link
            async with publishing(send):
                await wait_until(lambda: one.rows([2], time.monotonic()).finite[0]
                                 and sup.rows([1, 2], time.monotonic()).finite.all(), WAIT_S)
                one.publish_status(1, "hold", waiting_gate="formation")
                await wait_until(lambda: 1 in sup.statuses, WAIT_S)
                gate = sup.open_gate("formation")
                assert await asyncio.wait_for(one.control.get(), WAIT_S) == gate
            assert one.stats()[2].corrupt == 0 and sup.statuses[1].phase == "hold"
            beat.cancel()

    run_bounded(scenario(), TEST_S)


def test_an_agent_of_several_vehicles_puts_each_state_on_a_priority_of_its_own():
    async def scenario() -> None:
        # GIVEN an agent of vehicles 1 and 3 and one of 2 and 4, over mixed UDP
        network = ring_network(mixed_udp)
        odd = NeighbourBus(network, TEAM, IDS, [1, 3], [2, 4])
        even = NeighbourBus(network, TEAM, IDS, [2, 4], [1, 3])
        async with odd, even:
            # THEN each own vehicle's state has a priority of its own, the first the one a
            # single vehicle's agent uses (a best-effort message is dropped when it arrives
            # after a newer one of its priority: two states sent together and swapped by the
            # network must not be one priority)
            lanes = STATE_LANES
            assert len({int(p) for p in lanes}) == len(lanes) == 4
            assert lanes[0] == zenoh.Priority.DATA_HIGH
            priorities = odd.priorities()
            assert (priorities[odd.keys.state(1)], priorities[odd.keys.state(3)]) == lanes[:2]
            assert odd.reliabilities()[odd.keys.state(3)] == zenoh.Reliability.BEST_EFFORT

            def send() -> None:
                for bus, ids in ((odd, (1, 3)), (even, (2, 4))):
                    for vid in ids:
                        bus.publish(vid, time.monotonic(), **STATE)

            # AND the states of both priorities arrive, each vehicle's in its own row
            async with publishing(send):
                await wait_until(lambda: odd.rows([2, 4], time.monotonic()).finite.all()
                                 and even.rows([1, 3], time.monotonic()).finite.all(), WAIT_S)

    run_bounded(scenario(), TEST_S)


def test_an_agent_in_another_process_exchanges_samples_and_clocks():
    async def scenario() -> None:
        network = ring_network()
        spec = {"network": {"key_prefix": network.key_prefix,
                            "agents": {str(v): list(network.agent_listen(v)) for v in IDS},
                            "supervisor": list(network.supervisor_listen())},
                "team": TEAM, "ids": list(IDS), "own": 2, "neighbours": [1], "rate_hz": 50,
                "seconds": TEST_S}
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT),
                                                            os.environ.get("PYTHONPATH", "")])}
        # GIVEN vehicle 2's agent in its own process, publishing at 50 Hz
        proc = await asyncio.create_subprocess_exec(
            sys.executable, str(ROOT / "tests" / "integration" / "agent_peer.py"),
            json.dumps(spec), stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)
        try:
            async with agent(network, 1) as one:
                # WHEN vehicle 1 publishes here at 50 Hz
                async with publishing(lambda: one.publish(1, time.monotonic(), **STATE), 0.02):
                    await wait_until(lambda: one.stats()[2].received >= 50
                                     and one.table.clock(2).samples >= 40, WAIT_S * 2)
                # THEN 2's samples arrive in order, with 2's clock measured as this one's
                f = one.stats()[2]
                assert (f.corrupt, f.duplicates, f.restarts) == (0, 0, 0)
                assert abs(f.offset_s) < 0.002, f
                latest = one.table.latest(2)
                assert latest.vehicle_id == 2 and latest.position_enu_m[1:] == (1.0, 2.0)
                assert one.rows([2], time.monotonic()).finite[0]
            # AND the other process heard vehicle 1 (it prints its figures when told to stop)
            proc.stdin.close()
            out, _ = await asyncio.wait_for(proc.communicate(), WAIT_S)
            lines = out.decode().splitlines()
            assert lines[0] == "agent_peer: ready" and json.loads(lines[-1])["1"]["received"] >= 1
            assert await proc.wait() == 0
        finally:
            if proc.returncode is None:
                proc.kill()
                await proc.wait()

    run_bounded(scenario(), TEST_S * 2)


def test_an_endpoint_in_use_is_a_bus_error_naming_it():
    async def scenario() -> None:
        with socket.socket() as taken:
            taken.bind(("127.0.0.1", 0))
            taken.listen()
            port = taken.getsockname()[1]
            network = ring_network(agents=(AgentNetwork(1, (tcp(port),)),))
            with pytest.raises(BusError, match=rf"the Zenoh session does not open \(peer mode, "
                                                rf"listen tcp/127\.0\.0\.1:{port}, .*Address "
                                                rf"already in use"):
                async with agent(network, 1):
                    pass

    run_bounded(scenario(), TEST_S)
