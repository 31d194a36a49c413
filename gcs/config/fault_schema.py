"""The team file's `faults:` entries as dataclasses, one per kind (read by fault_section)."""

from __future__ import annotations

from dataclasses import dataclass

from gcs.config.declare import key
from gcs.config.modes import FAULT_KINDS, JITTER_KINDS

# Faults: each kind is its own dataclass with kind, vehicle (an id) and at_s (s from the formation
# start) first, read by fault_section with the team's ids and the mission's length; the kind's own
# keys are declared here. The emulator (vehicle_emulator/config/team.py) reads the same keys.


@dataclass(frozen=True, slots=True)
class FaultConfig:
    """Mass drop: at at_s the plant loses `fraction` of its mass (kind "mass_drop")."""

    kind: str = key(choices=FAULT_KINDS)
    vehicle: int = key()  # one of the team's ids
    at_s: float = key(ge=0.0)  # at or before the mission's end
    fraction: float = key(gt=0.0, lt=1.0)

    def summary(self) -> str:
        return (
            f"vehicle {self.vehicle} loses {self.fraction:.0%} of its mass at t = {self.at_s:g} s"
        )


@dataclass(frozen=True, slots=True)
class LinkLossFault:
    """At at_s the vehicle's MAVLink link goes down for duration_s (kind "link_loss")."""

    kind: str = key(choices=FAULT_KINDS)
    vehicle: int = key()  # one of the team's ids
    at_s: float = key(ge=0.0)  # at or before the mission's end
    duration_s: float = key(gt=0.0)

    def summary(self) -> str:
        return f"vehicle {self.vehicle} link down for {self.duration_s:g} s at t = {self.at_s:g} s"


@dataclass(frozen=True, slots=True)
class PacketLossFault:
    """From at_s (for duration_s; 0: to the end) each packet is lost with `probability`, else
    delayed by latency_ms + a jitter term (`jitter` 'uniform': U[0, jitter_ms]; 'normal':
    |N(0, jitter_ms^2)|) + the emulator's reorder hold with `reorder_probability`."""

    kind: str = key(choices=FAULT_KINDS)
    vehicle: int = key()  # one of the team's ids
    at_s: float = key(ge=0.0)  # at or before the mission's end
    probability: float = key(0.0, ge=0.0, le=1.0)
    latency_ms: float = key(0.0, ge=0.0, le=10000.0)
    jitter_ms: float = key(0.0, ge=0.0, le=10000.0)
    jitter: str = key("uniform", choices=JITTER_KINDS)
    reorder_probability: float = key(0.0, ge=0.0, le=1.0)
    duration_s: float = key(0.0, ge=0.0, le=1e6)  # 0: to the end

    def summary(self) -> str:
        jitter = f" + {self.jitter} jitter {self.jitter_ms:g} ms" if self.jitter_ms else ""
        reorder = (
            f", {self.reorder_probability:.0%} reordered" if self.reorder_probability else ""
        )
        until = f" for {self.duration_s:g} s" if self.duration_s else ""
        return (
            f"vehicle {self.vehicle} loses {self.probability:.0%} of packets, "
            f"+{self.latency_ms:g} ms latency{jitter}{reorder}, from t = {self.at_s:g} s{until}"
        )


@dataclass(frozen=True, slots=True)
class MotorEfficiencyFault:
    """From at_s rotor `motor` (1..4) gives `efficiency` (0..1) of its commanded thrust."""

    kind: str = key(choices=FAULT_KINDS)
    vehicle: int = key()  # one of the team's ids
    at_s: float = key(ge=0.0)  # at or before the mission's end
    motor: int = key(ge=1, le=4)
    efficiency: float = key(ge=0.0, le=1.0)

    def summary(self) -> str:
        return (
            f"vehicle {self.vehicle} motor {self.motor} at {self.efficiency:.0%} efficiency "
            f"from t = {self.at_s:g} s"
        )


Fault = FaultConfig | LinkLossFault | PacketLossFault | MotorEfficiencyFault
