"""One emulated vehicle put together from its spec and personality: its autopilot family's
node and state machine, its parameter table (personality defaults, the team file's, then the
command line's), its streams, faults and link impairment, its place in the fleet arrays."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from vehicle_emulator.autopilots.ardupilot.logic import ArduCopter
from vehicle_emulator.autopilots.ardupilot.node import DEFAULT_RATES_HZ as ARDUPILOT_RATES_HZ
from vehicle_emulator.autopilots.ardupilot.node import ArduPilotNode
from vehicle_emulator.autopilots.node import VehicleNode
from vehicle_emulator.autopilots.px4.logic import Autopilot
from vehicle_emulator.config.faults import FaultSchedule, LinkImpairment
from vehicle_emulator.config.params import ParamError, ParamStore
from vehicle_emulator.config.personality import personality_of
from vehicle_emulator.config.team import FaultSpec, VehicleSpec
from vehicle_emulator.mavlink.codec import GenericEncoder
from vehicle_emulator.mavlink.fleet_status import FleetStatus
from vehicle_emulator.mavlink.telemetry import Telemetry
from vehicle_emulator.physics.plant import FleetPlant

__all__ = ["assemble_vehicle"]

_FAMILIES: dict[str, tuple[type[VehicleNode], Any, str, str]] = {
    "px4": (VehicleNode, Autopilot, "MAV_SYS_ID", "MPC_THR_HOVER"),
    "ardupilot": (ArduPilotNode, ArduCopter, "MAV_SYSID", "MOT_THST_HOVER"),
}


def assemble_vehicle(i: int, spec: VehicleSpec, faults: Sequence[FaultSpec], plant: FleetPlant,
                     telemetry: Telemetry, status: FleetStatus, *, seed: int,
                     param_overrides: Mapping[str, float],
                     message_intervals_ms: Mapping[int, float], streams: str) -> VehicleNode:
    """Vehicle ``i`` of the fleet (row i of ``plant``, ``telemetry`` and ``status``), booted at
    t = 0 with ``faults`` (its own) scheduled; raises ValueError naming the vehicle for a
    parameter of the team file its autopilot does not have."""
    personality = personality_of(spec.autopilot)
    family = personality.protocol.family
    node_cls, autopilot_cls, sysid_param, hover_param = _FAMILIES[family]
    status.mav_autopilot[i] = personality.protocol.mav_autopilot
    params = ParamStore.for_family(family)
    params.set(sysid_param, spec.sysid, force=True)
    if "EMU_ACK_TWICE" in params:
        params.set("EMU_ACK_TWICE", 1.0 if personality.protocol.ack_twice else 0.0)
    for name, value in personality.protocol.param_defaults:
        params.set(name, value)
    params.set("EMU_SEED", seed)
    params.set(hover_param, float(plant.hover_thrust_norm[i]))
    params.set("EMU_MOT_TAU", float(plant.motor_time_constant_s[i]))
    params.set("EMU_NOISE", 1.0 if personality.sensors.noise_default else 0.0)
    params.set("EMU_MASS_KG", spec.mass_kg, force=True)
    params.set("EMU_THR_MAX_N", 4.0 * spec.rotor_thrust_max_n, force=True)
    for name, value in spec.autopilot_params:  # the team file's; --param wins
        try:
            params.set(name, value)
        except ParamError as exc:
            raise ValueError(f"vehicle {spec.vehicle_id} (sysid {spec.sysid}, "
                             f"{spec.autopilot}): emulator.autopilot_params: {exc}"
                             ) from None
    for name, value in param_overrides.items():
        if name in params:  # a mixed team: each vehicle takes the names it has
            params.set(name, value)
    if family == "ardupilot":
        telemetry.set_defaults(i, ARDUPILOT_RATES_HZ, delayed=("TIMESYNC",))
        for msgid, ms in message_intervals_ms.items():
            if not telemetry.set_interval(i, msgid, ms * 1e3, 0.0):
                raise ValueError(f"message intervals: message id {msgid} is not one "
                                 "the emulator streams")
    if streams == "requested":
        telemetry.requested_only(i)
    if spec.starts_in_air:
        plant.hold_here(i)
    node = node_cls(
        index=i,
        spec=spec,
        personality=personality,
        plant=plant,
        telemetry=telemetry,
        status=status,
        params=params,
        autopilot=Autopilot(vehicle_id=spec.vehicle_id, params=params),
        faults=FaultSchedule.from_specs(params, faults),
        impairment=LinkImpairment(np.random.default_rng(seed + i)),
        encoder=GenericEncoder(spec.sysid, 1, telemetry.seq, i),
    )
    node.autopilot = autopilot_cls.start(
        spec.vehicle_id,
        params,
        0.0,
        node.observe(),
        ready_after_s=personality.protocol.arming_ready_s,
    )
    origin = node.local_origin_enu_m
    home = node.autopilot.home_enu_m
    status.origin_ned_m[i] = (origin[1], origin[0], -origin[2])
    status.home_ned_m[i] = (home[1], home[0], -home[2])
    node.sync_all_params()
    node.apply_demand()
    node.refresh_status(0.0)
    return node
