"""Links as real vehicles use them, on real 127.0.0.1 UDP: addresses learned from the first valid
packet (ArduPilot's ephemeral source port, MAVProxy's udpin), several vehicles on one GCS port
demultiplexed by sysid (mavlink-router / MAVProxy --out), bad input counted; against real
`vehicle-emu` processes of both personalities and small pymavlink peers for the bad input."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.link import MavlinkPort, VehicleLinkConfig, VehicleProxy
from gcs.link.commands import CommandRejectedError
from gcs.link.enums import LinkState, MavResult
from gcs.link.udp import Address
from tests.harness import (
    EmulatorProcess,
    UdpPeer,
    free_udp_port,
    run_bounded,
    run_emulator,
    wait_until,
)

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

ESS_ID, TIMESYNC_ID = 245, 111


class Peer(UdpPeer):
    """A vehicle (or a stranger) written with plain pymavlink on its own ephemeral port: sends
    to the GCS port it is given, records what it receives, acknowledges every COMMAND_LONG."""

    def __init__(self, sysid: int) -> None:
        self.mav = mavlink.MAVLink(None, sysid, 1)
        self.received: list[mavlink.MAVLink_message] = []
        self.gcs: Address | None = None

    def datagram_received(self, data: bytes, addr: Address) -> None:  # type: ignore[override]
        for msg in self.mav.parse_buffer(data) or []:
            self.received.append(msg)
            if msg.get_type() == "COMMAND_LONG":
                self.send_raw(self.mav.command_ack_encode(
                    msg.command, MavResult.ACCEPTED, 0, 0, 255, 190).pack(self.mav))

    def packet(self, armed: bool = False) -> bytes:
        return self.mav.heartbeat_encode(2, 12, 1 | (128 if armed else 0), 0, 3).pack(self.mav)

    def send_raw(self, data: bytes) -> None:
        assert self.transport is not None and self.gcs is not None
        self.transport.sendto(data, self.gcs)

    def heartbeat(self, armed: bool = False) -> None:
        self.send_raw(self.packet(armed))

    def commands(self) -> list[mavlink.MAVLink_message]:
        return [m for m in self.received if m.get_type() == "COMMAND_LONG"]


def learned(vehicle_id: int, sysid: int | None = None, **kw: Any) -> VehicleLinkConfig:
    """A link that learns the vehicle's address (no configured remote)."""
    return VehicleLinkConfig(vehicle_id=vehicle_id, sysid=sysid or vehicle_id, local_port=0,
                             remote_port=None, learn_remote=True, **kw)


# --- one port, several vehicles (pymavlink peers) --------------------------------------------------


def test_one_port_serves_three_vehicles_each_at_its_own_learned_address(
        caplog: pytest.LogCaptureFixture) -> None:
    async def scenario() -> None:
        # GIVEN one GCS port shared by three vehicles whose addresses are not configured
        async with MavlinkPort(0) as port, contextlib.AsyncExitStack() as stack:
            proxies = [await stack.enter_async_context(VehicleProxy(learned(k), port=port))
                       for k in (1, 2, 3)]
            peers = [await stack.enter_async_context(Peer(k)) for k in (1, 2, 3)]
            # THEN nothing can be sent before a vehicle is heard (counted, not an error)
            assert all(p.remote is None for p in proxies)
            # WHEN each vehicle sends from its own ephemeral port to the one GCS port
            for peer in peers:
                peer.gcs = port.local_address
                peer.heartbeat()
            for proxy in proxies:
                await proxy.wait_heartbeat(timeout_s=2.0)
            # THEN each proxy learned its own vehicle's address
            assert [p.remote for p in proxies] == [peer.address for peer in peers]
            assert all(p.remote_learned and p.port.shared for p in proxies)
            # AND a command to each reaches that vehicle only, and is acknowledged by it
            for proxy in proxies:
                assert await proxy.commands.arm() == MavResult.ACCEPTED
            for k, peer in enumerate(peers, start=1):
                (cmd,) = peer.commands()
                assert (cmd.command, cmd.target_system) == (400, k)
                assert {m.get_type() for m in peer.received} <= {"HEARTBEAT", "COMMAND_LONG"}
            assert port.stats().datagrams_routed == 6  # 3 HEARTBEATs + 3 ACKs, one peek each
            assert proxies[0].stats().proxy.send_no_remote >= 1  # its first GCS HEARTBEAT

    with caplog.at_level(logging.INFO):
        run_bounded(scenario(), timeout_s=60.0)
    assert "vehicle 2 (sysid 2): address learned from its first message" in caplog.text


