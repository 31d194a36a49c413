"""MAVSDK (mavsdk 4.x, ``mavsdk.asyncio``) as a real third-party client of vehicle-emu, on the
px4 and the ardupilot personalities.

MAVSDK listens on 127.0.0.1:PORT (``udpin://``); the emulator sends there, so all traffic stays
on the loopback interface. MAVSDK 4.1 with ArduPilot (what these tests rely on): it finds the
vehicle on its ephemeral port and answers there, reports ``Autopilot.ARDUPILOT``, arms, takes off
(GUIDED, then NAV_TAKEOFF at a relative altitude), shows GUIDED as ``FlightMode.OFFBOARD`` (so
``offboard.start()`` means GUIDED), sends its attitude-rate setpoints as SET_ATTITUDE_TARGET;
telemetry needs its ``set_rate_*`` calls (ArduPilot streams nothing until asked), and none of
them asks for SYS_STATUS, so ``health.is_armable`` (its pre-arm bit) never arrives. It has no flight
mode for GUIDED_NOGPS, and ArduPilot's GUIDED does not lift a landed vehicle on thrust alone (a
takeoff comes first), so the ardupilot flight takes off before its offboard part.
"""

from __future__ import annotations

import asyncio
import time

import numpy as np
import pytest

from tests.harness import free_udp_port, hover_thrust, run_emulator
from vehicle_emulator.config.personality import DEFAULT_AUTOPILOT, PERSONALITIES

mavsdk_asyncio = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import OffboardAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.autopilot import Autopilot  # noqa: E402
from mavsdk.plugins.offboard import AttitudeRate, OffboardError  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode  # noqa: E402

#: MAVSDK's offboard plugin resends the latest setpoint at 20 Hz.
MAVSDK_SETPOINT_PERIOD_S = 0.05

pytestmark = [pytest.mark.integration, pytest.mark.timeout(120)]


async def _first(agen, timeout_s: float, cond=lambda x: True):
    async def go():
        async for item in agen:
            if cond(item):
                return item
        raise AssertionError("stream ended")

    return await asyncio.wait_for(go(), timeout_s)


async def _connect(mavsdk: Mavsdk, port: int, rates_hz: float | None = None):
    await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
    system = await mavsdk.first_autopilot(timeout_s=60.0)
    assert system is not None, "MAVSDK found no autopilot"
    telemetry = TelemetryAsync(system)
    if rates_hz is not None:  # ArduPilot: SET_MESSAGE_INTERVAL for what the test reads
        await telemetry.set_rate_position(rates_hz)
        await telemetry.set_rate_attitude_euler(rates_hz)
        await telemetry.set_rate_velocity_ned(rates_hz)
    return system, telemetry, ActionAsync(system), OffboardAsync(system)


async def _start_offboard(telemetry: TelemetryAsync, offboard: OffboardAsync, thrust: float):
    """MAVSDK's documented sequence: one setpoint, then ``start()`` (no retry). PX4 accepts it
    because its offboard check only asks for a setpoint younger than COM_OF_LOSS_T. Returns the
    wall times [s] ``start()`` took (until its ACCEPTED ACK) and from its return until telemetry
    reports OFFBOARD.

    One MAVSDK send period (50 ms, its 20 Hz) passes between the two: MAVSDK sends the setpoint
    from another thread than the mode command, and on a loaded machine (flights at real-time
    priority beside this test) the command went out first, 0.3 ms ahead of the setpoint, in 1
    of 5 runs; the emulator then answered TEMPORARILY_REJECTED, "Switching to Offboard is
    currently not available", as PX4 does to a command with no setpoint before it."""
    await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 0.0, thrust))
    await asyncio.sleep(MAVSDK_SETPOINT_PERIOD_S)
    t0 = time.monotonic()
    try:
        await offboard.start()
    except OffboardError as err:
        pytest.fail(f"offboard.start() right after one setpoint was refused: {err}")
    started = time.monotonic()
    await _first(telemetry.subscribe_flight_mode(), 5, lambda m: m == FlightMode.OFFBOARD)
    return started - t0, time.monotonic() - started


