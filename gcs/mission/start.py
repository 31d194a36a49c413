"""GOTO and HOLD: the flight to the start positions, and the hold before PRIME.

Steps of gcs.mission.machine.MissionMachine, as functions of the machine: they read and write its
state, which it alone owns. GOTO flies the vehicles the plan names to their team-file start
positions on position setpoints (the legs and the settle rule: gcs.mission.goto); then the
airborne vehicles that would act on the priming setpoints at once go to their hold mode (HOLD)
before PRIME. A failure goes to STOPPING (gcs.mission.stopping).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gcs.mission.goto import GoToStart, crossing_pairs, going_line
from gcs.mission.plan import EXIT_ABORTED, GATE_FORMATION, Cmd, Command, NoteLevel, Phase
from gcs.mission.progress import GotoProgress
from gcs.mission.safety import Problem
from gcs.mission.stopping import begin_stop

if TYPE_CHECKING:
    from gcs.mission.machine import MissionMachine

__all__ = ["go_to_start", "hold", "to_goto", "to_prime", "update_goto_vehicle"]


def to_goto(m: MissionMachine) -> list[Command]:
    """GOTO for the vehicles the plan names (module docstring), else PRIME (via HOLD)."""
    plan = m.plan.go_to_start
    flown = plan.flown(m._arming, m.vehicle_ids) if plan is not None else ()
    if not flown:
        return to_prime(m)
    positions = {vid: m._v[vid].status.position_enu_m for vid in flown}
    m._goto = GoToStart.begin(plan, m._now_s, positions)
    for vid in flown:
        m._v[vid].goto = GotoProgress()
    m._enter(Phase.GOTO)
    for vid in flown:
        m._note(going_line(m._v[vid].status.name, plan.start_of(vid), positions[vid]))
    starts = {vid: plan.start_of(vid) for vid in flown}
    for i, j, d in crossing_pairs(positions, starts, plan.separation_m):
        m._note(f"warning: vehicles {i} and {j} start within {plan.separation_m:g} m of "
                f"one altitude and their horizontal legs come {d:.2f} m apart",
                NoteLevel.WARNING)
    return m._drive()


def update_goto_vehicle(m: MissionMachine, vid: int) -> None:
    """Track a go-to-start vehicle's mode: seen in its position mode; released once it has
    acknowledged its hold/stop command and reports another mode."""
    v = m._v[vid]
    g, s = v.goto, v.status
    if g is None or s is None:
        return
    in_mode = s.mode == m.profile(vid).position_mode.name
    g.seen_position_mode = g.seen_position_mode or in_mode
    if g.hold_acked and not in_mode:
        g.released = True


def go_to_start(m: MissionMachine) -> list[Command]:
    g, plan = m._goto, m.plan.go_to_start
    assert g is not None and plan is not None
    flown = [vid for vid, v in m._v.items() if v.goto is not None]
    problems = m._flight_problems()
    for vid in flown:
        v, s = m._v[vid], m._v[vid].status
        name = m.profile(vid).position_mode.name
        if v.goto.seen_position_mode and s is not None and s.link == "alive" \
                and s.mode != name and v.pending is None:
            problems.append(Problem(vid, f"{s.name}: left {name} during the go-to-start "
                                         f"(now {s.mode or '?'})", "mode"))
    if problems:
        begin_stop(m, problems, EXIT_ABORTED)
        return m._drive()
    out = []
    for vid in flown:
        v = m._v[vid]
        if (v.pending is None and not v.goto.mode_sent
                and v.status.mode != m.profile(vid).position_mode.name
                and m._elapsed() >= plan.lead_s):
            v.goto.mode_sent = True
            out.append(m._send(vid, Cmd.POSITION_MODE))
    positions = {vid: m._v[vid].status.position_enu_m for vid in flown}
    velocities = {vid: m._v[vid].status.velocity_enu_mps for vid in flown}
    in_mode = all(m._v[vid].status.mode == m.profile(vid).position_mode.name
                  for vid in flown)
    if in_mode and m._idle(flown) and g.update(m._now_s, positions, velocities):
        m._note(g.settled_line())
        return out + to_prime(m)
    if g.timed_out(m._now_s):
        names = {vid: m._v[vid].status.name for vid in flown}
        lines = g.not_settled_lines(m._now_s, names, positions)
        begin_stop(m, [Problem(None, "\n  ".join(
            [f"not every vehicle settled at its start position within "
             f"{plan.timeout_s:g} s (fly.go_to_start.timeout_s):", *lines]))], EXIT_ABORTED)
        return out + m._drive()
    return out


def to_prime(m: MissionMachine) -> list[Command]:
    """PRIME, after switching to hold the airborne vehicles that would act on the priming
    setpoints at once (profile.hold_before_prime: ArduPilot in GUIDED or GUIDED_NOGPS)."""
    held = []
    for vid, v in m._v.items():
        s, profile = v.status, m.profile(vid)
        if s is not None and s.in_air and (
                (profile.hold_before_prime and s.mode in profile.setpoint_modes)
                or (v.goto is not None and not v.goto.released)):
            held.append(vid)
    if not held:
        if not m._gate(GATE_FORMATION):
            m._enter(Phase.PRIME)
        return []
    m._held = tuple(held)
    m._enter(Phase.HOLD)
    return [m._send(vid, Cmd.HOLD) for vid in held]


def hold(m: MissionMachine) -> list[Command]:
    if not m._idle():
        return []
    waiting = [vid for vid in m._held
               if not (m._v[vid].status is not None
                       and m._v[vid].status.mode == m.profile(vid).hold.name)]
    if not waiting and not m.position_targets:
        if not m._gate(GATE_FORMATION):
            m._enter(Phase.PRIME)
    elif m._elapsed() > m.plan.hold_timeout_s:
        names = ", ".join(f"{vid} ({m.profile(vid).hold.name})" for vid in waiting)
        begin_stop(m, [Problem(None, f"vehicles {names} did not report their hold mode "
                                     f"within {m.plan.hold_timeout_s:g} s")],
                   EXIT_ABORTED)
        return m._drive()
    return []
