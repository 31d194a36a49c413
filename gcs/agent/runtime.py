"""`gcs agent`'s flight: `gcs fly`'s flight of the agent's own vehicles, its law over its law
team (gcs/agent/neighbours.py), and `TeamWatch` beside it for the team around it.

`TeamWatch` is the agent's side of the supervisor's protocol (docs/agents.md):
* it publishes the agent's status (phase, the gate it waits at, why it stops, its outcome and,
  at the end, where its records are) at STATUS_RATE_HZ;
* it opens the mission machine's gates when the supervisor says so: GATE_FLIGHT at once,
  GATE_FORMATION at the agreed start, which the supervisor gives on its own clock and the agent
  turns into its own by the offset it measured from the heartbeats' echoes (before any, by the
  order's send time: off by the bus's one-way delay);
* it relays the supervisor's abort to the machine (with the action the supervisor names);
* it stops the flight with the team file's link-loss action (fly.link_loss_action) when the
  supervisor falls silent for network.supervisor_lost_after_s once heard, when no supervisor
  is heard within fly.connect_timeout_s, or, from PRIME on, when a neighbour's latest sample
  is older than fly.link_lost_after_s, or stamped further than that in the future (a clock
  that disagrees; with network.clocks disciplined, also one the echoes prove off). Until then
  the staleness rule (fly.stale_after_s, either way) keeps a late neighbour out of the law,
  tick by tick, as in `gcs fly`.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math
import resource
import time
from collections.abc import Callable
from typing import Any

from gcs.agent.bus import NeighbourBus
from gcs.agent.control import MAX_TEXT, Abort, Gate
from gcs.agent.neighbours import NeighbourRows
from gcs.agent.team import AgentTeam
from gcs.agent.wire import SUPERVISOR_ID
from gcs.config import ControlMode, TeamConfig
from gcs.fly.flight import Flight
from gcs.fly.sched import Scheduling, share_with_threads
from gcs.fly.setup import FlightSetup, FlightSetupError, FlyOptions, FlyResult, prepare
from gcs.mission.plan import GATE_FORMATION, GATES, Phase

logger = logging.getLogger("gcs.agent")

#: agent status messages per second
STATUS_RATE_HZ = 5.0
#: how often the watch wakes: gates, aborts and the loss rules act within this
WATCH_PERIOD_S = 0.02


def _cpu_s() -> float:
    """This process's processor time so far (user + system) [s]."""
    use = resource.getrusage(resource.RUSAGE_SELF)
    return round(use.ru_utime + use.ru_stime, 3)


def agent_setups(team: TeamConfig, own: tuple[int, ...], options: FlyOptions
                 ) -> tuple[AgentTeam, FlightSetup, FlightSetup]:
    """(the agent's share, its flight's setup, its law's setup): `gcs fly`'s set-up policy on
    the whole team (mode, gains, the loop criteria for every vehicle), then restricted to the
    own vehicles (links, machine with the team's gates, setpoints, records) and to the law
    team (own vehicles and their neighbours). FlightSetupError as `gcs fly`'s."""
    whole = prepare(team, options)
    if whole.mode == ControlMode.POSITION:
        raise FlightSetupError("position mode runs no law, so there is nothing to share among "
                               "agents: fly it with gcs fly (no --agents)")
    agent = AgentTeam(whole.team, own)
    # the formation check is the supervisor's: an agent sees only its own share of the team
    flight = dataclasses.replace(whole, team=agent.own_team, plan=dataclasses.replace(
        whole.plan, gates=frozenset(GATES), formation_max_error_m=math.inf))
    law = dataclasses.replace(whole, team=agent.law_team)
    return agent, flight, law


