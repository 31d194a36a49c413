"""A PX4-like quadrotor emulator that speaks MAVLink 2 over UDP (see docs/emulator.md)."""

import flightkit as _flightkit  # noqa: F401  (configures numba's cache first)
