"""VehicleProxy over real UDP on 127.0.0.1 against a pymavlink-encoding fake vehicle."""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from gcs.link.commands import CommandRejectedError, CommandTimeoutError
from gcs.link.config import VehicleLinkConfig
from gcs.link.enums import LandedState, LinkState, MavCmd, MavResult, Px4MainMode, px4_custom_mode
from gcs.link.proxy import VehicleProxy
from gcs.link.setpoints import SetpointError
from gcs.link.tlog import TlogWriter
from gcs.link.udp import Address, LinkClosedError
from tests.harness import UdpPeer, wait_until
from tests.harness import run_bounded as run

pytestmark = pytest.mark.integration

Msg = mavlink.MAVLink_message
AckPolicy = Callable[[Msg], int | None]  # COMMAND_LONG -> MAV_RESULT to answer, None: no answer
OFFBOARD = px4_custom_mode(Px4MainMode.OFFBOARD)
KEY = bytes(range(100, 132))


class ManualClock:
    def __init__(self, t_s: float = 100.0) -> None:
        self.t_s = t_s

    def now_s(self) -> float:
        return self.t_s


class FakeVehicle(UdpPeer):
    """A PX4-like peer written with plain pymavlink: answers COMMAND_LONG per ``ack_policy``,
    learns the GCS address from the first packet, records everything it receives."""

    def __init__(self, sysid: int = 1, ack_policy: AckPolicy = lambda m: MavResult.ACCEPTED,
                 signing_key: bytes | None = None) -> None:
        self.mav = mavlink.MAVLink(None, sysid, 1)
        if signing_key is not None:
            self.mav.signing.secret_key = signing_key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.timestamp = 1
        self.ack_policy = ack_policy
        self.received: list[Msg] = []
        self.gcs: Address | None = None

    @property
    def port(self) -> int:
        return self.address[1]

    def datagram_received(self, data: bytes, addr: Address) -> None:  # type: ignore[override]
        self.gcs = self.gcs or addr
        for msg in self.mav.parse_buffer(data) or []:
            self.received.append(msg)
            if msg.get_type() == "COMMAND_LONG":
                result = self.ack_policy(msg)
                if result is not None:
                    self.send(self.mav.command_ack_encode(msg.command, result, 0, 0,
                                                          msg.get_srcSystem(), 190))

    def send(self, msg: Msg, skip_seq: int = 0) -> None:
        assert self.transport is not None and self.gcs is not None
        self.mav.seq = (self.mav.seq + skip_seq) % 256
        self.transport.sendto(msg.pack(self.mav), self.gcs)
        self.mav.seq = (self.mav.seq + 1) % 256

    def heartbeat(self, armed: bool = True, custom_mode: int = OFFBOARD) -> None:
        self.send(self.mav.heartbeat_encode(2, 12, 1 | (128 if armed else 0), custom_mode, 4))

    def of_type(self, kind: str) -> list[Msg]:
        return [m for m in self.received if m.get_type() == kind]


def config(vehicle: FakeVehicle, **overrides: Any) -> VehicleLinkConfig:
    base = VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=0, remote_port=vehicle.port)
    return replace(base, **overrides)


async def connected(vehicle: FakeVehicle, proxy: VehicleProxy) -> None:
    """Wait until the vehicle heard the GCS (first HEARTBEAT) and the GCS heard the vehicle."""
    await wait_until(lambda: vehicle.gcs is not None)
    vehicle.heartbeat()
    await proxy.wait_heartbeat(timeout_s=2.0)


# --- heartbeat, state, lifetime ------------------------------------------------------------------