def test_unknown_sysid_on_a_shared_port_is_counted_logged_once_and_ignored(
        caplog: pytest.LogCaptureFixture) -> None:
    async def scenario() -> None:
        async with MavlinkPort(0) as port, contextlib.AsyncExitStack() as stack:
            proxies = [await stack.enter_async_context(VehicleProxy(learned(k), port=port))
                       for k in (1, 2)]
            one, stranger = [await stack.enter_async_context(Peer(s)) for s in (1, 9)]
            one.gcs = stranger.gcs = port.local_address
            # WHEN a system no vehicle of the team has (sysid 9) sends three HEARTBEATs
            for _ in range(3):
                stranger.heartbeat()
            one.heartbeat()
            await proxies[0].wait_heartbeat(timeout_s=2.0)
            await wait_until(lambda: port.stats().unknown_sysid_frames == 3)
            # THEN they are counted per sysid and go to no vehicle
            assert port.unknown_sysids() == {9: 3}
            assert proxies[1].latest("HEARTBEAT") is None
            assert proxies[1].link_state() == LinkState.WAITING
            # AND on a shared port a stranger is no reason to refuse a vehicle that is heard;
            # one not heard names it (connect diagnostics: "only sysid 9 was heard there")
            assert proxies[0].sysid_mismatch is None and proxies[1].sysid_mismatch == 9
            assert stranger.commands() == []

    with caplog.at_level(logging.WARNING):
        run_bounded(scenario(), timeout_s=60.0)
    lines = [r.getMessage() for r in caplog.records if "sysid 9" in r.getMessage()]
    assert len(lines) == 1, lines
    assert "messages from sysid 9 (compid 1)" in lines[0]
    assert "which no vehicle on this port has (vehicles: sysids 1, 2); counted and ignored" \
        in lines[0]


def test_a_stranger_address_on_a_learned_link_is_counted_and_ignored(
        caplog: pytest.LogCaptureFixture) -> None:
    async def scenario() -> None:
        async with VehicleProxy(learned(1)) as proxy, Peer(1) as vehicle, Peer(1) as impostor:
            vehicle.gcs = impostor.gcs = proxy.local_address
            # GIVEN a link that learned vehicle 1's address from its first (disarmed) HEARTBEAT
            vehicle.heartbeat(armed=False)
            await proxy.wait_heartbeat(timeout_s=2.0)
            # WHEN another address sends HEARTBEATs with vehicle 1's sysid, saying armed
            for _ in range(2):
                impostor.heartbeat(armed=True)
            await wait_until(lambda: proxy.stats().proxy.stranger_address == 2)
            # THEN they change nothing: the address, the state, the count of accepted messages
            assert proxy.remote == vehicle.address
            assert not proxy.state().armed
            assert proxy.stats().proxy.messages_accepted == 1
            # AND commands still go to the vehicle, not to the impostor
            assert await proxy.commands.arm() == MavResult.ACCEPTED
            assert len(vehicle.commands()) == 1 and impostor.commands() == []

    with caplog.at_level(logging.WARNING):
        run_bounded(scenario(), timeout_s=60.0)
    warnings = [r.getMessage() for r in caplog.records if "stranger_address" in r.getMessage()]
    assert len(warnings) == 1  # once per address
    assert warnings[0].startswith("vehicle 1 (sysid 1): messages with its sysid 1 from 127.0.0.1:")


