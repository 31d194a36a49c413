"""Fault schedule and link impairments of one vehicle. Pure: time is an argument, RNG injected.

Fault clock (parameter EMU_FLT_T0): 0 (default) starts at the vehicle's FIRST entry into OFFBOARD
(the formation start of the paper's scenarios, so ``at_s: 40`` means 40 s into the formation
flight); 1 starts at emulator boot. Its current value is the read-only parameter EMU_FLT_CLK, and
the start is announced by STATUSTEXT. A scheduled fault fires once, at the first physics tick at
or after its time (ticks are a multiple of the physics step, so at a step boundary).

The mass-drop schedule lives in parameters EMU_MDROP_T / EMU_MDROP_FRAC (seeded from the team
file, changeable at run time); other kinds (link loss, packet loss + latency, motor efficiency)
come from the team file. Run-time triggers: EMU_MASS_DROP, EMU_LINK_LOSS, EMU_PKT_LOSS,
EMU_LATENCY_MS, EMU_MOTn_EFF.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vehicle_emulator.params import ParamStore
from vehicle_emulator.team import FaultSpec

__all__ = ["FaultSchedule", "LinkImpairment"]


@dataclass(slots=True)
class LinkImpairment:
    """Seeded packet loss, added latency and link-down windows, for both directions."""

    rng: np.random.Generator
    loss_probability: float = 0.0
    latency_s: float = 0.0
    down_until_s: float = -1.0
    dropped: int = 0

    def is_down(self, now_s: float) -> bool:
        """True while a link-loss window is active."""
        return now_s < self.down_until_s

    def admit(self, now_s: float) -> float | None:
        """None if this packet is lost, else the delay [s] before it is delivered."""
        if now_s < self.down_until_s or (
            self.loss_probability > 0.0 and self.rng.random() < self.loss_probability
        ):
            self.dropped += 1
            return None
        return self.latency_s


@dataclass(slots=True)
class FaultSchedule:
    """Scheduled faults of one vehicle on its fault clock."""

    params: ParamStore
    pending: list[FaultSpec] = field(default_factory=list)
    clock_zero_s: float | None = None
    mass_drop_done: bool = False

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
        return not self.pending and (self.mass_drop_done or self.params["EMU_MDROP_T"] < 0.0)

    def clock_s(self, now_s: float, first_offboard_s: float | None) -> float | None:
        """Fault clock now, or None while it has not started."""
        if self.params.get_int("EMU_FLT_T0") == 1:
            self.clock_zero_s = 0.0
        elif self.clock_zero_s is None and first_offboard_s is not None:
            self.clock_zero_s = first_offboard_s
        if self.clock_zero_s is None:
            return None
        return now_s - self.clock_zero_s

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
