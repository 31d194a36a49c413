"""The emulator's parameter table (PX4 names where PX4 has one, EMU_* for emulator settings).

Pure: a ``ParamStore`` per vehicle holds typed values with limits; ``set`` returns the stored value
or raises ``ParamError`` (unknown name, read-only, out of range, not finite). MAVLink encoding of
INT32 values follows PX4 (bytewise in the float field): ``encode_value`` / ``decode_value``.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum

__all__ = [
    "PARAMS",
    "ParamDef",
    "ParamError",
    "ParamStore",
    "ParamType",
    "decode_value",
    "encode_value",
]


class ParamType(IntEnum):
    """MAV_PARAM_TYPE values used here."""

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
    ParamDef("EMU_LATENCY_MS", _F, 0.0, 0.0, 5000.0, "added one-way latency, both directions [ms]"),
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

_BY_NAME = {p.name: p for p in PARAMS}


class ParamStore:
    """Typed parameter values of one vehicle; ``on_change`` hooks are called after a write."""

    __slots__ = ("_values",)

    def __init__(self, overrides: dict[str, float] | None = None) -> None:
        self._values: dict[str, float] = {p.name: float(p.default) for p in PARAMS}
        for name, value in (overrides or {}).items():
            self.set(name, value, force=True)

    @staticmethod
    def definition(name: str) -> ParamDef:
        """The definition of ``name``; ParamError if unknown."""
        try:
            return _BY_NAME[name]
        except KeyError:
            raise ParamError(f"unknown parameter {name!r}") from None

    @staticmethod
    def names() -> list[str]:
        """Parameter names in table order (the PARAM_VALUE index order)."""
        return [p.name for p in PARAMS]

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
        if p.ptype is ParamType.INT32:
            x = float(round(x))
        if not p.minimum <= x <= p.maximum:
            raise ParamError(
                f"parameter {name}: value {x:g} outside [{p.minimum:g}, {p.maximum:g}]"
            )
        self._values[name] = x
        return x


def encode_value(ptype: ParamType, value: float) -> float:
    """PARAM_VALUE.param_value: REAL32 as is; INT32 bytewise in the float (PX4 convention)."""
    if ptype is ParamType.INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_value(ptype: ParamType, wire_value: float, wire_type: int) -> float:
    """PARAM_SET.param_value -> number.

    INT32 parameters: PX4 clients (MAVSDK, QGroundControl) send the integer bytewise in the float
    (a tiny denormal for small integers); pymavlink scripts often send the plain float. A whole
    non-zero float below 2**24 cannot be a bytewise small integer, so it is taken as is; anything
    else is read bytewise.
    """
    if ptype is ParamType.INT32:
        f = float(wire_value)
        if math.isfinite(f) and f != 0.0 and f == int(f) and abs(f) < 2**24:
            return f
        return float(struct.unpack("<i", struct.pack("<f", wire_value))[0])
    return float(wire_value)
