"""Typed samples of the messages the layers above the link read: frozen, units in the names,
MAVLink's own frames (NED/FRD) and the receive time on the GCS clock.

pymavlink's message objects stop here: `VehicleProxy.sample(kind)` decodes the latest message of
``kind.MESSAGE`` into ``kind``. Each ``from_message`` converts MAVLink's integer units (1e-7 deg,
mm, ms) once, so a reader never rescales a field.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, TypeVar

from gcs.link.enums import MavModeFlag

#: A decoded pymavlink message (gcs.link.codec.MAVLinkMessage); named loosely so that this module
#: imports no pymavlink and stays pure.
MAVLinkMessage = Any

Vec3 = tuple[float, float, float]

_ARMED = int(MavModeFlag.SAFETY_ARMED)  # a plain int: IntEnum arithmetic costs microseconds


class Sample(Protocol):
    MESSAGE: ClassVar[str]
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> Sample: ...


S = TypeVar("S", bound=Sample)


@dataclass(frozen=True, slots=True)
class Heartbeat:
    MESSAGE: ClassVar[str] = "HEARTBEAT"
    autopilot: int  # MAV_AUTOPILOT
    vehicle_type: int  # MAV_TYPE
    base_mode: int  # MAV_MODE_FLAG bits
    custom_mode: int
    system_status: int  # MAV_STATE
    rx_time_s: float

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & _ARMED)

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> Heartbeat:
        return cls(int(msg.autopilot), int(msg.type), int(msg.base_mode), int(msg.custom_mode),
                   int(msg.system_status), rx_time_s)


@dataclass(frozen=True, slots=True)
class LocalPositionNed:
    MESSAGE: ClassVar[str] = "LOCAL_POSITION_NED"
    time_boot_s: float  # the vehicle's stamp of the sample
    position_ned_m: Vec3
    velocity_ned_mps: Vec3
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> LocalPositionNed:
        return cls(msg.time_boot_ms * 1e-3, (msg.x, msg.y, msg.z), (msg.vx, msg.vy, msg.vz),
                   rx_time_s)


@dataclass(frozen=True, slots=True)
class AttitudeQuaternion:
    MESSAGE: ClassVar[str] = "ATTITUDE_QUATERNION"
    time_boot_s: float
    quaternion_wxyz: tuple[float, float, float, float]  # body FRD -> local NED
    rates_frd_radps: Vec3
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> AttitudeQuaternion:
        return cls(msg.time_boot_ms * 1e-3, (msg.q1, msg.q2, msg.q3, msg.q4),
                   (msg.rollspeed, msg.pitchspeed, msg.yawspeed), rx_time_s)


@dataclass(frozen=True, slots=True)
class HighresImu:
    MESSAGE: ClassVar[str] = "HIGHRES_IMU"
    specific_force_frd_mps2: Vec3  # the accelerometers' reading
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> HighresImu:
        return cls((msg.xacc, msg.yacc, msg.zacc), rx_time_s)


@dataclass(frozen=True, slots=True)
class ExtendedSysState:
    MESSAGE: ClassVar[str] = "EXTENDED_SYS_STATE"
    landed_state: int  # MAV_LANDED_STATE
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> ExtendedSysState:
        return cls(int(msg.landed_state), rx_time_s)


@dataclass(frozen=True, slots=True)
class SysStatus:
    MESSAGE: ClassVar[str] = "SYS_STATUS"
    sensors_present: int  # MAV_SYS_STATUS_SENSOR bits
    sensors_health: int
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> SysStatus:
        return cls(int(msg.onboard_control_sensors_present),
                   int(msg.onboard_control_sensors_health), rx_time_s)


@dataclass(frozen=True, slots=True)
class GlobalPosition:
    MESSAGE: ClassVar[str] = "GLOBAL_POSITION_INT"
    altitude_amsl_m: float
    height_above_home_m: float
    rx_time_s: float

    @property
    def home_amsl_m(self) -> float:
        return self.altitude_amsl_m - self.height_above_home_m

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> GlobalPosition:
        return cls(msg.alt * 1e-3, msg.relative_alt * 1e-3, rx_time_s)


@dataclass(frozen=True, slots=True)
class AttitudeTarget:
    MESSAGE: ClassVar[str] = "ATTITUDE_TARGET"
    thrust: float  # normalised collective thrust the autopilot commands, 0..1
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> AttitudeTarget:
        return cls(float(msg.thrust), rx_time_s)


@dataclass(frozen=True, slots=True)
class GpsGlobalOrigin:
    """The vehicle's EKF origin."""

    MESSAGE: ClassVar[str] = "GPS_GLOBAL_ORIGIN"
    latitude_deg: float
    longitude_deg: float
    altitude_amsl_m: float
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> GpsGlobalOrigin:
        return cls(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3, rx_time_s)


@dataclass(frozen=True, slots=True)
class HomePosition:
    """Home, geodetic and in the vehicle's local frame (relative to its EKF origin)."""

    MESSAGE: ClassVar[str] = "HOME_POSITION"
    latitude_deg: float
    longitude_deg: float
    altitude_amsl_m: float
    local_ned_m: Vec3
    rx_time_s: float

    @classmethod
    def from_message(cls, msg: MAVLinkMessage, rx_time_s: float) -> HomePosition:
        return cls(msg.latitude * 1e-7, msg.longitude * 1e-7, msg.altitude * 1e-3,
                   (msg.x, msg.y, msg.z), rx_time_s)
