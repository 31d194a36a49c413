"""What the ground station and the emulator share: the numba compile cache keyed by the sources
(jitcache), real-time scheduling (sched), the late-compile watcher (latecompile), the rigid-body
model both simulate (physics) and the emulator fleet's ready line (fleet_protocol). Imports
neither gcs nor vehicle_emulator."""

from flightkit import jitcache as _jitcache

_jitcache.configure()
