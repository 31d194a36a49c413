"""What a vehicle on the ground, disarmed, does not send in the mode its last landing left it in.

Pure. PX4 returns to the last selected mode that allows arming when it disarms after a landing
(docs/emulator.md, "After a landing"): a flight flown in OFFBOARD and ended with NAV_LAND leaves
it disarmed in OFFBOARD. There nothing publishes an attitude or rates setpoint, so PX4 sends no
ATTITUDE_TARGET, whatever interval was asked, and its pre-arm check fails (no offboard signal).
Preflight therefore commands the profile's arm mode (PX4 Hold) first, and a stream that still
does not come is reported with this cause, not as a rate shortfall.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from gcs.mission.autopilots import AutopilotProfile
from gcs.mission.safety import Problem, VehicleStatus

__all__ = ["quiet_mode_cause", "with_quiet_causes"]


def quiet_mode_cause(profile: AutopilotProfile, status: VehicleStatus) -> str | None:
    """'vehicle 1 (sysid 1): disarmed in OFFBOARD: PX4 sends no ATTITUDE_TARGET there' for a
    vehicle on the ground, disarmed, in one of `profile.quiet_modes`; None otherwise."""
    if status.armed or status.landed is not True or status.mode not in profile.quiet_modes:
        return None
    streams = " or ".join(profile.quiet_streams)
    return f"{status.name}: disarmed in {status.mode}: {profile.name} sends no {streams} there"


def with_quiet_causes(problems: Sequence[Problem], team: Sequence[VehicleStatus],
                      profiles: Mapping[int, AutopilotProfile]) -> list[Problem]:
    """`problems` with each missing-stream problem of a vehicle in a quiet mode (above) saying
    that cause first, then what was measured."""
    status = {s.vehicle_id: s for s in team}
    out = []
    for p in problems:
        s = status.get(p.vehicle_id) if p.vehicle_id is not None else None
        profile = profiles.get(p.vehicle_id) if p.vehicle_id is not None else None
        cause = quiet_mode_cause(profile, s) if s is not None and profile is not None else None
        if cause is not None and p.kind == "ready" and any(
                p.text.startswith(f"{s.name}: {stream} at ") for stream in profile.quiet_streams):
            out.append(Problem(p.vehicle_id, f"{cause} ({p.text[len(s.name) + 2:]})", p.kind))
        else:
            out.append(p)
    return out
