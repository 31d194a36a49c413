"""What the mission machine tracks of each vehicle while it drives the flight (mutable records).

Pure data, owned by gcs.mission.machine.MissionMachine (one `VehicleProgress` per vehicle):
its latest status, its outstanding command, and its progress through ARM, GOTO and STOPPING.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcs.config.modes import FlyAction
from gcs.mission.autopilots import AutopilotProfile
from gcs.mission.plan import Cmd
from gcs.mission.safety import VehicleStatus

__all__ = ["ArmProgress", "GotoProgress", "StopProgress", "VehicleProgress"]


@dataclass(slots=True)
class StopProgress:
    """Progress of one vehicle while STOPPING."""

    action: FlyAction | None  # None: lost, nothing to do
    attempts: int = 0
    last_attempt_s: float = -math.inf
    acked: bool = False
    done: bool = False
    landed_since_s: float | None = None
    failure: str = ""


@dataclass(slots=True)
class ArmProgress:
    """Progress of one ground vehicle through ARM (mode, readiness, attempts) and takeoff."""

    mode_sent: bool = False
    attempts: int = 0
    last_attempt_s: float = -math.inf
    last_result: str = ""
    armed: bool = False
    takeoff_sent: bool = False
    z0_m: float = math.nan  # ENU z (its own frame) where it took off
    waiting_noted: bool = False


@dataclass(slots=True)
class VehicleProgress:
    status: VehicleStatus | None = None
    pending: Cmd | None = None
    lost: bool = False
    offboard_sent: bool = False
    offboard_acked: bool = False
    seen_offboard: bool = False
    took_off: bool = False
    stop: StopProgress | None = None
    profile: AutopilotProfile | None = None  # fixed at preflight
    params: dict[str, float] | None = None  # READ_PARAMS result
    params_asked: bool = False
    version: int | None = None  # AUTOPILOT_VERSION.flight_sw_version (IDENTIFY result)
    version_asked: bool = False
    heard: bool = False  # a message has arrived since the flight started (CONNECT)
    quiet_left: bool = False  # PREFLIGHT commanded its arm mode to leave a quiet mode
    arm: ArmProgress | None = None  # vehicles that take off
    goto: GotoProgress | None = None  # vehicles that go to their start position


@dataclass(slots=True)
class GotoProgress:
    """One vehicle's part in GOTO: position setpoints stream to it until `released`."""

    mode_sent: bool = False
    seen_position_mode: bool = False
    hold_acked: bool = False
    released: bool = False  # acknowledged its hold/stop and left its position mode
