"""One vehicle's commands: COMMAND_LONG/INT and SET_MODE, answered by COMMAND_ACKs (some deferred).

``NodeCommands`` is mixed into ``VehicleNode`` (node.py), which owns the state it reads and
dispatches the messages to it. Every command is answered, a failing one with FAILED.

With EMU_ACK_TWICE = 1 (default) a DO_SET_MODE COMMAND_LONG/INT is answered as PX4 v1.16.0 does:
COMMAND_ACK ACCEPTED at once (its MAVLink receiver), then the real result (its commander) queued
in ``deferred_acks``, which the runner sends on its next tick with the command's STATUSTEXTs.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

from vehicle_emulator.autopilots.node_output import Link
from vehicle_emulator.autopilots.px4.logic import MavResult, Severity, not_emulated
from vehicle_emulator.config.team import FaultSpec
from vehicle_emulator.mavlink.codec import mavlink

log = logging.getLogger("vehicle_emulator.autopilots.node")  # the node's one logger

__all__ = ["DeferredAck", "NodeCommands"]

CMD_DO_SET_MODE = 176
GPS_GLOBAL_ORIGIN_MSGID = 49
HEARTBEAT_MSGID = 0  # PX4: its interval cannot be changed (SET_MESSAGE_INTERVAL -> FAILED)
# What is emulated: COMMAND_INT | PARAM_ENCODE_BYTEWISE | SET_ATTITUDE_TARGET |
# SET_POSITION_TARGET_LOCAL_NED | MAVLINK2 (+ SET_ACTUATOR_TARGET where the personality honours
# it). Not claimed: missions, fence, rally, FTP, SET_POSITION_TARGET_GLOBAL_INT, terrain.
CAPABILITIES = 0x8 | 0x10 | 0x40 | 0x80 | 0x2000
CAP_SET_ACTUATOR_TARGET = 0x400


@dataclass(frozen=True, slots=True)
class DeferredAck:
    """A COMMAND_ACK to send on the next tick: PX4's commander answering after its receiver."""

    command: int
    result: MavResult
    link: Link
    addr: Any
    target_system: int
    target_component: int


