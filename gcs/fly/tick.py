"""One tick of `gcs fly`: sample -> mission machine -> law (or formation slots) -> setpoints.

`TickLoop` keeps the fixed rate (absolute deadlines, lateness measured, missed periods skipped);
`Tick.step` is one tick: the team's telemetry snapshot, the mission machine every few ticks, the
WHOLE team's law in one vectorised `TeamLaw.step`, each streaming vehicle's setpoint (through
`Setpoints`) and the formation's record samples. `HoverStart` takes mhat(0) from the hover.
"""

from __future__ import annotations

import asyncio
import copy
import dataclasses
import logging
import math
import time
from collections.abc import Callable
from typing import Protocol

import numpy as np

from gcs.config import TORQUE_MODES, ControlMode, TeamConfig
from gcs.control.formation import reference_velocity
from gcs.control.gains import GRAVITY_MPS2
from gcs.control.law import SingularCommandError, TeamCommand, TeamLaw, TeamMeasurement
from gcs.control.predict import PredictionAudit, horizons_s, predict, uplink_delay_s
from gcs.control.slots import FormationSlots
from gcs.fly.collector import PacedCollector
from gcs.fly.commander import Commander
from gcs.fly.delay import unmeasured_delay_lines
from gcs.fly.hover import HoverStart
from gcs.fly.measure import (
    TeamSample,
    command_heading_rad,
    drop_stale_neighbours,
    fresh_mask,
    level_rotations,
    normalised_thrust,
)
from gcs.fly.origins import TeamTies
from gcs.fly.records import Figures, log_notes
from gcs.fly.setpoints import Setpoints
from gcs.fly.setup import FlightSetup, true_mass_kg
from gcs.fly.stats import TickStats, log_due
from gcs.fly.telemetry import StatusSlices, team_sample, vehicle_statuses
from gcs.fly.telemetry import warm_up as sample_warm_up
from gcs.link import HotTable, VehicleProxy, fastpath
from gcs.metrics import formation_error, formation_error_m
from gcs.mission.machine import MissionMachine
from gcs.mission.plan import GATE_FORMATION, Phase

logger = logging.getLogger("gcs.fly")

#: The tick wakes this much before its deadline and blocks precisely for the rest (TickLoop.run).
WAKE_EARLY_S = 1.5e-3
#: The mission machine (checks, phase changes) runs at about this rate, on tick boundaries.
MACHINE_RATE_HZ = 20.0


def build_law(setup: FlightSetup) -> tuple[TeamLaw, np.ndarray, bool]:
    """The team's law as `setup` flies it, its Jhat(0) per vehicle [kg m^2] and whether it
    estimates Jhat. Position mode (law "autopilot") runs no law: the one built is never stepped."""
    team = setup.team
    baseline = setup.law == "baseline"
    adaptive = setup.law == "adaptive"
    vehicles = team.vehicles
    nominal = team.nominal_masses_kg() if baseline else None
    rhohat = np.array([v.baseline_inertia_kgm2 if baseline else v.estimates.inertia_kgm2
                       for v in vehicles], dtype=float)
    d = team.controller.derivative
    # rhohat acts only through the torque (26): in rates and attitude mode it is held
    inertia_estimated = adaptive and setup.mode in TORQUE_MODES
    law = TeamLaw(
        setup.gains, team.adjacency(), team.offsets_enu_m(), team.initial_mhat(), rhohat,
        nominal_mass_kg=nominal, adaptive=not baseline, derivative=d.method,
        levant_lipschitz=d.levant_lipschitz, levant_substep_s=d.levant_substep_s,
        estimate_inertia=inertia_estimated,
    )
    law.inertia_step_max_s = 1.0 / setup.tick_rate_hz  # (27) never steps over a skipped gap
    return law, rhohat, inertia_estimated


def law_arrays(team: TeamConfig) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """The reference velocity's arrays and the formation offsets [m, ENU] as the tick reads them."""
    return (tuple(np.ascontiguousarray(a, dtype=float)
                  for a in team.reference_velocity.as_arrays()),
            np.ascontiguousarray(team.offsets_enu_m(), dtype=float))


