"""The fleet's autopilot status arrays, one element per vehicle, that telemetry reports."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(slots=True)
class FleetStatus:
    """Per-vehicle autopilot status arrays the runner keeps up to date (n,)."""

    sysid: np.ndarray  # uint8
    armed: np.ndarray  # bool
    custom_mode: np.ndarray  # uint32
    base_mode_flags: np.ndarray  # uint8, without SAFETY_ARMED
    landed_state: np.ndarray  # uint8 MAV_LANDED_STATE
    system_status: np.ndarray  # uint8 MAV_STATE
    prearm_ok: np.ndarray  # bool: SYS_STATUS pre-arm check health bit
    position_ok: np.ndarray  # bool: SYS_STATUS GPS bit present and enabled (global position)
    mav_autopilot: np.ndarray  # uint8 MAV_AUTOPILOT of the personality
    origin_ned_m: np.ndarray  # (n, 3) EKF origin in the team frame (NED): LOCAL_POSITION_NED zero
    home_ned_m: np.ndarray  # (n, 3) home in the team frame (NED)
    noise: np.ndarray  # bool
    #: int64 time_boot_ms from which the estimator has a position: LOCAL_POSITION_NED is sent only
    #: with samples taken then or later (a sample stamped before it has no estimate behind it)
    position_from_ms: np.ndarray
    vtol_state: np.ndarray  # uint8 EXTENDED_SYS_STATE.vtol_state (ArduCopter: MC, 3)
    battery_remaining: np.ndarray  # 0..1
    battery_voltage_v: np.ndarray
    battery_current_a: np.ndarray
    errors_comm: np.ndarray  # uint16: rejected input so far
    #: bool: the autopilot publishes an attitude/rates setpoint (else no ATTITUDE_TARGET is sent,
    #: whatever its interval: PX4 sends one only per new setpoint)
    attitude_target: np.ndarray

    #: The columns a vehicle refreshes at the autopilot's rate (`VehicleNode.status_row`), in
    #: the row's order.
    ROW_COLUMNS = ("armed", "system_status", "prearm_ok", "position_ok", "custom_mode",
                   "base_mode_flags", "landed_state", "errors_comm", "attitude_target")

    def write_row(self, i: int, row: tuple) -> None:
        """One vehicle's `ROW_COLUMNS` values."""
        for name, value in zip(self.ROW_COLUMNS, row, strict=True):
            getattr(self, name)[i] = value

    def write_rows(self, rows: list[tuple]) -> None:
        """Every vehicle's `ROW_COLUMNS` values (``rows[i]``: vehicle i's), a column at a time:
        at 240 vehicles and 50 Hz, a numpy write per value was a tenth of the fleet's time."""
        for name, column in zip(self.ROW_COLUMNS, zip(*rows, strict=True), strict=True):
            getattr(self, name)[:] = column

    def refresh_battery(self, charge_used_c: np.ndarray, thrust_n: np.ndarray,
                        capacity_c: np.ndarray | float, which: slice = slice(None)) -> None:
        """The battery model of the vehicles ``which`` (after their ``armed``): the charge used
        of ``capacity_c`` [C], 13.2 V empty to 16.8 V full, 0.5 A + 0.8 A per newton of thrust
        while armed."""
        remaining = np.maximum(0.0, 1.0 - charge_used_c[which] / capacity_c)
        self.battery_remaining[which] = remaining
        self.battery_voltage_v[which] = 13.2 + 3.6 * remaining
        self.battery_current_a[which] = np.where(self.armed[which], 0.5 + 0.8 * thrust_n[which],
                                                 0.0)

    @classmethod
    def create(cls, sysids: list[int]) -> FleetStatus:
        """Defaults for ``len(sysids)`` vehicles."""
        n = len(sysids)
        return cls(
            sysid=np.array(sysids, dtype=np.uint8),
            armed=np.zeros(n, dtype=bool),
            custom_mode=np.zeros(n, dtype=np.uint32),
            base_mode_flags=np.ones(n, dtype=np.uint8),
            landed_state=np.ones(n, dtype=np.uint8),
            system_status=np.full(n, 3, dtype=np.uint8),
            prearm_ok=np.ones(n, dtype=bool),
            position_ok=np.ones(n, dtype=bool),
            mav_autopilot=np.full(n, 12, dtype=np.uint8),
            origin_ned_m=np.zeros((n, 3)),
            home_ned_m=np.zeros((n, 3)),
            noise=np.zeros(n, dtype=bool),
            position_from_ms=np.zeros(n, dtype=np.int64),
            vtol_state=np.zeros(n, dtype=np.uint8),
            battery_remaining=np.ones(n),
            battery_voltage_v=np.full(n, 16.8),
            battery_current_a=np.zeros(n),
            errors_comm=np.zeros(n, dtype=np.uint16),
            attitude_target=np.ones(n, dtype=bool),
        )
