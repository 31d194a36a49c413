"""`gcs fly --agents`: the supervisor of a team whose law runs in one agent per vehicle.

The supervisor never runs the law and holds no MAVLink link. Over the bus (docs/agents.md) it
* hears every agent's status and every vehicle's state sample;
* opens GATE_FLIGHT once every agent waits there (every vehicle passed its preflight), and
  GATE_FORMATION once every agent's vehicles hold at their start, with the formation start
  agreed as an instant on its own clock, `start_lead_s` ahead (each agent turns it into its
  own clock by the message's send time);
* relays an abort to every agent when one agent stops (its reason, naming its vehicles),
  when an agent falls silent for network.stale_after_s, or at Ctrl-C;
* sends a heartbeat every HEARTBEAT_PERIOD_S once every agent has announced itself (each agent
  opens its vehicles' links only then: no link is judged while another agent of the machine is
  still starting); it repeats the open gates and the abort, and by it the agents know the
  supervisor is there and measure their clock offsets to it;
* ends when every agent reported its outcome and records (or its process exited), then merges
  the records (gcs/agent/merge.py).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TextIO

import numpy as np

from gcs.agent.control import MAX_TEXT, Status
from gcs.config import TeamConfig
from gcs.metrics import formation_error_m
from gcs.mission.plan import EXIT_ABORTED, EXIT_INTERRUPTED, EXIT_OK, GATE_FLIGHT, GATE_FORMATION

__all__ = ["AgentState", "Supervisor", "SupervisorOutcome"]

#: how often the supervisor wakes
PERIOD_S = 0.02
#: between two heartbeats (network.supervisor_lost_after_s should be several of these)
HEARTBEAT_PERIOD_S = 0.1


@dataclass
class AgentState:
    """What the supervisor knows of one agent (the vehicles it flies): its first vehicle's
    latest status (an agent's vehicles share its phase)."""

    vehicles: tuple[int, ...]
    status: Status | None = None
    heard_s: float | None = None
    exited: int | None = None  # the process's exit status, when the supervisor started it
    gone: bool = False  # silent past network.stale_after_s before its outcome

    @property
    def name(self) -> str:
        ids = ", ".join(str(v) for v in self.vehicles)
        return f"agent of vehicle{'s' if len(self.vehicles) > 1 else ''} {ids}"

    @property
    def outcome(self) -> dict[str, Any] | None:
        """{exit_code, reason} once the agent's flight has ended."""
        s = self.status
        if s is None or not s.done:
            return None
        return {"exit_code": s.exit_code if s.exit_code is not None else EXIT_ABORTED,
                "reason": s.outcome or ""}

    @property
    def records(self) -> str | None:
        return self.status.records if self.status is not None else None

    @property
    def finished(self) -> bool:
        return self.gone or self.exited is not None or self.outcome is not None


@dataclass
class SupervisorOutcome:
    exit_code: int
    reason: str
    agents: list[AgentState]
    events: list[dict[str, Any]] = field(default_factory=list)
    max_error_after_m: float = math.nan


class Supervisor:
    """See the module docstring. `bus` is a SupervisorBus (gcs/agent/supervisor.py); `exits` gives,
    per agent, its process's exit status or None (agents the supervisor did not start: None)."""

    def __init__(self, team: TeamConfig, bus: Any, groups: list[tuple[int, ...]],
                 exits: Callable[[int], int | None], *, prime_s: float, connect_timeout_s: float,
                 follow: tuple[float, float, float] = (10.0, 1.0, 0.5),
                 stream: TextIO | None = None, clock: Callable[[], float] = time.monotonic,
                 start_lead_s: float = 1.0) -> None:
        self.team = team
        self.bus = bus
        self.agents = [AgentState(tuple(g)) for g in groups]
        self._of_vehicle = {v: a for a in self.agents for v in a.vehicles}
        self.exits = exits
        self.prime_s = prime_s
        self.connect_timeout_s = connect_timeout_s
        #: the team's formation_check (plan: check from t [s], max error [m], max fraction of
        #: the error at t = 0): an agent sees only its own vehicles' share of the formation
        self.follow = follow
        self._error_t0: float | None = None
        self.stream = stream
        self.clock = clock
        self.start_lead_s = start_lead_s
        self.events: list[dict[str, Any]] = []
        self.aborted: str | None = None
        self.interrupted = False
        self.formation_at_s: float | None = None
        self._flight_gate_sent = False
        self._started_s = clock()
        self._last_beat_s = -1e9
        self._last_line_s = -1e9
        self._stop = asyncio.Event()
        # compiled (or loaded from the cache) here, not in the first status line: a second's
        # load there would silence the heartbeats past network.supervisor_lost_after_s
        formation_error_m(np.ascontiguousarray(team.initial_positions_enu_m()),
                          np.ascontiguousarray(team.offsets_enu_m()))

    def _event(self, text: str) -> None:
        self.events.append({"t_s": round(self.clock() - self._started_s, 3), "event": text})
        if self.stream is not None:
            print(f"gcs fly --agents: {text}", file=self.stream, flush=True)

    def interrupt(self) -> None:
        """Ctrl-C: every agent gets the abort (its vehicles the abort action)."""
        self.interrupted = True
        self.abort("operator abort (Ctrl-C)")

    def abort(self, reason: str) -> None:
        """Every agent stops with the team file's abort action (repeated by the heartbeats)."""
        if self.aborted is None:
            self.aborted = reason
            self._event(f"abort to every agent: {reason}")
            self.bus.abort(reason[:MAX_TEXT], action=self.team.fly.abort_action)

    # --- one wake-up -----------------------------------------------------------------------------

    def _hear(self) -> None:
        while not self.bus.status_updates.empty():  # each vehicle's latest is in `statuses`
            self.bus.status_updates.get_nowait()
        for k, a in enumerate(self.agents):
            first = a.vehicles[0]
            status = self.bus.statuses.get(first)
            if status is not None:
                a.status, a.heard_s = status, self.bus.status_received_s[first]
            if a.exited is None:
                a.exited = self.exits(k)

    def _gates(self, now: float) -> None:
        live = [a for a in self.agents if a.status is not None]
        if len(live) < len(self.agents):
            return
        waits = [a.status.waiting_gate for a in live]
        if not self._flight_gate_sent and all(w == GATE_FLIGHT for w in waits):
            self._flight_gate_sent = True
            self._event("every agent passed its preflight: flight gate opened")
            self.bus.open_gate(GATE_FLIGHT)
        if self.formation_at_s is None and all(w == GATE_FORMATION for w in waits):
            self.formation_at_s = now + self.prime_s + self.start_lead_s
            self._event(f"every vehicle holds at its start: the formation starts in "
                        f"{self.prime_s + self.start_lead_s:.1f} s")
            self.bus.open_gate(GATE_FORMATION, at_s=self.formation_at_s)

    def _watch(self, now: float) -> None:
        stale = self.team.network.stale_after_s
        for a in self.agents:
            if (a.heard_s is not None and not a.finished and not a.gone
                    and now - a.heard_s > stale):
                a.gone = True
                self._event(f"{a.name} silent for {now - a.heard_s:.2f} s > {stale:g} s "
                            "(network.stale_after_s): taken as gone")
        if self.aborted is not None:
            return
        for a in self.agents:
            s = a.status
            out = a.outcome
            if out is not None and out["exit_code"]:
                self.abort(f"{a.name} stopped: {out['reason']}")
                return
            if s is not None and not s.done and s.exit_code:
                self.abort(f"{a.name} stopping: {s.outcome}")
                return
            if a.exited is not None and out is None:
                self.abort(f"{a.name} exited with status {a.exited} without an outcome")
                return
            if a.heard_s is None:
                if now - self._started_s > self.connect_timeout_s:
                    self.abort(f"{a.name} not heard within {self.connect_timeout_s:g} s")
                    return
            elif a.gone:
                self.abort(f"{a.name} silent for {now - a.heard_s:.2f} s > {stale:g} s "
                           "(network.stale_after_s)")
                return

    def _following(self, now: float) -> None:
        """The team's formation error, from every vehicle's state on the bus, must fall as the
        law predicts (gcs fly's fly.formation_check, here over the whole team)."""
        if self.formation_at_s is None or self.aborted is not None or now < self.formation_at_s:
            return
        rows = self.bus.rows(self.team.ids(), now)
        if not bool(np.all(rows.finite)):
            return
        err = formation_error_m(np.ascontiguousarray(rows.position_enu_m),
                                np.ascontiguousarray(self.team.offsets_enu_m()))
        if self._error_t0 is None:
            self._error_t0 = err
        check_s, most_m, fraction = self.follow
        t = now - self.formation_at_s
        bound = max(most_m, fraction * self._error_t0)
        if t >= check_s and err > bound and all(a.outcome is None for a in self.agents):
            self.abort(f"the vehicles do not follow the formation: error {err:.2f} m at t = "
                       f"{t:.1f} s > {bound:.2f} m = max({most_m:g} m, {fraction:g} x "
                       f"{self._error_t0:.2f} m at t = 0) (fly.formation_check)")

    def _ready_in_time(self, now: float) -> None:
        """Every agent at the flight gate within connect_timeout_s of the start, else abort
        naming those that are not and why (their status says, e.g. a neighbour unheard)."""
        if self._flight_gate_sent or self.formation_at_s is not None or self.aborted is not None:
            return
        if now - self._started_s <= self.connect_timeout_s:
            return
        late = [f"{a.name} ({a.status.phase}"
                + (f": {a.status.outcome}" if a.status.outcome else "") + ")"
                for a in self.agents
                if a.status is not None and a.status.waiting_gate != GATE_FLIGHT]
        if late:
            self.abort(f"not every agent ready within {self.connect_timeout_s:g} s: "
                       + "; ".join(late))

    def _line(self, now: float) -> None:
        if self.stream is None or now - self._last_line_s < 1.0:
            return
        self._last_line_s = now
        ids = self.team.ids()
        rows = self.bus.rows(ids, now)
        phases = " ".join(f"{a.vehicles[0]}:{a.status.phase if a.status else '-'}"
                          for a in self.agents)
        err = (formation_error_m(np.ascontiguousarray(rows.position_enu_m),
                                 self.team.offsets_enu_m())
               if bool(np.all(rows.finite)) else math.nan)
        t = None if self.formation_at_s is None else now - self.formation_at_s
        when = "" if t is None else f" t={t:6.1f}s"
        print(f"gcs fly --agents:{when} formation error {err:.3f} m; {phases}",
              file=self.stream, flush=True)

    def step(self) -> bool:
        """One wake-up; True when every agent has finished."""
        now = self.clock()
        self._hear()
        # heartbeats once every agent is announced (each waits for the first before opening
        # its vehicles' links), or to carry an abort
        everyone = all(a.status is not None for a in self.agents)
        if (everyone or self.aborted is not None) and now - self._last_beat_s >= HEARTBEAT_PERIOD_S:
            self._last_beat_s = now
            self.bus.heartbeat()  # repeats the open gates and the abort
        if self.aborted is None:
            self._gates(now)
        self._watch(now)
        self._ready_in_time(now)
        self._following(now)
        self._line(now)
        return all(a.finished for a in self.agents)

    async def run(self) -> SupervisorOutcome:
        while not self.step():
            await asyncio.sleep(PERIOD_S)
        return self.outcome()

    def outcome(self) -> SupervisorOutcome:
        codes = []
        reasons = []
        for a in self.agents:
            out = a.outcome
            if out is None:
                codes.append(EXIT_ABORTED)
                why = "silent" if a.gone else f"exit status {a.exited}"
                reasons.append(f"{a.name}: no outcome ({why})")
            else:
                codes.append(int(out.get("exit_code", EXIT_ABORTED)))
                if out.get("exit_code"):
                    reasons.append(f"{a.name}: {out.get('reason')}")
        code = max(codes) if codes else EXIT_ABORTED
        if self.interrupted:
            code = EXIT_INTERRUPTED
        if code == EXIT_OK:
            reason = "formation complete (every agent)"
        else:
            reason = "; ".join(([self.aborted] if self.aborted else []) + reasons)
        return SupervisorOutcome(code, reason, self.agents, self.events)
