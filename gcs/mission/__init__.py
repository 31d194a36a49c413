"""The flight sequence of `gcs fly` as a pure state machine; pure safety and stability checks."""
