"""MAVSDK (mavsdk 4.x, ``mavsdk.asyncio``) as a real third-party client of vehicle-emu.

MAVSDK listens on 127.0.0.1:PORT (``udpin://``); the emulator sends there, so all traffic stays
on the loopback interface.
"""

from __future__ import annotations

import asyncio

import pytest

from vehicle_emulator.testing import free_udp_port, hover_thrust, run_emulator

mavsdk_asyncio = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import OffboardAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.autopilot import Autopilot  # noqa: E402
from mavsdk.plugins.offboard import AttitudeRate, OffboardError  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode  # noqa: E402

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


async def _first(agen, timeout_s: float, cond=lambda x: True):
    async def go():
        async for item in agen:
            if cond(item):
                return item
        raise AssertionError("stream ended")

    return await asyncio.wait_for(go(), timeout_s)


async def _fly(port: int) -> dict:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    out: dict = {}
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=60.0)
        assert system is not None, "MAVSDK found no autopilot"
        out["autopilot"] = await system.autopilot_type()
        telemetry = TelemetryAsync(system)
        action = ActionAsync(system)
        offboard = OffboardAsync(system)
        pos = await _first(telemetry.subscribe_position(), 10)
        att = await _first(telemetry.subscribe_attitude_euler(), 10)
        out["start_rel_alt_m"] = pos.relative_altitude_m
        out["start_roll_deg"] = att.roll_deg
        await action.arm()
        await _first(telemetry.subscribe_armed(), 5, bool)
        hover = hover_thrust(0.85, 6.0)
        await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 0.0, hover + 0.08))
        # PX4 rule: OFFBOARD only after the setpoint stream (MAVSDK sends 20 Hz) has run > 1 s;
        # a client retries, as it would against PX4
        out["rejected_starts"] = 0
        for _ in range(20):
            try:
                await offboard.start()
                break
            except OffboardError:
                out["rejected_starts"] += 1
                await asyncio.sleep(0.25)
        climbed = await _first(
            telemetry.subscribe_position(), 15, lambda p: p.relative_altitude_m > 1.0
        )
        out["climbed_to_m"] = climbed.relative_altitude_m
        # brake below hover thrust until the climb stops, then hold at hover thrust
        await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 0.0, hover - 0.08))
        await _first(telemetry.subscribe_velocity_ned(), 10, lambda v: v.down_m_s > -0.02)
        await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 0.0, hover))
        alts = []
        async for p in telemetry.subscribe_position():
            alts.append(p.relative_altitude_m)
            if len(alts) >= 100:  # 2 s at 50 Hz
                break
        out["hold_alt_m"] = alts
        out["mode"] = await _first(telemetry.subscribe_flight_mode(), 5)
        await offboard.stop()
    return out


def test_mavsdk_discovers_arms_and_flies_offboard_with_attitude_rate(tmp_path):
    port = free_udp_port()
    with run_emulator(["--id", "1"], remote_port=port, log_dir=str(tmp_path)):
        out = asyncio.run(_fly(port))
    assert out["autopilot"] == Autopilot.PX4
    assert abs(out["start_rel_alt_m"]) < 0.05 and abs(out["start_roll_deg"]) < 1.0
    assert 1 <= out["rejected_starts"] <= 8
    assert out["climbed_to_m"] > 1.0
    assert out["mode"] == FlightMode.OFFBOARD
    # at hover thrust the altitude holds (the drag-free model has no other damping)
    assert min(out["hold_alt_m"]) > 1.0
    assert max(out["hold_alt_m"]) - min(out["hold_alt_m"]) < 0.15
