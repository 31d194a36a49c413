"""The emulator's parameter tables: per autopilot family (``PARAMS``: PX4's names; ``ARDUCOPTER
PARAMS``: ArduCopter's), each with the EMU_* emulator settings.

Pure: a ``ParamStore`` per vehicle holds typed values with limits; ``set`` returns the stored value
or raises ``ParamError`` (unknown name, read-only, out of range, not finite). MAVLink encoding of
integer values follows the autopilot: PX4 puts the bits of an INT32 in the float field
(bytewise), ArduPilot casts the integer to float (``encode_value`` / ``decode_value``).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum

__all__ = [
    "ARDUCOPTER_PARAMS",
    "PARAMS",
    "ParamDef",
    "ParamError",
    "ParamStore",
    "ParamType",
    "decode_value",
    "encode_value",
    "param_table",
]


class ParamType(IntEnum):
    """MAV_PARAM_TYPE values used here."""

    INT8 = 2
    INT16 = 4
    INT32 = 6
    REAL32 = 9


class ParamError(ValueError):
    """A parameter write was refused; the message names the parameter and the reason."""


@dataclass(frozen=True, slots=True)
class ParamDef:
    """One parameter: name (<= 16 chars), type, default, limits, and a one-line meaning."""

    name: str
    ptype: ParamType
    default: float
    minimum: float
    maximum: float
    description: str
    read_only: bool = False


_I, _F = ParamType.INT32, ParamType.REAL32

PARAMS: tuple[ParamDef, ...] = (
    ParamDef("COM_OF_LOSS_T", _F, 1.0, 0.0, 60.0, "offboard setpoint loss timeout [s]"),
    ParamDef(
        "COM_OBL_RC_ACT",
        _I,
        0,
        0,
        7,
        "offboard loss action: 0/1/2/5 hold, 3/4 land, 6 hold (no termination), 7 disarm",
    ),
    ParamDef("COM_DISARM_LAND", _F, 2.0, -1.0, 20.0, "auto-disarm after landing [s], <0 off"),
    ParamDef("COM_DISARM_PRFLT", _F, 10.0, -1.0, 60.0, "auto-disarm if no takeoff [s], <0 off"),
    ParamDef("MIS_TAKEOFF_ALT", _F, 2.5, 0.5, 100.0, "default takeoff altitude above ground [m]"),
    ParamDef("MPC_LAND_SPEED", _F, 0.7, 0.2, 3.0, "landing descent speed [m/s]"),
    ParamDef("MPC_TKO_SPEED", _F, 1.5, 0.2, 5.0, "takeoff climb speed [m/s]"),
    ParamDef("MPC_Z_VEL_MAX_DN", _F, 1.0, 0.5, 4.0, "max descent speed, full-down stick [m/s]"),
    ParamDef(
        "COM_RC_IN_MODE", _I, 3, 0, 4,
        "manual control input; 4 none: in Position/Altitude the stick reads full down (descend)",
    ),
    ParamDef(
        "MPC_THR_HOVER", _F, 0.5, 0.05, 0.95, "hover thrust of the onboard controllers [0..1]"
    ),
    ParamDef("MAV_SYS_ID", _I, 1, 1, 254, "system id (set at start)", read_only=True),
    ParamDef("EMU_NOISE", _I, 0, 0, 1, "1: seeded noise (sensor model; nominal: telemetry)"),
    ParamDef("EMU_SEED", _I, 0, 0, 2**31 - 1, "seed of noise and packet-loss draws"),
    ParamDef("EMU_FLT_T0", _I, 0, 0, 1, "fault clock zero: 0 first OFFBOARD entry, 1 boot"),
    ParamDef(
        "EMU_FLT_CLK", _F, -1.0, -1.0, 1e9, "fault clock now [s], -1 not started", read_only=True
    ),
    ParamDef(
        "EMU_MDROP_T", _F, -1.0, -1.0, 1e6, "scheduled mass drop time on fault clock, <0 none"
    ),
    ParamDef("EMU_MDROP_FRAC", _F, 0.0, 0.0, 0.95, "scheduled mass drop fraction"),
    ParamDef("EMU_MASS_DROP", _F, 0.0, 0.0, 0.95, "write f > 0: drop fraction f of mass now"),
    ParamDef("EMU_LINK_LOSS", _F, 0.0, 0.0, 3600.0, "write t > 0: link silent for t seconds now"),
    ParamDef("EMU_PKT_LOSS", _F, 0.0, 0.0, 1.0, "packet loss probability, both directions"),
    ParamDef(
        "EMU_LATENCY_MS", _F, 0.0, 0.0, 10000.0, "added one-way latency, both directions [ms]"
    ),
    ParamDef("EMU_JITTER_MS", _F, 0.0, 0.0, 10000.0, "jitter on top of the latency [ms]"),
    ParamDef("EMU_JITTER_DIST", _I, 0, 0, 1, "jitter: 0 uniform [0, J], 1 half-normal |N(0, J)|"),
    ParamDef("EMU_REORDER_P", _F, 0.0, 0.0, 1.0, "probability a packet is held back 20 ms"),
    ParamDef("EMU_MOT1_EFF", _F, 1.0, 0.0, 1.0, "rotor 1 efficiency (thrust factor)"),
    ParamDef("EMU_MOT2_EFF", _F, 1.0, 0.0, 1.0, "rotor 2 efficiency (thrust factor)"),
    ParamDef("EMU_MOT3_EFF", _F, 1.0, 0.0, 1.0, "rotor 3 efficiency (thrust factor)"),
    ParamDef("EMU_MOT4_EFF", _F, 1.0, 0.0, 1.0, "rotor 4 efficiency (thrust factor)"),
    ParamDef("EMU_MOT_TAU", _F, 0.0, 0.0, 1.0, "first-order motor time constant [s], 0 off"),
    ParamDef(
        "MC_AIRMODE", _I, 0, 0, 1,
        "mixer at low thrust: 0 keep thrust, shrink torque (PX4 default); 1 raise thrust",
    ),
    ParamDef("EMU_MASS_KG", _F, 1.0, 0.0, 1e4, "true plant mass now [kg]", read_only=True),
    ParamDef(
        "EMU_THR_MAX_N", _F, 1.0, 0.0, 1e5, "max collective thrust 4 f_max [N]", read_only=True
    ),
    ParamDef(
        "EMU_ACK_TWICE", _I, 1, 0, 1,
        "DO_SET_MODE command ACKs: 1 ACCEPTED at once, then the result (PX4 v1.16.0); 0 result",
    ),
)

_I8, _I16 = ParamType.INT8, ParamType.INT16
_AP_ONLY_EMU = (
    ParamDef(
        "EMU_BOOT_SCALE", _F, 1.0, 0.0, 10.0,
        "time scale of the recorded ArduCopter boot timeline (0: booted at once)",
    ),
    ParamDef("EMU_BANNER", _I, 1, 0, 1, "1: plain-text boot banner before the first packet"),
)

#: ArduCopter 4.7 names, types, firmware defaults and ranges (the recording's params.txt), the
#: ones the ardupilot personality reads; then the emulator's settings (EMU_ACK_TWICE and the
#: PX4 mixer option excepted).
ARDUCOPTER_PARAMS: tuple[ParamDef, ...] = (
    ParamDef("GUID_OPTIONS", _I, 0, 0, 2**16 - 1,
             "guided options bitmask; bit 3 (8): SET_ATTITUDE_TARGET thrust is thrust"),
    ParamDef("GUID_TIMEOUT", _F, 3.0, 0.1, 5.0, "guided attitude/velocity target timeout [s]"),
    ParamDef("DISARM_DELAY", _I8, 10, 0, 127, "auto-disarm after this long landed [s], 0 off"),
    ParamDef("LAND_SPEED", _I16, 50, 30, 200, "landing speed below LAND_ALT_LOW [cm/s]"),
    ParamDef("LAND_ALT_LOW", _I16, 1000, 100, 10000, "altitude where LAND slows down [cm]"),
    ParamDef("WPNAV_SPEED_UP", _F, 250.0, 10.0, 1000.0, "climb speed [cm/s]"),
    ParamDef("WPNAV_SPEED_DN", _F, 150.0, 10.0, 500.0, "descent speed [cm/s]"),
    ParamDef("WPNAV_ACCEL_Z", _F, 100.0, 50.0, 500.0, "vertical acceleration [cm/s^2]"),
    ParamDef("PILOT_SPEED_UP", _I16, 250, 50, 500, "pilot climb rate [cm/s]"),
    ParamDef("PILOT_SPEED_DN", _I16, 0, 0, 500, "pilot descent rate [cm/s], 0: PILOT_SPEED_UP"),
    ParamDef("ARMING_CHECK", _I, 1, 0, 2**31 - 1, "pre-arm checks bitmask, 0: mandatory only"),
    ParamDef("MOT_THST_HOVER", _F, 0.35, 0.05, 0.95, "hover thrust [0..1] (set from the plant)"),
    ParamDef("MAV_SYSID", _I16, 1, 1, 255, "system id (set at start)", read_only=True),
    *_AP_ONLY_EMU,
    *(p for p in PARAMS if p.name.startswith("EMU_") and p.name != "EMU_ACK_TWICE"),
)

_TABLES = {"px4": PARAMS, "ardupilot": ARDUCOPTER_PARAMS}


def param_table(family: str) -> tuple[ParamDef, ...]:
    """The parameter table of an autopilot family ('px4', 'ardupilot')."""
    return _TABLES[family]


class ParamStore:
    """Typed parameter values of one vehicle, from one table (default PX4's)."""

    __slots__ = ("_values", "_defs", "_names", "bytewise_ints")

    def __init__(
        self,
        overrides: dict[str, float] | None = None,
        table: tuple[ParamDef, ...] = PARAMS,
        bytewise_ints: bool = True,
    ) -> None:
        self._defs = {p.name: p for p in table}
        self._names = [p.name for p in table]
        self._values: dict[str, float] = {p.name: float(p.default) for p in table}
        self.bytewise_ints = bytewise_ints  # PX4 True, ArduPilot False (see encode_value)
        for name, value in (overrides or {}).items():
            self.set(name, value, force=True)

    @classmethod
    def for_family(cls, family: str) -> ParamStore:
        """The table and integer encoding of an autopilot family ('px4', 'ardupilot')."""
        return cls(table=param_table(family), bytewise_ints=family == "px4")

    def definition(self, name: str) -> ParamDef:
        """The definition of ``name``; ParamError if unknown."""
        try:
            return self._defs[name]
        except KeyError:
            raise ParamError(f"unknown parameter {name!r}") from None

    def names(self) -> list[str]:
        """Parameter names in table order (the PARAM_VALUE index order)."""
        return self._names

    def __contains__(self, name: object) -> bool:
        return name in self._defs

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def get_int(self, name: str) -> int:
        """Value of an INT32 (or any) parameter as int."""
        return int(self._values[name])

    def set(self, name: str, value: float, *, force: bool = False) -> float:
        """Store ``value`` (rounded for INT32); ParamError names the reason when refused.

        ``force`` writes read-only parameters (the emulator's own bookkeeping).
        """
        p = self.definition(name)
        if p.read_only and not force:
            raise ParamError(f"parameter {name} is read-only")
        x = float(value)
        if not math.isfinite(x):
            raise ParamError(f"parameter {name}: value {value!r} is not finite")
        if p.ptype is not ParamType.REAL32:
            x = float(round(x))
        if not p.minimum <= x <= p.maximum:
            raise ParamError(
                f"parameter {name}: value {x:g} outside [{p.minimum:g}, {p.maximum:g}]"
            )
        self._values[name] = x
        return x


def encode_value(ptype: ParamType, value: float, bytewise: bool = True) -> float:
    """PARAM_VALUE.param_value: REAL32 as is; an integer bytewise in the float (PX4 convention)
    or, with ``bytewise=False``, cast to float (ArduPilot)."""
    if ptype is not ParamType.REAL32 and bytewise:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_value(
    ptype: ParamType, wire_value: float, wire_type: int, bytewise: bool = True
) -> float:
    """PARAM_SET.param_value -> number.

    INT32 parameters: PX4 clients (MAVSDK, QGroundControl) send the integer bytewise in the float
    (a tiny denormal for small integers); pymavlink scripts often send the plain float. A whole
    non-zero float below 2**24 cannot be a bytewise small integer, so it is taken as is; anything
    else is read bytewise. With ``bytewise=False`` (ArduPilot) the float is the value.
    """
    if not bytewise:
        return float(wire_value)
    if ptype is not ParamType.REAL32:
        f = float(wire_value)
        if math.isfinite(f) and f != 0.0 and f == int(f) and abs(f) < 2**24:
            return f
        return float(struct.unpack("<i", struct.pack("<f", wire_value))[0])
    return float(wire_value)
