"""Calibration and analysis tools (fits of the emulator to the recordings, the paper's tables): not benchmarks; each runs as `python -m benchmarks.calibration.<name>`."""
