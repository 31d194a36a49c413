"""`gcs agent`'s flight: `gcs fly`'s flight of the agent's own vehicles, its law over its law
team (gcs/agent/neighbours.py), and `TeamWatch` beside it for the team around it.

`TeamWatch` is the agent's side of the supervisor's protocol (docs/agents.md):
* it publishes the agent's status (phase, the gate it waits at, why it stops, its outcome and,
  at the end, where its records are) at STATUS_RATE_HZ;
* it opens the mission machine's gates when the supervisor says so: GATE_FLIGHT at once,
  GATE_FORMATION at the agreed start, which the supervisor gives on its own clock and the agent
  turns into its own by the message's send time (the difference is the bus's one-way delay);
* it relays the supervisor's abort to the machine (the plan's abort action);
* it stops the flight with the team file's link-loss action (fly.link_loss_action) when the
  supervisor falls silent for network.supervisor_lost_after_s once heard, when no supervisor
  is heard within fly.connect_timeout_s, or, from PRIME on, when a neighbour's latest sample
  is older than fly.link_lost_after_s. Until then the staleness rule (fly.stale_after_s)
  keeps a late neighbour out of the law, tick by tick, as in `gcs fly`.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from gcs.agent.neighbours import NeighbourRows, NeighbourSource
from gcs.agent.team import AgentTeam
from gcs.config import ControlMode, TeamConfig
from gcs.fly.flight import Flight
from gcs.fly.setup import FlightSetup, FlightSetupError, FlyOptions, FlyResult, prepare
from gcs.mission.plan import GATES, Phase

logger = logging.getLogger("gcs.agent")

#: agent status messages per second (and the supervisor's heartbeats)
STATUS_RATE_HZ = 5.0
#: how often the watch wakes: gates, aborts and the loss rules act within this
WATCH_PERIOD_S = 0.02


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
    flight = dataclasses.replace(whole, team=agent.own_team,
                                 plan=dataclasses.replace(whole.plan, gates=frozenset(GATES)))
    law = dataclasses.replace(whole, team=agent.law_team)
    return agent, flight, law


class TeamWatch:
    """The agent's side of the team (module docstring)."""

    def __init__(self, flight: Flight, bus: Any, rows: NeighbourRows, team: TeamConfig,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.flight = flight
        self.machine = flight.machine
        self.bus = bus
        self.rows = rows
        self.team = team
        self.clock = clock
        self.started_s = clock()
        self.supervisor_heard_s: float | None = None
        self.events: list[dict[str, Any]] = []  # what the watch did, for the records
        self._stopped_by_watch = False
        self._last_status_s = -1e9
        self.records: str | None = None

    # --- status ----------------------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        m = self.machine
        why = m.stop_reason
        return {
            "kind": "status", "vehicles": list(self.rows.own_ids), "phase": m.phase.value,
            "waiting_at": m.waiting_at, "formation_t_s": self.flight.tick.formation_t_s,
            "stopping": None if why is None else {"exit_code": why.exit_code,
                                                   "reason": why.reason},
            "done": m.done, "records": self.records, "sent_s": self.clock(),
        }

    def _note(self, what: str, **kw: Any) -> None:
        t = self.flight.tick.formation_t_s
        self.events.append({"t_since_start_s": round(self.clock() - self.started_s, 3),
                            "formation_t_s": t, "event": what, **kw})
        logger.warning("%s", what)

    # --- the supervisor's messages -----------------------------------------------------------

    def on_message(self, msg: dict[str, Any], rx_s: float) -> None:
        kind = msg.get("kind")
        self.supervisor_heard_s = rx_s
        m = self.machine
        if kind == "gate":
            gate = msg["gate"]
            if gate in GATES and not m.gate_open(gate):
                at = msg.get("at_s")
                local = None if at is None else rx_s + (float(at) - float(msg["sent_s"]))
                m.open_gate(gate, local)
                self._note(f"gate {gate} opened by the supervisor", at_local_s=local)
        elif kind == "abort" and m.phase not in (Phase.STOPPING, Phase.DONE):
            self._note(f"supervisor abort: {msg.get('reason', '')}")
            m.request_abort(f"supervisor: {msg.get('reason', 'abort')}", operator=False)

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
        heard = self.supervisor_heard_s
        if heard is None:
            wait = self.flight.setup.plan.connect_timeout_s
            if now_s - self.started_s > wait:
                self._stop(f"no supervisor heard within {wait:g} s (fly.connect_timeout_s)")
        elif now_s - heard > net.supervisor_lost_after_s:
            self._stop(f"lost the supervisor: silent for {now_s - heard:.2f} s > "
                       f"{net.supervisor_lost_after_s:g} s (network.supervisor_lost_after_s)")
        if m.phase in (Phase.PRIME, Phase.FORMATION) and self.rows.neighbour_ids:
            state = self.bus.rows(self.rows.neighbour_ids, now_s)
            age = now_s - state.taken_s
            bound = self.team.fly.link_lost_after_s
            late = [(vid, float(a)) for vid, a in zip(self.rows.neighbour_ids, age, strict=True)
                    if not a <= bound]
            if late:
                words = ", ".join(
                    f"vehicle {vid} ({f'{a:.2f} s' if np.isfinite(a) else 'never heard'})"
                    for vid, a in late)
                self._stop(f"neighbour lost: {words} older than {bound:g} s "
                           "(fly.link_lost_after_s)")

    async def run(self, finished: asyncio.Event) -> None:
        """Until the flight is done: the supervisor's messages, the loss rules, the status."""
        period = 1.0 / STATUS_RATE_HZ
        while not finished.is_set():
            for msg, rx_s in self.bus.take_control():
                self.on_message(msg, rx_s)
            now = self.clock()
            self.check(now)
            if now - self._last_status_s >= period:
                self._last_status_s = now
                self.bus.publish_status(self.status())
            await asyncio.sleep(WATCH_PERIOD_S)

    async def final(self, result: FlyResult, repeat: int = 5) -> None:
        """After the records are written: the final status, a few times (a late subscriber)."""
        self.records = str(result.out_dir) if result.log is not None else None
        for _ in range(repeat):
            self.bus.publish_status({**self.status(), "done": True, "outcome": {
                "exit_code": result.outcome.exit_code, "reason": result.outcome.reason}})
            await asyncio.sleep(1.0 / STATUS_RATE_HZ)

    def report(self) -> dict[str, Any]:
        """The records' `agent` section: own and neighbour vehicles, the neighbours' ages at
        use and the bus's per-edge figures, the watch's events."""
        ages = self.rows.ages
        p50, p99, top = (ages.percentiles_ms(q) for q in (50, 99, 100))
        stats = self.bus.stats()
        edges = {}
        for k, vid in enumerate(self.rows.neighbour_ids):
            edges[str(vid)] = {"age_p50_ms": float(p50[k]), "age_p99_ms": float(p99[k]),
                               "age_max_ms": float(top[k]),
                               "stale_ticks": int(ages.stale_own[k]),
                               "age_used_max_ms": (1e3 * float(self.rows.age_used_max_s[k])
                                                   if np.isfinite(self.rows.age_used_max_s[k])
                                                   else None),
                               **stats.get(vid, {})}
        return {"agent": {"vehicles": list(self.rows.own_ids),
                          "neighbours": list(self.rows.neighbour_ids), "edges": edges,
                          "events": self.events}}


async def fly_agent(team: TeamConfig, own: tuple[int, ...], options: FlyOptions,
                    open_bus: Callable[[AgentTeam], Any],
                    status_factory: Callable[[Flight], Any] | None = None) -> FlyResult:
    """Fly the agent's vehicles with the team: the bus opened by `open_bus(agent)` (an async
    context manager giving a NeighbourSource with the control channel)."""
    agent, setup, law_setup = agent_setups(team, own, options)
    async with open_bus(agent) as bus:
        source: NeighbourSource = bus
        rows = NeighbourRows(agent, source, team.fly.stale_after_s)
        flight = Flight(setup, options, status_factory, law_rows=rows, law_setup=law_setup)
        watch = TeamWatch(flight, bus, rows, team)
        flight.companions.append(watch.run)
        flight.report_more = watch.report
        result = await flight.run()
        await watch.final(result)
    return result
