"""ARM and TAKEOFF: each vehicle on the ground armed and taken off, then the takeoff judged.

Steps of gcs.mission.machine.MissionMachine, as functions of the machine: they read and write its
state, which it alone owns. Each ground vehicle goes to its arm mode, waits for its pre-arm checks
where they are reliable, is armed (retried while "not ready yet") and takes off at once; TAKEOFF
waits until each reports IN_AIR, its post-takeoff mode and its height above the takeoff point,
then goes on to GOTO/PRIME (gcs.mission.start). A timeout goes to STOPPING (gcs.mission.stopping).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gcs.link.enums import LandedState
from gcs.mission.lines import not_armed_line, takeoff_line
from gcs.mission.plan import EXIT_ABORTED, Cmd, Command, Phase
from gcs.mission.safety import Problem
from gcs.mission.start import to_goto
from gcs.mission.stopping import begin_stop

if TYPE_CHECKING:
    from gcs.mission.machine import MissionMachine

__all__ = ["arm_and_take_off", "takeoff"]


def arm_and_take_off(m: MissionMachine) -> list[Command]:
    """Each ground vehicle on its own: its arm mode (unless it reports it), its pre-arm
    checks (where reliable), arming (retried while "not ready yet"), then NAV_TAKEOFF at
    once (PX4 and ArduPilot disarm an armed vehicle that does not take off within 10 s)."""
    out: list[Command] = []
    now = m._now_s
    for vid in m._arming:
        v, profile = m._v[vid], m.profile(vid)
        a, s = v.arm, v.status
        if a is None or s is None or v.pending is not None or a.takeoff_sent:
            continue
        if a.armed:
            a.z0_m = s.position_enu_m[2]
            a.takeoff_sent = v.took_off = True
            out.append(m._send(vid, Cmd.TAKEOFF, m.plan.takeoff_altitude_m))
        elif s.mode != profile.arm_mode.name and not a.mode_sent:
            a.mode_sent = True
            out.append(m._send(vid, Cmd.ARM_MODE))
        elif profile.prearm_bit_reliable and s.prearm_ok is False:
            if not a.waiting_noted:
                a.waiting_noted = True
                m._note(f"{s.name}: waiting for its pre-arm checks (SYS_STATUS)")
        elif now - a.last_attempt_s >= m.plan.arm_retry_s:
            a.attempts += 1
            a.last_attempt_s = now
            out.append(m._send(vid, Cmd.ARM))
    if all(m._v[vid].arm.takeoff_sent for vid in m._arming) and m._idle():
        m._enter(Phase.TAKEOFF)
        return out
    if m._elapsed() > m.plan.arm_timeout_s:
        lines = [not_armed_line(vid, m._v[vid].status, m._v[vid].arm)
                 for vid in m._arming
                 if not m._v[vid].arm.armed]
        if lines:
            begin_stop(m, [Problem(None, "\n  ".join(
                [f"not every vehicle armed within {m.plan.arm_timeout_s:g} s "
                 "(fly.arm_timeout_s):", *lines]))], EXIT_ABORTED)
            return m._drive()
    return out


def takeoff(m: MissionMachine) -> list[Command]:
    if not m._idle():
        return []
    alt, tol = m.plan.takeoff_altitude_m, m.plan.takeoff_tolerance_m
    waiting = [vid for vid in m._arming if not _took_off(m, vid, alt - tol)]
    if not waiting:
        return to_goto(m)
    if m._elapsed() > m.plan.takeoff_timeout_s:
        lines = [takeoff_line(vid, m._v[vid].status, _height_m(m, vid),
                              m.profile(vid).takeoff_done_modes) for vid in waiting]
        begin_stop(m, [Problem(None, "\n  ".join(
            [f"vehicles {waiting} did not complete the takeoff to {alt:g} m (tolerance "
             f"{tol:g} m) within {m.plan.takeoff_timeout_s:g} s:", *lines]))],
            EXIT_ABORTED)
        return m._drive()
    return []


def _height_m(m: MissionMachine, vid: int) -> float:
    """Height above the takeoff point, as the vehicle reports it: GLOBAL_POSITION_INT
    relative_alt (above home, which the autopilot sets where it arms; the same reference as
    the NAV_TAKEOFF altitude), else the rise of its local z since it was armed. Never its
    local z alone: that is relative to its EKF origin, which need not be where it took off."""
    v = m._v[vid]
    if v.status is None or v.arm is None:
        return math.nan
    if math.isfinite(v.status.height_above_home_m):
        return v.status.height_above_home_m
    return v.status.position_enu_m[2] - v.arm.z0_m


def _took_off(m: MissionMachine, vid: int, min_height_m: float) -> bool:
    s = m._v[vid].status
    return (s is not None and s.landed_state == LandedState.IN_AIR
            and s.mode in m.profile(vid).takeoff_done_modes
            and _height_m(m, vid) >= min_height_m)
