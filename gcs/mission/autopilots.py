"""Per-autopilot profiles of `gcs fly`: which modes mean "the GCS flies it", hold, land and take
off, how they are commanded, and what must be configured on the vehicle before flying (pure).

One `AutopilotProfile` per supported autopilot, chosen per vehicle from its HEARTBEAT.autopilot
(`profile_for`), so a team may mix autopilots. The mission machine and the composition root use
the profile instead of PX4 constants. Facts: PX4 v1.16.0 and ArduCopter 4.7.0-dev SITL as
recorded (docs/mavlink.md, docs/emulator.md; docs/gcs.md says why each mode was chosen).

* PX4 (12): arms in Hold (AUTO_LOITER, commanded first when it reports another mode); OFFBOARD;
  hold AUTO_LOITER; land with MAV_CMD_NAV_LAND; NAV_TAKEOFF with an AMSL
  altitude, after which PX4 switches itself to AUTO_LOITER; the OFFBOARD switch needs a setpoint
  younger than COM_OF_LOSS_T (1 s); the PRIME phase streams for longer than that first, as good
  practice. Go-to-start: SET_POSITION_TARGET_LOCAL_NED in OFFBOARD, streamed before the switch.
* ArduPilot Copter (3): GUIDED_NOGPS (20), the attitude-only guided mode; hold BRAKE (17); land
  with the LAND mode (9); take off in GUIDED (4) with NAV_TAKEOFF at a relative altitude, then
  BRAKE before the setpoint stream starts (ArduPilot acts on SET_ATTITUDE_TARGET at once in GUIDED
  and GUIDED_NOGPS, and ignores it in every other mode). Go-to-start: SET_POSITION_TARGET_LOCAL_NED
  in GUIDED (relative to its EKF origin), where its takeoff leaves it. Preflight: GUID_OPTIONS
  bit 3 (8) must be set, otherwise `thrust` is read as a climb rate.

Position mode (`gcs fly --mode position`, the baseline) sends the formation's slots as
SET_POSITION_TARGET_LOCAL_NED, flown where the go-to-start flies them (`flies_in`: PX4 OFFBOARD,
ArduPilot GUIDED, never GUIDED_NOGPS); it sends no thrust, so GUID_OPTIONS is not read for it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from gcs.config.modes import ControlMode
from gcs.control.cascade import ARDUPILOT_RESPONSE, PX4_RESPONSE, AutopilotResponse
from gcs.link.enums import mode_name

PX4_AUTOPILOT = 12  # MAV_AUTOPILOT_PX4
ARDUPILOT_AUTOPILOT = 3  # MAV_AUTOPILOT_ARDUPILOTMEGA



@dataclass(frozen=True, slots=True)
class ModeSpec:
    """One flight mode: `name` as `AutopilotProfile.mode_name` reads it from HEARTBEAT, and the
    numbers DO_SET_MODE carries (PX4: main and sub mode; ArduPilot: the mode number, sub 0)."""

    name: str
    number: int
    sub: int = 0

    def custom_mode(self, family: str) -> int:
        """HEARTBEAT custom_mode of this mode (PX4: main << 16 | sub << 24)."""
        return (self.number << 16) | (self.sub << 24) if family == "px4" else self.number


@dataclass(frozen=True, slots=True)
class ParamRequirement:
    """A vehicle parameter whose bits in `mask` must all be set before flying one of
    `control_modes` (empty: every mode); `fix` says what to do and why, in one line."""

    name: str
    mask: int
    fix: str
    control_modes: frozenset[ControlMode] = frozenset()

    def needed_for(self, control_mode: ControlMode) -> bool:
        return not self.control_modes or control_mode in self.control_modes

    def problem(self, vehicle: str, value: float | None) -> str | None:
        """One line naming vehicle, parameter, value and fix; None when satisfied."""
        if value is None or not math.isfinite(value):
            return f"{vehicle}: {self.name} could not be read; {self.fix}"
        if int(round(value)) & self.mask != self.mask:
            return f"{vehicle}: {self.name} = {value:g} (bit mask {self.mask} clear); {self.fix}"
        return None


@dataclass(frozen=True, slots=True)
class AutopilotProfile:
    """How `gcs fly` drives one autopilot (see the module docstring for the values)."""

    name: str
    autopilot: int  # HEARTBEAT.autopilot (MAV_AUTOPILOT)
    family: str  # 'px4' | 'ardupilot': how a ModeSpec is encoded in DO_SET_MODE and HEARTBEAT
    offboard: ModeSpec  # the GCS flies the vehicle (setpoints stream) in this mode
    hold: ModeSpec  # position hold: end/abort/link-loss action `hold`
    land: ModeSpec | None  # None: MAV_CMD_NAV_LAND
    arm_mode: ModeSpec  # commanded (disarmed, on the ground) before arming, unless the vehicle
    # already reports it: a mode the autopilot arms in and takes off from
    takeoff_done_modes: frozenset[str]  # what a vehicle reports once its NAV_TAKEOFF finished
    takeoff_altitude_amsl: bool  # NAV_TAKEOFF param7 AMSL (PX4) or above home (ArduPilot)
    setpoint_modes: frozenset[str]  # modes in which the autopilot acts on SET_ATTITUDE_TARGET
    hold_before_prime: bool  # airborne vehicles in setpoint_modes go to `hold` before priming
    control_modes: frozenset[ControlMode]  # `gcs fly --mode` values whose setpoints it acts on
    # go-to-start: the mode that flies SET_POSITION_TARGET_LOCAL_NED (PX4 OFFBOARD, ArduPilot
    # GUIDED), and whether the vehicle needs the setpoint stream in it (PX4: OFFBOARD is refused
    # without a recent setpoint and left by a failsafe COM_OF_LOSS_T after the last one;
    # ArduPilot's GUIDED holds position on its own)
    position_mode: ModeSpec = ModeSpec("OFFBOARD", 6)
    position_needs_stream: bool = True
    required_params: tuple[ParamRequirement, ...] = ()
    # newest firmware (major, minor) that acts on SET_ACTUATOR_CONTROL_TARGET; None: never. The
    # version is read from AUTOPILOT_VERSION before an `actuators` flight (`needs_version`)
    actuators_until: tuple[int, int] | None = None
    force_arm_magic: int = 21196  # COMPONENT_ARM_DISARM param2 (gcs fly never forces)
    force_disarm_magic: int = 21196
    # MAV_RESULTs of an arming refusal that mean "not ready yet" (retried until fly.arm_timeout_s)
    arm_retry_results: frozenset[str] = frozenset({"TEMPORARILY_REJECTED"})
    # ... and those that mean it only with a pre-arm STATUSTEXT starting with one of these
    arm_retry_texts: tuple[str, ...] = ()
    # SYS_STATUS MAV_SYS_STATUS_PREARM_CHECK is a reliable "would arm now" (PX4: MAVSDK's
    # health.is_armable); ArduPilot sets it before its GUIDED needs are met, so it is not waited on
    prearm_bit_reliable: bool = False
    # how its own loops answer a setpoint at default tuning (the cascade criterion's default)
    response: AutopilotResponse = PX4_RESPONSE
    # modes in which, disarmed on the ground, it publishes no setpoint and so sends none of
    # `quiet_streams` (PX4: OFFBOARD, where a landing from OFFBOARD leaves it; gcs.mission.landed):
    # preflight commands `arm_mode` first
    quiet_modes: frozenset[str] = frozenset()
    quiet_streams: tuple[str, ...] = ()

    def arm_retryable(self, result: str, text: str) -> bool:
        """True when an arming attempt that ended with `result` (a MAV_RESULT name, or
        NOT_CONFIRMED: accepted but HEARTBEAT never showed armed) and the vehicle's STATUSTEXT
        `text` means the vehicle is not ready yet, so arming is tried again."""
        if result in self.arm_retry_results or result == "NOT_CONFIRMED":
            return True
        return bool(self.arm_retry_texts) and result == "FAILED" \
            and text.startswith(self.arm_retry_texts)

    def mode_name(self, custom_mode: int) -> str:
        """Name of a HEARTBEAT custom_mode, e.g. 'OFFBOARD', 'AUTO_LOITER', 'GUIDED_NOGPS'."""
        return mode_name(self.autopilot, custom_mode)

    def flies_in(self, control_mode: ControlMode) -> ModeSpec:
        """The mode the vehicle flies `control_mode`'s setpoints in: position mode's position
        setpoints in `position_mode` (PX4 OFFBOARD, ArduPilot GUIDED), the law's attitude, rate
        or actuator setpoints in `offboard` (PX4 OFFBOARD, ArduPilot GUIDED_NOGPS)."""
        return self.position_mode if control_mode == ControlMode.POSITION else self.offboard

    def params_for(self, control_mode: ControlMode) -> tuple[ParamRequirement, ...]:
        """The required parameters that flying `control_mode` depends on."""
        return tuple(r for r in self.required_params if r.needed_for(control_mode))

    def needs_version(self, control_mode: ControlMode) -> bool:
        """True when flying `control_mode` depends on the firmware version (AUTOPILOT_VERSION)."""
        return control_mode == ControlMode.ACTUATORS and self.actuators_until is not None

    def preflight_problems(self, vehicle: str, control_mode: ControlMode,
                           params: Mapping[str, float] | None,
                           version: int | None = None) -> list[str]:
        """What this autopilot needs before flying `control_mode`, given the parameters read from
        the vehicle (`required_params`) and its AUTOPILOT_VERSION.flight_sw_version (None: not
        read or no answer); one line per problem, naming the vehicle and the fix."""
        out: list[str] = []
        if control_mode not in self.control_modes:
            # the law's modes it flies (position mode is the baseline, not a fix for the law)
            allowed = " or ".join(sorted(self.control_modes - {ControlMode.POSITION}))
            out.append(f"{vehicle}: {self.name} does not act on {control_mode} setpoints; fly "
                       f"it with --mode {allowed}")
        elif self.needs_version(control_mode):
            until = ".".join(map(str, self.actuators_until or ()))
            if version is None:
                out.append(f"{vehicle}: no AUTOPILOT_VERSION: cannot confirm that {self.name} "
                           f"acts on actuator setpoints (only <= {until} does); fly it with "
                           "--mode rates")
            elif (version >> 24 & 0xFF, version >> 16 & 0xFF) > (self.actuators_until or ()):
                out.append(f"{vehicle}: {self.name} {version_text(version)} ignores "
                           f"SET_ACTUATOR_CONTROL_TARGET (only <= {until} acts on it); fly it "
                           "with --mode rates")
        for req in self.params_for(control_mode):
            text = req.problem(vehicle, None if params is None else params.get(req.name))
            if text is not None:
                out.append(text)
        return out


PX4 = AutopilotProfile(
    name="PX4", autopilot=PX4_AUTOPILOT, family="px4",
    offboard=ModeSpec("OFFBOARD", 6),
    hold=ModeSpec("AUTO_LOITER", 4, 3),
    land=None,
    arm_mode=ModeSpec("AUTO_LOITER", 4, 3),  # Hold; after a failsafe landing PX4 sits in
    # OFFBOARD, disarmed, and refuses to arm there without a fresh setpoint
    takeoff_done_modes=frozenset({"AUTO_LOITER"}),
    takeoff_altitude_amsl=True,
    setpoint_modes=frozenset({"OFFBOARD"}),
    hold_before_prime=False,
    # actuators: PX4 <= 1.13; position: SET_POSITION_TARGET_LOCAL_NED in OFFBOARD
    control_modes=frozenset(ControlMode),  # every mode
    actuators_until=(1, 13),  # PX4 1.14 moved actuator control to its ROS 2 bridge
    prearm_bit_reliable=True,
    response=PX4_RESPONSE,
    quiet_modes=frozenset({"OFFBOARD"}),
    quiet_streams=("ATTITUDE_TARGET",),
)

#: GUID_OPTIONS bit 3: SET_ATTITUDE_TARGET `thrust` is normalised thrust, not a climb rate.
GUID_OPTIONS_THRUST = ParamRequirement(
    "GUID_OPTIONS", 8,
    "set GUID_OPTIONS bit 3 (8): otherwise ArduPilot reads thrust as a climb rate",
    frozenset({ControlMode.RATES, ControlMode.ATTITUDE}))  # position mode sends no thrust

ARDUPILOT = AutopilotProfile(
    name="ArduPilot Copter", autopilot=ARDUPILOT_AUTOPILOT, family="ardupilot",
    offboard=ModeSpec("GUIDED_NOGPS", 20),
    hold=ModeSpec("BRAKE", 17),
    land=ModeSpec("LAND", 9),
    arm_mode=ModeSpec("GUIDED", 4),  # NAV_TAKEOFF needs GUIDED; LAND and BRAKE are not armable
    takeoff_done_modes=frozenset({"GUIDED"}),
    takeoff_altitude_amsl=False,
    setpoint_modes=frozenset({"GUIDED", "GUIDED_NOGPS"}),
    hold_before_prime=True,
    # SET_ATTITUDE_TARGET in GUIDED_NOGPS; position: SET_POSITION_TARGET_LOCAL_NED in GUIDED
    control_modes=frozenset({ControlMode.RATES, ControlMode.ATTITUDE, ControlMode.POSITION}),
    position_mode=ModeSpec("GUIDED", 4),  # where it is after NAV_TAKEOFF
    position_needs_stream=False,
    required_params=(GUID_OPTIONS_THRUST,),
    force_arm_magic=2989,
    force_disarm_magic=21196,
    # ArduPilot answers every failed pre-arm check with FAILED and a text "Arm: <reason>"
    # (its boot: "Arm: Gyros inconsistent", ..., GUIDED until the EKF uses GPS: "Arm: Need
    # Position Estimate"); "PreArm: ..." comes every 30 s while one fails
    arm_retry_results=frozenset({"TEMPORARILY_REJECTED"}),
    arm_retry_texts=("Arm: ", "PreArm: "),
    response=ARDUPILOT_RESPONSE,
)

def version_text(flight_sw_version: int) -> str:
    """'1.16.0' from AUTOPILOT_VERSION.flight_sw_version (major, minor, patch in the top bytes)."""
    v = int(flight_sw_version)
    return f"{v >> 24 & 0xFF}.{v >> 16 & 0xFF}.{v >> 8 & 0xFF}"


PROFILES: dict[int, AutopilotProfile] = {p.autopilot: p for p in (PX4, ARDUPILOT)}


def profile_for(autopilot: int) -> AutopilotProfile | None:
    """The profile of a HEARTBEAT.autopilot value; None for an autopilot gcs fly cannot fly."""
    return PROFILES.get(autopilot)


def unsupported_text(vehicle: str, autopilot: int) -> str:
    """One line for a vehicle whose autopilot has no profile."""
    known = " and ".join(f"{p.name} ({p.autopilot})" for p in PROFILES.values())
    return f"{vehicle}: autopilot {autopilot} is not supported; gcs fly flies {known} only"
