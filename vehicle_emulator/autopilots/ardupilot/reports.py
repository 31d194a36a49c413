"""What ArduCopter 4.7.0-dev SITL reports of its state machine: position and pre-arm health,
ATTITUDE_TARGET, HEARTBEAT system_status and base_mode, EXTENDED_SYS_STATE's landed state (as
recorded; docs/emulator.md, "ArduPilot personality"). A mixin of ``ArduCopter`` (its state lives
there). Pure."""

from __future__ import annotations

from vehicle_emulator.autopilots.ardupilot.modes import XY_CONTROL, Mode

__all__ = ["CopterReports"]


class CopterReports:
    """The report queries of an ``ArduCopter`` (module docstring)."""

    __slots__ = ()

    def position_ok(self, now_s: float) -> bool:
        """The EKF has a position estimate (LOCAL_POSITION_NED is sent, GUIDED is armable)."""
        return self.boot.position_ok(now_s)

    def prearm_ok(self, now_s: float) -> bool:
        """SYS_STATUS pre-arm check bit: the pre-arm checks pass (recorded: set at 23.5 s, when
        the gyros became consistent, in STABILIZE)."""
        return not self.arm_failures(now_s, mode_check=False)

    def attitude_target_published(self) -> bool:
        """ATTITUDE_TARGET is sent at its rate in every mode (the attitude controller's target)."""
        return True

    def system_status(self, now_s: float) -> int:
        """HEARTBEAT system_status: BOOT (1) before "ArduPilot Ready", STANDBY (3) landed,
        ACTIVE (4) flying."""
        if not self.boot.initialised(now_s):
            return 1
        return 3 if self.land_complete else 4

    def base_mode(self, now_s: float) -> int:
        """HEARTBEAT base_mode: CUSTOM_MODE_ENABLED | STABILIZE | MANUAL_INPUT (81), GUIDED (8)
        while the horizontal position controller runs, SAFETY_ARMED (128)."""
        xy = self.mode in XY_CONTROL or not self.boot.initialised(now_s)
        if self.mode is Mode.GUIDED_NOGPS and not self.armed:
            xy = True  # recorded 89
        if self.mode is Mode.GUIDED and self.angle_control and self.armed:
            xy = False
        return 81 | (8 if xy else 0) | (128 if self.armed else 0)

    def landed_state(self) -> int:
        """EXTENDED_SYS_STATE landed_state: ON_GROUND 1, IN_AIR 2, TAKEOFF 3, LANDING 4."""
        if self.land_complete:
            return 1
        if self.mode is Mode.LAND:
            return 4
        return 3 if self._taking_off else 2
