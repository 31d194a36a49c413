"""PRIME and FORMATION: the law's setpoints before the offboard switch, then the formation.

Steps of gcs.mission.machine.MissionMachine, as functions of the machine: they read and write its
state, which it alone owns. PRIME streams the law's setpoints for `prime_s` with the in-flight
rules watched, then commands the offboard mode at t = 0; FORMATION flies until `duration_s`
and stops (gcs.mission.stopping) when a rule fails, a vehicle leaves or never reports its
offboard mode, or the formation error does not fall as the law predicts (`not_following`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from gcs.mission.plan import EXIT_ABORTED, EXIT_OK, GATE_FORMATION, Cmd, Command, Phase
from gcs.mission.safety import Problem
from gcs.mission.stopping import begin_stop

if TYPE_CHECKING:
    from gcs.mission.machine import MissionMachine

__all__ = ["formation", "not_following", "prime"]


def prime(m: MissionMachine) -> list[Command]:
    """The law's setpoints stream for `prime_s` under the in-flight rules, or until the
    team's agreed start (GATE_FORMATION's time); then t = 0."""
    problems = m._flight_problems()
    if problems:
        begin_stop(m, problems, EXIT_ABORTED)
        return m._drive()
    at = m.gate_time_s(GATE_FORMATION)
    if m._now_s < at if at is not None else m._elapsed() < m.plan.prime_s:
        return []
    m.formation_t0_s = m._now_s
    m._enter(Phase.FORMATION)
    return [m._send(vid, Cmd.OFFBOARD) for vid in m.vehicle_ids]


def formation(m: MissionMachine) -> list[Command]:
    """Fly until `duration_s`; stop at a failed rule, a vehicle out of its offboard mode, or a
    formation that does not follow (`not_following`)."""
    t = m._now_s - (m.formation_t0_s or m._now_s)
    problems = m._flight_problems()
    problems += not_following(m, t)
    for vid, v in m._v.items():
        s = v.status
        if v.seen_offboard and s is not None and not m._in_offboard(vid) \
                and s.link == "alive":
            name = m.offboard_mode(vid).name
            problems.append(Problem(vid, f"{s.name}: left {name} (now {s.mode or '?'})",
                                    "mode"))
    if problems:
        begin_stop(m, problems, EXIT_ABORTED)
        return m._drive()
    if t >= m.plan.duration_s:
        never = [Problem(vid, f"{v.status.name}: never reported "
                              f"{m.offboard_mode(vid).name} during the formation "
                              f"(reports {v.status.mode or '?'})", "mode")
                 for vid, v in m._v.items() if not v.seen_offboard and v.status is not None]
        if never:
            begin_stop(m, never, EXIT_ABORTED)
            return m._drive()
        begin_stop(m, [], EXIT_OK, end=True)
        return m._drive()
    return []


def not_following(m: MissionMachine, t: float) -> list[Problem]:
    """The vehicles do not fly the law: one never reported the offboard mode within
    `mode_timeout_s` + 2 s (the command's own confirmation normally fails first), or the
    formation error did not fall as the law predicts (module docstring)."""
    out = []
    if t > m.plan.mode_timeout_s + 2.0:
        for vid, v in m._v.items():
            s = v.status
            if not v.seen_offboard and s is not None and s.link == "alive":
                name = m.offboard_mode(vid).name
                out.append(Problem(vid, f"{s.name}: never reported {name} in {t:.1f} s of "
                                    f"formation (reports {s.mode or '?'}): it does not "
                                    "fly the setpoints", "mode"))
    e = m._formation_error_m
    if math.isfinite(e) and m._error_t0 is None:
        m._error_t0 = e
    e0 = m._error_t0
    if t >= m.plan.formation_check_s and e0 is not None and math.isfinite(e):
        bound = max(m.plan.formation_max_error_m, m.plan.formation_max_fraction * e0)
        if e > bound:
            out.append(Problem(None, (
                f"the vehicles do not follow the formation: error {e:.2f} m at t = "
                f"{t:.1f} s > {bound:.2f} m = max({m.plan.formation_max_error_m:g} m, "
                f"{m.plan.formation_max_fraction:g} x {e0:.2f} m at t = 0) "
                "(fly.formation_check)"), "follow"))
    return out
