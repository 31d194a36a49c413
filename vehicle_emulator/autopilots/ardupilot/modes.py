"""ArduCopter's flight modes: their numbers and names, and which of them arm, fly, need a
position estimate, run the horizontal position controller or read the pilot's sticks."""

from __future__ import annotations

from enum import IntEnum


class Mode(IntEnum):
    """ArduCopter flight mode numbers (HEARTBEAT custom_mode, DO_SET_MODE param2)."""

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


M = Mode
FLOWN = frozenset({M.STABILIZE, M.ALT_HOLD, M.GUIDED, M.LOITER, M.LAND, M.POSHOLD, M.BRAKE,
                   M.GUIDED_NOGPS})
# Mode::allows_arming (ArduCopter 4.7)
ARMABLE = frozenset({M.STABILIZE, M.ACRO, M.ALT_HOLD, M.GUIDED, M.LOITER, M.DRIFT, M.SPORT,
                     M.POSHOLD, M.GUIDED_NOGPS, M.THROW, M.FLOWHOLD, M.ZIGZAG, M.TURTLE})
# Mode::requires_GPS
NEEDS_POSITION = frozenset({M.AUTO, M.GUIDED, M.LOITER, M.RTL, M.CIRCLE, M.DRIFT, M.POSHOLD,
                            M.BRAKE, M.THROW, M.SMART_RTL, M.FOLLOW, M.ZIGZAG, M.AUTO_RTL})
GUIDED_MODES = frozenset({M.GUIDED, M.GUIDED_NOGPS})  # Mode::in_guided_mode
# HEARTBEAT base_mode GUIDED_ENABLED (8): the horizontal position controller runs (recorded:
# STABILIZE 81, GUIDED / BRAKE / LAND 89 disarmed, 217 armed, GUIDED_NOGPS 89 disarmed, 209 armed)
XY_CONTROL = frozenset({M.AUTO, M.GUIDED, M.LOITER, M.RTL, M.CIRCLE, M.LAND, M.POSHOLD, M.BRAKE,
                        M.SMART_RTL, M.FOLLOW, M.ZIGZAG, M.AUTO_RTL})
PILOT_MODES = frozenset({M.STABILIZE, M.ALT_HOLD, M.LOITER, M.POSHOLD})


def mode_name(number: int) -> str:
    """ArduCopter's name of a mode number ('GUIDED_NOGPS'), or 'MODE <n>'."""
    try:
        return Mode(number).name
    except ValueError:
        return f"MODE {number}"