def test_gcs_heartbeat_and_vehicle_state() -> None:
    async def scenario() -> None:
        async with FakeVehicle() as vehicle:
            async with VehicleProxy(config(vehicle, heartbeat_period_s=0.05)) as proxy:
                await connected(vehicle, proxy)
                # THEN the GCS heartbeats periodically as a GCS with an invalid autopilot
                await wait_until(lambda: len(vehicle.of_type("HEARTBEAT")) >= 3)
                hb = vehicle.of_type("HEARTBEAT")[0]
                assert (hb.type, hb.autopilot, hb.get_srcSystem(), hb.get_srcComponent()) == \
                    (6, 8, 255, 190)
                state = proxy.state()
                assert state.armed and state.mode == "OFFBOARD" and state.sysid == 1
                assert proxy.link_state() == LinkState.ALIVE
            # AND after the context the socket is closed and no task is left
            with pytest.raises(LinkClosedError):
                _ = proxy.local_address
            assert all(t.done() for t in asyncio.all_tasks() if "vehicle 1" in t.get_name())

    run(scenario())


def test_latest_value_ages_and_loss_from_a_100hz_stream() -> None:
    # GIVEN a vehicle streaming LOCAL_POSITION_NED at 100 Hz with x = k, skipping a sequence
    # number before every 10th message (10 packets "lost")
    clock = ManualClock(100.0)

    async def scenario() -> None:
        async with FakeVehicle() as vehicle, VehicleProxy(config(vehicle), clock=clock) as proxy:
            await connected(vehicle, proxy)
            last = asyncio.create_task(proxy.wait_message(
                "LOCAL_POSITION_NED", 5.0, predicate=lambda m: m.x == 99.0))
            for k in range(100):
                vehicle.send(vehicle.mav.local_position_ned_encode(
                    k * 10, float(k), 0.5, -2.0, 1.0, 0.0, -0.5), skip_seq=int(k % 10 == 9))
                await asyncio.sleep(0.01)  # paces the 100 Hz stream, not a synchronisation
            received = await last
            clock.t_s = 100.25
            # THEN the cache holds the latest value, converted to ENU, with its age
            state = proxy.state()
            np.testing.assert_allclose(state.position_enu_m, [0.5, 99.0, 2.0])
            np.testing.assert_allclose(state.velocity_enu_mps, [0.0, 1.0, 0.5])
            assert received.rx_time_s == 100.0 and state.position_age_s == pytest.approx(0.25)
            stats = proxy.stats()
            assert stats.by_type["LOCAL_POSITION_NED"].count == 100
            assert (stats.sequence.lost, stats.sequence.received) == (10, 101)
            assert stats.codec.errors == 0

    run(scenario())


def test_link_lost_after_silence() -> None:
    clock = ManualClock(10.0)

    async def scenario() -> None:
        async with FakeVehicle() as vehicle:
            cfg = config(vehicle, link_timeout_s=0.2)
            async with VehicleProxy(cfg, clock=clock) as proxy:
                assert proxy.link_state() == LinkState.WAITING
                await connected(vehicle, proxy)
                assert proxy.link_state() == LinkState.ALIVE
                clock.t_s += 0.21
                assert proxy.link_state() == LinkState.LOST
                await wait_until(lambda: proxy.stats().proxy.link_lost_events == 1)

    run(scenario())


def test_sysid_mismatch_is_reported_and_ignored(caplog: pytest.LogCaptureFixture) -> None:
    async def scenario() -> None:
        async with FakeVehicle(sysid=7) as vehicle, VehicleProxy(config(vehicle)) as proxy:
            await wait_until(lambda: vehicle.gcs is not None)
            vehicle.heartbeat()
            await wait_until(lambda: proxy.sysid_mismatch == 7)
            assert proxy.latest("HEARTBEAT") is None
            assert proxy.link_state() == LinkState.WAITING
            assert proxy.stats().proxy.foreign_sysid == 1

    with caplog.at_level(logging.ERROR):
        run(scenario())
    assert "vehicle 1 (sysid 1): HEARTBEAT from sysid 7 (compid 1)" in caplog.text
    assert "expected sysid 1" in caplog.text


def test_learns_the_remote_from_the_first_valid_packet() -> None:
    async def scenario() -> None:
        async with FakeVehicle() as vehicle:
            cfg = config(vehicle, remote_port=None, learn_remote=True)
            async with VehicleProxy(cfg) as proxy:
                vehicle.gcs = proxy.local_address
                vehicle.heartbeat()
                await proxy.wait_heartbeat(timeout_s=2.0)
                assert proxy.remote == ("127.0.0.1", vehicle.port)
                assert await proxy.commands.arm() == MavResult.ACCEPTED

    run(scenario())


