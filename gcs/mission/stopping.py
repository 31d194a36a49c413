"""STOPPING and DONE: each vehicle landed, held or left to its failsafe, then the outcome.

Steps of gcs.mission.machine.MissionMachine, as functions of the machine: they read and write its
state, which it alone owns. `begin_stop` is where every problem ends up (module docstring of
gcs.mission.machine): it chooses each vehicle's stop action; `stopping` commands it, retried, and
disarms a vehicle that stays armed on the ground; `finish` records the outcome.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from gcs.config.modes import FlyAction
from gcs.mission.plan import EXIT_ABORTED, EXIT_INTERRUPTED, Cmd, Command, NoteLevel, Outcome, Phase
from gcs.mission.progress import StopProgress
from gcs.mission.safety import Problem

if TYPE_CHECKING:
    from gcs.mission.machine import MissionMachine

__all__ = ["begin_stop", "finish", "stopping"]


def begin_stop(m: MissionMachine, problems: Sequence[Problem], code: int,
               end: bool = False, action: FlyAction | None = None) -> None:
    """Stop for `problems`: each vehicle gets the end action (`end`), `action` when given, the
    link-loss action when a vehicle's link was lost, else the abort action."""
    if m.phase in (Phase.STOPPING, Phase.DONE):
        return
    lost = {p.vehicle_id for p in problems if p.kind == "link" and p.vehicle_id is not None}
    if end:
        action, reason = m.plan.end_action, "formation complete"
    elif action is not None:
        reason = "; ".join(p.text for p in problems)
    elif lost and code != EXIT_INTERRUPTED:
        action = m.plan.link_loss_action
        reason = "; ".join(p.text for p in problems)
    else:
        action = m.plan.abort_action
        reason = "; ".join(p.text for p in problems)
    for vid, v in m._v.items():
        if vid in lost:
            v.lost = True
            v.stop = StopProgress(None, done=True)
        elif v.status is None or v.status.link != "alive":
            v.stop = StopProgress(None, done=True, failure="no link")
        else:
            v.stop = StopProgress(action)
    m._stop_reason = Outcome(code, reason)
    m._stopping_since_s = m._now_s
    m._note(f"stopping ({action}): {reason}", NoteLevel.INFO if end else NoteLevel.WARNING)
    m._enter(Phase.STOPPING)


def stopping(m: MissionMachine) -> list[Command]:
    out: list[Command] = []
    now = m._now_s
    for vid, v in m._v.items():
        st, s = v.stop, v.status
        if st is None or st.done:
            continue
        if s is not None and s.link == "alive" and not s.armed and not s.in_air:
            st.done = True  # disarmed, not flying (landed state known or not): never commanded
            continue
        if s is None or s.link == "lost" or (s.data_age_s > m.plan.rules.link_lost_after_s):
            v.lost = True
            st.done, st.failure = True, "link lost while stopping"
            continue
        on_ground = s.landed is True
        if v.pending is not None:
            continue
        if on_ground:  # landed but still armed
            st.landed_since_s = st.landed_since_s if st.landed_since_s is not None else now
            if now - st.landed_since_s > m.plan.disarm_after_landed_s:
                out.append(m._send(vid, Cmd.DISARM))
                st.landed_since_s = now
            continue
        if st.action == FlyAction.HOLD and st.acked and s.mode == m.profile(vid).hold.name:
            st.done = True
            continue
        if (not st.acked and st.attempts < m.plan.command_attempts
                and now - st.last_attempt_s >= m.plan.command_retry_s):
            st.attempts += 1
            st.last_attempt_s = now
            out.append(m._send(vid, Cmd.LAND if st.action == FlyAction.LAND else Cmd.HOLD))
        if now - m._stopping_since_s > m.plan.land_timeout_s:
            st.done = True
            st.failure = f"not {st.action}ed within {m.plan.land_timeout_s:g} s"
    if all(v.stop is None or v.stop.done for v in m._v.values()) and m._idle():
        base = m._stop_reason or Outcome(EXIT_ABORTED, "stopped")
        failures = [f"vehicle {vid}: {v.stop.failure}" for vid, v in m._v.items()
                    if v.stop is not None and v.stop.failure]
        if failures:
            code = base.exit_code or EXIT_ABORTED
            finish(m, Outcome(code, "; ".join([base.reason, *failures])))
        else:
            finish(m, base)
    return out


def finish(m: MissionMachine, outcome: Outcome) -> None:
    m.outcome = outcome
    m._note(f"done: exit {outcome.exit_code}: {outcome.reason}")
    m._enter(Phase.DONE)
