"""What makes an emulated vehicle an autopilot: the personalities, parameter tables, the
vehicle node that speaks MAVLink (PX4's dialect; ArduPilot's overrides it) and the setpoint
decoders. The autopilots' own logic lives in `px4/` and `ardupilot/`; ``nominal`` is PX4's logic
over the paper's nominal model (`personality.py`)."""
