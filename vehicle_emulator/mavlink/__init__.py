"""The emulator's MAVLink side: codec, the UDP server of each link, telemetry scheduling."""