async def _hold_altitudes(telemetry: TelemetryAsync, n: int = 100) -> list[float]:
    return [alt for _, alt in await _hold_track(telemetry, n)]


async def _hold_track(telemetry: TelemetryAsync, n: int = 100) -> list[tuple[float, float]]:
    """(receive time [s], relative altitude [m]) of the next ``n`` positions (2 s at 50 Hz)."""
    track = []
    async for p in telemetry.subscribe_position():
        track.append((time.monotonic(), p.relative_altitude_m))
        if len(track) >= n:
            break
    return track


def _net_vertical_accel(track: list[tuple[float, float]], drag_per_s: float) -> float:
    """The vertical acceleration [m/s^2] left over at a thrust command, apart from the drag's.

    With a constant thrust error a and the vehicle's linear drag c, dv/dt = a - c v, so from any
    starting speed v0 the altitude follows h0 + v0 tau(t) + a (t - tau(t)) / c, with
    tau(t) = (1 - exp(-c t)) / c (t^2 / 2 in place of (t - tau) / c without drag). A least-squares
    fit of h0, v0 and a to the track gives a whatever speed the vehicle had when the command
    changed: at the hover thrust a is ~0; a thrust error of 1 % of hover is 0.098 m/s^2."""
    t = np.array([s for s, _ in track]) - track[0][0]
    h = np.array([alt for _, alt in track])
    if drag_per_s > 1e-9:
        tau = -np.expm1(-drag_per_s * t) / drag_per_s
        accel_basis = (t - tau) / drag_per_s
    else:
        tau, accel_basis = t, 0.5 * t * t
    design = np.column_stack([np.ones_like(t), tau, accel_basis])
    (_, _, accel), *_ = np.linalg.lstsq(design, h, rcond=None)
    return float(accel)


async def _fly(port: int, ardupilot: bool = False) -> dict:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    out: dict = {}
    async with Mavsdk(config) as mavsdk:
        system, telemetry, action, offboard = await _connect(
            mavsdk, port, 50.0 if ardupilot else None)
        out["autopilot"] = await system.autopilot_type()
        pos = await _first(telemetry.subscribe_position(), 10)
        att = await _first(telemetry.subscribe_attitude_euler(), 10)
        out["start_rel_alt_m"] = pos.relative_altitude_m
        out["start_roll_deg"] = att.roll_deg
        # as MAVSDK's examples do: wait for the health checks before arming (PX4 refuses to
        # arm for its first seconds after boot; health.is_armable is the pre-arm check bit).
        # Not on ArduPilot: the bit is in SYS_STATUS, which MAVSDK never asks ArduPilot for
        if not ardupilot:
            health = await _first(telemetry.subscribe_health(), 15, lambda h: h.is_armable)
            out["home_position_ok"] = health.is_home_position_ok
        await action.arm()
        await _first(telemetry.subscribe_armed(), 5, bool)
        if ardupilot:  # GUIDED + NAV_TAKEOFF (MAVSDK's action.takeoff for ArduPilot)
            await action.set_takeoff_altitude(2.0)
            await action.takeoff()
            up = await _first(telemetry.subscribe_position(), 20,
                              lambda p: p.relative_altitude_m > 1.9)
            out["took_off_m"] = up.relative_altitude_m
            out["start_rel_alt_m"] = 0.0
        hover = _hover(ardupilot)
        out["offboard_timing_s"] = await _start_offboard(telemetry, offboard, hover + 0.08)
        climbed = await _first(
            telemetry.subscribe_position(), 15,
            lambda p: p.relative_altitude_m > 1.0 + out.get("took_off_m", 0.0),
        )
        out["climbed_to_m"] = climbed.relative_altitude_m
        # brake below hover thrust until the climb stops, then hold at hover thrust
        await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 0.0, hover - 0.08))
        await _first(telemetry.subscribe_velocity_ned(), 10, lambda v: v.down_m_s > -0.02)
        await offboard.set_attitude_rate(AttitudeRate(0.0, 0.0, 0.0, hover))
        out["hold_track"] = await _hold_track(telemetry)
        out["mode"] = await _first(telemetry.subscribe_flight_mode(), 5)
        await offboard.stop()
    return out


