"""`gcs fly`: the team's telemetry -> the law -> setpoints, with its records (fly/flight.py)."""
