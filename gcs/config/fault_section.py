"""The team file's `faults:` entries -> the fault dataclasses of fault_schema."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from gcs.config.fault_schema import (
    Fault,
    FaultConfig,
    LinkLossFault,
    MotorEfficiencyFault,
    PacketLossFault,
)
from gcs.config.modes import FAULT_KINDS, JITTER_KINDS
from gcs.config.yamlnode import Node, kind_of


def read_fault(node: Node, ids: list[int], duration_s: float) -> Fault:
    """Common keys kind, vehicle, at_s, then the kind's own keys (table below)."""
    if not isinstance(node.value, dict):
        node.fail(
            f"expected a mapping with keys kind, vehicle, at_s, ..., got {kind_of(node.value)}"
        )
    kind = node.child("kind").string(choices=FAULT_KINDS)
    cls, required, optional, read = _FAULT_KINDS[kind]
    node.keys("kind vehicle at_s " + required, optional)
    vehicle = node.child("vehicle").integer()
    if vehicle not in ids:
        node.child("vehicle").fail(
            f"unknown vehicle id {vehicle}; ids are {', '.join(map(str, ids))}"
        )
    at_s = node.child("at_s").number(ge=0.0, le=duration_s)
    return cls(kind, vehicle, at_s, *read(node))


# kind -> (dataclass, required keys, optional keys, reader of the kind's own fields). A new kind
# adds its dataclass to Fault, a row here and its name to FAULT_KINDS.
_FAULT_KINDS: dict[str, tuple[type, str, str, Callable[[Node], tuple[Any, ...]]]] = {
    "mass_drop": (
        FaultConfig,
        "fraction",
        "",
        lambda n: (n.child("fraction").number(gt=0.0, lt=1.0),),
    ),
    "link_loss": (
        LinkLossFault,
        "duration_s",
        "",
        lambda n: (n.child("duration_s").number(gt=0.0),),
    ),
    "packet_loss": (
        PacketLossFault,
        "",
        "probability latency_ms jitter_ms jitter reorder_probability duration_s",
        lambda n: (
            n.child("probability").number(0.0, ge=0.0, le=1.0),
            n.child("latency_ms").number(0.0, ge=0.0, le=10000.0),
            n.child("jitter_ms").number(0.0, ge=0.0, le=10000.0),
            n.child("jitter").string("uniform", choices=JITTER_KINDS),
            n.child("reorder_probability").number(0.0, ge=0.0, le=1.0),
            n.child("duration_s").number(0.0, ge=0.0, le=1e6),
        ),
    ),
    "motor_efficiency": (
        MotorEfficiencyFault,
        "motor efficiency",
        "",
        lambda n: (
            n.child("motor").integer(ge=1, le=4),
            n.child("efficiency").number(ge=0.0, le=1.0),
        ),
    ),
}