def warm_up(law: TeamLaw, team: TeamConfig, period_s: float) -> None:
    """Compile (or load from numba's cache) every kernel the flight runs, on throwaway
    copies: the law's, the prediction audit's, the team sample's and the formation error's
    in the tick, the error series' of the records at the end. Compiled in the first
    formation tick instead (a new machine's first flight), the audit's stalled it for 0.5 s
    and more on a loaded machine: every link then read as lost, and the formation stopped
    at its start."""
    scratch = copy.deepcopy(law)
    ref_arrays, offsets_m = law_arrays(team)
    n = team.n
    rotation = np.tile(np.eye(3), (n, 1, 1))
    meas = TeamSample(
        np.ascontiguousarray(team.initial_positions_enu_m(), dtype=float), np.zeros((n, 3)),
        np.zeros((n, 3)), rotation, np.zeros((n, 3)), np.zeros(n), np.zeros(n),
        np.ones(n, dtype=bool), np.zeros(n), np.zeros(n), np.zeros(n),
        np.zeros(n)).measurement()
    ref = reference_velocity(0.0, *ref_arrays)
    fresh = np.ones(n, dtype=bool)
    for _ in range(2):
        drop_stale_neighbours(scratch.graph, fresh, scratch.active_graph.weight)
        scratch.step(meas, ref, period_s)
    formation_error_m(meas.position_m, offsets_m)
    formation_error(meas.position_m[None], offsets_m)  # the records' series
    audit = PredictionAudit(n)
    taken = np.zeros(n)
    audit.record(0.0, meas, meas, taken)
    audit.observe(meas.position_m, meas.velocity_mps, taken, meas.rotation, meas.omega_radps,
                  taken)
    fastpath.warm_up()
    sample_warm_up()


class TickLoop:
    """The fixed-rate tick: `run` calls `tick(k, deadline_s, started_s)` on absolute deadlines
    t_start + k h of the event loop's clock until the mission machine is done, then sets
    `finished`; the formation's lateness and compute times go to `ticks`."""

    def __init__(self, machine: MissionMachine, period_s: float, ticks: TickStats,
                 tick: Callable[[int, float, float], None], finished: asyncio.Event) -> None:
        self.machine = machine
        self.period_s = period_s
        self.ticks = ticks
        self._tick = tick
        self._finished = finished

    async def run(self) -> None:
        """Fixed-rate tick on absolute deadlines t_start + k h; lateness recorded; a tick more
        than one period late is skipped (counted), never run twice."""
        loop = asyncio.get_running_loop()
        h = self.period_s
        margin = min(WAKE_EARLY_S, 0.25 * h)
        t_start = loop.time()
        k = 0
        try:
            # garbage collection between ticks, never in one (gcs/fly/collector.py)
            with PacedCollector() as collector:
                while not self.machine.done:
                    deadline = t_start + k * h
                    # asyncio's timers wake on a millisecond grid and after the I/O callbacks that
                    # are ready: wake `margin` early (telemetry handled meanwhile), then block for
                    # the sub-millisecond rest (time.sleep is precise and uses no CPU).
                    wait = deadline - loop.time() - margin
                    if wait > 0:
                        await asyncio.sleep(wait)
                    else:
                        await asyncio.sleep(0)  # let the telemetry callbacks run every tick
                    rest = deadline - loop.time()
                    if rest > 0:
                        time.sleep(rest)
                    started = loop.time()
                    behind = int((started - deadline) / h)
                    if behind >= 1:  # missed whole periods: jump to the newest deadline
                        if self.machine.phase is Phase.FORMATION:
                            self._stalled(behind, deadline)
                        k += behind
                        deadline = t_start + k * h
                    self._tick(k, deadline, started)
                    if self.machine.phase is Phase.FORMATION:  # the tick statistics of the report
                        self.ticks.record(started - deadline, loop.time() - started)
                    k += 1
                    collector.after_tick(t_start + k * h - loop.time(),
                                         bool(self.machine.streaming))
        finally:
            self._finished.set()

    def _stalled(self, periods: int, deadline_s: float) -> None:
        """Count the skipped ticks; a stall (gcs.fly.stats.STALL_S or longer) is logged: the
        vehicles flew it on their last setpoints."""
        t_s = self.machine.formation_time_s(deadline_s)
        t_s = math.nan if t_s is None else t_s
        gap_s = self.ticks.skip(periods, t_s)
        if gap_s is not None:
            logger.warning("tick: the ground station stopped for %.0f ms at t = %.2f s (%d ticks "
                           "skipped): the vehicles held their last setpoints meanwhile",
                           1e3 * gap_s, t_s, periods)


