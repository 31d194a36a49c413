"""PX4 v1.16's logic as the emulator plays it: arming, modes, offboard rules, failsafes."""
