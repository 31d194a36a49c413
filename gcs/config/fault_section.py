"""The team file's `faults:` entries -> the fault dataclasses of fault_schema."""

from __future__ import annotations

from typing import Any

from gcs.config.declare import read_field, read_section
from gcs.config.fault_schema import (
    Fault,
    FaultConfig,
    LinkLossFault,
    MotorEfficiencyFault,
    PacketLossFault,
)
from gcs.config.yamlnode import Node, kind_of


def read_fault(node: Node, ids: list[int], duration_s: float) -> Fault:
    """Common keys kind, vehicle, at_s, then the kind's own keys (declared by its dataclass)."""
    if not isinstance(node.value, dict):
        node.fail(
            f"expected a mapping with keys kind, vehicle, at_s, ..., got {kind_of(node.value)}"
        )
    kind = read_field(node, FaultConfig, "kind")
    cls = _FAULT_KINDS[kind]

    def vehicle(_: dict[str, Any]) -> int:
        vid = read_field(node, cls, "vehicle")
        if vid not in ids:
            node.child("vehicle").fail(
                f"unknown vehicle id {vid}; ids are {', '.join(map(str, ids))}")
        return vid

    return read_section(node, cls, given={
        "kind": lambda _: kind,
        "vehicle": vehicle,
        "at_s": lambda _: read_field(node, cls, "at_s", le=duration_s),
    })


# kind -> its dataclass. A new kind adds its dataclass to Fault, a row here and its name to
# FAULT_KINDS.
_FAULT_KINDS: dict[str, type] = {
    "mass_drop": FaultConfig,
    "link_loss": LinkLossFault,
    "packet_loss": PacketLossFault,
    "motor_efficiency": MotorEfficiencyFault,
}
