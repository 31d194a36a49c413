"""How each autopilot is commanded: the mission machine's commands, one task each, as each
vehicle's profile (gcs.mission.autopilots) encodes them; results go back to the machine."""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Sequence
from typing import Any

from gcs.link import (
    CommandNotConfirmedError,
    CommandRejectedError,
    CommandTimeoutError,
    LinkClosedError,
    VehicleProxy,
)
from gcs.link.enums import MSG_ID, MavCmd, MavModeFlag
from gcs.link.samples import GlobalPosition
from gcs.mission.autopilots import AutopilotProfile, ModeSpec, version_text
from gcs.mission.machine import MissionMachine
from gcs.mission.plan import Cmd, Command, CommandResult

logger = logging.getLogger("gcs.fly")

#: Streams that are not needed and cost CPU on both sides: switched off (0) or slowed down; and
#: the few the checks read that a vehicle streaming only what is asked for (PX4's MAVLink modes
#: without defaults, `vehicle-emu --streams requested`) would not send: SYS_STATUS (pre-arm).
OPTIONAL_RATES_HZ = {"ATTITUDE": 0.0, "ODOMETRY": 0.0, "GLOBAL_POSITION_INT": 5.0, "HEARTBEAT": 5.0,
                     "SYS_STATUS": 2.0}


