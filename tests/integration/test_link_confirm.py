"""Commands confirmed by what the vehicle reports: `VehicleProxy.command_confirmed` over real UDP
against real `vehicle-emu` processes (px4: PX4 v1.16.0's two ACKs per DO_SET_MODE; ardupilot),
and against a scripted peer for a vehicle that acknowledges a mode it never shows."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from pathlib import Path
from typing import Any

import pytest

from gcs.link import CommandNotConfirmedError, CommandRejectedError, VehicleLinkConfig, VehicleProxy
from gcs.link.enums import MavCmd, MavModeFlag, MavResult, mode_name, px4_custom_mode
from tests.harness import run_emulator

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]

OFFBOARD, HOLD = px4_custom_mode(6), px4_custom_mode(4, 3)
GUIDED_NOGPS = 20


def run(coro: Coroutine[Any, Any, Any], timeout_s: float = 60.0) -> Any:
    async def bounded() -> Any:
        async with asyncio.timeout(timeout_s):
            return await coro
    return asyncio.run(bounded())


def reported(hb: Any) -> str:
    if hb is None:
        return "nothing"
    armed = "armed" if hb.base_mode & MavModeFlag.SAFETY_ARMED else "disarmed"
    return f"{mode_name(hb.autopilot, hb.custom_mode)}, {armed}"


async def set_mode(proxy: VehicleProxy, custom_mode: int, params: list[float], name: str,
                   timeout_s: float = 3.0) -> tuple[MavResult, ...]:
    return await proxy.commands.command_confirmed(
        MavCmd.DO_SET_MODE, params, want=f"mode {name}",
        shows=lambda hb: int(hb.custom_mode) == custom_mode, reported=reported,
        timeout_s=timeout_s)


def on_emulator(tmp: Path, *args: str, scenario: Callable[[VehicleProxy], Awaitable[None]]
                ) -> None:
    """Run `scenario(proxy)` with a proxy linked to `vehicle-emu --id 1 ARGS` once it is heard."""
    with run_emulator(["--id", "1", *args], log_dir=str(tmp)) as emu:
        cfg = VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=emu.remote_port,
                                remote_port=emu.bind_port)

        async def linked() -> None:
            async with VehicleProxy(cfg) as proxy:
                await heard(proxy)
                await scenario(proxy)

        run(linked())


async def heard(proxy: VehicleProxy) -> None:
    async with asyncio.timeout(30.0):
        while proxy.latest("HEARTBEAT") is None:
            await proxy.wait_message("HEARTBEAT", 30.0)


def test_px4_refusal_after_accepted_wins_and_a_shown_mode_is_confirmed(tmp_path: Path) -> None:
    # GIVEN the px4 personality holding in the air (armed), no offboard setpoint ever sent
    async def scenario(proxy: VehicleProxy) -> None:
        # WHEN OFFBOARD is asked: PX4 v1.16.0 answers ACCEPTED, then TEMPORARILY_REJECTED
        with pytest.raises(CommandRejectedError) as err:
            await set_mode(proxy, OFFBOARD, [129.0, 6.0, 0.0], "OFFBOARD")
        # THEN the refusal wins, and the message names vehicle, mode, report, ACKs, text
        assert err.value.result == MavResult.TEMPORARILY_REJECTED
        assert err.value.acks == (MavResult.ACCEPTED, MavResult.TEMPORARILY_REJECTED)
        assert str(err.value) == (
            "vehicle 1 (sysid 1): MAV_CMD_DO_SET_MODE (176) for mode OFFBOARD refused: "
            "HEARTBEAT reports AUTO_LOITER, armed; COMMAND_ACKs seen: ACCEPTED, "
            "TEMPORARILY_REJECTED; the vehicle said CRITICAL \"Switching to Offboard is "
            "currently not available\"")
        # AND with setpoints streamed (20 Hz, as a ground station does: a single one would let
        # PX4's COM_OF_LOSS_T failsafe, 1 s, race its 1 Hz HEARTBEAT), OFFBOARD is confirmed by
        # a HEARTBEAT showing it
        async def stream() -> None:
            while True:
                proxy.setpoints.send_rates_thrust([0.0, 0.0, 0.0], 0.5)
                await asyncio.sleep(0.05)

        setpoints = asyncio.create_task(stream())
        await asyncio.sleep(0.1)
        acks = await set_mode(proxy, OFFBOARD, [129.0, 6.0, 0.0], "OFFBOARD")
        assert acks == (MavResult.ACCEPTED, MavResult.ACCEPTED)
        assert proxy.state().mode == "OFFBOARD"
        # back to Hold (confirmed), so the vehicle is not left without setpoints
        await set_mode(proxy, HOLD, [129.0, 4.0, 3.0], "AUTO_LOITER")
        setpoints.cancel()
        assert proxy.state().mode == "AUTO_LOITER"
        assert proxy.stats().commands.acks_unexpected == 0

    on_emulator(tmp_path, "--in-air", "--autopilot", "px4", scenario=scenario)


def test_ardupilot_single_ack_mode_change_is_confirmed_by_heartbeat(tmp_path: Path) -> None:
    # GIVEN the ardupilot personality on the ground, booted at once, on a bound port
    async def scenario(proxy: VehicleProxy) -> None:
        acks = await set_mode(proxy, GUIDED_NOGPS, [1.0, 20.0], "GUIDED_NOGPS")
        assert acks == (MavResult.ACCEPTED,)
        assert proxy.state().mode == "GUIDED_NOGPS"
        # a mode the vehicle refuses (FAILED) names its STATUSTEXT
        with pytest.raises(CommandRejectedError, match=(
                r"for mode RTL refused: HEARTBEAT reports GUIDED_NOGPS, disarmed; "
                r"COMMAND_ACKs seen: FAILED; the vehicle said WARNING \"Mode change to "
                r"RTL failed: not emulated\"$")):
            await set_mode(proxy, 6, [1.0, 6.0], "RTL")

    on_emulator(tmp_path, "--autopilot", "ardupilot", "--param", "EMU_BOOT_SCALE=0",
                scenario=scenario)


class SilentModePeer(asyncio.DatagramProtocol):
    """A vehicle that ACKs every command ACCEPTED (twice, as PX4 v1.16.0) and keeps reporting
    Hold in its HEARTBEAT: it never shows the mode it accepted."""

    def __init__(self) -> None:
        from pymavlink.dialects.v20 import common as mavlink

        self.mav = mavlink.MAVLink(None, 1, 1)
        self.transport: asyncio.DatagramTransport | None = None
        self.gcs: tuple[str, int] | None = None

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:  # type: ignore[override]
        assert self.transport is not None
        self.gcs = addr
        for msg in self.mav.parse_buffer(data) or []:
            if msg.get_type() == "COMMAND_LONG":
                for _ in range(2):
                    self.transport.sendto(self.mav.command_ack_encode(
                        msg.command, 0, 0, 0, msg.get_srcSystem(), 190).pack(self.mav), addr)

    def heartbeat(self) -> None:
        if self.transport is not None and self.gcs is not None:
            self.transport.sendto(self.mav.heartbeat_encode(2, 12, 129, HOLD, 4).pack(self.mav),
                                  self.gcs)


@contextlib.asynccontextmanager
async def linked_to(peer: SilentModePeer) -> AsyncIterator[VehicleProxy]:
    """A proxy (vehicle 3, sysid 1) linked to the scripted `peer` over real UDP, the peer's
    HEARTBEAT beating at 10 Hz, once it is heard."""
    loop = asyncio.get_running_loop()
    transport, _ = await loop.create_datagram_endpoint(lambda: peer, local_addr=("127.0.0.1", 0))
    peer.transport = transport
    port = int(transport.get_extra_info("sockname")[1])
    cfg = VehicleLinkConfig(vehicle_id=3, sysid=1, local_port=0, remote_port=port,
                            heartbeat_period_s=0.05)

    async def beat() -> None:
        while True:
            peer.heartbeat()
            await asyncio.sleep(0.1)

    try:
        async with VehicleProxy(cfg) as proxy, asyncio.TaskGroup() as tg:
            task = tg.create_task(beat())
            await heard(proxy)
            try:
                yield proxy
            finally:
                task.cancel()
    finally:
        transport.close()


def test_a_mode_acknowledged_but_never_shown_is_not_confirmed() -> None:
    async def scenario() -> None:
        async with linked_to(SilentModePeer()) as proxy:
            with pytest.raises(CommandNotConfirmedError) as err:
                await set_mode(proxy, OFFBOARD, [129.0, 6.0, 0.0], "OFFBOARD", timeout_s=0.5)
            assert str(err.value) == (
                "vehicle 3 (sysid 1): mode OFFBOARD not confirmed within 0.5 s: HEARTBEAT "
                "reports AUTO_LOITER, armed; COMMAND_ACKs seen: ACCEPTED, ACCEPTED")
            assert err.value.acks == (MavResult.ACCEPTED, MavResult.ACCEPTED)

    run(scenario())


class LossyModePeer(SilentModePeer):
    """Takes the mode it is asked for (its HEARTBEAT shows it), but the link loses every HEARTBEAT
    for `mute_s` after each command (a lossy radio); `mute_s` None: it falls silent for good."""

    def __init__(self, mute_s: float | None) -> None:
        super().__init__()
        self.mute_s = mute_s
        self.custom_mode = HOLD
        self.muted_until = 0.0

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:  # type: ignore[override]
        for msg in self.mav.parse_buffer(bytes(data)) or []:
            if msg.get_type() == "COMMAND_LONG":
                self.custom_mode = px4_custom_mode(int(msg.param2), int(msg.param3))
                now = asyncio.get_running_loop().time()
                self.muted_until = now + self.mute_s if self.mute_s is not None else float("inf")
        # the ACKs (and the GCS's address) as the silent peer does; the bytes are parsed again
        super().datagram_received(data, addr)

    def heartbeat(self) -> None:
        if self.transport is None or self.gcs is None:
            return
        if asyncio.get_running_loop().time() < self.muted_until:
            return  # lost on the way
        self.transport.sendto(self.mav.heartbeat_encode(2, 12, 129, self.custom_mode, 4).pack(
            self.mav), self.gcs)


@pytest.mark.parametrize("mute_s", [0.9, None])
def test_heartbeats_lost_after_the_ack_extend_the_wait_and_silence_is_named(mute_s) -> None:
    # GIVEN a vehicle that switches to OFFBOARD when asked, behind a link that loses its
    # HEARTBEATs for 0.9 s after the command (or for good); the timeout is 0.5 s
    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        async with linked_to(LossyModePeer(mute_s)) as proxy:
            t0 = loop.time()
            if mute_s is not None:
                # THEN no HEARTBEAT said otherwise, so the wait went on past 0.5 s, and the
                # first one that got through confirmed the mode
                acks = await set_mode(proxy, OFFBOARD, [129.0, 6.0, 0.0], "OFFBOARD",
                                      timeout_s=0.5)
                assert acks == (MavResult.ACCEPTED, MavResult.ACCEPTED)
                assert 0.85 <= loop.time() - t0 <= 1.4
                assert proxy.state().mode == "OFFBOARD"
            else:
                # THEN a vehicle heard no more is not confirmed after 3 x the timeout, and the
                # message says nothing was heard
                with pytest.raises(CommandNotConfirmedError) as err:
                    await set_mode(proxy, OFFBOARD, [129.0, 6.0, 0.0], "OFFBOARD",
                                   timeout_s=0.5)
                assert 1.5 <= loop.time() - t0 <= 2.2
                assert str(err.value) == (
                    "vehicle 3 (sysid 1): mode OFFBOARD not confirmed within 1.5 s (0 "
                    "HEARTBEATs heard after the ACK): HEARTBEAT reports AUTO_LOITER, armed; "
                    "COMMAND_ACKs seen: ACCEPTED, ACCEPTED")

    run(scenario())
