"""The law of an agent over its law team: its own rows from its telemetry, its neighbours'
rows from the neighbour bus (gcs/agent/team.py says which rows are which).

`NeighbourRows` is what `gcs fly`'s tick (gcs/fly/tick.py) asks when the flight is an agent's:
it publishes the agent's own vehicles' states each tick, and turns the own rows the tick
measured into the law team's rows. The same rules as `gcs fly` hold for a neighbour's row: it
counts only while its age at use (now minus when its vehicle took it, on this agent's clock
through the bus's clock offset) is within `fly.stale_after_s`, either way (a sample from further
in the future than that has a wrong time: a clock disagrees), and with `fly.predict` it is
predicted to the instant this tick's setpoints act, as the agent's own rows are. A neighbour
never heard, or whose sample is not finite, gets a placeholder row (its formation slot beside
the agent's first vehicle, at rest) that is stale: the staleness rule removes it from every
own row, so the placeholder only keeps the unused row finite.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from gcs.agent.table import Rows
from gcs.agent.team import AgentTeam
from gcs.control.law import TeamCommand, TeamMeasurement
from gcs.control.predict import horizons_s, predict
from gcs.fly.measure import TeamSample
from gcs.fly.stats import AgeStats
from gcs.frames import quat_wxyz_from_rotation

__all__ = ["NeighbourRows", "NeighbourSource"]


class NeighbourSource(Protocol):
    """The neighbour bus as the tick uses it (gcs/agent/bus.py)."""

    def publish(self, vehicle_id: int, taken_s: float, position: np.ndarray,
                velocity: np.ndarray, acceleration: np.ndarray, quaternion_wxyz: np.ndarray,
                omega: np.ndarray) -> None: ...

    def rows(self, ids: tuple[int, ...], now_s: float) -> Rows: ...


class NeighbourRows:
    """The tick's view of the neighbour bus (module docstring)."""

    def __init__(self, agent: AgentTeam, source: NeighbourSource, stale_after_s: float) -> None:
        self.agent = agent
        self.source = source
        self.stale_after_s = stale_after_s
        self.own_ids = agent.own
        self.neighbour_ids = agent.neighbours
        self.law_team = agent.law_team
        self.n_law = self.law_team.n
        self.own_rows, self.neighbour_rows = agent.rows()
        offsets = self.law_team.offsets_enu_m()
        self._slot_from_first = offsets[self.neighbour_rows] - offsets[self.own_rows[0]]
        #: per neighbour, at each formation tick: its age at use, since received, stale
        self.ages = AgeStats(len(self.neighbour_ids))
        #: per neighbour, the oldest sample the law used (fresh) [s]: at most stale_after_s
        self.age_used_max_s = np.full(len(agent.neighbours), -np.inf)
        self._state: Rows | None = None
        self.unpublished = 0  # ticks an own vehicle's sample was not complete and finite
        self._fresh = np.zeros(len(self.neighbour_ids), dtype=bool)
        self._ok = np.zeros(len(self.neighbour_ids), dtype=bool)  # a finite sample to use

    # --- publishing ------------------------------------------------------------------------------

    def publish(self, sample: TeamSample) -> None:
        """Each own vehicle's latest state on the bus, its velocity and acceleration as the law
        reads them (the tick passes them through its consistency filters); skipped while it is
        not finite."""
        if not sample.finite.any():
            return
        quats = quat_wxyz_from_rotation(sample.rotation)
        for i, vid in enumerate(self.own_ids):
            values = (sample.position_m[i], sample.velocity_mps[i],
                      sample.acceleration_mps2[i], quats[i], sample.omega_radps[i])
            taken = float(sample.position_taken_s[i])
            if not (sample.finite[i] and math.isfinite(taken)
                    and all(np.isfinite(v).all() for v in values)):
                self.unpublished += 1
                continue
            self.source.publish(vid, taken, *values)

    # --- the law's rows --------------------------------------------------------------------------

    def fresh(self, own_fresh: np.ndarray, now_s: float) -> np.ndarray:
        """(n_law,) the staleness rule's mask over the law team; reads the bus once per tick
        (this tick's neighbour state, used by `measurement`)."""
        state = self.source.rows(self.neighbour_ids, now_s)
        self._state = state
        age = now_s - state.taken_local_s
        self._ok = (state.finite & np.isfinite(state.position_enu_m).all(axis=1)
                    & np.isfinite(state.velocity_enu_mps).all(axis=1)
                    & np.isfinite(state.acceleration_enu_mps2).all(axis=1))
        self._fresh = (self._ok & np.isfinite(age) & (age <= self.stale_after_s)
                       & (age >= -self.stale_after_s))
        out = np.zeros(self.n_law, dtype=bool)
        out[self.own_rows] = own_fresh
        out[self.neighbour_rows] = self._fresh
        return out

    def record_ages(self, now_s: float) -> None:
        """The formation's record of each neighbour's age at use this tick."""
        s = self._state
        if s is None or not len(self.neighbour_ids):
            return
        age = now_s - s.taken_local_s
        self.ages.record(age, now_s - s.received_s, self._fresh,
                         np.zeros(len(self.neighbour_ids), dtype=np.int64))
        used = np.where(self._fresh, age, -np.inf)
        np.maximum(self.age_used_max_s, used, out=self.age_used_max_s)

    def measurement(self, own: TeamMeasurement, act_s: float | None,
                    own_taken_s: np.ndarray | None = None) -> TeamMeasurement:
        """The law team's measurement: `own` (as the tick held or predicted it) in the own
        rows, each neighbour's latest sample in its row, predicted to `act_s` when given (with
        `fly.predict`), else to the instant of the agent's newest own sample `own_taken_s`.

        The latter is what `gcs fly` sees without prediction: every vehicle's latest sample,
        each taken within one telemetry period. A neighbour's sample crossed the bus after its
        agent's tick and is a tick older than that; carried forward by its own velocity and
        acceleration to the own sample's instant (never backward), it stands where `gcs fly`
        would have measured it."""
        n = self.n_law
        s = self._state
        k = len(self.neighbour_ids)
        pos = np.empty((n, 3))
        vel = np.empty((n, 3))
        acc = np.empty((n, 3))
        rot = np.tile(np.eye(3), (n, 1, 1))
        omega = np.zeros((n, 3))
        pos[self.own_rows] = own.position_m
        vel[self.own_rows] = own.velocity_mps
        acc[self.own_rows] = own.acceleration_mps2
        rot[self.own_rows] = own.rotation
        omega[self.own_rows] = own.omega_radps
        if k:
            if s is None:
                raise RuntimeError("NeighbourRows.measurement before fresh() this tick")
            n_pos, n_vel, n_acc = s.position_enu_m, s.velocity_enu_mps, s.acceleration_enu_mps2
            to_s = act_s
            if to_s is None and own_taken_s is not None and np.isfinite(own_taken_s).any():
                to_s = float(np.nanmax(own_taken_s))
            if to_s is not None:
                h = horizons_s(to_s, s.taken_local_s)
                held = TeamMeasurement(n_pos, n_vel, n_acc, np.tile(np.eye(3), (k, 1, 1)),
                                       np.zeros((k, 3)))
                p = predict(held, h, np.zeros(k))
                n_pos, n_vel = p.position_m, p.velocity_mps
            ok = self._ok
            first = own.position_m[0]
            stand_in = first + self._slot_from_first
            pos[self.neighbour_rows] = np.where(ok[:, None], n_pos, stand_in)
            vel[self.neighbour_rows] = np.where(ok[:, None], n_vel, own.velocity_mps[0])
            acc[self.neighbour_rows] = np.where(ok[:, None], n_acc, 0.0)
        return TeamMeasurement(pos, vel, acc, rot, omega)

    def heading(self, own_heading_rad: np.ndarray) -> np.ndarray:
        """(n_law,) the law's heading turn: the own rows', zero for the neighbours' rows."""
        out = np.zeros(self.n_law)
        out[self.own_rows] = own_heading_rad
        return out

    def own(self, command: TeamCommand) -> TeamCommand:
        """The law team's command restricted to the own rows (what the tick sends)."""
        r = self.own_rows
        return TeamCommand(
            thrust_n=command.thrust_n[r], torque_nm=command.torque_nm[r],
            rate_cmd_radps=command.rate_cmd_radps[r], force_n=command.force_n[r],
            command_rotation=command.command_rotation[r],
            mass_estimate_kg=command.mass_estimate_kg[r],
            inertia_estimate_kgm2=command.inertia_estimate_kgm2[r],
            attitude_error=command.attitude_error[r],
            omega_error_radps=command.omega_error_radps[r])