class TeamWatch:
    """The agent's side of the team (module docstring). `bus` is its NeighbourBus."""

    def __init__(self, flight: Flight, bus: NeighbourBus, rows: NeighbourRows,
                 team: TeamConfig, clock: Callable[[], float] = time.monotonic) -> None:
        self.flight = flight
        self.machine = flight.machine
        self.bus = bus
        self.rows = rows
        self.team = team
        self.clock = clock
        self.started_s = clock()
        self.events: list[dict[str, Any]] = []  # what the watch did, for the records
        # the supervisor's clock minus ours as the formation start was converted (None before)
        self.start_offset_s: float | None = None
        self._stopped_by_watch = False
        self._last_status_s = -1e9
        self.records: str | None = None
        self.final_outcome: tuple[int, str] | None = None

    # --- status ----------------------------------------------------------------------------------

    def publish_status(self) -> None:
        """Each own vehicle's status: the machine's phase and gate, why it stops, its end."""
        m = self.machine
        why = m.stop_reason if self.final_outcome is None else None
        code, text = ((why.exit_code, why.reason) if why is not None
                      else self.final_outcome or (None, None))
        waiting = m.waiting_at
        if waiting is not None and text is None:
            not_ready = self.not_ready(self.clock())
            if not_ready is not None:  # not ready for the team, and why
                waiting, text = None, not_ready
        for vid in self.rows.own_ids:
            self.bus.publish_status(
                vid, m.phase.value, waiting,
                None if text is None else " ".join(text.split())[:MAX_TEXT],
                exit_code=code, done=self.final_outcome is not None, records=self.records,
                formation_t_s=self.flight.tick.formation_t_s)

    def not_ready(self, now_s: float) -> str | None:
        """Why the agent may not report itself ready at a gate (None: it may): a clock that
        the echoes prove off (network.clocks disciplined; the supervisor's, whose formation
        start the agents would then not agree on, or a neighbour's), or neighbours unheard."""
        table = self.bus.table
        if (problem := table.clock_problem(SUPERVISOR_ID)) is not None:
            return problem
        missing = self.unheard(now_s)
        if not missing:
            return None
        problems = [p for vid in missing if (p := table.clock_problem(vid)) is not None]
        return (problems[0] if problems else
                f"waiting for neighbours {', '.join(map(str, missing))} on the bus")

    def unheard(self, now_s: float) -> list[int]:
        """The neighbours whose latest state is older than fly.link_lost_after_s (or never
        arrived with a known clock offset), or whose clock is not yet known to agree with
        ours (network.clocks disciplined): the agent does not report itself ready at a gate
        while there are any."""
        if not self.rows.neighbour_ids:
            return []
        state = self.bus.rows(self.rows.neighbour_ids, now_s)
        ages = now_s - state.taken_local_s
        bound = self.team.fly.link_lost_after_s
        table = self.bus.table
        return [vid for vid, a in zip(self.rows.neighbour_ids, ages, strict=True)
                if not a <= bound or not table.clock_known(vid)]

    def _note(self, what: str, **kw: Any) -> None:
        self.events.append({"t_since_start_s": round(self.clock() - self.started_s, 3),
                            "formation_t_s": self.flight.tick.formation_t_s, "event": what,
                            **kw})
        logger.warning("%s", what)

    # --- the supervisor's orders -------------------------------------------------------------

    def on_order(self, order: Gate | Abort, now_s: float) -> None:
        m = self.machine
        if isinstance(order, Gate):
            if order.name not in GATES or m.gate_open(order.name):
                return
            at = None
            if order.name == GATE_FORMATION:
                at = self.bus.supervisor_instant(order.opened_s)
                if not math.isfinite(at):  # no clock offset yet: the order's own send time
                    at = now_s + (order.opened_s - order.sent_s)
                self.start_offset_s = order.opened_s - self.bus.wire_s(at)
            m.open_gate(order.name, at)
            share_with_threads()  # threads the bus started for new connections since
            self._note(f"gate {order.name} opened by the supervisor",
                       **({} if at is None else {"starts_in_s": round(at - now_s, 3)}))
        elif m.phase not in (Phase.STOPPING, Phase.DONE):
            self._note(f"supervisor abort ({order.action}): {order.reason}")
            m.request_abort(f"supervisor: {order.reason}", operator=False, action=order.action)

    # --- the loss rules --------------------------------------------------------------------------

    def _stop(self, reason: str) -> None:
        if self._stopped_by_watch or self.machine.phase in (Phase.STOPPING, Phase.DONE):
            return
        self._stopped_by_watch = True
        self._note(reason)
        self.machine.request_abort(reason, operator=False,
                                   action=self.flight.setup.plan.link_loss_action)

    def check(self, now_s: float) -> None:
        m = self.machine
        if m.phase in (Phase.STOPPING, Phase.DONE):
            return
        net = self.team.network
        age = self.bus.supervisor_age_s(now_s)
        wait = self.flight.setup.plan.connect_timeout_s
        if not math.isfinite(age):
            if now_s - self.started_s > wait:
                self._stop(f"no supervisor heard within {wait:g} s (fly.connect_timeout_s)")
        elif age > net.supervisor_lost_after_s:
            self._stop(f"lost the supervisor: silent for {age:.2f} s > "
                       f"{net.supervisor_lost_after_s:g} s (network.supervisor_lost_after_s)")
        if m.phase in (Phase.PRIME, Phase.FORMATION) and self.rows.neighbour_ids:
            state = self.bus.rows(self.rows.neighbour_ids, now_s)
            ages = now_s - state.taken_local_s
            bound = self.team.fly.link_lost_after_s
            late = [(vid, float(a)) for vid, a in zip(self.rows.neighbour_ids, ages, strict=True)
                    if not -bound <= a <= bound]
            if late:
                words = ", ".join(f"vehicle {vid} ({self._lateness(vid, a)})" for vid, a in late)
                self._stop(f"neighbour lost: {words}, beyond {bound:g} s "
                           "(fly.link_lost_after_s)")

    def _lateness(self, vid: int, age_s: float) -> str:
        """How late neighbour `vid`'s state is, or why it has no time here."""
        if math.isfinite(age_s) and age_s < 0.0:
            return f"its sample {-age_s:.2f} s in the future: its clock disagrees with ours"
        if math.isfinite(age_s):
            return f"{age_s:.2f} s"
        problem = self.bus.table.clock_problem(vid)
        return "never heard" if problem is None else problem

    async def run(self, finished: asyncio.Event) -> None:
        """Until the flight is done: the supervisor's orders, the loss rules, the status."""
        period = 1.0 / STATUS_RATE_HZ
        while not finished.is_set():
            now = self.clock()
            while not self.bus.control.empty():
                self.on_order(self.bus.control.get_nowait(), now)
            self.check(now)
            if now - self._last_status_s >= period:
                self._last_status_s = now
                self.publish_status()
            await asyncio.sleep(WATCH_PERIOD_S)

    async def wait_for_supervisor(self) -> None:
        """Before the flight opens its links: announce the agent (loaded, its bus open) until
        the supervisor's heartbeat is heard, which it sends once every agent of the team is
        announced; so no vehicle's link is judged while another agent is still starting on
        the same machine. Returns after fly.connect_timeout_s regardless (the flight then
        stops on the missing supervisor)."""
        wait = self.flight.setup.plan.connect_timeout_s
        period = 1.0 / STATUS_RATE_HZ
        while (not math.isfinite(self.bus.supervisor_age_s(self.clock()))
               and self.clock() - self.started_s < wait):
            self.publish_status()
            await asyncio.sleep(period)

    async def final(self, result: FlyResult, repeat: int = 5) -> None:
        """After the records are written: the final status, a few times (a late subscriber)."""
        self.records = str(result.out_dir.resolve()) if result.log is not None else None
        self.final_outcome = (result.outcome.exit_code, result.outcome.reason)
        for _ in range(repeat):
            self.publish_status()
            await asyncio.sleep(1.0 / STATUS_RATE_HZ)

    def report(self) -> dict[str, Any]:
        """The records' `agent` section: own and neighbour vehicles, per neighbour its ages at
        use, the oldest sample the law used and the bus's figures; the watch's events."""
        ages = self.rows.ages
        p50, p99, top = (ages.percentiles_ms(q) for q in (50, 99, 100))
        stats = self.bus.stats()
        used = self.rows.age_used_max_s
        edges = {}
        for k, vid in enumerate(self.rows.neighbour_ids):
            fig = stats.get(vid)
            edges[str(vid)] = {
                "age_p50_ms": float(p50[k]), "age_p99_ms": float(p99[k]),
                "age_max_ms": float(top[k]), "stale_ticks": int(ages.stale_own[k]),
                "age_used_max_ms": 1e3 * float(used[k]) if math.isfinite(used[k]) else None,
                **({} if fig is None else {**dataclasses.asdict(fig),
                                           "loss_fraction": fig.loss_fraction})}
        return {"agent": {"vehicles": list(self.rows.own_ids),
                          "neighbours": list(self.rows.neighbour_ids), "edges": edges,
                          "unpublished_samples": self.rows.unpublished,
                          "bus_traffic": dict(self.bus.traffic),
                          "cpu_s": _cpu_s(), "wall_s": round(self.clock() - self.started_s, 3),
                          "clocks": self.bus.table.clocks.value,
                          "supervisor_offset_s": self.bus.offset(SUPERVISOR_ID),
                          # the echoes' measure of the supervisor's wire clock minus ours
                          "supervisor_offset_measured_s":
                              self.bus.table.clock(SUPERVISOR_ID).offset_s,
                          "formation_start_offset_s": self.start_offset_s,
                          "control_corrupt": self.bus.control_corrupt,
                          "events": self.events}}


async def fly_agent(team: TeamConfig, own: tuple[int, ...], options: FlyOptions,
                    status_factory: Callable[[Flight], Any] | None = None,
                    scheduling: Scheduling | None = None) -> FlyResult:
    """Fly the agent's vehicles with the team over its neighbour bus (`scheduling`: what the
    OS gave the process, for the records)."""
    agent, setup, law_setup = agent_setups(team, own, options)
    async with NeighbourBus.for_team(team, agent.own) as bus:
        share_with_threads()  # the bus's receive threads: the tick's priority (gcs/fly/sched.py)
        rows = NeighbourRows(agent, bus, team.fly.stale_after_s)
        flight = Flight(setup, options, status_factory, law_rows=rows, law_setup=law_setup)
        flight.scheduling = scheduling
        watch = TeamWatch(flight, bus, rows, team)
        flight.companions.append(watch.run)
        flight.report_more = watch.report
        await watch.wait_for_supervisor()
        result = await flight.run()
        await watch.final(result)
    return result