# --- commands ------------------------------------------------------------------------------------


def test_arm_sends_command_long_and_returns_the_ack() -> None:
    async def scenario() -> None:
        async with FakeVehicle() as vehicle, VehicleProxy(config(vehicle)) as proxy:
            await connected(vehicle, proxy)
            assert await proxy.commands.arm() == MavResult.ACCEPTED
            (cmd,) = vehicle.of_type("COMMAND_LONG")
            assert (cmd.command, cmd.param1, cmd.confirmation) == (400, 1.0, 0)
            assert (cmd.target_system, cmd.target_component) == (1, 1)

    run(scenario())


def test_dropped_first_ack_is_retried() -> None:
    async def scenario() -> None:
        policy: AckPolicy = lambda m: None if m.confirmation == 0 else MavResult.ACCEPTED  # noqa: E731
        async with FakeVehicle(ack_policy=policy) as vehicle, \
                VehicleProxy(config(vehicle)) as proxy:
            await connected(vehicle, proxy)
            assert await proxy.commands.disarm(force=True, timeout_s=0.3) == MavResult.ACCEPTED
            cmds = vehicle.of_type("COMMAND_LONG")
            assert [c.confirmation for c in cmds] == [0, 1]
            assert cmds[1].param2 == 21196.0
            assert proxy.stats().commands.retries == 1

    run(scenario())


def test_unanswered_command_times_out_naming_vehicle_and_command() -> None:
    async def scenario() -> None:
        async with FakeVehicle(ack_policy=lambda m: None) as vehicle, \
                VehicleProxy(config(vehicle)) as proxy:
            await connected(vehicle, proxy)
            with pytest.raises(CommandTimeoutError, match=(
                    r"vehicle 1 \(sysid 1\): MAV_CMD_NAV_LAND \(21\) got no COMMAND_ACK in 2 "
                    r"attempts of 0\.05 s")):
                await proxy.commands.land(timeout_s=0.05, retries=1)
            assert len(vehicle.of_type("COMMAND_LONG")) == 2

    run(scenario())


def test_rejection_and_mode_takeoff_interval_params() -> None:
    def policy(m: Msg) -> int:
        return MavResult.TEMPORARILY_REJECTED if m.command == MavCmd.DO_SET_MODE else 0

    async def scenario() -> None:
        async with FakeVehicle(ack_policy=policy) as vehicle, \
                VehicleProxy(config(vehicle)) as proxy:
            await connected(vehicle, proxy)  # the vehicle reports armed
            with pytest.raises(CommandRejectedError, match=(
                    r"vehicle 1 \(sysid 1\): MAV_CMD_DO_SET_MODE \(176\) answered "
                    r"TEMPORARILY_REJECTED")) as err:
                await proxy.commands.set_mode_px4(Px4MainMode.OFFBOARD)
            assert err.value.result == MavResult.TEMPORARILY_REJECTED
            assert await proxy.commands.set_mode_px4(6, check=False) == MavResult.TEMPORARILY_REJECTED
            await proxy.commands.takeoff(2.5)
            await proxy.commands.set_message_interval(32, 50.0)
            await proxy.commands.set_message_interval(331, 0.0)
            mode, _, takeoff, interval, off = vehicle.of_type("COMMAND_LONG")
            assert (mode.param1, mode.param2, mode.param3) == (129.0, 6.0, 0.0)
            assert takeoff.command == 22 and takeoff.param7 == 2.5 and math.isnan(takeoff.param4)
            assert (interval.param1, interval.param2) == (32.0, 20000.0)
            assert (off.param1, off.param2) == (331.0, -1.0)

    run(scenario())


# --- setpoints -----------------------------------------------------------------------------------


