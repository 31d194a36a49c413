"""`gcs fly`: the team's telemetry -> the law -> setpoints, with its records (see gcs/app.py)."""
