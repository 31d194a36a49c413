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
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from gcs.config.modes import FlyAction
from gcs.link.enums import LandedState
from gcs.mission.autopilots import PX4, AutopilotProfile, ModeSpec, profile_for
from gcs.mission.goto import GotoResult, GoToStart, Vec3, crossing_pairs, going_line
from gcs.mission.landed import quiet_mode_cause, with_quiet_causes
from gcs.mission.lines import (
    CONNECT_SHOW_WAITING,
    connect_failure_line,
    connect_progress_line,
    connect_waiting_label,
    not_armed_line,
    takeoff_line,
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
from gcs.mission.progress import ArmProgress, GotoProgress, StopProgress, VehicleProgress
from gcs.mission.safety import (
    Problem,
    SustainedDelays,
    VehicleStatus,
    flight_problems,
    preflight_problems,
)

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
    _abort: list[tuple[str, int]] = field(default_factory=list)
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

    def request_abort(self, reason: str, *, operator: bool = True) -> None:
        """Ctrl-C, the abort key (operator) or an outside failure; acted on at the next tick."""
        code = EXIT_INTERRUPTED if operator else EXIT_ABORTED
        if self.phase is Phase.STOPPING and operator:
            self._interrupts += 1
        self._abort.append((reason, code))

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
            self._update_goto_vehicle(result.vehicle_id)
        if result.cmd is Cmd.OFFBOARD:
            v.offboard_acked = result.ok
            if not result.ok and self.phase is Phase.FORMATION:
                name = self.offboard_mode(result.vehicle_id).name
                self._begin_stop(
                    [Problem(result.vehicle_id, f"vehicle {result.vehicle_id}: {name} refused: "
                                                f"{result.detail}")],
                    EXIT_ABORTED,
                )
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
            self._begin_stop(
                [Problem(result.vehicle_id, (f"{cause}; " if cause else "")
                         + f"vehicle {result.vehicle_id}: {result.cmd.value} failed: "
                           f"{result.detail}")],
                EXIT_ABORTED,
            )
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
                self._update_goto_vehicle(s.vehicle_id)
        if self._abort:
            reasons = [r for r, _ in self._abort]
            code = max(c for _, c in self._abort)
            self._abort.clear()
            if self.phase is Phase.STOPPING:
                if self._interrupts:
                    self._finish(Outcome(code, f"{'; '.join(reasons)} while stopping; the "
                                               "autopilots' failsafes take over"))
                    return []
            elif self.phase is not Phase.DONE:
                self._begin_stop([Problem(None, r) for r in reasons], code)
        return self._drive()

    # --- the sequence ----------------------------------------------------------------------------

    def _drive(self) -> list[Command]:
        handler = {
            Phase.CONNECT: self._connect,
            Phase.PREFLIGHT: self._preflight,
            Phase.ARM: self._arm_and_take_off,
            Phase.TAKEOFF: self._takeoff,
            Phase.GOTO: self._go_to_start,
            Phase.HOLD: self._hold,
            Phase.PRIME: self._prime,
            Phase.FORMATION: self._formation,
            Phase.STOPPING: self._stopping,
        }.get(self.phase)
        return handler() if handler is not None else []

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

    def _connect(self) -> list[Command]:
        """Wait, up to connect_timeout_s, until every vehicle has been heard; nothing is
        commanded before that, so a vehicle that never answers ends the flight at once, with a
        line per missing vehicle (where the ground station listened, which sysid it expected)."""
        team = self._statuses()
        for s in team:
            v = self._v[s.vehicle_id]
            if s.link == "alive" and not v.heard:
                v.heard = True
                self._note(f"heard {s.name} on {s.listen or 'its link'} after "
                           f"{self._elapsed():.1f} s")
        if len(team) == len(self._v) and all(s.link == "alive" for s in team):
            self._enter(Phase.PREFLIGHT)
            return [self._send(vid, Cmd.CONFIGURE) for vid in self.vehicle_ids]
        if self._elapsed() > self.plan.connect_timeout_s:
            missing = [vid for vid, v in self._v.items()
                       if v.status is None or v.status.link != "alive"]
            lines = [connect_failure_line(vid, self._v[vid].status, self._v[vid].heard)
                     for vid in missing]
            self._finish(Outcome(EXIT_ABORTED, (
                f"no link to {len(missing)} of {len(self._v)} vehicles within "
                f"{self.plan.connect_timeout_s:g} s (nothing was commanded):\n"
                + "\n".join(f"  {line}" for line in lines))))
        return []

    def connect_progress(self) -> str:
        """While connecting: who has been heard and who not, and how long is left."""
        heard = [vid for vid, v in self._v.items() if v.heard]
        waiting = [connect_waiting_label(vid, v.status) for vid, v in self._v.items()
                   if not v.heard]
        return connect_progress_line(self._elapsed(), self.plan.connect_timeout_s, heard,
                                     len(self._v), waiting)

    def _preflight(self) -> list[Command]:
        if self._configured_s is None:
            if not self._idle():
                return []
            self._configured_s = self._now_s
        if not self._idle() or self._now_s - self._configured_s < self.plan.settle_s:
            return []
        team = self._statuses()
        reads = self._read_params(team) or self._leave_quiet_modes(team)
        if reads:
            return reads
        if self._elapsed() < self.plan.arm_timeout_s and any(
                v.quiet_left and quiet_mode_cause(v.profile, v.status) is not None
                for v in self._v.values()):
            return []  # its arm mode was confirmed; its status shows it at a later tick
        if any(s.frame_pending for s in team if s.link == "alive") and \
                self._elapsed() < self.plan.origin_timeout_s:
            return []  # the origins are asked for by the composition root; their answers wait
        problems = with_quiet_causes(
            preflight_problems(team, self.plan.rules, self._configured_s), team,
            {vid: v.profile for vid, v in self._v.items() if v.profile is not None})
        for s in team:
            profile = self._v[s.vehicle_id].profile
            if profile is not None:
                v = self._v[s.vehicle_id]
                problems += [Problem(s.vehicle_id, text) for text in profile.preflight_problems(
                    s.name, self.plan.control_mode, v.params, v.version)]
        ground = [s.vehicle_id for s in team if s.landed is True]
        airborne = [s.vehicle_id for s in team if s.in_air]
        if self.plan.start == "in_air" and ground:
            problems.append(Problem(None, f"start: in_air, but vehicles {ground} are on the "
                                          "ground"))
        if self.plan.start == "takeoff" and airborne:
            problems.append(Problem(None, f"start: takeoff, but vehicles {airborne} are "
                                          "airborne"))
        for s in team:
            if s.in_air and not s.armed:
                problems.append(Problem(s.vehicle_id, f"{s.name}: in the air but not armed"))
        if problems and self._not_ready_yet(problems):
            return []
        if problems:
            self._begin_stop(problems, EXIT_ABORTED)
            return self._drive()
        self._note("preflight checks passed")
        if ground:
            self._arming = tuple(ground)
            for vid in ground:
                self._v[vid].arm = ArmProgress()
            self._enter(Phase.ARM)
            return self._drive()
        return self._to_goto()

    def _not_ready_yet(self, problems: list[Problem]) -> bool:
        """Wait (True) while every problem is a vehicle on the ground not ready yet (a stream or
        its position estimate missing: ArduPilot sends LOCAL_POSITION_NED only once its EKF uses
        GPS, ~41.6 s after boot), up to arm_timeout_s; then append, per vehicle, a problem
        quoting its latest STATUSTEXT."""
        ids = {p.vehicle_id for p in problems}
        ground = all(p.kind == "ready" and p.vehicle_id is not None
                     and self._v[p.vehicle_id].status is not None
                     and self._v[p.vehicle_id].status.landed is True for p in problems)
        if not ground:
            return False
        if self._elapsed() < self.plan.arm_timeout_s:
            if not self._waiting_ready:
                self._waiting_ready = True
                self._note("waiting for the vehicles to be ready: "
                           + "; ".join(p.text for p in problems))
            return True
        for vid in sorted(i for i in ids if i is not None):
            s = self._v[vid].status
            text = s.status_text if s is not None and s.status_text else "none"
            problems.append(Problem(vid, f"{s.name if s else vid}: not ready within "
                                         f"{self.plan.arm_timeout_s:g} s (fly.arm_timeout_s); "
                                         f"latest STATUSTEXT: {text}"))
        return False

    def _read_params(self, team: Sequence[VehicleStatus]) -> list[Command]:
        """Fix each live vehicle's profile from its HEARTBEAT; ask once for the parameters the
        profile requires, then once for AUTOPILOT_VERSION where the control mode depends on it
        (the checks run when every answer is in)."""
        out = []
        for s in team:
            v = self._v[s.vehicle_id]
            profile = profile_for(s.autopilot)
            if profile is None or s.link != "alive":
                continue
            v.profile = profile
            names = tuple(r.name for r in profile.params_for(self.plan.control_mode))
            if names and not v.params_asked:
                v.params_asked = True
                out.append(self._send(s.vehicle_id, Cmd.READ_PARAMS, names=names))
            elif profile.needs_version(self.plan.control_mode) and not v.version_asked:
                v.version_asked = True
                out.append(self._send(s.vehicle_id, Cmd.IDENTIFY))
        return out

    def _leave_quiet_modes(self, team: Sequence[VehicleStatus]) -> list[Command]:
        """Once per vehicle on the ground, disarmed in a mode where its autopilot sends no
        setpoint stream (gcs.mission.landed): its arm mode, before the streams are judged."""
        out = []
        for s in team:
            v = self._v[s.vehicle_id]
            if v.profile is None or v.quiet_left or s.link != "alive":
                continue
            cause = quiet_mode_cause(v.profile, s)
            if cause is not None:
                v.quiet_left = True
                self._note(f"{cause}: commanding {v.profile.arm_mode.name} first")
                out.append(self._send(s.vehicle_id, Cmd.ARM_MODE))
        return out

    def _to_prime(self) -> list[Command]:
        """PRIME, after switching to hold the airborne vehicles that would act on the priming
        setpoints at once (profile.hold_before_prime: ArduPilot in GUIDED or GUIDED_NOGPS)."""
        held = []
        for vid, v in self._v.items():
            s, profile = v.status, self.profile(vid)
            if s is not None and s.in_air and (
                    (profile.hold_before_prime and s.mode in profile.setpoint_modes)
                    or (v.goto is not None and not v.goto.released)):
                held.append(vid)
        if not held:
            self._enter(Phase.PRIME)
            return []
        self._held = tuple(held)
        self._enter(Phase.HOLD)
        return [self._send(vid, Cmd.HOLD) for vid in held]

    def _hold(self) -> list[Command]:
        if not self._idle():
            return []
        waiting = [vid for vid in self._held
                   if not (self._v[vid].status is not None
                           and self._v[vid].status.mode == self.profile(vid).hold.name)]
        if not waiting and not self.position_targets:
            self._enter(Phase.PRIME)
        elif self._elapsed() > self.plan.hold_timeout_s:
            names = ", ".join(f"{vid} ({self.profile(vid).hold.name})" for vid in waiting)
            self._begin_stop([Problem(None, f"vehicles {names} did not report their hold mode "
                                            f"within {self.plan.hold_timeout_s:g} s")],
                             EXIT_ABORTED)
            return self._drive()
        return []

    # --- go to start --------------------------------------------------------------------------

    def _to_goto(self) -> list[Command]:
        """GOTO for the vehicles the plan names (module docstring), else PRIME (via HOLD)."""
        plan = self.plan.go_to_start
        flown = plan.flown(self._arming, self.vehicle_ids) if plan is not None else ()
        if not flown:
            return self._to_prime()
        positions = {vid: self._v[vid].status.position_enu_m for vid in flown}
        self._goto = GoToStart.begin(plan, self._now_s, positions)
        for vid in flown:
            self._v[vid].goto = GotoProgress()
        self._enter(Phase.GOTO)
        for vid in flown:
            self._note(going_line(self._v[vid].status.name, plan.start_of(vid), positions[vid]))
        starts = {vid: plan.start_of(vid) for vid in flown}
        for i, j, d in crossing_pairs(positions, starts, plan.separation_m):
            self._note(f"warning: vehicles {i} and {j} start within {plan.separation_m:g} m of "
                       f"one altitude and their horizontal legs come {d:.2f} m apart",
                       NoteLevel.WARNING)
        return self._drive()

    def _update_goto_vehicle(self, vid: int) -> None:
        """Track a go-to-start vehicle's mode: seen in its position mode; released once it has
        acknowledged its hold/stop command and reports another mode."""
        v = self._v[vid]
        g, s = v.goto, v.status
        if g is None or s is None:
            return
        in_mode = s.mode == self.profile(vid).position_mode.name
        g.seen_position_mode = g.seen_position_mode or in_mode
        if g.hold_acked and not in_mode:
            g.released = True

    def _go_to_start(self) -> list[Command]:
        g, plan = self._goto, self.plan.go_to_start
        assert g is not None and plan is not None
        flown = [vid for vid, v in self._v.items() if v.goto is not None]
        problems = self._flight_problems()
        for vid in flown:
            v, s = self._v[vid], self._v[vid].status
            name = self.profile(vid).position_mode.name
            if v.goto.seen_position_mode and s is not None and s.link == "alive" \
                    and s.mode != name and v.pending is None:
                problems.append(Problem(vid, f"{s.name}: left {name} during the go-to-start "
                                             f"(now {s.mode or '?'})", "mode"))
        if problems:
            self._begin_stop(problems, EXIT_ABORTED)
            return self._drive()
        out = []
        for vid in flown:
            v = self._v[vid]
            if (v.pending is None and not v.goto.mode_sent
                    and v.status.mode != self.profile(vid).position_mode.name
                    and self._elapsed() >= plan.lead_s):
                v.goto.mode_sent = True
                out.append(self._send(vid, Cmd.POSITION_MODE))
        positions = {vid: self._v[vid].status.position_enu_m for vid in flown}
        velocities = {vid: self._v[vid].status.velocity_enu_mps for vid in flown}
        in_mode = all(self._v[vid].status.mode == self.profile(vid).position_mode.name
                      for vid in flown)
        if in_mode and self._idle(flown) and g.update(self._now_s, positions, velocities):
            self._note(g.settled_line())
            return out + self._to_prime()
        if g.timed_out(self._now_s):
            names = {vid: self._v[vid].status.name for vid in flown}
            lines = g.not_settled_lines(self._now_s, names, positions)
            self._begin_stop([Problem(None, "\n  ".join(
                [f"not every vehicle settled at its start position within "
                 f"{plan.timeout_s:g} s (fly.go_to_start.timeout_s):", *lines]))], EXIT_ABORTED)
            return out + self._drive()
        return out

    def _arm_and_take_off(self) -> list[Command]:
        """Each ground vehicle on its own: its arm mode (unless it reports it), its pre-arm
        checks (where reliable), arming (retried while "not ready yet"), then NAV_TAKEOFF at
        once (PX4 and ArduPilot disarm an armed vehicle that does not take off within 10 s)."""
        out: list[Command] = []
        now = self._now_s
        for vid in self._arming:
            v, profile = self._v[vid], self.profile(vid)
            a, s = v.arm, v.status
            if a is None or s is None or v.pending is not None or a.takeoff_sent:
                continue
            if a.armed:
                a.z0_m = s.position_enu_m[2]
                a.takeoff_sent = v.took_off = True
                out.append(self._send(vid, Cmd.TAKEOFF, self.plan.takeoff_altitude_m))
            elif s.mode != profile.arm_mode.name and not a.mode_sent:
                a.mode_sent = True
                out.append(self._send(vid, Cmd.ARM_MODE))
            elif profile.prearm_bit_reliable and s.prearm_ok is False:
                if not a.waiting_noted:
                    a.waiting_noted = True
                    self._note(f"{s.name}: waiting for its pre-arm checks (SYS_STATUS)")
            elif now - a.last_attempt_s >= self.plan.arm_retry_s:
                a.attempts += 1
                a.last_attempt_s = now
                out.append(self._send(vid, Cmd.ARM))
        if all(self._v[vid].arm.takeoff_sent for vid in self._arming) and self._idle():
            self._enter(Phase.TAKEOFF)
            return out
        if self._elapsed() > self.plan.arm_timeout_s:
            lines = [not_armed_line(vid, self._v[vid].status, self._v[vid].arm)
                     for vid in self._arming
                     if not self._v[vid].arm.armed]
            if lines:
                self._begin_stop([Problem(None, "\n  ".join(
                    [f"not every vehicle armed within {self.plan.arm_timeout_s:g} s "
                     "(fly.arm_timeout_s):", *lines]))], EXIT_ABORTED)
                return self._drive()
        return out

    def _takeoff(self) -> list[Command]:
        if not self._idle():
            return []
        alt, tol = self.plan.takeoff_altitude_m, self.plan.takeoff_tolerance_m
        waiting = [vid for vid in self._arming if not self._took_off(vid, alt - tol)]
        if not waiting:
            return self._to_goto()
        if self._elapsed() > self.plan.takeoff_timeout_s:
            lines = [takeoff_line(vid, self._v[vid].status, self._height_m(vid),
                                  self.profile(vid).takeoff_done_modes) for vid in waiting]
            self._begin_stop([Problem(None, "\n  ".join(
                [f"vehicles {waiting} did not complete the takeoff to {alt:g} m (tolerance "
                 f"{tol:g} m) within {self.plan.takeoff_timeout_s:g} s:", *lines]))],
                EXIT_ABORTED)
            return self._drive()
        return []

    def _height_m(self, vid: int) -> float:
        """Height above the takeoff point, as the vehicle reports it: GLOBAL_POSITION_INT
        relative_alt (above home, which the autopilot sets where it arms; the same reference as
        the NAV_TAKEOFF altitude), else the rise of its local z since it was armed. Never its
        local z alone: that is relative to its EKF origin, which need not be where it took off."""
        v = self._v[vid]
        if v.status is None or v.arm is None:
            return math.nan
        if math.isfinite(v.status.height_above_home_m):
            return v.status.height_above_home_m
        return v.status.position_enu_m[2] - v.arm.z0_m

    def _took_off(self, vid: int, min_height_m: float) -> bool:
        s = self._v[vid].status
        return (s is not None and s.landed_state == LandedState.IN_AIR
                and s.mode in self.profile(vid).takeoff_done_modes
                and self._height_m(vid) >= min_height_m)

    def _prime(self) -> list[Command]:
        problems = self._flight_problems()
        if problems:
            self._begin_stop(problems, EXIT_ABORTED)
            return self._drive()
        if self._elapsed() < self.plan.prime_s:
            return []
        self.formation_t0_s = self._now_s
        self._enter(Phase.FORMATION)
        return [self._send(vid, Cmd.OFFBOARD) for vid in self.vehicle_ids]

    def _formation(self) -> list[Command]:
        t = self._now_s - (self.formation_t0_s or self._now_s)
        problems = self._flight_problems()
        problems += self._not_following(t)
        for vid, v in self._v.items():
            s = v.status
            if v.seen_offboard and s is not None and not self._in_offboard(vid) \
                    and s.link == "alive":
                name = self.offboard_mode(vid).name
                problems.append(Problem(vid, f"{s.name}: left {name} (now {s.mode or '?'})",
                                        "mode"))
        if problems:
            self._begin_stop(problems, EXIT_ABORTED)
            return self._drive()
        if t >= self.plan.duration_s:
            never = [Problem(vid, f"{v.status.name}: never reported "
                                  f"{self.offboard_mode(vid).name} during the formation "
                                  f"(reports {v.status.mode or '?'})", "mode")
                     for vid, v in self._v.items() if not v.seen_offboard and v.status is not None]
            if never:
                self._begin_stop(never, EXIT_ABORTED)
                return self._drive()
            self._begin_stop([], EXIT_OK, end=True)
            return self._drive()
        return []

    def _not_following(self, t: float) -> list[Problem]:
        """The vehicles do not fly the law: one never reported the offboard mode within
        `mode_timeout_s` + 2 s (the command's own confirmation normally fails first), or the
        formation error did not fall as the law predicts (module docstring)."""
        out = []
        if t > self.plan.mode_timeout_s + 2.0:
            for vid, v in self._v.items():
                s = v.status
                if not v.seen_offboard and s is not None and s.link == "alive":
                    name = self.offboard_mode(vid).name
                    out.append(Problem(vid, f"{s.name}: never reported {name} in {t:.1f} s of "
                                            f"formation (reports {s.mode or '?'}): it does not "
                                            "fly the setpoints", "mode"))
        e = self._formation_error_m
        if math.isfinite(e) and self._error_t0 is None:
            self._error_t0 = e
        e0 = self._error_t0
        if t >= self.plan.formation_check_s and e0 is not None and math.isfinite(e):
            bound = max(self.plan.formation_max_error_m, self.plan.formation_max_fraction * e0)
            if e > bound:
                out.append(Problem(None, (
                    f"the vehicles do not follow the formation: error {e:.2f} m at t = "
                    f"{t:.1f} s > {bound:.2f} m = max({self.plan.formation_max_error_m:g} m, "
                    f"{self.plan.formation_max_fraction:g} x {e0:.2f} m at t = 0) "
                    "(fly.formation_check)"), "follow"))
        return out

    # --- stopping --------------------------------------------------------------------------------

    def _begin_stop(self, problems: Sequence[Problem], code: int, end: bool = False) -> None:
        if self.phase in (Phase.STOPPING, Phase.DONE):
            return
        lost = {p.vehicle_id for p in problems if p.kind == "link" and p.vehicle_id is not None}
        if end:
            action, reason = self.plan.end_action, "formation complete"
        elif lost and code != EXIT_INTERRUPTED:
            action = self.plan.link_loss_action
            reason = "; ".join(p.text for p in problems)
        else:
            action = self.plan.abort_action
            reason = "; ".join(p.text for p in problems)
        for vid, v in self._v.items():
            if vid in lost:
                v.lost = True
                v.stop = StopProgress(None, done=True)
            elif v.status is None or v.status.link != "alive":
                v.stop = StopProgress(None, done=True, failure="no link")
            else:
                v.stop = StopProgress(action)
        self._stop_reason = Outcome(code, reason)
        self._stopping_since_s = self._now_s
        self._note(f"stopping ({action}): {reason}", NoteLevel.INFO if end else NoteLevel.WARNING)
        self._enter(Phase.STOPPING)

    def _stopping(self) -> list[Command]:
        out: list[Command] = []
        now = self._now_s
        for vid, v in self._v.items():
            st, s = v.stop, v.status
            if st is None or st.done:
                continue
            if s is not None and s.link == "alive" and not s.armed and not s.in_air:
                st.done = True  # disarmed, not flying (landed state known or not): never commanded
                continue
            if s is None or s.link == "lost" or (s.data_age_s > self.plan.rules.link_lost_after_s):
                v.lost = True
                st.done, st.failure = True, "link lost while stopping"
                continue
            on_ground = s.landed is True
            if v.pending is not None:
                continue
            if on_ground:  # landed but still armed
                st.landed_since_s = st.landed_since_s if st.landed_since_s is not None else now
                if now - st.landed_since_s > self.plan.disarm_after_landed_s:
                    out.append(self._send(vid, Cmd.DISARM))
                    st.landed_since_s = now
                continue
            if st.action == FlyAction.HOLD and st.acked and s.mode == self.profile(vid).hold.name:
                st.done = True
                continue
            if (not st.acked and st.attempts < self.plan.command_attempts
                    and now - st.last_attempt_s >= self.plan.command_retry_s):
                st.attempts += 1
                st.last_attempt_s = now
                out.append(self._send(vid, Cmd.LAND if st.action == FlyAction.LAND else Cmd.HOLD))
            if now - self._stopping_since_s > self.plan.land_timeout_s:
                st.done = True
                st.failure = f"not {st.action}ed within {self.plan.land_timeout_s:g} s"
        if all(v.stop is None or v.stop.done for v in self._v.values()) and self._idle():
            base = self._stop_reason or Outcome(EXIT_ABORTED, "stopped")
            failures = [f"vehicle {vid}: {v.stop.failure}" for vid, v in self._v.items()
                        if v.stop is not None and v.stop.failure]
            if failures:
                code = base.exit_code or EXIT_ABORTED
                self._finish(Outcome(code, "; ".join([base.reason, *failures])))
            else:
                self._finish(base)
        return out

    def _finish(self, outcome: Outcome) -> None:
        self.outcome = outcome
        self._note(f"done: exit {outcome.exit_code}: {outcome.reason}")
        self._enter(Phase.DONE)