def test_setpoints_are_converted_checked_and_counted() -> None:
    async def scenario() -> None:
        async with FakeVehicle() as vehicle, VehicleProxy(config(vehicle)) as proxy:
            await connected(vehicle, proxy)
            proxy.setpoints.send_rates_thrust([0.1, 0.2, 0.3], 0.6)
            proxy.setpoints.send_rates_thrust(np.zeros(3), 1.4)  # clamped to 1
            proxy.setpoints.send_attitude_thrust(np.eye(3), 0.5)  # facing east
            proxy.setpoints.send_actuator_controls([0.5, 2.0, -0.1], 0.4)  # pitch torque clamped
            with pytest.raises(SetpointError, match=r"vehicle 1 \(sysid 1\): rates_flu_radps"):
                proxy.setpoints.send_rates_thrust([0.0, math.nan, 0.0], 0.5)
            with pytest.raises(SetpointError, match="thrust_norm: expected finite, got inf"):
                proxy.setpoints.send_rates_thrust([0.0, 0.0, 0.0], math.inf)
            with pytest.raises(SetpointError, match="not a rotation matrix"):
                proxy.setpoints.send_attitude_thrust(2.0 * np.eye(3), 0.5)
            await wait_until(lambda: len(vehicle.of_type("SET_ACTUATOR_CONTROL_TARGET")) == 1)
            rates, clamped, att = vehicle.of_type("SET_ATTITUDE_TARGET")
            assert rates.type_mask == 128
            assert (rates.target_system, rates.target_component) == (1, 1)
            np.testing.assert_allclose(
                [rates.body_roll_rate, rates.body_pitch_rate, rates.body_yaw_rate, rates.thrust],
                [0.1, -0.2, -0.3, 0.6], rtol=1e-6)
            assert clamped.thrust == 1.0
            assert att.type_mask == 7
            np.testing.assert_allclose(att.q, [math.sqrt(0.5), 0, 0, math.sqrt(0.5)], atol=1e-7)
            (act,) = vehicle.of_type("SET_ACTUATOR_CONTROL_TARGET")
            assert act.group_mlx == 0
            np.testing.assert_allclose(act.controls, [0.5, -1.0, 0.1, 0.4, 0, 0, 0, 0], atol=1e-7)
            counters = proxy.stats().proxy
            assert (counters.setpoints_sent, counters.setpoints_rejected) == (4, 3)
            assert (counters.thrust_clamped, counters.torque_clamped) == (1, 1)

    run(scenario())


# --- signing and tlog ----------------------------------------------------------------------------


def test_signed_link_end_to_end() -> None:
    async def scenario() -> None:
        async with FakeVehicle(signing_key=KEY) as vehicle, \
                VehicleProxy(config(vehicle, signing_key=KEY)) as proxy:
            await connected(vehicle, proxy)
            assert await proxy.commands.arm() == MavResult.ACCEPTED
            assert vehicle.mav.signing.goodsig_count >= 2  # our HEARTBEAT and COMMAND_LONG
            assert all(m._signed for m in vehicle.received)
            # WHEN the vehicle stops signing THEN its packets are rejected and counted
            vehicle.mav.signing.sign_outgoing = False
            vehicle.heartbeat()
            await wait_until(lambda: proxy.stats().codec.unsigned_rejected == 1)

    run(scenario())


def test_tlog_records_both_directions(tmp_path: Path) -> None:
    path = tmp_path / "flight.tlog"

    async def scenario() -> None:
        with TlogWriter(path) as tlog:
            async with FakeVehicle() as vehicle, \
                    VehicleProxy(config(vehicle), tlog=tlog) as proxy:
                await connected(vehicle, proxy)
                await proxy.commands.arm()
                vehicle.send(vehicle.mav.extended_sys_state_encode(0, LandedState.ON_GROUND))
                await proxy.wait_message("EXTENDED_SYS_STATE", 2.0)

    run(scenario())
    log = mavutil.mavlink_connection(str(path))
    seen: list[tuple[str, int]] = []
    while (msg := log.recv_msg()) is not None:
        seen.append((msg.get_type(), msg.get_srcSystem()))
    log.close()
    assert seen[0] == ("HEARTBEAT", 255)
    for item in [("HEARTBEAT", 1), ("COMMAND_LONG", 255), ("COMMAND_ACK", 1),
                 ("EXTENDED_SYS_STATE", 1)]:
        assert item in seen