def test_corrupt_batched_and_unframed_datagrams_on_a_shared_port() -> None:
    async def scenario() -> None:
        async with MavlinkPort(0) as port, contextlib.AsyncExitStack() as stack:
            proxies = [await stack.enter_async_context(VehicleProxy(learned(k), port=port))
                       for k in (1, 2)]
            a, b = [await stack.enter_async_context(Peer(s)) for s in (1, 2)]
            router = await stack.enter_async_context(Peer(99))  # sends others' frames
            for p in (a, b, router):
                p.gcs = port.local_address
            # WHEN a router batches frames of vehicles 1 and 2 into one datagram
            router.send_raw(a.packet() + b.packet() + a.packet())
            await wait_until(lambda: all(p.stats().proxy.messages_accepted >= 1 for p in proxies))
            # THEN each vehicle got its own frames, from the router's address
            assert [p.stats().proxy.messages_accepted for p in proxies] == [2, 1]
            assert proxies[0].remote == proxies[1].remote == router.address
            assert port.stats().split_datagrams == 1
            # AND a frame of vehicle 2 with a bad checksum is counted by vehicle 2's codec
            bad = bytearray(b.packet())
            bad[-1] ^= 0xFF
            b.send_raw(bytes(bad))
            await wait_until(lambda: proxies[1].stats().codec.bad_crc == 1)
            # AND a plain-text datagram (ArduPilot's boot banner) is counted by the port
            banner = b"Init ArduCopter V4.7.0-dev (90700977)\n"
            b.send_raw(banner)
            await wait_until(lambda: port.stats().unframed_datagrams == 1)
            assert port.codec_stats().garbage_bytes == len(banner)
            assert [p.stats().proxy.messages_accepted for p in proxies] == [2, 1]

    run_bounded(scenario(), timeout_s=60.0)


# --- real emulators: both personalities on one GCS port -------------------------------------------


@contextlib.contextmanager
def emulators_on(port: int, tmp: Path, personalities: list[str]) -> Iterator[list[EmulatorProcess]]:
    """`vehicle-emu --id k` per personality, all sending to 127.0.0.1:port; ardupilot ones from
    their ephemeral port (as SITL), px4 ones from a bound port (as SITL)."""
    with contextlib.ExitStack() as stack:
        emus = []
        for k, autopilot in enumerate(personalities, start=1):
            log_dir = tmp / f"emu{k}"
            log_dir.mkdir()
            # (ArduPilot: its boot banner before the first packet, EMU_BANNER's default)
            boot = ["--param", "EMU_BOOT_SCALE=0"] if autopilot == "ardupilot" else []
            emus.append(stack.enter_context(run_emulator(
                ["--id", str(k), "--autopilot", autopilot, *boot],
                remote_port=port, log_dir=str(log_dir), bind=autopilot == "px4")))
        yield emus


def test_both_personalities_on_one_port_are_learned_and_their_streams_requested(
        tmp_path: Path) -> None:
    gcs_port = free_udp_port()
    personalities = ["ardupilot", "px4", "ardupilot"]

    async def scenario() -> list[tuple[str, int] | None]:
        async with MavlinkPort(gcs_port) as port, contextlib.AsyncExitStack() as stack:
            proxies = [await stack.enter_async_context(VehicleProxy(learned(k), port=port))
                       for k in (1, 2, 3)]
            for proxy in proxies:
                await proxy.wait_heartbeat(timeout_s=60.0)
            # WHEN the GCS asks each vehicle for EXTENDED_SYS_STATE at 5 Hz
            for proxy in proxies:
                assert await proxy.commands.set_message_interval(ESS_ID, 5.0) == MavResult.ACCEPTED
            # THEN each one's stream arrives (ArduPilot sends it only when asked)
            for proxy in proxies:
                await proxy.wait_message("EXTENDED_SYS_STATE", timeout_s=5.0)
            # AND ArduPilot's refusal of a message it has no ap_message for names both
            with pytest.raises(CommandRejectedError, match=(
                    r"^vehicle 3 \(sysid 3\): stream TIMESYNC \(111\) at 1 Hz: "
                    r"SET_MESSAGE_INTERVAL answered DENIED$")):
                await proxies[2].commands.set_message_interval(TIMESYNC_ID, 1.0)
            assert port.stats().unknown_sysid_frames == 0
            return [p.remote for p in proxies]

    with emulators_on(gcs_port, tmp_path, personalities) as emus:
        remotes = run_bounded(scenario(), timeout_s=100.0)
        logs = [e.log_text() for e in emus]
    # THEN the px4 vehicle was answered at its bound port, the ardupilot ones at their ephemeral
    # ports (each process got its own, which its log names)
    assert remotes[1] == ("127.0.0.1", emus[1].bind_port)
    for k in (0, 2):
        assert remotes[k] is not None and remotes[k] != remotes[1]
        assert f":{remotes[k][1]}" in logs[k], logs[k][-2000:]
    assert len(set(remotes)) == 3


