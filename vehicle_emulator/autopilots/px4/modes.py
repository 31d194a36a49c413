"""PX4's flight modes as the emulator flies them: their custom_mode encoding (main << 16 |
sub << 24), names, and which of them arm, fly from sticks, or are not emulated. Pure."""

from __future__ import annotations

from enum import IntEnum

__all__ = ["NavState", "custom_mode_of", "nav_state_of", "not_emulated"]


class NavState(IntEnum):
    """Flight modes the emulator flies; values are PX4 (main_mode, sub_mode) packed as below."""

    ALTCTL = 2 << 16
    POSCTL = 3 << 16
    AUTO_TAKEOFF = (4 << 16) | (2 << 24)
    AUTO_LOITER = (4 << 16) | (3 << 24)
    AUTO_LAND = (4 << 16) | (6 << 24)
    OFFBOARD = 6 << 16


def custom_mode_of(state: NavState) -> int:
    """HEARTBEAT custom_mode of a nav state (main_mode << 16 | sub_mode << 24)."""
    return int(state)


def nav_state_of(main_mode: int, sub_mode: int) -> NavState | None:
    """The NavState for a PX4 (main, sub) pair, or None when the emulator does not fly it."""
    if main_mode == 4:
        sub = {2: NavState.AUTO_TAKEOFF, 3: NavState.AUTO_LOITER, 6: NavState.AUTO_LAND}
        return sub.get(sub_mode)
    return {2: NavState.ALTCTL, 3: NavState.POSCTL, 6: NavState.OFFBOARD}.get(main_mode)


#: (main, sub) modes PX4 flies and the emulator does not: AUTO_RTL. A DO_SET_MODE for one gets a
#: single UNSUPPORTED ACK, not PX4's ACCEPTED first, so no client takes it for a mode change.
_NOT_EMULATED = frozenset({(4, 5)})


def not_emulated(main_mode: int, sub_mode: int) -> bool:
    """True for a PX4 mode the emulator does not fly (and refuses as UNSUPPORTED)."""
    return (main_mode, sub_mode) in _NOT_EMULATED


MANUAL = frozenset({NavState.POSCTL, NavState.ALTCTL})  # modes flown from (RC) sticks
# the modes the emulator flies that PX4 refuses to arm in (mode_req_prevent_arming): never the
# mode after disarming
PREVENTS_ARMING = frozenset({NavState.AUTO_LAND})

MODE_NAMES = {
    NavState.ALTCTL: "Altitude",
    NavState.POSCTL: "Position",
    NavState.AUTO_TAKEOFF: "Takeoff",
    NavState.AUTO_LOITER: "Hold",
    NavState.AUTO_LAND: "Land",
    NavState.OFFBOARD: "Offboard",
}
