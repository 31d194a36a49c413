"""PREFLIGHT: each vehicle's profile, parameters and version, its arm mode, then the checks.

Steps of gcs.mission.machine.MissionMachine, as functions of the machine: they read and write its
state, which it alone owns. After CONFIGURE has settled, each live vehicle's profile is fixed from
its HEARTBEAT, the parameters and firmware version the profile needs are read, a vehicle sitting
in a quiet mode (gcs.mission.landed) is put in its arm mode, and the preflight rules are judged
(gcs.mission.safety and the profile's own). A pass goes on to ARM (vehicles on the ground) or
GOTO/PRIME (gcs.mission.start); a failure to STOPPING (gcs.mission.stopping).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from gcs.mission.autopilots import profile_for
from gcs.mission.landed import quiet_mode_cause, with_quiet_causes
from gcs.mission.plan import EXIT_ABORTED, GATE_FLIGHT, Cmd, Command, Phase
from gcs.mission.progress import ArmProgress
from gcs.mission.safety import Problem, VehicleStatus, preflight_problems
from gcs.mission.start import to_goto
from gcs.mission.stopping import begin_stop

if TYPE_CHECKING:
    from gcs.mission.machine import MissionMachine

__all__ = ["preflight"]


def preflight(m: MissionMachine) -> list[Command]:
    if m._configured_s is None:
        if not m._idle():
            return []
        m._configured_s = m._now_s
    if not m._idle() or m._now_s - m._configured_s < m.plan.settle_s:
        return []
    team = m._statuses()
    reads = _read_params(m, team) or _leave_quiet_modes(m, team)
    if reads:
        return reads
    if m._elapsed() < m.plan.arm_timeout_s and any(
            v.quiet_left and quiet_mode_cause(v.profile, v.status) is not None
            for v in m._v.values()):
        return []  # its arm mode was confirmed; its status shows it at a later tick
    if any(s.frame_pending for s in team if s.link == "alive") and \
            m._elapsed() < m.plan.origin_timeout_s:
        return []  # the origins are asked for by the composition root; their answers wait
    problems = with_quiet_causes(
        preflight_problems(team, m.plan.rules, m._configured_s), team,
        {vid: v.profile for vid, v in m._v.items() if v.profile is not None})
    for s in team:
        profile = m._v[s.vehicle_id].profile
        if profile is not None:
            v = m._v[s.vehicle_id]
            problems += [Problem(s.vehicle_id, text) for text in profile.preflight_problems(
                s.name, m.plan.control_mode, v.params, v.version)]
    ground = [s.vehicle_id for s in team if s.landed is True]
    airborne = [s.vehicle_id for s in team if s.in_air]
    if m.plan.start == "in_air" and ground:
        problems.append(Problem(None, f"start: in_air, but vehicles {ground} are on the "
                                      "ground"))
    if m.plan.start == "takeoff" and airborne:
        problems.append(Problem(None, f"start: takeoff, but vehicles {airborne} are "
                                      "airborne"))
    for s in team:
        if s.in_air and not s.armed:
            problems.append(Problem(s.vehicle_id, f"{s.name}: in the air but not armed"))
    if problems and _not_ready_yet(m, problems):
        return []
    if problems:
        begin_stop(m, problems, EXIT_ABORTED)
        return m._drive()
    if m._gate(GATE_FLIGHT):
        return []
    m._note("preflight checks passed")
    if ground:
        m._arming = tuple(ground)
        for vid in ground:
            m._v[vid].arm = ArmProgress()
        m._enter(Phase.ARM)
        return m._drive()
    return to_goto(m)


def _not_ready_yet(m: MissionMachine, problems: list[Problem]) -> bool:
    """Wait (True) while every problem is a vehicle on the ground not ready yet (a stream or
    its position estimate missing: ArduPilot sends LOCAL_POSITION_NED only once its EKF uses
    GPS, ~41.6 s after boot), up to arm_timeout_s; then append, per vehicle, a problem
    quoting its latest STATUSTEXT."""
    ids = {p.vehicle_id for p in problems}
    ground = all(p.kind == "ready" and p.vehicle_id is not None
                 and m._v[p.vehicle_id].status is not None
                 and m._v[p.vehicle_id].status.landed is True for p in problems)
    if not ground:
        return False
    if m._elapsed() < m.plan.arm_timeout_s:
        if not m._waiting_ready:
            m._waiting_ready = True
            m._note("waiting for the vehicles to be ready: "
                    + "; ".join(p.text for p in problems))
        return True
    for vid in sorted(i for i in ids if i is not None):
        s = m._v[vid].status
        text = s.status_text if s is not None and s.status_text else "none"
        problems.append(Problem(vid, f"{s.name if s else vid}: not ready within "
                                     f"{m.plan.arm_timeout_s:g} s (fly.arm_timeout_s); "
                                     f"latest STATUSTEXT: {text}"))
    return False


def _read_params(m: MissionMachine, team: Sequence[VehicleStatus]) -> list[Command]:
    """Fix each live vehicle's profile from its HEARTBEAT; ask once for the parameters the
    profile requires, then once for AUTOPILOT_VERSION where the control mode depends on it
    (the checks run when every answer is in)."""
    out = []
    for s in team:
        v = m._v[s.vehicle_id]
        profile = profile_for(s.autopilot)
        if profile is None or s.link != "alive":
            continue
        v.profile = profile
        names = tuple(r.name for r in profile.params_for(m.plan.control_mode))
        if names and not v.params_asked:
            v.params_asked = True
            out.append(m._send(s.vehicle_id, Cmd.READ_PARAMS, names=names))
        elif profile.needs_version(m.plan.control_mode) and not v.version_asked:
            v.version_asked = True
            out.append(m._send(s.vehicle_id, Cmd.IDENTIFY))
    return out


def _leave_quiet_modes(m: MissionMachine, team: Sequence[VehicleStatus]) -> list[Command]:
    """Once per vehicle on the ground, disarmed in a mode where its autopilot sends no
    setpoint stream (gcs.mission.landed): its arm mode, before the streams are judged."""
    out = []
    for s in team:
        v = m._v[s.vehicle_id]
        if v.profile is None or v.quiet_left or s.link != "alive":
            continue
        cause = quiet_mode_cause(v.profile, s)
        if cause is not None:
            v.quiet_left = True
            m._note(f"{cause}: commanding {v.profile.arm_mode.name} first")
            out.append(m._send(s.vehicle_id, Cmd.ARM_MODE))
    return out