def test_timesync_round_trips_are_measured_on_px4_whose_replies_carry_newer_fields(
        tmp_path: Path) -> None:
    # GIVEN a px4 and an ardupilot vehicle on one GCS port; PX4 v1.16.0 answers TIMESYNC with
    # the newer 18-byte message (two target bytes it leaves unset), ArduPilot with 16 bytes
    gcs_port = free_udp_port()

    async def scenario() -> list[Any]:
        async with MavlinkPort(gcs_port) as port, contextlib.AsyncExitStack() as stack:
            proxies = [await stack.enter_async_context(VehicleProxy(learned(k), port=port))
                       for k in (1, 2)]
            for proxy in proxies:
                await proxy.wait_heartbeat(timeout_s=60.0)
            # WHEN the ground station's TIMESYNC requests (every 0.5 s) run for a while
            await wait_until(lambda: all(p.stats().proxy.timesync_replies >= 4 for p in proxies),
                             timeout_s=30.0)
            return [p.stats() for p in proxies]

    with emulators_on(gcs_port, tmp_path, ["px4", "ardupilot"]):
        px4, ardupilot = run_bounded(scenario(), timeout_s=100.0)
    # THEN both links time their round trips, px4's replies read past their newer fields
    assert px4.codec.newer_fields >= 4 and px4.codec.bad_length == 0
    assert ardupilot.codec.newer_fields == 0 and ardupilot.codec.bad_length == 0


# --- liveness ---------------------------------------------------------------------------------------


def test_a_heartbeat_only_vehicle_stays_up_and_a_silent_one_is_lost_within_link_timeout(
        tmp_path: Path) -> None:
    # GIVEN an ArduPilot vehicle as it boots: nothing but its 1 Hz HEARTBEAT (and a TIMESYNC
    # every 10 s) until a ground station asks for streams; the default link timeout (3 s)
    gcs_port = free_udp_port()
    cfg = learned(1)
    assert cfg.link_timeout_s == 3.0

    async def scenario(emu: EmulatorProcess) -> tuple[list[LinkState], float, float]:
        loop = asyncio.get_running_loop()
        async with MavlinkPort(gcs_port) as port, VehicleProxy(cfg, port=port) as proxy:
            await proxy.wait_heartbeat(timeout_s=60.0)
            # WHEN it is watched for 4.5 s (four beats)
            states, end = [], loop.time() + 4.5
            while loop.time() < end:
                states.append(proxy.link_state())
                await asyncio.sleep(0.02)
            beats = proxy.stats().by_type["HEARTBEAT"].count
            # AND WHEN the vehicle goes silent (its process killed)
            await asyncio.to_thread(emu.proc.kill)
            last_rx = max(t.last_rx_s for t in proxy.stats().by_type.values())  # any message
            await wait_until(lambda: proxy.link_state() == LinkState.LOST, timeout_s=10.0)
            detected = time.monotonic()
            assert proxy.stats().proxy.link_lost_events <= 1
            return states, detected - last_rx, beats

    with emulators_on(gcs_port, tmp_path, ["ardupilot"]) as (emu,):
        states, silent_s, beats = run_bounded(scenario(emu), timeout_s=90.0)
    # THEN the link never flapped while only HEARTBEATs came (4-6 of them)
    assert 4 <= beats <= 6, beats
    assert set(states) == {LinkState.ALIVE}
    # AND the silence was detected link_timeout_s after the last message (any type), not later
    assert 3.0 <= silent_s <= 3.5, silent_s
