"""MAVLink offboard ground control for adaptive distributed formation flight."""

import vehicle_emulator as _vehicle_emulator  # noqa: F401  (configures numba's cache first)
