"""The team file's named choices: control modes, stop actions and the other keys' option lists.

No imports from the rest of gcs: the config schema, the mission logic and the flight all read
their modes from here.
"""

from __future__ import annotations

LAWS = ("adaptive", "baseline")
MODES = ("rates", "actuators", "attitude")  # attitude: gcs fly only (the autopilot's loop)
#: gcs fly's baseline: no law, each vehicle gets its slot of the moving formation as a position
#: setpoint and the autopilot closes every loop (gcs/control/slots.py; never chosen by auto)
POSITION_MODE = "position"
FLY_CONTROL_MODES = (*MODES, POSITION_MODE)  # what gcs fly can fly (fly.<mode> blocks)
FLY_MODES = ("auto", *FLY_CONTROL_MODES)  # fly.mode / gcs fly --mode
AUTO_MODES = ("rates", "attitude")  # what fly.mode auto chooses from, in order (gcs/fly/setup.py)
#: the modes whose setpoint is the law's torque (26): the only ones in which the inertia estimate
#: rhohat of (27) acts on the vehicle, so the only ones that integrate it (in rates and attitude
#: mode the autopilot's own loops turn the setpoint into torque; rhohat stays at its initial value)
TORQUE_MODES = ("actuators",)
SIM_MODES = ("rates", "actuators")
DERIVATIVE_METHODS = ("model", "levant")
FAULT_KINDS = ("mass_drop", "link_loss", "packet_loss", "motor_efficiency")
JITTER_KINDS = ("uniform", "normal")  # packet_loss jitter distributions (as the emulator's)
FLY_ACTIONS = ("land", "hold")  # what `gcs fly` tells vehicles to do when it stops flying them
FLY_STARTS = ("auto", "in_air", "takeoff")
FLY_HEADINGS = ("hold", "paper")  # or a compass heading in degrees
#: fly.initial_mass: the vehicles' `estimates.mhat`, or every one from its hover thrust
FLY_INITIAL_MASSES = ("team", "from_hover")
FLY_SCHEDULING = ("auto", "realtime", "raised", "normal")  # gcs/fly/sched.py
