"""ArduCopter 4.7's logic and its MAVLink side: boot, modes, GUIDED targets, the node."""
