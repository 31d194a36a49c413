"""MAVLink offboard ground control for adaptive distributed formation flight."""

import flightkit as _flightkit  # noqa: F401  (configures numba's cache first)