class Commander:
    """Runs each command of the mission machine as a task of the flight's TaskGroup, through the
    vehicle's autopilot profile, and hands its result back to the machine."""

    def __init__(self, machine: MissionMachine, requested_rates_hz: dict[str, float],
                 mode_timeout_s: float, proxy_by_id: dict[int, VehicleProxy]) -> None:
        self.machine = machine
        self.requested_rates_hz = requested_rates_hz  # the setup's streams (Cmd.CONFIGURE)
        self.mode_timeout_s = mode_timeout_s  # a mode change's confirmation (the plan's)
        self.proxy_by_id = proxy_by_id  # vehicle id -> its proxy, filled as the links open
        self.tg: asyncio.TaskGroup | None = None  # the flight's, while it runs

    def dispatch(self, commands: Sequence[Command]) -> None:
        assert self.tg is not None
        for c in commands:
            self.tg.create_task(self.execute(c), name=f"vehicle {c.vehicle_id} {c.cmd.value}")

    async def execute(self, c: Command) -> None:
        p = self.proxy_by_id[c.vehicle_id]
        profile = self.machine.profile(c.vehicle_id)
        ok, detail, result, text = True, "", "", ""
        values: list[tuple[str, float]] = []
        try:
            if c.cmd is Cmd.CONFIGURE:
                for kind, hz in self.requested_rates_hz.items():
                    await p.commands.set_message_interval(MSG_ID[kind], hz)
                for kind, hz in OPTIONAL_RATES_HZ.items():
                    await p.commands.set_message_interval(MSG_ID[kind], hz, check=False)
            elif c.cmd is Cmd.READ_PARAMS:
                for name in c.names:
                    values.append((name, await p.commands.param_read(name)))
                detail = ", ".join(f"{name} = {value:g}" for name, value in values)
            elif c.cmd is Cmd.IDENTIFY:
                word = await p.commands.autopilot_version()
                values.append(("flight_sw_version", float(word)))
                detail = f"{profile.name} {version_text(word)}"
            elif c.cmd is Cmd.ARM_MODE:
                await self.set_mode(p, profile, profile.arm_mode, confirm=self.mode_timeout_s)
            elif c.cmd is Cmd.ARM:
                await self.arm(p, profile, self.mode_timeout_s)
            elif c.cmd is Cmd.DISARM:
                await p.commands.disarm()
            elif c.cmd is Cmd.TAKEOFF:
                await p.commands.takeoff(self.takeoff_amsl_m(p, c.altitude_m)
                                         if profile.takeoff_altitude_amsl else c.altitude_m)
            elif c.cmd is Cmd.OFFBOARD:
                await self.set_mode(p, profile, self.machine.offboard_mode(c.vehicle_id),
                                    confirm=self.mode_timeout_s)
            elif c.cmd is Cmd.POSITION_MODE:
                await self.set_mode(p, profile, profile.position_mode,
                                    confirm=self.mode_timeout_s)
            elif c.cmd is Cmd.HOLD:
                await self.set_mode(p, profile, profile.hold, confirm=self.mode_timeout_s)
            elif c.cmd is Cmd.LAND:
                await self.land(p, profile, confirm=self.mode_timeout_s)
        except CommandRejectedError as exc:
            ok, detail, result, text = False, str(exc), exc.result.name, exc.text
        except CommandNotConfirmedError as exc:
            ok, detail, result, text = False, str(exc), "NOT_CONFIRMED", exc.text
        except (CommandTimeoutError, LinkClosedError, TimeoutError) as exc:
            ok, detail, result = False, str(exc), "TIMEOUT"
        logger.log(logging.INFO if ok else logging.WARNING, "vehicle %d: %s %s%s", c.vehicle_id,
                   c.cmd.value, "ok" if ok else "failed", f": {detail}" if detail else "")
        self.dispatch(self.machine.on_result(
            CommandResult(c.vehicle_id, c.cmd, ok, detail, tuple(values) if ok else (),
                          result, text)))

    @staticmethod
    def mode_params(p: VehicleProxy, profile: AutopilotProfile, mode: ModeSpec) -> list[float]:
        """DO_SET_MODE params as the vehicle's autopilot encodes `mode` (PX4: +128 when armed,
        as MAVSDK sends it)."""
        if profile.family == "ardupilot":
            return [float(MavModeFlag.CUSTOM_MODE_ENABLED), mode.number]
        armed = p.state().armed
        base = MavModeFlag.CUSTOM_MODE_ENABLED | (MavModeFlag.SAFETY_ARMED if armed else 0)
        return [float(base), mode.number, mode.sub]

    @staticmethod
    def reported(profile: AutopilotProfile) -> Callable[[Any], str]:
        """What a HEARTBEAT says, for messages: 'AUTO_LOITER, disarmed'."""
        def text(hb: Any) -> str:
            if hb is None:
                return "nothing (no HEARTBEAT yet)"
            armed = "armed" if int(hb.base_mode) & MavModeFlag.SAFETY_ARMED else "disarmed"
            return f"{profile.mode_name(int(hb.custom_mode))}, {armed}"
        return text

    @classmethod
    async def set_mode(cls, p: VehicleProxy, profile: AutopilotProfile, mode: ModeSpec, *,
                       confirm: float | None = None, timeout_s: float = 0.5,
                       retries: int = 2) -> None:
        """DO_SET_MODE as the vehicle's autopilot encodes `mode`. With `confirm` (seconds):
        returns when a HEARTBEAT after the ACK shows the mode, every ACK read (a later refusal
        wins); raises CommandRejectedError / CommandNotConfirmedError / CommandTimeoutError
        naming the vehicle, the mode asked, the mode reported and the ACKs. Without: returns
        when the first ACK accepts it (the emergency stop's best effort)."""
        params = cls.mode_params(p, profile, mode)
        if confirm is None:
            await p.commands.command_long(MavCmd.DO_SET_MODE, params, timeout_s=timeout_s,
                                          retries=retries)
            return
        want = mode.custom_mode(profile.family)
        await p.commands.command_confirmed(
            MavCmd.DO_SET_MODE, params, want=f"mode {mode.name}",
            shows=lambda hb: int(hb.custom_mode) == want, reported=cls.reported(profile),
            timeout_s=confirm, ack_timeout_s=timeout_s, retries=retries)

    @classmethod
    async def arm(cls, p: VehicleProxy, profile: AutopilotProfile, confirm: float) -> None:
        """COMPONENT_ARM_DISARM 1 (never forced); returns when HEARTBEAT shows armed."""
        await p.commands.command_confirmed(
            MavCmd.COMPONENT_ARM_DISARM, [1.0, 0.0], want="armed",
            shows=lambda hb: bool(int(hb.base_mode) & MavModeFlag.SAFETY_ARMED),
            reported=cls.reported(profile), timeout_s=confirm)

    @classmethod
    async def land(cls, p: VehicleProxy, profile: AutopilotProfile, *,
                   confirm: float | None = None, timeout_s: float = 0.5,
                   retries: int = 2) -> None:
        """The profile's land: its LAND mode (ArduPilot, confirmed with `confirm`) or
        MAV_CMD_NAV_LAND (PX4); returns when accepted, not when landed."""
        if profile.land is not None:
            await cls.set_mode(p, profile, profile.land, confirm=confirm, timeout_s=timeout_s,
                               retries=retries)
        else:
            await p.commands.land(timeout_s=timeout_s, retries=retries)

    @staticmethod
    def takeoff_amsl_m(p: VehicleProxy, altitude_m: float) -> float:
        """PX4 NAV_TAKEOFF wants AMSL: home AMSL (GLOBAL_POSITION_INT alt - relative_alt) + alt;
        NaN (the autopilot's MIS_TAKEOFF_ALT) when the vehicle sent no global position."""
        gpi = p.sample(GlobalPosition)
        return math.nan if gpi is None else gpi.home_amsl_m + altitude_m
