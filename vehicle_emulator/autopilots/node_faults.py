"""One vehicle's scheduled faults: the fault clock's start, mass drops, link loss and packet
loss windows, motor efficiency.

``NodeFaults`` is mixed into ``VehicleNode`` (node.py), which owns the state it changes (plant
arrays, parameter store, link impairment, fault schedule); each fault is announced by STATUSTEXT.
"""

from __future__ import annotations

from vehicle_emulator.autopilots.demand import Severity
from vehicle_emulator.config.faults import LINK_PARAMS, link_param_values, link_text
from vehicle_emulator.config.team import FaultSpec

__all__ = ["NodeFaults"]


class NodeFaults:
    """The fault handlers of a ``VehicleNode`` (module docstring)."""

    __slots__ = ()

    def tick_fault_clock(self, now_s: float) -> None:
        """The fault clock's STATUSTEXT when it starts. Its parameter, EMU_FLT_CLK, is worked
        out when it is read (`_param_msg`), not written at every tick: a fleet's 240 writes at
        50 Hz were 5 % of its time."""
        if self._fault_clock_announced:
            return
        if self.faults.clock_s(now_s, self.autopilot.first_offboard_s) is not None:
            self._fault_clock_announced = True
            t = self.params["EMU_MDROP_T"]
            plan = f", mass drop at {t:.1f} s" if t >= 0 else ""
            self.statustext(Severity.INFO, f"Fault clock started{plan}")

    def apply_faults(self, now_s: float) -> None:
        """Fire the scheduled faults that are due on the fault clock."""
        clock = self.faults.clock_s(now_s, self.autopilot.first_offboard_s)
        for f in self.faults.due(clock):
            self.apply_fault(now_s, f, clock)
        for r in self.faults.restores_due(now_s):
            self._set_link(r.values)
            at = "" if clock is None else f" at {clock:.3f} s"
            self.statustext(Severity.INFO, f"Fault end: {link_text(r.values)}{at}")

    def apply_fault(self, now_s: float, f: FaultSpec, clock: float | None) -> None:
        """Apply one fault now."""
        i = self.index
        at = "" if clock is None else f" at {clock:.3f} s"
        if f.kind == "mass_drop":
            before = float(self.plant.mass_kg[i])
            self.plant.mass_kg[i] = before * (1.0 - f.fraction)
            self.params.set("EMU_MASS_KG", float(self.plant.mass_kg[i]), force=True)
            self.statustext(
                Severity.WARNING,
                f"Fault: mass {before:.3f}->{self.plant.mass_kg[i]:.3f} kg{at}",
            )
        elif f.kind == "link_loss":
            self.impairment.down_until_s = now_s + f.duration_s
            self.statustext(Severity.WARNING, f"Fault: link lost for {f.duration_s:.1f} s{at}")
        elif f.kind == "packet_loss":
            if f.duration_s > 0.0:
                before = tuple(self.params[name] for name in LINK_PARAMS)
                self.faults.restore_at(now_s + f.duration_s, before)
            values = link_param_values(f)
            self._set_link(values)
            window = f" for {f.duration_s:g} s" if f.duration_s > 0.0 else ""
            self.statustext(Severity.WARNING, f"Fault: {link_text(values)}{window}{at}")
        elif f.kind == "motor_efficiency":
            name = f"EMU_MOT{f.motor}_EFF"
            self.params.set(name, f.efficiency)
            self._sync_param(name)
            self.statustext(Severity.WARNING, f"Fault: motor {f.motor} eff {f.efficiency:.2f}{at}")

    def _set_link(self, values: tuple[float, ...]) -> None:
        """Write the link parameters (``LINK_PARAMS`` order) and apply them."""
        for name, value in zip(LINK_PARAMS, values, strict=True):
            self.params.set(name, value)
            self._sync_param(name)
