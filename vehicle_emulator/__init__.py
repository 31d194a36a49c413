"""A PX4-like quadrotor emulator that speaks MAVLink 2 over UDP (see docs/emulator.md)."""