class NodeCommands:
    """The command handlers and COMMAND_ACKs of a ``VehicleNode`` (module docstring)."""

    __slots__ = ()

    def _on_set_mode(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if msg.target_system not in (0, self.sysid):
            self.counters.other_target += 1
            return
        if not msg.base_mode & 1:
            self.counters.unhandled += 1
            self.statustext_limited(now_s, Severity.ERROR, "SET_MODE without custom mode")
            return
        main, sub = (msg.custom_mode >> 16) & 0xFF, (msg.custom_mode >> 24) & 0xFF
        result = self.autopilot.set_mode(now_s, self.observe(), main, sub)
        self._ack(176, result, link, addr, msg)
        self.drain_events(now_s)

    def _on_command(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if not self._for_me(msg):
            return
        p = [msg.param1, msg.param2, msg.param3, msg.param4]
        if msg.get_msgId() == 75:  # COMMAND_INT: x, y are scaled integers, z a float
            p += [msg.x * 1e-7, msg.y * 1e-7, msg.z]
        else:
            p += [msg.param5, msg.param6, msg.param7]
        # a mode the emulator does not fly gets one ACK, UNSUPPORTED, not ACCEPTED first
        twice = msg.command == CMD_DO_SET_MODE and self._ack_twice() and not _not_emulated(p)
        if twice:  # PX4 v1.16.0's MAVLink receiver ACKs before its commander has looked
            self._ack(CMD_DO_SET_MODE, MavResult.ACCEPTED, link, addr, msg)
        try:
            result = self.command(now_s, int(msg.command), p, link, addr)
        except Exception:  # never leave a command unanswered
            log.exception("vehicle %d: command %d failed", self.spec.vehicle_id, msg.command)
            result = MavResult.FAILED
        log.info("vehicle %d (sysid %d): command %d (%s) -> %s", self.spec.vehicle_id,
                 self.sysid, msg.command, ", ".join(f"{x:g}" for x in p), result.name)
        if twice:
            self.deferred_acks.append(
                DeferredAck(
                    CMD_DO_SET_MODE, result, link, addr, msg.get_srcSystem(), msg.get_srcComponent()
                )
            )
            return  # the commander's ACK and its STATUSTEXTs go out on the next tick
        self._ack(int(msg.command), result, link, addr, msg)
        self.drain_events(now_s)

    def _ack_twice(self) -> bool:
        """DO_SET_MODE answered twice (PX4 v1.16.0, EMU_ACK_TWICE = 1)."""
        return self.params.get_int("EMU_ACK_TWICE") == 1

    def _ack(self, command: int, result: MavResult, link: Link, addr: Any, msg: Any) -> None:
        ack = mavlink.MAVLink_command_ack_message(
            command, int(result), 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
        )
        self.send_msg(ack, link, addr)

    def command(self, now_s: float, cmd: int, p: list[float], link: Link, addr: Any) -> MavResult:
        """Execute a COMMAND_LONG / COMMAND_INT; returns the MAV_RESULT to acknowledge."""
        ap, obs = self.autopilot, self.observe()
        if cmd == 400:  # COMPONENT_ARM_DISARM
            if p[0] not in (0.0, 1.0):
                return MavResult.DENIED
            return ap.arm(now_s, obs, p[0] == 1.0, force=_int(p[1]) in (21196, 2989))
        if cmd == 176:  # DO_SET_MODE
            if not _int(p[0]) & 1 or not math.isfinite(p[1]):
                return MavResult.DENIED
            return ap.set_mode(now_s, obs, _int(p[1]), _int(p[2]))
        if cmd == 22:  # NAV_TAKEOFF: param7 altitude AMSL (PX4)
            home_ned_m = self.status.home_ned_m[self.index]
            home_amsl_m = self.telemetry.origin_lla[2] - float(home_ned_m[2])
            alt = p[6] - home_amsl_m if math.isfinite(p[6]) else math.nan
            return ap.takeoff(now_s, obs, alt)
        if cmd == 21:  # NAV_LAND
            return ap.land(now_s, obs)
        if cmd in (20, 192):  # NAV_RETURN_TO_LAUNCH, DO_REPOSITION: not emulated (as AUTO_RTL)
            return MavResult.UNSUPPORTED
        if cmd == 511:  # SET_MESSAGE_INTERVAL
            if not (math.isfinite(p[0]) and math.isfinite(p[1])):
                return MavResult.DENIED
            if _int(p[0], -1) == HEARTBEAT_MSGID:
                return MavResult.FAILED  # PX4 v1.16.0: recorded FAILED, stays at 1 Hz
            ok = self.telemetry.set_interval(self.index, _int(p[0], -1), p[1], now_s)
            return MavResult.ACCEPTED if ok else MavResult.UNSUPPORTED
        if cmd == 510:  # GET_MESSAGE_INTERVAL
            msgid = _int(p[0], -1)
            us = (
                self.telemetry.interval_us(self.index, msgid)
                if msgid in self.telemetry.msgids
                else 0
            )
            self.send_msg(mavlink.MAVLink_message_interval_message(msgid & 0xFFFF, us), link, addr)
            return MavResult.ACCEPTED
        if cmd in (512, 520):  # REQUEST_MESSAGE, REQUEST_AUTOPILOT_CAPABILITIES
            msgid = 148 if cmd == 520 else _int(p[0], -1)
            return self._send_requested(now_s, msgid, link, addr)
        if cmd == 420:  # INJECT_FAILURE
            return self._inject_failure(now_s, p)
        return MavResult.UNSUPPORTED

    def _send_requested(self, now_s: float, msgid: int, link: Link, addr: Any) -> MavResult:
        if msgid == 148:
            protocol = self.personality.protocol
            caps = CAPABILITIES | (CAP_SET_ACTUATOR_TARGET if protocol.actuator_setpoints else 0)
            msg = mavlink.MAVLink_autopilot_version_message(
                caps,
                protocol.version_word,
                0,
                0,
                0,
                [0] * 8,
                [0] * 8,
                [0] * 8,
                0,
                0,
                self.sysid,
                [0] * 18,
            )
        elif msgid == GPS_GLOBAL_ORIGIN_MSGID:
            msg = self.origin_message(now_s)
        elif msgid in self.telemetry.msgids:
            k = self.telemetry.msgids[msgid]
            self.telemetry.next_due_s[self.index, k] = now_s  # sent on the next tick
            return MavResult.ACCEPTED
        else:
            return MavResult.UNSUPPORTED
        self.send_msg(msg, link, addr)
        return MavResult.ACCEPTED

    def _inject_failure(self, now_s: float, p: list[float]) -> MavResult:
        """MAV_CMD_INJECT_FAILURE: unit 101 motor (instance 1-4, 0 all), 302 MAVLink signal.
        Types: 0 OK, 1 OFF, 3 SLOW (50% efficiency)."""
        unit, ftype, inst = _int(p[0], -1), _int(p[1], -1), _int(p[2], 0)
        if unit == 101 and ftype in (0, 1, 3) and 0 <= inst <= 4:
            eff = {0: 1.0, 1: 0.0, 3: 0.5}[ftype]
            for m in [inst] if inst else [1, 2, 3, 4]:
                self.apply_fault(
                    now_s, FaultSpec("motor_efficiency", 0, 0.0, motor=m, efficiency=eff), None
                )
            return MavResult.ACCEPTED
        if unit == 302 and ftype in (0, 1):
            self.impairment.down_until_s = now_s + 3600.0 if ftype == 1 else -1.0
            return MavResult.ACCEPTED
        return MavResult.UNSUPPORTED

    def send_deferred_acks(self, now_s: float) -> None:
        """The queued second COMMAND_ACKs (see module docstring), then the STATUSTEXTs of those
        commands (PX4 v1.16.0 sent "Switching to Offboard is currently not available" right
        after its TEMPORARILY_REJECTED)."""
        acks, self.deferred_acks = self.deferred_acks, []
        for a in acks:
            msg = mavlink.MAVLink_command_ack_message(
                a.command, int(a.result), 0, 0, a.target_system, a.target_component
            )
            self.send_msg(msg, a.link, a.addr)
        self.drain_events(now_s)


def _not_emulated(p: list[float]) -> bool:
    """DO_SET_MODE params name a PX4 mode the emulator does not fly (autopilot.not_emulated)."""
    return not_emulated(_int(p[1], -1), _int(p[2], -1))


def _int(x: float, default: int = 0) -> int:
    """int of a command parameter; ``default`` for NaN/inf (MAVSDK sends NaN for unused)."""
    return int(x) if math.isfinite(x) and abs(x) < 2**31 else default
