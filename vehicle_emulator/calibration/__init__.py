"""The emulator against the recordings: replay of a recorded SITL flight in-process and the
recordings' figures computed alike."""
