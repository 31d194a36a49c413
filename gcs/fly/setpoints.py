"""The setpoints to the vehicles: the law's command scaled and limited per mode, the go-to-start
and formation-slot position targets turned into each vehicle's local NED frame; rates mode sends
the team in one batch (gcs.link.fastpath)."""

from __future__ import annotations

from typing import Any

import numpy as np

from gcs.config import ControlMode, TeamConfig
from gcs.control.law import TeamCommand
from gcs.control.slots import SlotTargets
from gcs.fly.measure import (
    TeamSample,
    command_heading_rad,
    desaturate_torque,
    limit_rate_command,
    normalised_thrust,
    normalised_torque,
    torque_max_nm,
)
from gcs.fly.origins import TeamTies
from gcs.link import SetpointError, VehicleProxy
from gcs.link.setpoints import TeamSetpoints
from gcs.mission.machine import MissionMachine
from gcs.mission.plan import Phase


class Setpoints:
    """Sends each streaming vehicle its setpoint; a setpoint the link refuses stops the flight
    (`MissionMachine.request_abort`). Sends return at once (UDP)."""

    def __init__(self, team: TeamConfig, mode: ControlMode, machine: MissionMachine, ties: TeamTies,
                 proxies: list[VehicleProxy], limited_ticks: np.ndarray) -> None:
        vehicles = team.vehicles
        self.mode = mode
        self.machine = machine
        self.ties = ties
        self.proxies = proxies  # the team's, in team order once the links are open
        self.n = team.n
        self.ids = team.ids()
        self.max_thrust_n = np.array([v.airframe.max_thrust_n for v in vehicles])
        self.arm_m = np.array([v.airframe.arm_length_m for v in vehicles])
        self.anti_torque_m = np.array([v.airframe.anti_torque_m for v in vehicles])
        self.rotor_max_n = np.array([v.airframe.rotor_thrust_max_n for v in vehicles])
        self.torque_max = torque_max_nm(self.arm_m, self.anti_torque_m, self.rotor_max_n)
        self.max_rate_radps = team.fly.rates.max_rate_radps
        self.max_yaw_rate_radps = team.fly.rates.max_yaw_rate_radps
        self.limited_ticks = limited_ticks  # per vehicle, formation ticks a limit applied in
        self.setpoint_errors = 0
        self._team_setpoints: TeamSetpoints | None = None  # once the proxies are open
        self._batchable = np.zeros(0, dtype=bool)  # per link: rates go in the team's batch
        # the rows of the last streaming set (the set, as a list, as an array)
        self._streaming_rows: tuple[frozenset[int] | None, list[int], np.ndarray] = (
            None, [], np.zeros(0, dtype=np.intp))
        self._goto_yaw_enu: dict[int, float] = {}  # heading held while going to start [rad]

    def send(self, c: TeamCommand, streaming: frozenset[int]) -> None:
        """Thrust / max thrust; actuators: thrust-preserving torque limit of (51), then torque /
        torque scale; rates: body-rate norm limit (docs/gcs.md)."""
        thrust = normalised_thrust(c.thrust_n, self.max_thrust_n)
        if self.mode == ControlMode.ACTUATORS:
            torque, limited = desaturate_torque(c.thrust_n, c.torque_nm, self.arm_m,
                                                self.anti_torque_m, self.rotor_max_n)
            vec = normalised_torque(torque, self.torque_max)
        elif self.mode == ControlMode.ATTITUDE:  # R^c itself; the autopilot limits its own tilt
            vec = self.ties.rotations_to_local(c.command_rotation)
            limited = np.zeros(self.n, dtype=bool)
        else:
            vec, limited = limit_rate_command(c.rate_cmd_radps, self.max_rate_radps,
                                              self.max_yaw_rate_radps)
        if self.machine.phase is Phase.FORMATION:
            self.limited_ticks += limited
        self.send_vectors(vec, thrust, streaming)

    def send_vectors(self, vec: np.ndarray, thrust: np.ndarray,
                     streaming: frozenset[int]) -> None:
        """Row i of ``vec`` (rates, attitude or torque, as the mode sends) and ``thrust`` to
        vehicle i if it is streaming; rates mode packs the team in one call."""
        if streaming != self._streaming_rows[0]:  # a new set: its rows, once
            picked = [i for i in range(self.n) if self.ids[i] in streaming]
            self._streaming_rows = (streaming, picked, np.asarray(picked, dtype=np.intp))
        _, rows, at = self._streaming_rows
        # rates mode: the team at once (gcs.link.fastpath), bad rows one by one
        if self.mode == ControlMode.RATES:
            if self._team_setpoints is None:
                self._team_setpoints = TeamSetpoints(self.proxies)
                self._batchable = np.array([p.batch_sendable for p in self.proxies], dtype=bool)
            ok = (np.isfinite(vec).all(axis=1) & np.isfinite(thrust) & self._batchable)[at]
            self._team_setpoints.send_rates_thrust(at[ok].tolist(), vec, thrust)
            rows = at[~ok].tolist()
        for i in rows:
            self._send_one(i, self.proxies[i], vec[i], thrust[i])

    def _send_one(self, i: int, p: VehicleProxy, vec: np.ndarray, thrust_norm: float) -> None:
        try:
            if self.mode == ControlMode.ACTUATORS:
                p.setpoints.send_actuator_controls(vec, thrust_norm)
            elif self.mode == ControlMode.ATTITUDE:
                p.setpoints.send_attitude_thrust(vec, thrust_norm)
            else:
                p.setpoints.send_rates_thrust(vec, thrust_norm)
        except SetpointError as exc:
            self.setpoint_errors += 1
            self.machine.request_abort(str(exc), operator=False)

    def send_position_targets(self, sample: TeamSample) -> None:
        """Go to start: each vehicle the machine names gets its team-frame target and the
        target's velocity as feed-forward (`_send_position_target`), and the heading it had
        when it first got one (so it does not yaw)."""
        targets = self.machine.position_targets
        if not targets:
            return
        hold = None
        for i in range(self.n):
            vid = self.ids[i]
            if vid not in targets or self.ties.ties[i] is None:
                continue
            if vid not in self._goto_yaw_enu:
                if hold is None:
                    hold = self.yaw_enu(sample, "hold")
                self._goto_yaw_enu[vid] = float(hold[i])
            position, velocity = targets[vid]
            self._send_position_target(i, position, velocity, self._goto_yaw_enu[vid])

    def _send_position_target(self, i: int, position_enu_m: Any, velocity_enu_mps: Any,
                              yaw_enu_rad: float, acceleration_enu_mps2: Any = None) -> None:
        """A position target to vehicle i: a team-frame target in its own local frame
        (p_local = R_i^T (p_team - o_i)), velocity (and acceleration) feed-forward turned the
        same way (R_i^T v_team), `yaw_enu_rad` already local; a setpoint the link refuses stops
        the flight."""
        tie = self.ties.ties[i]
        assert tie is not None  # preflight refuses an untied vehicle
        position = tie.local_from_team(position_enu_m)
        velocity = tie.vectors_local_from_team(velocity_enu_mps)
        acceleration = (None if acceleration_enu_mps2 is None
                        else tie.vectors_local_from_team(acceleration_enu_mps2))
        try:
            self.proxies[i].setpoints.send_position_target(position, velocity, yaw_enu_rad,
                                                           acceleration)
        except SetpointError as exc:
            self.setpoint_errors += 1
            self.machine.request_abort(str(exc), operator=False)

    def yaw_enu(self, sample: TeamSample, heading: str | float) -> np.ndarray:
        """(n,) the yaw of a position setpoint [rad, from east, anticlockwise] in each vehicle's
        local frame for a `fly.heading` policy: 'hold' its heading now, 'paper' east, a number
        that compass heading (gcs.fly.measure.command_heading_rad)."""
        return command_heading_rad(heading, self.ties.rotations_to_local(sample.rotation))

    def send_slots(self, targets: SlotTargets, yaw_enu_rad: np.ndarray,
                   streaming: frozenset[int]) -> None:
        """Formation slots (position mode): vehicle i's slot to it if it is streaming."""
        for i in range(self.n):
            if self.ids[i] in streaming:
                self._send_position_target(i, targets.position_enu_m[i], targets.velocity_enu_mps,
                                           float(yaw_enu_rad[i]), targets.acceleration_enu_mps2)