class LawRows(Protocol):
    """An agent's law team around the flight's own vehicles (gcs/agent/neighbours.py): the
    tick publishes its own states, and its law runs over the own rows plus neighbours' rows."""

    own_rows: np.ndarray

    def publish(self, sample: TeamSample) -> None: ...
    def fresh(self, own_fresh: np.ndarray, now_s: float) -> np.ndarray: ...
    def record_ages(self, now_s: float) -> None: ...
    def measurement(self, own: TeamMeasurement, act_s: float | None) -> TeamMeasurement: ...
    def heading(self, own_heading_rad: np.ndarray) -> np.ndarray: ...
    def own(self, command: TeamCommand) -> TeamCommand: ...


class Tick:
    """One tick of the team (`step`), and what it last saw and did (`last_sample`,
    `last_command`, `formation_error_m`, `formation_t_s`: the live status reads them).

    With `law_rows` (an agent's flight, gcs/agent/), the law runs over the agent's law team:
    the flight's own vehicles and their neighbours from the bus; only own rows are sent."""

    def __init__(self, setup: FlightSetup, machine: MissionMachine, law: TeamLaw,
                 ties: TeamTies, hot: HotTable, proxies: list[VehicleProxy],
                 commander: Commander, setpoints: Setpoints, figures: Figures,
                 law_rows: LawRows | None = None) -> None:
        team = setup.team
        self.law_rows = law_rows
        self.setup = setup
        self.team = team
        self.n = team.n
        self.ids = team.ids()
        self.period_s = 1.0 / setup.tick_rate_hz
        self.machine = machine
        self.law = law
        self.position_mode = setup.mode == ControlMode.POSITION
        self.ref_arrays, self.offsets_m = law_arrays(team)
        self.ties = ties
        self._tie_arrays = (None if team.frame.vehicles == "shared"
                            else (ties.offsets_enu_m, ties.rotations))
        self.hot = hot  # the team's hot telemetry, a row per link
        self.proxies = proxies  # the team's, in team order once the links are open
        self.commander = commander
        self.setpoints = setpoints
        self.figures = figures
        self.consistency = figures.consistency
        self.accel_consistency = figures.accel_consistency
        self.hover = HoverStart(setup, machine, law, hot, proxies, figures.hover_estimates,
                                None if law_rows is None else law_rows.own_rows)
        self._from_hover = setup.law == "adaptive" and any(v.estimates.from_hover
                                                           for v in team.vehicles)
        self.slots: FormationSlots | None = None  # position mode: fixed at the formation start
        self._slot_yaw_enu = np.zeros(self.n)  # position mode: the heading each slot holds
        # Before the formation starts (PRIME), vehicles get level, zero-rate setpoints at the
        # law's own initial mass estimate times g (what the law itself would ask at rest).
        kappa0 = (np.asarray(team.nominal_masses_kg(), dtype=float) if setup.law == "baseline"
                  else setup.gains.alpha_m * team.initial_mhat() / 2.0)
        self.prime_thrust_norm = normalised_thrust(kappa0 * GRAVITY_MPS2, setpoints.max_thrust_n)
        self.machine_every = max(1, round(setup.tick_rate_hz / MACHINE_RATE_HZ))
        self._status_slices = StatusSlices(team.n, self.machine_every)  # the mission's statuses
        self._clocks_in_table = False  # every proxy's clock filter writes its line into hot
        self.last_sample: TeamSample | None = None
        self.last_command: TeamCommand | None = None
        self.formation_error_m = math.nan
        self.formation_t_s: float | None = None
        self._k0: int | None = None
        self._next_log_k = 0  # the tick the flight log's next sample is due at (log_due)
        self._last_law_k: int | None = None
        self._notes_logged = 0

    def links_opened(self) -> None:
        """Once every proxy is open: read the clocks from the table if each proxy has its row."""
        self._clocks_in_table = all(p.slot == i for i, p in enumerate(self.proxies))

    def step(self, k: int, deadline_s: float, now_s: float) -> None:
        """Tick k: its deadline and its start `now_s` on the event loop's clock."""
        sample = team_sample(self.proxies, now_s, self.last_sample, self._tie_arrays, self.hot)
        self.last_sample = sample
        self.consistency.update(sample.position_m, sample.velocity_mps, sample.position_taken_s,
                                sample.finite)
        law_velocity = self.consistency.velocity(sample.velocity_mps)
        self.accel_consistency.update(law_velocity, sample.acceleration_mps2,
                                      sample.position_taken_s, sample.finite)
        if self.law_rows is not None:  # the own vehicles' states as this law reads them
            self.law_rows.publish(dataclasses.replace(
                sample, velocity_mps=law_velocity,
                acceleration_mps2=self.accel_consistency.corrected(sample.acceleration_mps2)))
        m = self.machine
        rows = self._status_slices.rows(k)
        if rows is None or rows:
            want_rates = (tuple(self.setup.plan.rules.required_rates_hz)
                          if m.phase in (Phase.CONNECT, Phase.PREFLIGHT) else ())
            judge = self.setup.delay_judge if m.phase is Phase.PREFLIGHT else None
            self._status_slices.store(rows, vehicle_statuses(
                self.proxies, self.ids, sample, want_rates, self.ties, judge, self.hot, rows=rows))
        if self._status_slices.due(k):
            self.commander.dispatch(m.on_tick(deadline_s, self._status_slices.latest(),
                                              self.formation_error_m))
            self._notes_logged = log_notes(m, self._notes_logged)
            self.setpoints.send_position_targets(sample)
        streaming = m.streaming
        if m.phase is Phase.PRIME and self._from_hover:
            self.hover.record()
        if m.law_active and (streaming or m.phase is Phase.FORMATION) and self.position_mode:
            self._fly_slots(k, sample, streaming)
        elif m.law_active and (streaming or m.phase is Phase.FORMATION):
            command = self._run_law(k, sample, now_s, deadline_s)
            if command is not None:
                self.setpoints.send(command, streaming)
        elif m.phase is Phase.PRIME and self.position_mode:
            self._prime_slots(sample, streaming)
        elif m.phase is Phase.PRIME:
            # level and still: zero rates or torque; in attitude mode, level at the heading
            level = (self.ties.rotations_to_local(level_rotations(sample.rotation))
                     if self.setup.mode == ControlMode.ATTITUDE else np.zeros((self.n, 3)))
            self.setpoints.send_vectors(level, np.asarray(self.prime_thrust_norm, dtype=float),
                                        streaming)

    # --- position mode: the formation slots (gcs/control/slots.py) ----------------------------

    def _fly_slots(self, k: int, sample: TeamSample, streaming: frozenset[int]) -> None:
        """Position mode from the formation start: c(0) fixed from the team's positions at its
        first tick, then every streaming vehicle gets its slot c(t) + theta_i, v_r(t), v_r'(t)
        and its heading (fly.heading); records as the law's, with no law figures."""
        if self._k0 is None:
            self._start_formation(k, sample)
            try:
                self.slots = FormationSlots.start(sample.position_m, self.offsets_m,
                                                  self.ref_arrays)
            except ValueError as exc:
                self.machine.request_abort(f"t = 0 s: {exc}", operator=False)
                return
            self._slot_yaw_enu = self.setpoints.yaw_enu(sample, self.team.fly.heading)
        if self.slots is None:  # the start failed: the flight is stopping, the failsafes act
            return
        t = (k - self._k0) * self.period_s
        targets = self.slots.at(t)
        self.formation_t_s = t
        log, self._next_log_k = log_due(k, self._k0, self.setup.log_every, self._next_log_k)
        if self.machine.phase is Phase.FORMATION:
            fresh = fresh_mask(sample, self.team.fly.stale_after_s)
            self.figures.ages.record(sample.delay_s, sample.age_s, fresh,
                                     np.zeros(self.n, dtype=np.int64))
            if log:
                self.log(t, sample, targets.velocity_enu_mps, None)
        self.setpoints.send_slots(targets, self._slot_yaw_enu, streaming)

    def _prime_slots(self, sample: TeamSample, streaming: frozenset[int]) -> None:
        """Position mode's PRIME: the slots of a formation starting now (no vehicle acts on them
        in its hold mode), so that PX4 has a recent setpoint when OFFBOARD is commanded."""
        try:
            targets = FormationSlots.start(sample.position_m, self.offsets_m,
                                           self.ref_arrays).at(0.0)
        except ValueError as exc:
            self.machine.request_abort(f"prime: {exc}", operator=False)
            return
        self.setpoints.send_slots(targets, self.setpoints.yaw_enu(sample, self.team.fly.heading),
                                  streaming)

    def _log_unmeasured_delays(self) -> None:
        """At the law's start: name the links whose delay no TIMESYNC round trip measured."""
        fly = self.team.fly
        for line in unmeasured_delay_lines(
                [(p.name, p.round_trips_s().size, p.stats().proxy.timesync_sent)
                 for p in self.proxies], fly.timesync_period_s, fly.link_delay_s):
            logger.warning("%s", line)

    def _start_formation(self, k: int, sample: TeamSample) -> None:
        """The formation's first tick k (t = 0): each go-to-start vehicle's distance from its
        start position then (the records)."""
        self._k0 = self._next_log_k = k
        for vid, r in self.machine.goto_results.items():
            i = self.team.index_of(vid)
            self.figures.start_error_m[vid] = float(np.linalg.norm(
                sample.position_m[i] - np.asarray(r.target_enu_m)))

    def _run_law(self, k: int, sample: TeamSample, now_s: float,
                 deadline_s: float) -> TeamCommand | None:
        if self._k0 is None:
            self._start_formation(k, sample)
            heading = command_heading_rad(self.team.fly.heading, sample.rotation)
            self.law.heading_rad = (heading if self.law_rows is None
                                    else self.law_rows.heading(heading))
            self._log_unmeasured_delays()
            if not self.hover.initial_mass(sample, now_s):
                return self.last_command
        # t from the first law tick; a team's agreed start (an agent's GATE_FORMATION time)
        # instead where there is one, so that every agent's v_r(t) is the same function of time
        agreed = self.machine.gate_time_s(GATE_FORMATION)
        t = (k - self._k0) * self.period_s if agreed is None else max(0.0, deadline_s - agreed)
        dt = (k - (self._last_law_k if self._last_law_k is not None else k - 1)) * self.period_s
        self._last_law_k = k
        fresh = fresh_mask(sample, self.team.fly.stale_after_s)
        rows = self.law_rows
        # the staleness rule, per edge and in place: the law's weights a_ij of this tick
        stale_neighbours = drop_stale_neighbours(
            self.law.graph, fresh if rows is None else rows.fresh(fresh, now_s),
            self.law.active_graph.weight)
        if rows is not None:
            stale_neighbours = stale_neighbours[rows.own_rows]
        ref = reference_velocity(t, *self.ref_arrays)
        meas = self._law_input(sample, now_s)
        try:
            # The estimators adapt only while the formation is flown: afterwards the vehicles
            # switch to their own modes (land/hold) and the thrust applied is no longer ours.
            command = self.law.step(meas, ref, dt, adapt=self.machine.phase is Phase.FORMATION)
        except SingularCommandError as exc:
            self.machine.request_abort(f"t = {t:.2f} s: {exc}", operator=False)
            return self.last_command
        if not (np.isfinite(command.thrust_n).all() and np.isfinite(command.rate_cmd_radps).all()
                and np.isfinite(command.torque_nm).all()):
            self.machine.request_abort(f"t = {t:.2f} s: the law produced a non-finite command",
                                       operator=False)
            return self.last_command
        if rows is not None:
            command = rows.own(command)
        self.last_command = command
        self.formation_t_s = t
        log, self._next_log_k = log_due(k, self._k0, self.setup.log_every, self._next_log_k)
        if self.machine.phase is Phase.FORMATION:
            self.figures.ages.record(sample.delay_s, sample.age_s, fresh, stale_neighbours)
            if rows is not None:
                rows.record_ages(now_s)
            self.consistency.update_figures()
            self.accel_consistency.update_figures()
            if log:
                self.log(t, sample, ref[0], command, now_s)
        return command

    def _law_input(self, sample: TeamSample, now_s: float) -> TeamMeasurement:
        """The samples as they are, or (fly.predict) predicted to when this tick's setpoints act:
        now plus the team's uplink delay (gcs/control/predict.py); in formation, the audit compares
        each prediction with what the vehicles report for that instant."""
        held = sample.measurement()
        if self.consistency.on:
            held = held._replace(velocity_mps=self.consistency.velocity(held.velocity_mps))
        if self.accel_consistency.on:
            held = held._replace(
                acceleration_mps2=self.accel_consistency.corrected(held.acceleration_mps2))
        if self.figures.audit is None:
            return held if self.law_rows is None else self.law_rows.measurement(
                held, None, own_taken_s=sample.position_taken_s)
        # each link's least one-way delay: the table's copy of the clock filters' (a column)
        least = (self.hot.clock_line[:, 3] if self._clocks_in_table
                 else np.array([p.clock.least_delay_s for p in self.proxies]))
        act = now_s + uplink_delay_s(least)
        h_pos = horizons_s(act, sample.position_taken_s)
        predicted = predict(held, h_pos, horizons_s(act, sample.attitude_taken_s))
        if self.machine.phase is Phase.FORMATION:
            self.figures.audit.observe(sample.position_m, sample.velocity_mps,
                                       sample.position_taken_s, sample.rotation,
                                       sample.omega_radps, sample.attitude_taken_s)
            self.figures.audit.record(act, predicted, held, h_pos)
        return predicted if self.law_rows is None else self.law_rows.measurement(predicted, act)

    def log(self, t: float, sample: TeamSample, ref_velocity_enu_mps: np.ndarray,
            c: TeamCommand | None, now_s: float | None = None) -> None:
        """One record sample; `c` None (position mode: no law) records its figures as NaN."""
        p = sample.position_m
        if now_s is not None:  # to the tick's instant; a lost link's sample stays where it was
            h = horizons_s(now_s, sample.position_taken_s)
            h[h > self.team.fly.link_lost_after_s] = 0.0
            carry = sample.velocity_mps * h[:, None]
            p = p + np.where(np.isfinite(carry), carry, 0.0)
        self.formation_error_m = formation_error_m(p, self.offsets_m)  # no (n, n, 3) array
        law = {} if c is None else {
            "attitude_error": c.attitude_error, "omega_error_radps": c.omega_error_radps,
            "mass_estimate_kg": c.mass_estimate_kg,
            "inertia_estimate_kgm2": c.inertia_estimate_kgm2, "thrust_n": c.thrust_n,
            "force_enu_n": c.force_n}
        self.figures.builder.append(t_s=t, position_enu_m=p,
                                    velocity_enu_mps=sample.velocity_mps,
                                    reference_velocity_enu_mps=ref_velocity_enu_mps,
                                    mass_true_kg=true_mass_kg(self.team, t), **law)
