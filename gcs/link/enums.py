"""MAVLink enumerations and PX4/ArduPilot mode encodings the GCS uses, as IntEnums."""

from __future__ import annotations

from enum import Enum, IntEnum


class MavResult(IntEnum):
    """MAV_RESULT of a COMMAND_ACK."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5
    CANCELLED = 6
    COMMAND_LONG_ONLY = 7
    COMMAND_INT_ONLY = 8
    COMMAND_UNSUPPORTED_MAV_FRAME = 9


class MavCmd(IntEnum):
    """The MAV_CMD subset the GCS sends in COMMAND_LONG."""

    NAV_LAND = 21
    NAV_TAKEOFF = 22
    DO_SET_MODE = 176
    COMPONENT_ARM_DISARM = 400
    SET_MESSAGE_INTERVAL = 511
    REQUEST_MESSAGE = 512


class MavType(IntEnum):
    QUADROTOR = 2
    GCS = 6


class MavAutopilot(IntEnum):
    GENERIC = 0
    ARDUPILOTMEGA = 3
    INVALID = 8
    PX4 = 12


class MavModeFlag(IntEnum):
    CUSTOM_MODE_ENABLED = 1
    SAFETY_ARMED = 128


class MavState(IntEnum):
    ACTIVE = 4


class LandedState(IntEnum):
    """MAV_LANDED_STATE from EXTENDED_SYS_STATE."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class Px4MainMode(IntEnum):
    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class Px4AutoSubMode(IntEnum):
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6


class ArduCopterMode(IntEnum):
    """ArduCopter flight modes (HEARTBEAT custom_mode is the mode number)."""

    STABILIZE = 0
    ACRO = 1
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    CIRCLE = 7
    LAND = 9
    DRIFT = 11
    SPORT = 13
    FLIP = 14
    AUTOTUNE = 15
    POSHOLD = 16
    BRAKE = 17
    THROW = 18
    AVOID_ADSB = 19
    GUIDED_NOGPS = 20
    SMART_RTL = 21
    FLOWHOLD = 22
    FOLLOW = 23
    ZIGZAG = 24
    SYSTEMID = 25
    AUTOROTATE = 26
    AUTO_RTL = 27
    TURTLE = 28


class LinkState(Enum):
    """WAITING: nothing heard yet; ALIVE: heard within the timeout; LOST: silent longer."""

    WAITING = "waiting"
    ALIVE = "alive"
    LOST = "lost"


#: MAVLink id of the messages the GCS reads (for SET_MESSAGE_INTERVAL).
MSG_ID: dict[str, int] = {
    "HEARTBEAT": 0,
    "SYS_STATUS": 1,
    "ATTITUDE": 30,
    "ATTITUDE_QUATERNION": 31,
    "LOCAL_POSITION_NED": 32,
    "GLOBAL_POSITION_INT": 33,
    "GPS_GLOBAL_ORIGIN": 49,
    "ATTITUDE_TARGET": 83,
    "HIGHRES_IMU": 105,
    "ODOMETRY": 331,
    "HOME_POSITION": 242,
    "EXTENDED_SYS_STATE": 245,
}


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """PX4 HEARTBEAT custom_mode: main_mode << 16 | sub_mode << 24 (OFFBOARD -> 393216)."""
    if not 0 <= main_mode <= 255 or not 0 <= sub_mode <= 255:
        raise ValueError(f"PX4 mode: expected main, sub in 0..255, got {main_mode}, {sub_mode}")
    return (main_mode << 16) | (sub_mode << 24)


def px4_mode_parts(custom_mode: int) -> tuple[int, int]:
    """(main_mode, sub_mode) of a PX4 custom_mode."""
    return (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF


def mode_name(autopilot: int, custom_mode: int) -> str:
    """Human name of a HEARTBEAT custom_mode, e.g. 'OFFBOARD', 'AUTO_LAND', 'GUIDED'."""
    if autopilot == MavAutopilot.ARDUPILOTMEGA:
        try:
            return ArduCopterMode(custom_mode).name
        except ValueError:
            return f"CUSTOM({custom_mode})"
    main, sub = px4_mode_parts(custom_mode)
    try:
        main_name = Px4MainMode(main).name
    except ValueError:
        return f"CUSTOM({custom_mode})"
    if main == Px4MainMode.AUTO:
        try:
            return f"AUTO_{Px4AutoSubMode(sub).name}"
        except ValueError:
            return f"AUTO({sub})"
    return main_name
