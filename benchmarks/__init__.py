"""The repository's benchmarks and calibration tools: every script runs as `python -m benchmarks.<name>` from the repository root."""
