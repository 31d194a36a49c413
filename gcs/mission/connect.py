"""CONNECT: wait until every vehicle has been heard; nothing is commanded before that.

A step of gcs.mission.machine.MissionMachine, as a function of the machine: it reads and writes
the machine's state, which the machine alone owns. A vehicle that never answers ends the flight
with a line per missing vehicle (gcs.mission.lines).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gcs.mission.lines import connect_failure_line
from gcs.mission.plan import EXIT_ABORTED, Cmd, Command, Outcome, Phase
from gcs.mission.stopping import finish

if TYPE_CHECKING:
    from gcs.mission.machine import MissionMachine

__all__ = ["connect"]


def connect(m: MissionMachine) -> list[Command]:
    """Wait, up to connect_timeout_s, until every vehicle has been heard; nothing is
    commanded before that, so a vehicle that never answers ends the flight at once, with a
    line per missing vehicle (where the ground station listened, which sysid it expected)."""
    team = m._statuses()
    for s in team:
        v = m._v[s.vehicle_id]
        if s.link == "alive" and not v.heard:
            v.heard = True
            m._note(f"heard {s.name} on {s.listen or 'its link'} after {m._elapsed():.1f} s")
    if len(team) == len(m._v) and all(s.link == "alive" for s in team):
        m._enter(Phase.PREFLIGHT)
        return [m._send(vid, Cmd.CONFIGURE) for vid in m.vehicle_ids]
    if m._elapsed() > m.plan.connect_timeout_s:
        missing = [vid for vid, v in m._v.items()
                   if v.status is None or v.status.link != "alive"]
        lines = [connect_failure_line(vid, m._v[vid].status, m._v[vid].heard)
                 for vid in missing]
        finish(m, Outcome(EXIT_ABORTED, (
            f"no link to {len(missing)} of {len(m._v)} vehicles within "
            f"{m.plan.connect_timeout_s:g} s (nothing was commanded):\n"
            + "\n".join(f"  {line}" for line in lines))))
    return []
