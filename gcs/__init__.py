"""MAVLink offboard ground control for adaptive distributed formation flight."""