def _hover(ardupilot: bool) -> float:
    """Hover thrust of the default vehicle 1: m g / (4 f_max), less ArduPilot's battery and
    air-density compensation (docs/emulator.md, "Calibration")."""
    scale = PERSONALITIES["ardupilot"].dynamics.thrust_scale if ardupilot else 1.0
    return hover_thrust(0.85, 6.0) / scale


async def _take_over_in_the_air(port: int, ardupilot: bool = False) -> dict:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    out: dict = {}
    async with Mavsdk(config) as mavsdk:
        _, telemetry, _, offboard = await _connect(mavsdk, port, 50.0 if ardupilot else None)
        out["armed"] = await _first(telemetry.subscribe_armed(), 10)
        out["mode_before"] = await _first(telemetry.subscribe_flight_mode(), 10)
        pos = await _first(telemetry.subscribe_position(), 10)
        out["start_rel_alt_m"] = pos.relative_altitude_m
        hover = _hover(ardupilot)
        out["offboard_timing_s"] = await _start_offboard(telemetry, offboard, hover)
        out["hold_alt_m"] = await _hold_altitudes(telemetry)
        out["mode"] = await _first(telemetry.subscribe_flight_mode(), 5)
        await offboard.stop()
    return out


# start() returns on the ACK (PX4 SITL: 2-4 ms after the setpoint); telemetry learns the mode from
# the 1 Hz HEARTBEAT (as on PX4), so it shows at the next one: up to one period later
ACK_WITHIN_S = 0.3
MODE_SEEN_WITHIN_S = 1.0 + 0.3


# The open-loop hold below checks the thrust normalisation. The brake ends when MAVSDK reports
# the climb has stopped, by when the vehicle is already sinking (a few cm/s for each 10 ms the
# client takes to see it and answer), so the check is on the acceleration fitted from any start
# speed (_net_vertical_accel), not on the altitude's spread. The fit needs a clean track, and
# px4's estimate carries an EKF2-like wander (docs/emulator.md, "Calibration"): the assertion is
# about the thrust, not the estimator, so this flight is noise-free.
#: |net vertical acceleration| at hover thrust [m/s^2]: half a percent of the hover thrust (a
#: 1 % error fits 0.096, the right thrust within 0.002, on this machine)
HOVER_ACCEL_WITHIN = 0.05
NOISE_FREE = ["--param", "EMU_NOISE=0"]


def _assert_hover_thrust_holds(track, autopilot: str, above_m: float) -> None:
    drag = PERSONALITIES[autopilot].dynamics.linear_drag_per_s
    accel = _net_vertical_accel(track, drag)
    alts = [alt for _, alt in track]
    assert abs(accel) < HOVER_ACCEL_WITHIN, (
        f"at hover thrust the vehicle accelerated {accel:+.3f} m/s^2 beyond its drag "
        f"(altitude {alts[0]:.3f} -> {alts[-1]:.3f} m in {track[-1][0] - track[0][0]:.2f} s)")
    assert min(alts) > above_m


