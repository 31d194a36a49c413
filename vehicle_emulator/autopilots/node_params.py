"""One vehicle's parameter protocol: PARAM_REQUEST_LIST/READ, PARAM_SET and their side effects.

``NodeParams`` is mixed into ``VehicleNode`` (node.py), which owns the state it reads (the
parameter store, plant and status arrays, link impairment, counters). Its handlers answer with
PARAM_VALUE; a refused read or write is counted and reported by a rate-limited STATUSTEXT.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from vehicle_emulator.autopilots.demand import Severity
from vehicle_emulator.autopilots.node_output import Link
from vehicle_emulator.config.faults import LINK_PARAMS
from vehicle_emulator.config.params import ParamError, decode_value, encode_value
from vehicle_emulator.config.team import FaultSpec
from vehicle_emulator.mavlink.codec import mavlink

__all__ = ["NodeParams"]


class NodeParams:
    """The parameter handlers and side effects of a ``VehicleNode`` (module docstring)."""

    __slots__ = ()

    def _param_msg(self, name: str) -> Any:
        if name == "EMU_FLT_CLK":  # the fault clock now, on the emulator's (simulated) clock
            clock = self.faults.clock_s(self.plant.time_s, self.autopilot.first_offboard_s)
            self.params.set(name, -1.0 if clock is None else min(clock, 1e9), force=True)
        d = self.params.definition(name)
        names = self.params.names()
        return mavlink.MAVLink_param_value_message(
            name.encode(),
            encode_value(d.ptype, self.params[name], self.params.bytewise_ints),
            int(d.ptype),
            len(names),
            names.index(name),
        )

    def _on_param_request_list(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if not self._for_me(msg):
            return
        for name in self.params.names():
            self.send_msg(self._param_msg(name), link, addr)

    @staticmethod
    def _param_name(raw: Any) -> str:
        if isinstance(raw, bytes):
            raw = raw.decode("ascii", errors="replace")
        return str(raw).split("\x00", 1)[0]

    def _on_param_request_read(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if not self._for_me(msg):
            return
        names = self.params.names()
        if msg.param_index >= 0:
            if msg.param_index >= len(names):
                self._param_refused(now_s, f"no parameter index {msg.param_index}")
                return
            name = names[msg.param_index]
        else:
            name = self._param_name(msg.param_id)
            if name not in names:
                self._param_refused(now_s, f"unknown parameter {name}")
                return
        self.send_msg(self._param_msg(name), link, addr)

    def _on_param_set(self, now_s: float, msg: Any, link: Link, addr: Any) -> None:
        if not self._for_me(msg):
            return
        name = self._param_name(msg.param_id)
        try:
            d = self.params.definition(name)
            value = decode_value(d.ptype, msg.param_value, msg.param_type,
                                 self.params.bytewise_ints)
            self.params.set(name, value)
        except ParamError as exc:
            self._param_refused(now_s, str(exc))
            if name in self.params.names():  # MAVLink: answer a refused write with the value
                self.send_msg(self._param_msg(name))
            return
        self._sync_param(name)
        self._param_triggers(now_s, name)
        self.send_msg(self._param_msg(name))

    def _param_refused(self, now_s: float, text: str) -> None:
        self.counters.params_refused += 1
        self.counters.last_reject_reason = text
        self.statustext_limited(now_s, Severity.ERROR, text)

    def _param_triggers(self, now_s: float, name: str) -> None:
        v = self.params[name]
        if name == "EMU_MASS_DROP" and v > 0.0:
            self.apply_fault(now_s, FaultSpec("mass_drop", 0, 0.0, fraction=v), None)
        elif name == "EMU_LINK_LOSS" and v > 0.0:
            self.apply_fault(now_s, FaultSpec("link_loss", 0, 0.0, duration_s=v), None)

    def _sync_param(self, name: str) -> None:
        """Side effects of a parameter value on the arrays and the link."""
        i, v = self.index, self.params[name]
        if name.startswith("EMU_MOT") and name.endswith("_EFF"):
            self.plant.rotor_efficiency[i, int(name[7]) - 1] = v
        elif name == "EMU_MOT_TAU":
            self.plant.motor_time_constant_s[i] = v
        elif name == "MC_AIRMODE":
            self.plant.airmode[i] = float(v)
        elif name == "EMU_NOISE":  # the sensor model's noise, or telemetry noise (nominal)
            self.status.noise[i] = self.plant.set_noise(i, bool(v))
        elif name in LINK_PARAMS:
            self.impairment.set_param(name, v)
        elif name == "EMU_SEED":
            self.impairment.rng = np.random.default_rng(int(v) + self.index)
            self.plant.seed_noise(i, int(v))
        elif name in ("MPC_THR_HOVER", "MOT_THST_HOVER"):
            self.plant.hover_thrust_norm[i] = v
        elif name in ("EMU_MDROP_T", "EMU_MDROP_FRAC"):
            self.faults.mass_drop_done = False

    def sync_all_params(self) -> None:
        """Push every parameter's side effect (after start-up overrides)."""
        for name in self.params.names():
            self._sync_param(name)
