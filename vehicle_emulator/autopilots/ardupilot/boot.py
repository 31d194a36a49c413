"""ArduCopter 4.7.0-dev SITL's boot as recorded: when it is ready, sets its origin, has a
position estimate, and which "Arm: ..." reasons it gives before then."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class BootTimeline:
    """What ArduCopter 4.7.0-dev SITL did after process start (recorded twice, s), times
    ``scale``. ``arm_reasons`` are the "Arm: ..." failures of an arming attempt at a time."""

    scale: float = 1.0

    READY_S = 2.46  # "ArduPilot Ready": system_status BOOT -> STANDBY
    EKF_INIT_S = 4.46
    TILT_S = 5.81
    ACCELS_OK_S = 13.6  # "Accels inconsistent" until 13.26-14.02 s
    GYROS_OK_S = 23.6  # "Gyros inconsistent" until 23.26-24.02 s (armed at 24.02 / 24.26 s)
    ORIGIN_S = 20.03  # EKF origin: GPS_GLOBAL_ORIGIN + HOME_POSITION
    POSITION_S = 41.63  # "EKF3 IMU0 is using GPS": position estimate, LOCAL_POSITION_NED
    PREARM_FIRST_S = 29.46  # "PreArm: <reason>" while disarmed and failing, every 30 s
    PREARM_PERIOD_S = 30.0
    TEXTS = (
        (0.33, "Calibrating barometer"),
        (1.93, "Barometer 1 calibration complete"),
        (1.93, "Barometer 2 calibration complete"),
        (2.46, "ArduPilot Ready"),
        (2.46, "AHRS: DCM active"),
        (4.46, "EKF3 IMU0 initialised"),
        (4.46, "EKF3 IMU1 initialised"),
        (4.46, "AHRS: EKF3 active"),
        (5.81, "EKF3 IMU0 tilt alignment complete"),
        (5.81, "EKF3 IMU1 tilt alignment complete"),
        (5.91, "EKF3 IMU0 MAG0 initial yaw alignment complete"),
        (5.91, "EKF3 IMU1 MAG0 initial yaw alignment complete"),
        (9.81, "GPS 1: probing for u-blox at 230400 baud"),
        (9.84, "GPS 1: detected u-blox"),
        (20.03, "EKF3 IMU0 origin set"),
        (20.23, "EKF3 IMU1 origin set"),
        (41.63, "EKF3 IMU0 is using GPS"),
        (41.64, "EKF3 IMU1 is using GPS"),
    )

    def at(self, t_recorded_s: float) -> float:
        """Emulator time of a recorded boot time."""
        return t_recorded_s * self.scale

    def initialised(self, now_s: float) -> bool:
        return now_s >= self.at(self.READY_S)

    def origin_set(self, now_s: float) -> bool:
        return now_s >= self.at(self.ORIGIN_S)

    def position_ok(self, now_s: float) -> bool:
        return now_s >= self.at(self.POSITION_S)

    def sensor_reasons(self, now_s: float) -> list[str]:
        """The boot-time "Arm: ..." reasons (without the "Arm: " prefix), in recorded order."""
        if not self.initialised(now_s):
            return ["System not initialised"]
        if now_s < self.at(self.EKF_INIT_S):
            return ["Accels inconsistent", "EKF attitude is bad",
                    "AHRS: not using configured AHRS type"]
        if now_s < self.at(self.TILT_S):
            return ["Accels inconsistent", "EKF attitude is bad", "AHRS: EKF3 still initialising"]
        if now_s < self.at(self.ACCELS_OK_S):
            return ["Accels inconsistent"]
        if now_s < self.at(self.GYROS_OK_S):
            return ["Gyros inconsistent"]
        return []


PAST_BOOT = BootTimeline(scale=0.0)  # a vehicle that starts in the air