def test_mavsdk_discovers_arms_and_flies_offboard_with_attitude_rate(tmp_path):
    port = free_udp_port()
    with run_emulator(["--id", "1", *NOISE_FREE], remote_port=port, log_dir=str(tmp_path)):
        out = asyncio.run(_fly(port))
    assert out["autopilot"] == Autopilot.PX4
    assert out["home_position_ok"]
    assert abs(out["start_rel_alt_m"]) < 0.05 and abs(out["start_roll_deg"]) < 1.0
    ack_s, mode_s = out["offboard_timing_s"]
    assert ack_s < ACK_WITHIN_S and mode_s < MODE_SEEN_WITHIN_S
    assert out["climbed_to_m"] > 1.0
    assert out["mode"] == FlightMode.OFFBOARD
    # at hover thrust nothing but SIH's linear drag accelerates the vehicle
    _assert_hover_thrust_holds(out["hold_track"], DEFAULT_AUTOPILOT, above_m=1.0)


def test_mavsdk_takes_over_a_hovering_vehicle_with_one_setpoint_then_start(tmp_path):
    # GIVEN a vehicle holding at 10 m, armed WHEN MAVSDK sends one setpoint and start()s
    # THEN it is in OFFBOARD at once and holds its altitude at hover thrust
    # (noise off, as above: the Hold it takes over from wanders 0.35 m RMS with noise, which
    # is test_emulator_hold_estimate's subject, not this one's)
    port = free_udp_port()
    with run_emulator(["--id", "1", "--in-air", *NOISE_FREE], remote_port=port,
                      log_dir=str(tmp_path)):
        out = asyncio.run(_take_over_in_the_air(port))
    assert out["armed"] and out["mode_before"] == FlightMode.HOLD
    assert abs(out["start_rel_alt_m"] - 10.0) < 0.1
    ack_s, mode_s = out["offboard_timing_s"]
    assert ack_s < ACK_WITHIN_S and mode_s < MODE_SEEN_WITHIN_S
    assert out["mode"] == FlightMode.OFFBOARD
    assert max(abs(a - out["start_rel_alt_m"]) for a in out["hold_alt_m"]) < 0.15


ARDUPILOT = ["--autopilot", "ardupilot", "--param", "EMU_BOOT_SCALE=0", "--param",
             "GUID_OPTIONS=8"]  # booted at once; thrust is thrust (GUID_OPTIONS bit 3)


def test_mavsdk_on_ardupilot_arms_takes_off_and_flies_attitude_rates_in_guided(tmp_path):
    # GIVEN the ardupilot personality on its ephemeral port (no --bind), on the ground
    port = free_udp_port()
    with run_emulator(["--id", "1", *ARDUPILOT], remote_port=port, log_dir=str(tmp_path),
                      bind=False):
        out = asyncio.run(_fly(port, ardupilot=True))
    # THEN MAVSDK sees ArduPilot, arms, takes off; one setpoint then start() flies GUIDED
    assert out["autopilot"] == Autopilot.ARDUPILOT
    assert abs(out["start_roll_deg"]) < 1.0 and out["took_off_m"] > 1.9
    ack_s, mode_s = out["offboard_timing_s"]
    assert ack_s < ACK_WITHIN_S and mode_s < MODE_SEEN_WITHIN_S
    assert out["climbed_to_m"] > 1.0 + out["took_off_m"]
    assert out["mode"] == FlightMode.OFFBOARD  # MAVSDK's name of ArduPilot's GUIDED
    _assert_hover_thrust_holds(out["hold_track"], "ardupilot", above_m=1.0 + out["took_off_m"])


def test_mavsdk_on_ardupilot_takes_over_a_hovering_vehicle(tmp_path):
    # GIVEN an ArduCopter in the air (past boot: armed in GUIDED, holding)
    port = free_udp_port()
    with run_emulator(["--id", "1", "--in-air", *ARDUPILOT], remote_port=port,
                      log_dir=str(tmp_path), bind=False):
        out = asyncio.run(_take_over_in_the_air(port, ardupilot=True))
    assert out["armed"] and out["mode_before"] == FlightMode.OFFBOARD  # GUIDED
    assert abs(out["start_rel_alt_m"] - 10.0) < 0.1
    assert out["mode"] == FlightMode.OFFBOARD
    assert max(abs(a - out["start_rel_alt_m"]) for a in out["hold_alt_m"]) < 0.15
