"""Fault schedule and link impairments of one vehicle. Pure: time is an argument, RNG injected.

Fault clock (parameter EMU_FLT_T0): 0 (default) starts at the vehicle's FIRST entry into OFFBOARD
(the formation start of the paper's scenarios, so ``at_s: 40`` means 40 s into the formation
flight); 1 starts at emulator boot. Its current value is the read-only parameter EMU_FLT_CLK, and
the start is announced by STATUSTEXT. A scheduled fault fires once, at the first physics tick at
or after its time (ticks are a multiple of the physics step, so at a step boundary).

The mass-drop schedule lives in parameters EMU_MDROP_T / EMU_MDROP_FRAC (seeded from the team
file, changeable at run time); other kinds (link loss, packet loss + latency + jitter +
reordering, motor efficiency) come from the team file. Run-time triggers: EMU_MASS_DROP,
EMU_LINK_LOSS, and the link parameters ``LINK_PARAMS`` (EMU_PKT_LOSS, EMU_LATENCY_MS,
EMU_JITTER_MS, EMU_JITTER_DIST, EMU_REORDER_P), EMU_MOTn_EFF.

Delay of a packet that is not lost (``LinkImpairment.admit``), every term >= 0:

    delay = latency + jitter term + (REORDER_HOLD_S with probability reorder_probability)

jitter term: uniform, U[0, jitter] (mean jitter / 2, standard deviation jitter / sqrt(12));
normal, |N(0, jitter^2)| (a half-normal: mean jitter sqrt(2 / pi), standard deviation
jitter sqrt(1 - 2 / pi)). ``latency`` is thus the least delay. A packet held back by the reorder
hold is overtaken by those sent within the hold after it; jitter alone also reorders two packets
whose delays differ by more than their spacing. A packet_loss fault with ``duration_s`` > 0 puts
the link parameters back to their values before it at the first tick at or after its start +
duration_s on the emulator's clock (``FaultSchedule.restore_at``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from vehicle_emulator.config.params import ParamStore
from vehicle_emulator.config.team import FaultSpec

__all__ = [
    "LINK_PARAMS",
    "REORDER_HOLD_S",
    "FaultSchedule",
    "Jitter",
    "LinkImpairment",
    "LinkRestore",
    "link_param_values",
    "link_text",
]

REORDER_HOLD_S = 0.020  # extra delay of a packet picked for reordering [s]

#: the run-time parameters of a packet_loss fault, in the order they are applied
LINK_PARAMS = (
    "EMU_PKT_LOSS", "EMU_LATENCY_MS", "EMU_JITTER_MS", "EMU_JITTER_DIST", "EMU_REORDER_P"
)


class Jitter(IntEnum):
    """Distribution of the jitter term (parameter EMU_JITTER_DIST; see the module docstring)."""

    UNIFORM = 0
    NORMAL = 1


@dataclass(slots=True)
class LinkImpairment:
    """Seeded packet loss, added latency, jitter, reordering and link-down windows, for both
    directions (one per vehicle, shared by its links)."""

    rng: np.random.Generator
    loss_probability: float = 0.0
    latency_s: float = 0.0
    jitter_s: float = 0.0
    jitter: Jitter = Jitter.UNIFORM
    reorder_probability: float = 0.0
    down_until_s: float = -1.0
    dropped: int = 0
    held_back: int = 0  # packets given the reorder hold

    def is_down(self, now_s: float) -> bool:
        """True while a link-loss window is active."""
        return now_s < self.down_until_s

    def admit(self, now_s: float) -> float | None:
        """None if this packet is lost, else the delay [s] before it is delivered (module
        docstring). Draws, in this order and only where the setting is non-zero: loss, jitter,
        reorder; so a seed gives the same sequence of delays."""
        if now_s < self.down_until_s or (
            self.loss_probability > 0.0 and self.rng.random() < self.loss_probability
        ):
            self.dropped += 1
            return None
        delay = self.latency_s
        if self.jitter_s > 0.0:
            if self.jitter is Jitter.NORMAL:
                delay += self.jitter_s * abs(self.rng.standard_normal())
            else:
                delay += self.jitter_s * self.rng.random()
        if self.reorder_probability > 0.0 and self.rng.random() < self.reorder_probability:
            self.held_back += 1
            delay += REORDER_HOLD_S
        return delay

    def set_param(self, name: str, value: float) -> None:
        """Take the value of one of ``LINK_PARAMS`` (ms -> s; KeyError for other names)."""
        if name == "EMU_PKT_LOSS":
            self.loss_probability = value
        elif name == "EMU_LATENCY_MS":
            self.latency_s = value * 1e-3
        elif name == "EMU_JITTER_MS":
            self.jitter_s = value * 1e-3
        elif name == "EMU_JITTER_DIST":
            self.jitter = Jitter(int(value))
        elif name == "EMU_REORDER_P":
            self.reorder_probability = value
        else:
            raise KeyError(f"{name} is not a link parameter ({', '.join(LINK_PARAMS)})")


def link_param_values(spec: FaultSpec) -> tuple[float, ...]:
    """The ``LINK_PARAMS`` values of a packet_loss fault."""
    dist = Jitter.NORMAL if spec.jitter == "normal" else Jitter.UNIFORM
    return (
        spec.probability, spec.latency_ms, spec.jitter_ms, float(dist), spec.reorder_probability
    )


def link_text(values: tuple[float, ...]) -> str:
    """``LINK_PARAMS`` values as a STATUSTEXT fragment: 'loss 0.10 +30 ms' and, where set,
    jitter ('+U10': uniform up to 10 ms, '+N10': half-normal of scale 10 ms) and reordering."""
    loss, latency_ms, jitter_ms, dist, reorder = values
    jitter = f"+{'N' if int(dist) == Jitter.NORMAL else 'U'}{jitter_ms:.0f}" if jitter_ms else ""
    text = f"loss {loss:.2f} +{latency_ms:.0f}{jitter} ms"
    return text + (f" reorder {reorder:.2f}" if reorder else "")


@dataclass(frozen=True, slots=True)
class LinkRestore:
    """Link parameter values (``LINK_PARAMS`` order) to put back at ``at_s`` (emulator clock)."""

    at_s: float
    values: tuple[float, ...]


@dataclass(slots=True)
class FaultSchedule:
    """Scheduled faults of one vehicle on its fault clock."""

    params: ParamStore
    pending: list[FaultSpec] = field(default_factory=list)
    clock_zero_s: float | None = None
    mass_drop_done: bool = False
    restores: list[LinkRestore] = field(default_factory=list)  # by at_s

    @classmethod
    def from_specs(cls, params: ParamStore, specs: list[FaultSpec]) -> FaultSchedule:
        """Mass drops go to EMU_MDROP_T/FRAC (the first one; later ones stay in ``pending``)."""
        sched = cls(params=params)
        for spec in sorted(specs, key=lambda s: s.at_s):
            if spec.kind == "mass_drop" and params["EMU_MDROP_T"] < 0.0:
                params.set("EMU_MDROP_T", spec.at_s)
                params.set("EMU_MDROP_FRAC", spec.fraction)
            else:
                sched.pending.append(spec)
        return sched

    @property
    def idle(self) -> bool:
        """True when nothing is scheduled (no need to check every tick)."""
        return (
            not self.pending
            and not self.restores
            and (self.mass_drop_done or self.params["EMU_MDROP_T"] < 0.0)
        )

    def restore_at(self, at_s: float, values: tuple[float, ...]) -> None:
        """Put the link parameters back to ``values`` at ``at_s`` on the emulator's clock (the
        end of a packet_loss window); ``restores_due`` returns it then."""
        self.restores.append(LinkRestore(at_s, values))
        self.restores.sort(key=lambda r: r.at_s)

    def restores_due(self, now_s: float) -> list[LinkRestore]:
        """Restores whose time has come, oldest first (each returned once)."""
        due: list[LinkRestore] = []
        while self.restores and now_s >= self.restores[0].at_s - 1e-9:
            due.append(self.restores.pop(0))
        return due

    def clock_s(self, now_s: float, first_offboard_s: float | None) -> float | None:
        """Fault clock now, or None while it has not started."""
        if self.params.get_int("EMU_FLT_T0") == 1:
            self.clock_zero_s = 0.0
        elif self.clock_zero_s is None and first_offboard_s is not None:
            self.clock_zero_s = first_offboard_s
        if self.clock_zero_s is None:
            return None
        return now_s - self.clock_zero_s

    def next_due_s(self) -> float:
        """When the next scheduled fault falls due on the emulator's clock (physics time), or
        inf: none is left, or the fault clock has not started (it starts on a tick, never
        inside a run of physics steps)."""
        if self.clock_zero_s is None:
            return math.inf
        times = [f.at_s for f in self.pending[:1]]
        t_drop = self.params["EMU_MDROP_T"]
        if not self.mass_drop_done and t_drop >= 0.0:
            times.append(t_drop)
        return self.clock_zero_s + min(times) if times else math.inf

    def due(self, clock_s: float | None) -> list[FaultSpec]:
        """Faults whose time has come (each returned once)."""
        if clock_s is None:
            return []
        fired: list[FaultSpec] = []
        t_drop = self.params["EMU_MDROP_T"]
        if not self.mass_drop_done and t_drop >= 0.0 and clock_s >= t_drop - 1e-9:
            self.mass_drop_done = True
            fired.append(FaultSpec("mass_drop", 0, t_drop, fraction=self.params["EMU_MDROP_FRAC"]))
        while self.pending and clock_s >= self.pending[0].at_s - 1e-9:
            fired.append(self.pending.pop(0))
        return fired
