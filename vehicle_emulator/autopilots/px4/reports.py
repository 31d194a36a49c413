"""What PX4 v1.16.0 reports of its state machine: the pre-arm and GPS health bits of
SYS_STATUS, whether ATTITUDE_TARGET is sent, HEARTBEAT's system_status (recorded on SIH;
docs/emulator.md). Mixed into `Autopilot` (logic.py), which owns the state these read. Pure."""

from __future__ import annotations

from vehicle_emulator.autopilots.px4.modes import NavState

__all__ = ["Px4Reports"]


class Px4Reports:
    """The report queries of an `Autopilot` (module docstring)."""

    __slots__ = ()

    def prearm_ok(self, now_s: float) -> bool:
        """PX4's pre-arm check result (SYS_STATUS MAV_SYS_STATUS_PREARM_CHECK health bit):
        what ``arm`` would refuse with TEMPORARILY_REJECTED is failing."""
        if now_s < self.ready_s:
            return False
        return not (self.nav_state is NavState.OFFBOARD and not self.offboard_available(now_s))

    def position_ok(self, now_s: float) -> bool:
        """The estimator has a global position (SYS_STATUS GPS bit present, enabled, healthy):
        PX4 v1.16.0 SIH set it in the same SYS_STATUS as the pre-arm bit, when arming became
        possible; MAVSDK's ``is_global_position_ok`` reads it."""
        return now_s >= self.ready_s

    def attitude_target_published(self) -> bool:
        """Whether PX4 publishes an attitude or rates setpoint, which its ATTITUDE_TARGET stream
        sends (only on a new one): not disarmed in OFFBOARD, where no controller runs and no
        setpoint arrives (PX4 v1.16.0 sent none there for 60 s; in Hold, disarmed, it did)."""
        return self.armed or self.nav_state is not NavState.OFFBOARD

    def system_status(self, now_s: float) -> int:
        """HEARTBEAT system_status as PX4 v1.16.0 sent it: UNINIT (0) disarmed before the
        estimator is ready and disarmed in OFFBOARD, CRITICAL (5) while a failsafe holds the
        mode, ACTIVE (4) armed, STANDBY (3) otherwise."""
        if self.armed:
            return 5 if self.failsafe_active else 4
        if now_s < self.ready_s or self.nav_state is NavState.OFFBOARD:
            return 0
        return 3
