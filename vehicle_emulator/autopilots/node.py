"""One emulated vehicle: its state, status and faults, and the dispatch of its MAVLink input.

``VehicleNode`` glues the pure parts of vehicle ``index`` (autopilot, params, fault schedule,
link impairment) to the fleet arrays (plant, telemetry status) and to its links. Handlers get
decoded pymavlink messages and answer through ``Link.send`` (bytes out); they never block, never
raise on bad input (it is counted, logged and reported by STATUSTEXT), and never see sockets.
Outgoing messages are in node_output.py, commands and their ACKs in node_commands.py, the
parameter protocol in node_params.py, the scheduled faults in node_faults.py.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

from vehicle_emulator.autopilots.node_commands import DeferredAck, NodeCommands
from vehicle_emulator.autopilots.node_commands import (
    _int as _int,  # ardupilot/node.py imports it from here
)
from vehicle_emulator.autopilots.node_faults import NodeFaults
from vehicle_emulator.autopilots.node_output import REPORT_PERIOD_S, Link, NodeOutput
from vehicle_emulator.autopilots.node_params import NodeParams
from vehicle_emulator.autopilots.px4.logic import (
    ActuatorSetpoint,
    AttitudeSetpoint,
    Autopilot,
    Demand,
    Idle,
    MotorsOff,
    NavState,
    Observation,
    PositionTarget,
    RatesSetpoint,
    Severity,
)
from vehicle_emulator.autopilots.setpoints import (
    PositionTargetFields,
    from_actuator_control_target,
    from_attitude_target,
    from_position_target_local_ned,
)
from vehicle_emulator.config.faults import (
    FaultSchedule,
    LinkImpairment,
)
from vehicle_emulator.config.params import ParamStore
from vehicle_emulator.config.personality import Personality
from vehicle_emulator.config.team import VehicleSpec
from vehicle_emulator.mavlink.codec import GenericEncoder, mavlink
from vehicle_emulator.mavlink.fleet_status import FleetStatus
from vehicle_emulator.mavlink.telemetry import Telemetry
from vehicle_emulator.physics.plant import ControlMode, FleetPlant

log = logging.getLogger(__name__)

__all__ = ["DeferredAck", "Link", "VehicleNode", "InputCounters"]

COMPID = 1

# PX4 base_mode flags per nav state (besides CUSTOM_MODE_ENABLED and SAFETY_ARMED).
_BASE_FLAGS = {
    NavState.ALTCTL: 64 | 16,  # MANUAL_INPUT | STABILIZE
    NavState.POSCTL: 64 | 16,  # PX4 v1.16.0 recorded base_mode 209 armed
    NavState.OFFBOARD: 0,  # PX4 v1.16.0 recorded base_mode 1 disarmed, 129 armed
}


@dataclass(slots=True)
class InputCounters:
    """Per-vehicle counters of input that was not used as is."""

    other_target: int = 0
    own_echo: int = 0
    setpoints_rejected: int = 0
    setpoints_clamped: int = 0
    setpoints_ignored: int = 0  # a setpoint message this autopilot does not act on (not an error)
    unhandled: int = 0
    params_refused: int = 0
    last_reject_reason: str = ""
    reported_total: int = 0
    setpoints_by_mode: dict[str, int] = field(default_factory=dict)  # by the mode they met

    def total(self, decode_rejected: int) -> int:
        """Everything suspicious so far (for SYS_STATUS.errors_comm and the reports)."""
        return (
            decode_rejected
            + self.other_target
            + self.setpoints_rejected
            + self.setpoints_clamped
            + self.params_refused
        )


@dataclass(slots=True)
class VehicleNode(NodeOutput, NodeCommands, NodeParams, NodeFaults):
    """Vehicle ``index`` of the fleet; see module docstring. Outgoing messages are
    ``NodeOutput``'s (node_output.py), commands ``NodeCommands``'s (node_commands.py), the
    parameter protocol ``NodeParams``'s (node_params.py)."""

    index: int
    spec: VehicleSpec
    personality: Personality
    plant: FleetPlant
    telemetry: Telemetry
    status: FleetStatus
    params: ParamStore
    autopilot: Autopilot
    faults: FaultSchedule
    impairment: LinkImpairment
    encoder: GenericEncoder
    links: list[Link] = field(default_factory=list)
    counters: InputCounters = field(default_factory=InputCounters)
    setpoints_taken: int = 0
    applied_version: int = -1
    deferred_acks: list[DeferredAck] = field(default_factory=list)
    _next_report_s: float = REPORT_PERIOD_S
    _fault_clock_announced: bool = False
    _origin_announced: bool = False
    _text_id: int = 0  # id of the last chunked STATUSTEXT
    _limited_window_end_s: float = 0.0
    _limited_in_window: int = 0
    _limited_last: dict[str, float] = field(default_factory=dict)

    @property
    def sysid(self) -> int:
        """MAVLink system id."""
        return self.spec.sysid

    @property
    def decode_rejected(self) -> int:
        """Datagram content the links' parsers could not use (bad CRC, unknown ids, junk),
        counted when read: the status at the autopilot's rate, not per message."""
        total = 0
        for link in self.links:
            decoder = getattr(link, "decoder", None)
            if decoder is not None:
                total += decoder.stats.rejected
        return total

    @property
    def local_origin_enu_m(self) -> tuple[float, float, float]:
        """Where this vehicle's local NED frame (LOCAL_POSITION_NED, position targets) is zero,
        in the team frame; frames.enu_from_local_ned / local_ned_from_enu convert."""
        return self.spec.local_origin_enu_m(self.personality.protocol.own_origin)

    def setpoint_driven(self) -> bool:
        """Armed and flying the ground station's setpoints (lockstep waits for these)."""
        return self.autopilot.armed and self.autopilot.nav_state is NavState.OFFBOARD

    def boot_banner(self) -> list[bytes]:
        """Datagrams sent when a link opens, before any MAVLink (PX4: none)."""
        return []

    # --- state exchange with the fleet arrays ------------------------------------------------

    def observe(self) -> Observation:
        """This vehicle as its autopilot knows it: with a sensor model (the calibrated
        personalities), its own estimates (what PX4 and ArduPilot hold, take off from and fly
        their position loops on, and what LOCAL_POSITION_NED reports), else the plant's state;
        the landed flag is the plant's. (The runner's tick gathers the whole fleet's at once:
        `observe_fleet`.)"""
        i, p = self.index, self.plant
        ob = p.onboard
        est = bool(ob.sensor_model[i])
        pos = ob.position_est_enu_m[i] if est else p.position_enu_m[i]
        vel = ob.velocity_est_enu_mps[i] if est else p.velocity_enu_mps[i]
        rot = ob.rotation_est[i] if est else p.rotation[i]
        return self.observation(
            (float(pos[0]), float(pos[1]), float(pos[2])),
            (float(vel[0]), float(vel[1]), float(vel[2])),
            math.atan2(rot[1, 0], rot[0, 0]),
            bool(p.on_ground[i]),
            float(self.status.battery_remaining[i]),
            float(p.rotation[i, 2, 2]),
        )

    def observation(self, position: tuple[float, float, float],
                    velocity: tuple[float, float, float], yaw: float, on_ground: bool,
                    battery_remaining: float, tilt_cos: float) -> Observation:
        """The autopilot's observation from these values (`tilt_cos`: the plant's R[2, 2], which
        only some personalities read)."""
        return Observation(position, velocity, yaw, on_ground, battery_remaining)

    def apply_demand(self) -> None:
        """Write the autopilot's demand into the plant arrays (if it changed)."""
        ap = self.autopilot
        if ap.demand_version == self.applied_version:
            return
        self.applied_version = ap.demand_version
        write_demand(self.plant, self.index, ap.demand)

    def refresh_status(self, now_s: float) -> None:
        """Status arrays for telemetry, the battery model and the fault clock parameter. (The
        runner's tick does the same for the whole fleet, writing `status_row`s by column.)"""
        i = self.index
        self.status.write_row(i, self.status_row(now_s))
        self.status.refresh_battery(self.plant.charge_used_c, self.plant.thrust_n,
                                    self.battery_capacity_c, slice(i, i + 1))
        self.refresh_extra(now_s)
        self.tick_fault_clock(now_s)

    @property
    def battery_capacity_c(self) -> float:
        """The battery's charge [C]: 3 Ah per kg of take-off mass (at least 3 Ah)."""
        return max(1.0, 3.0 * self.spec.mass_kg) * 3600.0

    def status_row(self, now_s: float) -> tuple:
        """This vehicle's values of `FleetStatus.ROW_COLUMNS`, in that order."""
        ap = self.autopilot
        return (
            ap.armed,
            ap.system_status(now_s),
            ap.prearm_ok(now_s),
            self.position_ok(now_s),
            ap.custom_mode,
            self.base_mode_flags(now_s),
            self.landed_state(),
            min(self.counters.total(self.decode_rejected), 65535),
            ap.attitude_target_published(),
        )

    def position_ok(self, now_s: float) -> bool:
        """SYS_STATUS GPS bit present and enabled: the estimator has a global position."""
        return self.autopilot.position_ok(now_s)

    def base_mode_flags(self, now_s: float) -> int:
        """HEARTBEAT base_mode without SAFETY_ARMED (added per HEARTBEAT): PX4's flags of the
        navigation state."""
        return 1 | _BASE_FLAGS.get(self.autopilot.nav_state, 4 | 16 | 8)

    def landed_state(self) -> int:
        """MAV_LANDED_STATE: on the ground by the plant, else from the navigation state."""
        nav = self.autopilot.nav_state
        if self.plant.on_ground[self.index]:
            return 1
        if nav is NavState.AUTO_TAKEOFF:
            return 3
        if nav is NavState.AUTO_LAND:
            return 4
        return 2

    def refresh_extra(self, now_s: float) -> None:
        """Status a personality keeps beyond `status_row`'s columns (none here)."""

    # --- input ---------------------------------------------------------------------------------

    def _for_me(self, msg: Any) -> bool:
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        if ts not in (0, self.sysid) or tc not in (0, COMPID):
            self.counters.other_target += 1
            self.counters.last_reject_reason = f"target {ts}/{tc}"
            return False
        return True

    def handle(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """Dispatch one decoded message (never raises for bad content)."""
        if msg.get_srcSystem() == self.sysid and msg.get_srcComponent() == COMPID:
            self.counters.own_echo += 1
            return
        mid = msg.get_msgId()
        name = _HANDLERS.get(mid)
        if name is None:
            self.counters.unhandled += 1
            return
        try:
            getattr(self, name)(now_s, msg, link, addr)  # by name: a personality may override
        except Exception:  # a handler bug must not kill the vehicle: count and log it
            self.counters.unhandled += 1
            self.counters.last_reject_reason = f"handler error on {msg.get_type()}"
            log.exception("vehicle %d: error handling %s", self.spec.vehicle_id, msg.get_type())
        self.apply_demand()

    def _on_attitude_target(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if not self._for_me(msg):
            return
        prev = getattr(self.autopilot.setpoint, "thrust_norm", None)
        d = from_attitude_target(
            msg.type_mask,
            msg.q,
            (msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate),
            msg.thrust,
            getattr(msg, "thrust_body", None),
            prev,
        )
        self._take_setpoint(now_s, d)

    def _on_actuator_target(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if not self._for_me(msg):
            return
        if not self.personality.protocol.actuator_setpoints:
            # PX4 >= 1.14 dropped the message from its MAVLink receiver: no answer, no effect
            self.counters.setpoints_ignored += 1
            return
        self._take_setpoint(now_s, from_actuator_control_target(msg.group_mlx, msg.controls))

    def _on_position_target_local(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """SET_POSITION_TARGET_LOCAL_NED, PX4's rules (setpoints.py): an offboard setpoint (proof
        of life for COM_OF_LOSS_T), flown in OFFBOARD; PX4's texts for refused ones."""
        if not self._for_me(msg):
            return
        obs = self.observe()
        d = from_position_target_local_ned(
            PositionTargetFields.of(msg), self.local_origin_enu_m, obs.position_enu_m,
            obs.yaw_enu_rad,
        )
        if d.setpoint is None and (d.rejected or "").startswith("SET_POSITION_TARGET"):
            self.statustext_limited(now_s, Severity.CRITICAL, d.rejected or "")
        self._take_setpoint(now_s, d)

    def _on_position_target_global(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """SET_POSITION_TARGET_GLOBAL_INT: not emulated for PX4 (counted, ignored)."""
        self.counters.unhandled += 1

    def _take_setpoint(self, now_s: float, d: Any) -> None:
        if d.setpoint is None:
            self.counters.setpoints_rejected += 1
            self.counters.last_reject_reason = d.rejected or "setpoint"
            return
        self.setpoints_taken += 1
        if d.clamped:
            self.counters.setpoints_clamped += 1
            self.counters.last_reject_reason = "setpoint clamped"
        self.autopilot.on_setpoint(now_s, d.setpoint)

    def _on_request_data_stream(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """REQUEST_DATA_STREAM (deprecated): PX4 does not handle it; an ArduPilot node does."""
        self.counters.unhandled += 1

    def _on_heartbeat(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        """A GCS heartbeat: nothing to do."""

    def _on_timesync(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if msg.tc1 == 0:
            reply = mavlink.MAVLink_timesync_message(int(now_s * 1e9), msg.ts1)
            targets = self.personality.protocol.timesync_reply_targets
            link.send(self.encoder.pack_newer(reply, targets) if targets
                      else self.encoder.pack(reply), addr)


def write_demand(plant: FleetPlant, i: int, demand: Demand) -> None:
    """Set vehicle i's control mode and setpoint arrays for an autopilot demand."""
    prev_mode = int(plant.mode[i])
    if isinstance(demand, MotorsOff):
        plant.mode[i] = ControlMode.OFF
    elif isinstance(demand, Idle):
        plant.mode[i] = ControlMode.IDLE
    elif isinstance(demand, PositionTarget):
        plant.position_sp_enu_m[i] = demand.position_enu_m
        plant.velocity_ff_enu_mps[i] = demand.velocity_ff_enu_mps
        plant.position_mask[i] = demand.mask
        plant.yaw_sp_enu_rad[i] = demand.yaw_enu_rad
        plant.yaw_rate_ff_radps[i] = 0.0
        if prev_mode != ControlMode.POSITION:
            plant.velocity_integral[i] = 0.0
        plant.mode[i] = ControlMode.POSITION
    elif isinstance(demand, RatesSetpoint):
        plant.rate_cmd_flu_radps[i] = demand.rate_flu_radps
        plant.thrust_cmd_norm[i] = demand.thrust_norm
        plant.mode[i] = ControlMode.RATES
    elif isinstance(demand, AttitudeSetpoint):
        plant.attitude_cmd[i] = demand.rotation_enu_flu
        plant.yaw_rate_ff_radps[i] = demand.yaw_rate_ff_flu_radps
        plant.thrust_cmd_norm[i] = demand.thrust_norm
        plant.mode[i] = ControlMode.ATTITUDE
    elif isinstance(demand, ActuatorSetpoint):
        plant.torque_cmd_norm[i] = demand.torque_norm_flu
        plant.thrust_cmd_norm[i] = demand.thrust_norm
        plant.mode[i] = ControlMode.ACTUATOR


_HANDLERS = {  # msgid -> VehicleNode method name (looked up on the node: overridable)
    82: "_on_attitude_target",
    84: "_on_position_target_local",
    86: "_on_position_target_global",
    139: "_on_actuator_target",
    11: "_on_set_mode",
    66: "_on_request_data_stream",
    76: "_on_command",
    75: "_on_command",
    111: "_on_timesync",
    21: "_on_param_request_list",
    20: "_on_param_request_read",
    23: "_on_param_set",
    0: "_on_heartbeat",
}
