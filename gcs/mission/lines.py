"""The mission machine's longer status and failure lines, as pure functions of what they read.

Each vehicle's line names it (`VehicleStatus.name`, else "vehicle <id>") and says what it
reported; the machine (gcs.mission.machine) joins them under the failure they explain.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

from gcs.link.enums import LandedState
from gcs.mission.progress import ArmProgress
from gcs.mission.safety import VehicleStatus

__all__ = [
    "CONNECT_SHOW_WAITING",
    "connect_failure_line",
    "connect_progress_line",
    "connect_waiting_label",
    "not_armed_line",
    "takeoff_line",
]

#: While connecting, the status names at most this many of the vehicles not heard yet.
CONNECT_SHOW_WAITING = 4


def connect_progress_line(elapsed_s: float, timeout_s: float, heard: Sequence[int], team_size: int,
                          waiting: Sequence[str]) -> str:
    """While connecting: the vehicles `heard` (ids) of `team_size`, the labels of those still
    awaited (`waiting`, connect_waiting_label; the first CONNECT_SHOW_WAITING shown), and the
    time spent of the connect timeout [s]."""
    text = f"connecting {elapsed_s:.0f}/{timeout_s:g} s: heard {len(heard)}/{team_size}"
    if heard:
        text += f" ({', '.join(str(vid) for vid in heard)})"
    if waiting:
        shown = waiting[:CONNECT_SHOW_WAITING]
        more = len(waiting) - len(shown)
        text += "; waiting for " + ", ".join(shown) + (f" and {more} more" if more else "")
    return text


def connect_waiting_label(vehicle_id: int, status: VehicleStatus | None) -> str:
    """'vehicle 2 (sysid 2) on udp 127.0.0.1:14541' (plus a foreign sysid heard there)."""
    if status is None:
        return f"vehicle {vehicle_id}"
    text = f"{status.name} on {status.listen}" if status.listen else status.name
    if status.sysid_mismatch is not None:
        text += f" [heard sysid {status.sysid_mismatch} there instead]"
    return text


def connect_failure_line(vehicle_id: int, status: VehicleStatus | None, heard: bool) -> str:
    """One line per vehicle never heard: where the ground station listened and what it got."""
    if status is None:
        return f"vehicle {vehicle_id}: no status"
    where = f" on {status.listen}" if status.listen else ""
    if status.sysid_mismatch is not None:
        return (f"{status.name}: only sysid {status.sysid_mismatch} was heard{where}; "
                f"check the team file's sysid and link for this vehicle")
    if heard:
        return f"{status.name}: heard{where}, then silent"
    return f"{status.name}: nothing heard{where}; is it running, and does it send there?"


def not_armed_line(vehicle_id: int, status: VehicleStatus | None, arm: ArmProgress | None) -> str:
    """Why a ground vehicle is not armed yet: its attempts, the last answer, its pre-arm
    checks, its mode and its latest STATUSTEXT."""
    a, s = arm, status
    name = s.name if s is not None else f"vehicle {vehicle_id}"
    attempts = a.attempts if a is not None else 0
    last = f", last answer {a.last_result}" if a is not None and a.last_result else ""
    ready = (", pre-arm checks failing (SYS_STATUS)"
             if s is not None and s.prearm_ok is False else "")
    text = s.status_text if s is not None and s.status_text else "none"
    mode = s.mode if s is not None and s.mode else "?"
    return (f"{name}: not armed after {attempts} attempts{last}{ready}, mode {mode}; "
            f"latest STATUSTEXT: {text}")


def takeoff_line(vehicle_id: int, status: VehicleStatus | None, height_m: float,
                 done_modes: Collection[str]) -> str:
    """Why a vehicle has not completed its takeoff: its height above the takeoff point [m],
    its landed state and its mode (vs `done_modes`, the profile's takeoff_done_modes)."""
    s = status
    if s is None:
        return f"vehicle {vehicle_id}: no status"
    try:
        landed = LandedState(s.landed_state).name
    except ValueError:
        landed = str(s.landed_state)
    done = " or ".join(sorted(done_modes))
    return (f"{s.name}: {height_m:.2f} m above its takeoff point (home), "
            f"landed state {landed} (need IN_AIR), mode {s.mode or '?'} (need {done})")
