"""The flight sequence of `gcs fly` as an explicit, pure state machine (sans-IO).

Phases: CONNECT -> PREFLIGHT -> [ARM -> TAKEOFF] -> [GOTO] -> [HOLD] -> PRIME -> FORMATION ->
STOPPING -> DONE.

Each vehicle is driven through its autopilot's profile (gcs.mission.autopilots, chosen from its
HEARTBEAT.autopilot and fixed at preflight): "offboard" below means the profile's offboard mode
(PX4 OFFBOARD, ArduPilot GUIDED_NOGPS), or, when the plan's control mode is `position` (the
baseline: position setpoints, no law), its position mode (PX4 OFFBOARD, ArduPilot GUIDED;
`offboard_mode`); "hold" its hold mode (PX4 AUTO_LOITER, ArduPilot BRAKE).

The machine never touches a socket or a clock. The composition root (gcs/fly/flight.py) feeds it
`on_tick(now_s, team)` with every vehicle's `VehicleStatus` as received, `on_result(...)` when a
command it asked for finished, and `request_abort(...)` for Ctrl-C or the abort key; it executes the
`Command`s the machine returns, streams setpoints to the vehicles in `streaming`, and runs the law
while `law_active`. Rules (docs/gcs.md):

* At most one command is outstanding per vehicle (so a late OFFBOARD ack cannot override a LAND).
* Setpoints stream to a vehicle from PRIME until it has acknowledged its stop command (LAND or
  HOLD) AND reported a mode other than offboard: a vehicle is never left in offboard without
  setpoints while its link is up. A lost vehicle gets nothing (its own offboard-loss failsafe acts).
* Go to start (GOTO, gcs.mission.goto): the vehicles the plan's `go_to_start` names (by default
  those that took off) get position setpoints (`position_targets`, team ENU) towards their
  team-file start positions, first vertically, then across; the setpoints stream before the
  profile's position mode is commanded (PX4 OFFBOARD, ArduPilot GUIDED); once every one has
  settled they go to hold (HOLD phase) and PRIME starts from there. A vehicle that got position
  setpoints keeps getting them, in GOTO, HOLD and STOPPING, until it has acknowledged its hold
  or stop command AND reports a mode other than its position mode.
* Priming is inert: before PRIME, an airborne vehicle whose autopilot would act on the priming
  setpoints at once (ArduPilot in GUIDED, e.g. after its takeoff) is switched to hold (HOLD phase).
* Autopilot parameters the profile requires (ArduPilot GUID_OPTIONS) are read in PREFLIGHT
  (READ_PARAMS) and checked with the other preflight rules; so is the firmware version
  (IDENTIFY, AUTOPILOT_VERSION) when the control mode depends on it (PX4 >= 1.14 ignores
  actuator setpoints: `actuators` is refused there).
* Commands count when the vehicle shows them (the composition root confirms every mode change
  and arming in HEARTBEAT, reading every COMMAND_ACK). Before arming, a vehicle is put in its
  profile's `arm_mode` (PX4 Hold: after a failsafe landing PX4 sits in OFFBOARD, disarmed, and
  refuses to arm there); arming waits for the pre-arm checks where the autopilot reports them
  reliably (PX4's SYS_STATUS bit) and is retried every `arm_retry_s` while the answer means "not
  ready yet" (profile.arm_retryable), up to `arm_timeout_s`; each vehicle takes off as soon as it
  is armed. Takeoff is complete when the vehicle reports IN_AIR, its post-takeoff mode and a
  height above its takeoff point (GLOBAL_POSITION_INT relative_alt, else the rise of its local
  z since arming) within `takeoff_tolerance_m` of the altitude asked.
* A formation never ends "complete" unless every vehicle reported the offboard mode, and for
  t >= `formation_check_s` the formation error stays at or below max(`formation_max_error_m`,
  `formation_max_fraction` x its value at t = 0) (docs/gcs.md, "Did the vehicles follow?").
* Any problem (failed check, rejected command, geofence, tilt, lost link, operator abort) moves to
  STOPPING: the lost vehicles are left to their failsafe, the others get `abort_action` (or
  `link_loss_action` when the cause is a lost link), and the outcome is non-zero with the reason.
* A second abort request while STOPPING ends at once (the autopilots' failsafes take over).

`MissionMachine` alone owns the state; it takes the inputs, answers the queries and steps the
CONNECT, PRIME and FORMATION phases itself. The other phases' steps are functions of the machine,
one module per stage: gcs.mission.preflight (PREFLIGHT), gcs.mission.takeoff (ARM, TAKEOFF),
gcs.mission.start (GOTO, HOLD), gcs.mission.stopping (STOPPING, DONE). Its interface types are in
gcs.mission.plan, its per-vehicle records in gcs.mission.progress, its longer lines in
gcs.mission.lines; this module re-exports the names callers import from it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from gcs.config.modes import FlyAction
from gcs.mission.autopilots import PX4, AutopilotProfile, ModeSpec, profile_for
from gcs.mission.connect import connect
from gcs.mission.formation import formation, prime
from gcs.mission.goto import GotoResult, GoToStart, Vec3
from gcs.mission.landed import quiet_mode_cause
from gcs.mission.lines import (
    CONNECT_SHOW_WAITING,
    connect_failure_line,
    connect_progress_line,
    connect_waiting_label,
)
from gcs.mission.plan import (
    EXIT_ABORTED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    Cmd,
    Command,
    CommandResult,
    MissionPlan,
    NoteLevel,
    Outcome,
    Phase,
)
from gcs.mission.preflight import preflight
from gcs.mission.progress import VehicleProgress
from gcs.mission.safety import Problem, SustainedDelays, VehicleStatus, flight_problems
from gcs.mission.start import go_to_start, hold, update_goto_vehicle
from gcs.mission.stopping import begin_stop, finish, stopping
from gcs.mission.takeoff import arm_and_take_off, takeoff

__all__ = [
    "CONNECT_SHOW_WAITING",
    "EXIT_ABORTED",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "HOLD_MODE",
    "OFFBOARD_MODE",
    "Cmd",
    "Command",
    "CommandResult",
    "MissionMachine",
    "MissionPlan",
    "NoteLevel",
    "Outcome",
    "Phase",
    "connect_failure_line",
    "connect_waiting_label",
]

# PX4's names, kept for callers; the machine reads each vehicle's own from its profile.
HOLD_MODE = PX4.hold.name
OFFBOARD_MODE = PX4.offboard.name


@dataclass(slots=True)
class MissionMachine:
    """See the module docstring. Time (`now_s`) is any monotonic clock in seconds."""

    plan: MissionPlan
    vehicle_ids: tuple[int, ...]
    phase: Phase = Phase.CONNECT
    formation_t0_s: float | None = None
    outcome: Outcome | None = None
    notes: list[str] = field(default_factory=list)  # human-readable events, newest last
    note_levels: list[NoteLevel] = field(default_factory=list)  # notes[k]'s level
    _v: dict[int, VehicleProgress] = field(default_factory=dict)
    _phase_since_s: float | None = None
    _configured_s: float | None = None  # PREFLIGHT: when the CONFIGURE commands had all ended
    _now_s: float = 0.0
    _abort: list[tuple[str, int, FlyAction | None]] = field(default_factory=list)
    _stop_reason: Outcome | None = None
    _stopping_since_s: float = 0.0
    _interrupts: int = 0
    _held: tuple[int, ...] = ()  # vehicles sent to hold in the HOLD phase
    _arming: tuple[int, ...] = ()  # vehicles that arm and take off
    _waiting_ready: bool = False  # PREFLIGHT waits for vehicles on the ground not ready yet
    _formation_error_m: float = math.nan  # latest, from the composition root
    _error_t0: float | None = None  # formation error at the formation start
    _goto: GoToStart | None = None  # the team's go-to-start progress
    _delays: SustainedDelays = field(default_factory=SustainedDelays)
    #: the gate (plan.gates) the machine waits at now, None when it waits at none
    waiting_at: str | None = None
    _gates_open: dict[str, float | None] = field(default_factory=dict)  # gate -> its time

    def __post_init__(self) -> None:
        self._v = {vid: VehicleProgress() for vid in self.vehicle_ids}

    # --- queries ---------------------------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    @property
    def law_active(self) -> bool:
        """The law runs (and its states advance) from the formation start until the end."""
        return self.formation_t0_s is not None and self.phase is not Phase.DONE

    @property
    def streaming(self) -> frozenset[int]:
        """Vehicles that must get a setpoint this tick."""
        if self.phase is Phase.PRIME or self.phase is Phase.FORMATION:
            return frozenset(vid for vid, v in self._v.items() if not v.lost)
        if self.phase is Phase.STOPPING:
            return frozenset(
                vid for vid, v in self._v.items()
                if not v.lost and v.offboard_sent and v.stop is not None
                and not (v.stop.acked and v.status is not None and not self._in_offboard(vid))
            )
        return frozenset()

    @property
    def position_targets(self) -> dict[int, tuple[Vec3, Vec3]]:
        """Vehicles that must get a position setpoint this tick: (position [m], velocity
        feed-forward [m/s]), team ENU; in
        GOTO every vehicle going to its start; afterwards (HOLD, STOPPING) each until it has
        acknowledged its hold or stop command and left its position mode. Never a vehicle that
        is in `streaming`."""
        g = self._goto
        if g is None or self.phase not in (Phase.GOTO, Phase.HOLD, Phase.STOPPING):
            return {}
        out = {}
        for vid, v in self._v.items():
            if v.goto is not None and not v.lost and not v.goto.released:
                out[vid] = g.target(vid, self._now_s)
        return out

    @property
    def goto_results(self) -> dict[int, GotoResult]:
        """Per vehicle that went to its start: target, final error and speed, time taken."""
        return dict(self._goto.results) if self._goto is not None else {}

    @property
    def stop_reason(self) -> Outcome | None:
        """Why the machine is stopping (from STOPPING on; the outcome once DONE)."""
        return self.outcome or self._stop_reason

    @property
    def lost(self) -> frozenset[int]:
        return frozenset(vid for vid, v in self._v.items() if v.lost)

    def profile(self, vehicle_id: int) -> AutopilotProfile:
        """The vehicle's autopilot profile: fixed at preflight from its HEARTBEAT.autopilot;
        before that (or for an autopilot without a profile) the one its latest status names,
        else PX4's."""
        v = self._v[vehicle_id]
        if v.profile is not None:
            return v.profile
        found = profile_for(v.status.autopilot) if v.status is not None else None
        return found if found is not None else PX4

    def offboard_mode(self, vehicle_id: int) -> ModeSpec:
        """The mode the vehicle flies the formation's setpoints in (Cmd.OFFBOARD): the profile's
        offboard mode, or in position mode its position mode (ArduPilot GUIDED, not
        GUIDED_NOGPS; PX4 OFFBOARD either way)."""
        return self.profile(vehicle_id).flies_in(self.plan.control_mode)

    def _in_offboard(self, vehicle_id: int) -> bool:
        s = self._v[vehicle_id].status
        return s is not None and s.mode == self.offboard_mode(vehicle_id).name

    def formation_time_s(self, now_s: float) -> float | None:
        return None if self.formation_t0_s is None else now_s - self.formation_t0_s

    # --- inputs ----------------------------------------------------------------------------------

    def request_abort(self, reason: str, *, operator: bool = True,
                      action: FlyAction | None = None) -> None:
        """Ctrl-C, the abort key (operator) or an outside failure; acted on at the next tick.
        `action` replaces the plan's abort action (e.g. the link-loss action when the team
        around this machine, not a vehicle of its own, was lost)."""
        code = EXIT_INTERRUPTED if operator else EXIT_ABORTED
        if self.phase is Phase.STOPPING and operator:
            self._interrupts += 1
        self._abort.append((reason, code, action))

    def open_gate(self, gate: str, at_s: float | None = None) -> None:
        """Let the machine pass `gate` (plan.gates); for GATE_FORMATION, `at_s` is the agreed
        formation start on this machine's clock (PRIME streams until then)."""
        self._gates_open[gate] = at_s

    def gate_time_s(self, gate: str) -> float | None:
        return self._gates_open.get(gate)

    def gate_open(self, gate: str) -> bool:
        return gate in self._gates_open

    def _gate(self, gate: str) -> bool:
        """True while the machine must wait at `gate`: one of the plan's, not opened yet."""
        if gate not in self.plan.gates or gate in self._gates_open:
            if self.waiting_at == gate:
                self.waiting_at = None
            return False
        if self.waiting_at != gate:
            self.waiting_at = gate
            self._note(f"waiting for the team at the {gate} gate")
        return True

    def on_result(self, result: CommandResult) -> list[Command]:
        """A command finished (acknowledged, rejected or timed out)."""
        v = self._v[result.vehicle_id]
        if v.pending is result.cmd:
            v.pending = None
        if not result.ok:
            self._note(f"vehicle {result.vehicle_id}: {result.cmd.value} failed: {result.detail}")
        if result.cmd is Cmd.READ_PARAMS and result.ok:
            v.params = dict(result.values)
        if result.cmd is Cmd.IDENTIFY and result.ok:
            v.version = int(dict(result.values)["flight_sw_version"])
        if result.cmd is Cmd.ARM and self.phase is Phase.ARM and v.arm is not None:
            if result.ok:
                v.arm.armed = True
                return self._drive()
            v.arm.last_result = result.result or "FAILED"
            if self.profile(result.vehicle_id).arm_retryable(v.arm.last_result, result.text):
                return self._drive()  # not ready yet: tried again after arm_retry_s
        if result.cmd in (Cmd.HOLD, Cmd.LAND) and result.ok and v.goto is not None:
            v.goto.hold_acked = True
            update_goto_vehicle(self, result.vehicle_id)
        if result.cmd is Cmd.OFFBOARD:
            v.offboard_acked = result.ok
            if not result.ok and self.phase is Phase.FORMATION:
                name = self.offboard_mode(result.vehicle_id).name
                begin_stop(self, [Problem(result.vehicle_id, f"vehicle {result.vehicle_id}: {name} "
                                                             f"refused: {result.detail}")],
                           EXIT_ABORTED)
        elif self.phase is Phase.STOPPING and v.stop is not None and result.cmd in (
            Cmd.LAND, Cmd.HOLD
        ):
            if result.ok:
                v.stop.acked = True
            elif v.stop.attempts >= self.plan.command_attempts:
                v.stop.done = True
                v.stop.failure = f"{result.cmd.value} not accepted ({result.detail})"
        elif not result.ok and self.phase in (Phase.CONNECT, Phase.PREFLIGHT, Phase.ARM,
                                              Phase.TAKEOFF, Phase.GOTO, Phase.HOLD):
            cause = (quiet_mode_cause(v.profile, v.status) if result.cmd is Cmd.ARM_MODE
                     and v.profile is not None and v.status is not None else None)
            begin_stop(self, [Problem(result.vehicle_id, (f"{cause}; " if cause else "")
                                      + f"vehicle {result.vehicle_id}: {result.cmd.value} "
                                        f"failed: {result.detail}")],
                       EXIT_ABORTED)
        return self._drive()

    def on_tick(self, now_s: float, team: Sequence[VehicleStatus],
                formation_error_m: float = math.nan) -> list[Command]:
        """Advance with the latest status of every vehicle and, during the formation, the
        latest formation error [m] (max over pairs of |p_i - p_j - (d_i - d_j)|, NaN unknown);
        returns the commands to send now."""
        self._now_s = now_s
        self._formation_error_m = formation_error_m
        if self._phase_since_s is None:
            self._phase_since_s = now_s
        for s in team:
            v = self._v[s.vehicle_id]
            v.status = s
            if v.offboard_sent and self._in_offboard(s.vehicle_id):
                v.seen_offboard = True
            if v.goto is not None:
                update_goto_vehicle(self, s.vehicle_id)
        if self._abort:
            reasons = [r for r, _, _ in self._abort]
            code = max(c for _, c, _ in self._abort)
            actions = [a for _, _, a in self._abort if a is not None]
            self._abort.clear()
            if self.phase is Phase.STOPPING:
                if self._interrupts:
                    finish(self, Outcome(code, f"{'; '.join(reasons)} while stopping; the "
                                                "autopilots' failsafes take over"))
                    return []
            elif self.phase is not Phase.DONE:
                begin_stop(self, [Problem(None, r) for r in reasons], code,
                           action=actions[0] if actions else None)
        return self._drive()

    # --- the sequence ----------------------------------------------------------------------------

    def _drive(self) -> list[Command]:
        """Run the current phase's step (_PHASES); DONE has none."""
        step = _PHASES.get(self.phase)
        return step(self) if step is not None else []

    def _elapsed(self) -> float:
        since = self._phase_since_s if self._phase_since_s is not None else self._now_s
        return self._now_s - since

    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self._phase_since_s = self._now_s
        self._note(f"phase {phase.value}")

    def _note(self, text: str, level: NoteLevel = NoteLevel.INFO) -> None:
        self.notes.append(text)
        self.note_levels.append(level)

    def _statuses(self) -> list[VehicleStatus]:
        return [v.status for v in self._v.values() if v.status is not None]

    def _flight_problems(self) -> list[Problem]:
        """The in-flight rules now; a link delay only once it has lasted (SustainedDelays)."""
        return self._delays.sustained(flight_problems(self._statuses(), self.plan.rules),
                                      self._now_s)

    def _send(self, vid: int, cmd: Cmd, altitude_m: float = math.nan,
              names: tuple[str, ...] = ()) -> Command:
        self._v[vid].pending = cmd
        if cmd is Cmd.OFFBOARD:
            self._v[vid].offboard_sent = True
        return Command(vid, cmd, altitude_m, names)

    def _idle(self, vids: Sequence[int] | None = None) -> bool:
        return all(self._v[vid].pending is None for vid in (vids or self.vehicle_ids))

    def connect_progress(self) -> str:
        """While connecting: who has been heard and who not, and how long is left."""
        heard = [vid for vid, v in self._v.items() if v.heard]
        waiting = [connect_waiting_label(vid, v.status) for vid, v in self._v.items()
                   if not v.heard]
        return connect_progress_line(self._elapsed(), self.plan.connect_timeout_s, heard,
                                     len(self._v), waiting)



#: Each phase's step: the commands to send now (it may move the machine to another phase).
_PHASES: dict[Phase, Callable[[MissionMachine], list[Command]]] = {
    Phase.CONNECT: connect,
    Phase.PREFLIGHT: preflight,
    Phase.ARM: arm_and_take_off,
    Phase.TAKEOFF: takeoff,
    Phase.GOTO: go_to_start,
    Phase.HOLD: hold,
    Phase.PRIME: prime,
    Phase.FORMATION: formation,
    Phase.STOPPING: stopping,
}
