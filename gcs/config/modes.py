"""The team file's named choices: control modes, stop actions and the other keys' option lists.

ControlMode (gcs/control/modes.py, with the law whose loops it names) and FlyAction are StrEnums
whose values are the team file's strings, so a member formats, compares, hashes and serialises
(json) as its string. Where a message or the command line lists choices, `as_strings` gives the
plain strings (a member's repr names its class). No imports from the rest of gcs but that enum:
the config schema, the mission logic and the flight read their modes here.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable

from gcs.control.modes import ControlMode

# ControlMode is re-exported: the team file's choice
__all__ = ["ClockMode", "ControlMode", "FlyAction", "NetworkMode"]


class FlyAction(enum.StrEnum):
    """What `gcs fly` tells a vehicle to do when it stops flying it."""

    LAND = "land"
    HOLD = "hold"  # the autopilot's hold mode (PX4 AUTO_LOITER, ArduPilot BRAKE)


class NetworkMode(enum.StrEnum):
    """network.mode: how an agent's Zenoh session joins the others (gcs/agent/bus.py)."""

    PEER = "peer"  # listens on its own endpoints and connects to every other process's
    CLIENT = "client"  # connects to network.router only, which routes every message


class ClockMode(enum.StrEnum):
    """network.clocks: how an agent puts its neighbours' sample times on its own clock
    (gcs/agent/table.py)."""

    MEASURED = "measured"  # by each peer's clock offset, estimated from the samples' echoes
    DISCIPLINED = "disciplined"  # the hosts' system clocks agree (PTP, chrony): samples carry
    #                              them; the echoes only check that they do
    ONE_HOST = "one-host"  # every process's monotonic clock is one (all on one host)


LAWS = ("adaptive", "baseline")
MODES = (ControlMode.RATES, ControlMode.ACTUATORS, ControlMode.ATTITUDE)  # controller.mode
POSITION_MODE = ControlMode.POSITION
FLY_CONTROL_MODES = (*MODES, POSITION_MODE)  # what gcs fly can fly (fly.<mode> blocks)
AUTO_MODE = "auto"  # fly.mode / gcs fly --mode: gcs fly picks the first of AUTO_MODES that passes
FLY_MODES = (AUTO_MODE, *FLY_CONTROL_MODES)  # fly.mode / gcs fly --mode
#: what fly.mode auto chooses from, in order (gcs/fly/setup.py)
AUTO_MODES = (ControlMode.RATES, ControlMode.ATTITUDE)
#: the modes whose setpoint is the law's torque (26): the only ones in which the inertia estimate
#: rhohat of (27) acts on the vehicle, so the only ones that integrate it (in rates and attitude
#: mode the autopilot's own loops turn the setpoint into torque; rhohat stays at its initial value)
TORQUE_MODES = (ControlMode.ACTUATORS,)
SIM_MODES = (ControlMode.RATES, ControlMode.ACTUATORS)  # what gcs sim models
DERIVATIVE_METHODS = ("model", "levant")
FAULT_KINDS = ("mass_drop", "link_loss", "packet_loss", "motor_efficiency")
JITTER_KINDS = ("uniform", "normal")  # packet_loss jitter distributions (as the emulator's)
FLY_ACTIONS = (FlyAction.LAND, FlyAction.HOLD)
FLY_STARTS = ("auto", "in_air", "takeoff")
FLY_HEADINGS = ("hold", "paper")  # or a compass heading in degrees
#: fly.initial_mass: the vehicles' `estimates.mhat`, or every one from its hover thrust
FLY_INITIAL_MASSES = ("team", "from_hover")
FLY_SCHEDULING = ("auto", "realtime", "raised", "normal")  # gcs/fly/sched.py


def as_strings(options: Iterable[str]) -> tuple[str, ...]:
    """`options` as plain strings: how messages and the command line list choices."""
    return tuple(str(option) for option in options)


def fly_mode(name: str) -> ControlMode | str:
    """fly.mode or `gcs fly --mode` `name` (one of FLY_MODES): its ControlMode, or AUTO_MODE."""
    return AUTO_MODE if name == AUTO_MODE else ControlMode(name)
