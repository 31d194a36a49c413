"""What the ground station sends each vehicle, and so which of its loops the law closes.

A StrEnum whose values are the team file's strings (`controller.mode`, `fly.mode`), so a member
formats, compares, hashes and serialises (json) as its string. It lives with the law because the
law's stability analysis (cascade.py) is written per mode; the team file's other named choices are
in gcs/config/modes.py.
"""

from __future__ import annotations

import enum


class ControlMode(enum.StrEnum):
    """What the ground station sends each vehicle, and so which of its loops the law closes."""

    RATES = "rates"  # thrust + body rates (the autopilot's rate loop)
    ACTUATORS = "actuators"  # thrust + the law's torque (26)
    ATTITUDE = "attitude"  # thrust + the command attitude (14); gcs fly only
    #: gcs fly's baseline: no law, each vehicle gets its slot of the moving formation as a
    #: position setpoint and the autopilot closes every loop (gcs/control/slots.py; never chosen
    #: by auto)
    POSITION = "position"
