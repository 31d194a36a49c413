"""What the ground station and the emulator share: the numba compile cache keyed by the sources
(jitcache), real-time scheduling (sched), the late-compile watcher (latecompile), the rigid-body
model both simulate (physics) and the emulator fleet's ready line (fleet_protocol). Imports
neither gcs nor vehicle_emulator, and importing it does nothing: each program calls
`flightkit.jitcache.configure()` itself, before it imports compiled code."""
