"""The emulated vehicles' physical side: plant, motors, sensors and estimates, inner loops,
frames and geodesy. Pure and compiled; no MAVLink."""
