"""The mission machine's interface: its plan, the commands it asks for, their results, its outcome.

Pure data (gcs.mission.machine drives a flight with them): what to fly and the rules
(`MissionPlan`), the phases, the commands the composition root executes (`Command`, `Cmd`) and
their results (`CommandResult`), the notes' levels and the exit codes of the `Outcome`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from gcs.config.modes import ControlMode, FlyAction
from gcs.mission.goto import GoToStartPlan
from gcs.mission.safety import SafetyRules

__all__ = [
    "EXIT_ABORTED",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "GATES",
    "GATE_FLIGHT",
    "GATE_FORMATION",
    "Cmd",
    "Command",
    "CommandResult",
    "MissionPlan",
    "NoteLevel",
    "Outcome",
    "Phase",
]

EXIT_OK = 0
EXIT_ABORTED = 1
EXIT_INTERRUPTED = 130


class Phase(Enum):
    CONNECT = "connect"
    PREFLIGHT = "preflight"
    ARM = "arm"
    TAKEOFF = "takeoff"
    GOTO = "goto"  # fly to the team file's start positions (position setpoints)
    HOLD = "hold"  # only when needed: airborne vehicles that would act on priming setpoints
    PRIME = "prime"
    FORMATION = "formation"
    STOPPING = "stopping"
    DONE = "done"


class NoteLevel(Enum):
    """How much a note matters: INFO for the flight's normal course, its normal end included;
    WARNING for an anomaly (a stop before the formation's end, start paths that cross)."""

    INFO = "info"
    WARNING = "warning"


class Cmd(Enum):
    """What the app must do to one vehicle (it maps these to proxy calls)."""

    CONFIGURE = "configure"  # telemetry rates (SET_MESSAGE_INTERVAL)
    READ_PARAMS = "read_params"  # the profile's required parameters (`names`), values in result
    IDENTIFY = "identify"  # AUTOPILOT_VERSION; result values (("flight_sw_version", word),)
    ARM_MODE = "arm_mode"  # the profile's arm_mode (PX4 Hold, ArduPilot GUIDED), confirmed
    ARM = "arm"  # confirmed when HEARTBEAT shows armed
    TAKEOFF = "takeoff"  # altitude_m above home
    OFFBOARD = "offboard"  # the profile's offboard mode (PX4 OFFBOARD, ArduPilot GUIDED_NOGPS;
    # in position mode its position mode: ArduPilot GUIDED), MissionMachine.offboard_mode
    POSITION_MODE = "position_mode"  # the profile's position mode (PX4 OFFBOARD, ArduPilot
    # GUIDED), for the go-to-start position setpoints; confirmed
    HOLD = "hold"  # the profile's hold mode (PX4 AUTO_LOITER, ArduPilot BRAKE)
    LAND = "land"  # PX4 NAV_LAND, ArduPilot LAND mode
    DISARM = "disarm"


@dataclass(frozen=True, slots=True)
class Command:
    vehicle_id: int
    cmd: Cmd
    altitude_m: float = math.nan
    names: tuple[str, ...] = ()  # READ_PARAMS: parameter ids


@dataclass(frozen=True, slots=True)
class CommandResult:
    vehicle_id: int
    cmd: Cmd
    ok: bool
    detail: str = ""
    values: tuple[tuple[str, float], ...] = ()  # READ_PARAMS: (parameter id, value)
    result: str = ""  # MAV_RESULT name of a refusal, NOT_CONFIRMED, TIMEOUT; '' when ok
    text: str = ""  # the vehicle's STATUSTEXT that came with the refusal, if any


@dataclass(frozen=True, slots=True)
class Outcome:
    exit_code: int
    reason: str


#: Gate before the first command that moves a vehicle (arming, go to start, priming): every
#: machine of the team has passed its preflight.
GATE_FLIGHT = "flight"
#: Gate before PRIME: every machine's vehicles hold at their start; opened with the agreed
#: formation start time.
GATE_FORMATION = "formation"
GATES = (GATE_FLIGHT, GATE_FORMATION)


@dataclass(frozen=True, slots=True)
class MissionPlan:
    """What to fly and the rules, from the team file's `mission:` and `fly:` sections."""

    duration_s: float
    rules: SafetyRules = SafetyRules()
    # which setpoints the vehicles will get, and so the autopilot mode they fly them in
    # (AutopilotProfile.flies_in: position mode's in the profile's position mode)
    control_mode: ControlMode = ControlMode.RATES
    start: str = "auto"  # auto | in_air | takeoff
    takeoff_altitude_m: float = 2.5
    end_action: FlyAction = FlyAction.LAND
    abort_action: FlyAction = FlyAction.LAND
    link_loss_action: FlyAction = FlyAction.HOLD
    connect_timeout_s: float = 60.0  # emulators compiling, autopilots booting (PX4 SITL 10-25 s)
    # after CONFIGURE, before the rates and the link delay are judged (from what was measured
    # since: not the ground station's own load while it configured the team)
    settle_s: float = 1.0
    takeoff_timeout_s: float = 60.0
    takeoff_tolerance_m: float = 0.3  # height above the takeoff point vs takeoff_altitude_m
    arm_timeout_s: float = 60.0  # ARM phase: every ground vehicle armed and taking off
    arm_retry_s: float = 1.0  # between two arming attempts of one vehicle
    mode_timeout_s: float = 3.0  # a mode change shows in HEARTBEAT (PX4: 1 Hz) within this
    formation_check_s: float = 10.0  # from this formation time on, the error rule applies
    formation_max_error_m: float = 1.0
    formation_max_fraction: float = 0.5
    prime_s: float = 1.5  # setpoints stream before the offboard switch: good practice, not a
    # PX4 requirement (PX4 only needs one setpoint younger than COM_OF_LOSS_T); it also proves
    # the stream reaches every vehicle before any of them acts on it
    hold_timeout_s: float = 10.0  # HOLD phase: vehicles reach their hold mode within this
    origin_timeout_s: float = 10.0  # PREFLIGHT: every vehicle's origin (its frame tie) by then
    land_timeout_s: float = 120.0
    disarm_after_landed_s: float = 3.0  # PX4 auto-disarms after COM_DISARM_LAND (2 s)
    command_attempts: int = 3  # per stop command (each has its own ack retries)
    command_retry_s: float = 1.0  # between two attempts of a refused stop command
    go_to_start: GoToStartPlan | None = None  # None: no go-to-start phase
    # the team's gates (GATE_FLIGHT, GATE_FORMATION) this machine waits at until another
    # party opens them (MissionMachine.open_gate): a team whose vehicles several machines fly
    gates: frozenset[str] = frozenset()
