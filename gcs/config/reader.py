"""Team configuration reader: YAML (line numbers kept, duplicate keys refused, 1e4 read as a
number) -> checked values -> the schema's dataclasses; the public entry points."""

from __future__ import annotations

import dataclasses
import difflib
import math
import numbers
import os
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from gcs.config.schema import (
    DERIVATIVE_METHODS,
    FAULT_KINDS,
    FLY_ACTIONS,
    FLY_CONTROL_MODES,
    FLY_HEADINGS,
    FLY_INITIAL_MASSES,
    FLY_MODES,
    FLY_SCHEDULING,
    FLY_STARTS,
    FRAME_VEHICLES,
    GAIN_NAMES,
    GO_TO_START_ENABLED,
    GRAVITY_MPS2,
    JITTER_KINDS,
    LAWS,
    MODES,
    RESPONSE_KEYS,
    THRUST_MARGIN,
    ZERO3,
    Airframe,
    AxisReference,
    ConfigError,
    ControllerConfig,
    Cosine,
    DerivativeConfig,
    Edge,
    Estimates,
    Fault,
    FaultConfig,
    FlyConfig,
    FlyModeConfig,
    FormationCheckConfig,
    FrameConfig,
    Gains,
    GeofenceConfig,
    GoToStartConfig,
    GraphConfig,
    InitialState,
    LinkConfig,
    LinkLossFault,
    MissionConfig,
    MotorEfficiencyFault,
    PacketLossFault,
    PlantParams,
    PositionModeConfig,
    ReferenceVelocity,
    ResponseConfig,
    SimConfig,
    TeamConfig,
    VehicleConfig,
    _choices,
    initial_phi,
    proposition2_min_mhat,
)
from gcs.control.gains import LawGains

# --------------------------------------------------------------------------------------------
# YAML: safe loading that keeps line numbers, rejects duplicate keys and reads 1e4 as a number.


class _YamlMap(dict):
    __slots__ = ("lines",)


class _YamlSeq(list):
    __slots__ = ("lines",)


class _Loader(yaml.SafeLoader):
    """yaml.SafeLoader (nothing but plain data) that records the line of every key and item."""


class _Dumper(yaml.SafeDumper):
    """yaml.SafeDumper that quotes every string `_Loader` would read as something else."""


# pyyaml follows YAML 1.1, which reads 1e4 and 1.0e4 as strings; here they are numbers (YAML 1.2),
# and the dumper quotes such strings (a name "1e4") so that what it writes reads back the same.
for _cls in (_Loader, _Dumper):
    _cls.add_implicit_resolver(
        "tag:yaml.org,2002:float",
        re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
        list("-+0123456789."),
    )


def _construct_map(loader: _Loader, node: yaml.MappingNode) -> _YamlMap:
    loader.flatten_mapping(node)
    out = _YamlMap()
    out.lines = {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        if not isinstance(key, str | int | float | bool | None):
            raise yaml.constructor.ConstructorError(
                None, None, "a key must be a plain scalar", key_node.start_mark
            )
        if key in out:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"duplicate key {key!r} (first on line {out.lines[key]})",
                key_node.start_mark,
            )
        out[key] = loader.construct_object(value_node, deep=True)
        out.lines[key] = key_node.start_mark.line + 1
    return out


def _construct_seq(loader: _Loader, node: yaml.SequenceNode) -> _YamlSeq:
    out = _YamlSeq(loader.construct_object(child, deep=True) for child in node.value)
    out.lines = {k: child.start_mark.line + 1 for k, child in enumerate(node.value)}
    return out


_Loader.add_constructor("tag:yaml.org,2002:map", _construct_map)
_Loader.add_constructor("tag:yaml.org,2002:seq", _construct_seq)


#: pyyaml contexts whose mark is where a construct opened that the parser found unfinished: the
#: fault is on that line, however far below the parser gave up (a missing `]` on line 35 is
#: noticed at the next key, line 45). Other contexts (`while parsing a block mapping`) mark the
#: enclosing block; there the fault is where the parser stopped.
_OPENED_AT_CONTEXT = {
    "while parsing a flow mapping": "the flow mapping opened there is not closed",
    "while parsing a flow sequence": "the flow sequence opened there is not closed",
    "while scanning a quoted scalar": "the quoted string opened there is not closed",
    "while scanning a simple key": "the key there has no ':'",
}


def _yaml_error(exc: yaml.MarkedYAMLError, source: str) -> ConfigError:
    """One line naming the line of the fault and the line where pyyaml gave up, if another."""
    context, problem = exc.context_mark, exc.problem_mark
    opened = _OPENED_AT_CONTEXT.get(exc.context or "")
    fault = context if opened is not None and context is not None else problem or context
    if fault is None:
        return ConfigError(source, "(top level)", f"invalid YAML: {exc.problem or exc}")
    notes = []
    if opened is not None:
        notes.append(opened)
    elif exc.context and context is not None and context.line != fault.line:
        what = exc.context.removeprefix("while parsing a ")
        notes.append(f"in the {what} that starts at line {context.line + 1}"
                     if what != exc.context else f"{exc.context} at line {context.line + 1}")
    if problem is not None and problem.line != fault.line:
        notes.append(f"the parser gave up at line {problem.line + 1}")
    syntax = isinstance(exc, yaml.scanner.ScannerError | yaml.parser.ParserError)
    kind = "YAML syntax error" if syntax else "invalid YAML"
    where = f"{kind} at line {fault.line + 1}, column {fault.column + 1}" + (
        f" ({'; '.join(notes)})" if notes else "")
    err = ConfigError(source, where, exc.problem or exc.context or "syntax error")
    err.line = fault.line + 1
    return err


def _parse_yaml(text: str, source: str) -> Any:
    try:
        return yaml.load(text, Loader=_Loader)  # _Loader is a SafeLoader: plain data only
    except yaml.MarkedYAMLError as exc:
        raise _yaml_error(exc, source) from None
    except yaml.YAMLError as exc:
        raise ConfigError(source, "(top level)", f"invalid YAML: {exc}") from None


# --------------------------------------------------------------------------------------------
# Reading: a value with its key path; each read either returns a checked value or raises.

_MISSING: Any = object()


def _kind(value: Any) -> str:
    if value is _MISSING:
        return "nothing"
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"bool {value}"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)} item{'' if len(value) == 1 else 's'}"
    text = repr(value)
    text = text if len(text) <= 40 else text[:37] + "..."
    return f"{'string' if isinstance(value, str) else type(value).__name__} {text}"


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)


def _interval(gt: float | None, ge: float | None, lt: float | None, le: float | None) -> str:
    lo = f"({gt:g}" if gt is not None else f"[{ge:g}" if ge is not None else None
    hi = f"{lt:g})" if lt is not None else f"{le:g}]" if le is not None else None
    if lo and hi:
        return f"a value in {lo}, {hi}"
    if lo:
        return f"{'>' if lo[0] == '(' else '>='} {lo[1:]}"
    return f"{'<' if hi[-1] == ')' else '<='} {hi[:-1]}"


class _Node:
    __slots__ = ("source", "path", "value", "line")

    def __init__(self, source: str, path: str, value: Any, line: int | None) -> None:
        self.source, self.path, self.value, self.line = source, path, value, line

    def fail(self, problem: str) -> NoReturn:
        raise ConfigError(self.source, self.path or "(top level)", problem, self.line)

    @property
    def absent(self) -> bool:
        """Key not given, or given as null (null on an optional key means its default)."""
        return self.value is _MISSING or self.value is None

    def _sub(self, key: Any, label: str) -> _Node:
        container = self.value if isinstance(self.value, dict | list | tuple) else {}
        lines = getattr(container, "lines", {})
        if isinstance(container, dict):
            value = container.get(key, _MISSING)
        elif isinstance(key, int) and 0 <= key < len(container):
            value = container[key]
        else:
            value = _MISSING
        return _Node(self.source, label, value, lines.get(key, self.line))

    def child(self, dotted: str) -> _Node:
        node = self
        for key in dotted.split("."):
            node = node._sub(key, f"{node.path}.{key}" if node.path else str(key))
        return node

    def item(self, k: int) -> _Node:
        return self._sub(k, f"{self.path}[{k}]")

    def keys(self, required: str, optional: str = "") -> _Node:
        """Check a mapping: all of `required` present, nothing outside required + optional."""
        req, allowed = required.split(), required.split() + optional.split()
        if not isinstance(self.value, dict):
            self.fail(f"expected a mapping with keys {', '.join(allowed)}, got {_kind(self.value)}")
        for key in self.value:
            if key not in allowed:
                close = difflib.get_close_matches(str(key), allowed, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                self._sub(key, f"{self.path}.{key}" if self.path else str(key)).fail(
                    f"unknown key; {hint}allowed keys: {', '.join(allowed)}"
                )
        for key in req:
            if key not in self.value:
                self.child(key).fail("required key is missing")
        return self

    def items(self, what: str, *, min_len: int = 0) -> list[_Node]:
        """Check a list; a missing optional list is empty."""
        if self.absent and min_len == 0:
            return []
        if not isinstance(self.value, list | tuple) or len(self.value) < min_len:
            self.fail(
                f"expected a list of {what}{f' (at least {min_len})' if min_len else ''}, "
                f"got {_kind(self.value)}"
            )
        return [self.item(k) for k in range(len(self.value))]

    def number(
        self,
        default: Any = _MISSING,
        *,
        gt: float | None = None,
        ge: float | None = None,
        lt: float | None = None,
        le: float | None = None,
    ) -> Any:
        """A finite float within the bounds; `default` when absent (required if no default)."""
        if self.absent and default is not _MISSING:
            return default
        if self.value is _MISSING:
            self.fail("required key is missing")
        if not _is_number(self.value):
            self.fail(f"expected a number, got {_kind(self.value)}")
        try:
            x = float(self.value)
        except OverflowError:
            self.fail(f"expected a finite number, got {_kind(self.value)}")
        if not math.isfinite(x):
            self.fail(f"expected a finite number, got {x!r}")
        if (
            (gt is not None and not x > gt)
            or (ge is not None and not x >= ge)
            or (lt is not None and not x < lt)
            or (le is not None and not x <= le)
        ):
            self.fail(f"expected {_interval(gt, ge, lt, le)}, got {x!r}")
        return x

    def integer(
        self, default: Any = _MISSING, *, ge: int | None = None, le: int | None = None
    ) -> Any:
        if self.absent and default is not _MISSING:
            return default
        if self.value is _MISSING:
            self.fail("required key is missing")
        if not isinstance(self.value, numbers.Integral) or isinstance(self.value, bool | np.bool_):
            self.fail(f"expected an integer, got {_kind(self.value)}")
        x = int(self.value)
        if (ge is not None and x < ge) or (le is not None and x > le):
            self.fail(f"expected {_interval(None, ge, None, le)}, got {x}")
        return x

    def boolean(self, default: Any = _MISSING) -> Any:
        if self.absent and default is not _MISSING:
            return default
        if self.value is _MISSING:
            self.fail("required key is missing")
        if not isinstance(self.value, bool):
            self.fail(f"expected true or false, got {_kind(self.value)}")
        return self.value

    def string(self, default: Any = _MISSING, choices: Sequence[str] = ()) -> Any:
        if self.absent and default is not _MISSING:
            return default
        if self.value is _MISSING:
            self.fail("required key is missing")
        if choices and self.value not in choices:
            self.fail(f"expected one of {_choices(choices)}, got {_kind(self.value)}")
        if not isinstance(self.value, str) or not self.value.strip():
            self.fail(f"expected a non-empty string, got {_kind(self.value)}")
        return self.value

    def vec3(self, default: Any = _MISSING, *, gt: float | None = None) -> Any:
        if self.absent and default is not _MISSING:
            return default
        if self.value is _MISSING:
            self.fail("required key is missing")
        if not isinstance(self.value, list | tuple) or len(self.value) != 3:
            self.fail(f"expected a list of 3 numbers, got {_kind(self.value)}")
        return tuple(self.item(k).number(gt=gt) for k in range(3))


# --------------------------------------------------------------------------------------------
# Sections.


def _controller(node: _Node) -> ControllerConfig:
    node.keys("law mode gains", "derivative")
    g = node.child("gains").keys(" ".join(n for n in GAIN_NAMES if n != "k_eps_yaw"), "k_eps_yaw")
    values = {name: g.child(name).number(gt=0.0) for name in GAIN_NAMES if name != "k_eps_yaw"}
    values["k_eps_yaw"] = g.child("k_eps_yaw").number(values["k_eps"], gt=0.0)  # default k_eps
    gains = Gains(**values)
    d = node.child("derivative")
    if not d.absent:
        d.keys("", "method levant_lipschitz levant_substep_s")
    derivative = DerivativeConfig(
        d.child("method").string("model", DERIVATIVE_METHODS),
        d.child("levant_lipschitz").number(1e4, gt=0.0),
        d.child("levant_substep_s").number(1e-4, gt=0.0),
    )
    return ControllerConfig(
        node.child("law").string(choices=LAWS),
        node.child("mode").string(choices=MODES),
        gains,
        derivative,
    )


def _axis(node: _Node) -> AxisReference:
    node.keys("", "constant cosines")
    cosines = []
    for c in node.child("cosines").items("cosines {amplitude, period_s, phase_rad}"):
        c.keys("amplitude period_s", "phase_rad")
        cosines.append(
            Cosine(
                c.child("amplitude").number(),
                c.child("period_s").number(gt=0.0),
                c.child("phase_rad").number(0.0),
            )
        )
    return AxisReference(node.child("constant").number(0.0), tuple(cosines))


# vehicle-emu's personalities and origin rules (its `emulator:` sections; the ground station
# checks them so that `gcs check` catches a typo, and otherwise leaves them to the emulator)
EMULATOR_AUTOPILOTS = ("nominal", "px4", "ardupilot")
EMULATOR_ORIGINS = ("own", "shared")


def _emulator_section(node: _Node, allowed: str) -> None:
    if node.absent:
        return
    node.keys("", allowed)
    node.child("autopilot").string(None, choices=EMULATOR_AUTOPILOTS)
    if "origin" in allowed.split():
        node.child("origin").string(None, choices=EMULATOR_ORIGINS)
    for key in ("origin_enu_m", "boot_position_enu_m"):
        if key in allowed.split() and not node.child(key).absent:
            node.child(key).vec3()
    # the parameters the real vehicles were booted with: names -> numbers (the emulator checks
    # the names against its personality's table)
    params = node.child("autopilot_params")
    if not params.absent:
        if not isinstance(params.value, dict):
            params.fail(f"expected a mapping of parameter names to numbers, got "
                        f"{_kind(params.value)}")
        for name in params.value:
            params.child(str(name)).number()


def _estimates(est: _Node, plant: _Node, gains: Gains) -> Estimates:
    """vehicles[].estimates; `mhat: from_hover` needs a mass for its stand-in and Proposition 2's
    mbar: the plant's mass_kg or mass_bound_kg."""
    inertia = est.child("inertia_kgm2").vec3(gt=0.0)
    bound = est.child("mass_bound_kg").number(None, gt=0.0)
    node = est.child("mhat")
    if node.value != "from_hover":
        if isinstance(node.value, str):
            node.fail(f"expected a number > 0 or 'from_hover', got {node.value!r}")
        return Estimates(node.number(gt=0.0), inertia, bound)
    mass = plant.child("mass_kg").number(gt=0.0) if not plant.absent else bound
    if mass is None:
        node.fail("from_hover needs estimates.mass_bound_kg (Proposition 2's mbar, checked "
                  "against the hover estimate) or a plant")
    # the stand-in: what the hover would give with v(0) = 0 (phi(0) = 2)
    return Estimates(2.0 * mass / gains.alpha_m, inertia, bound, from_hover=True)


def _vehicle(node: _Node, gains: Gains) -> VehicleConfig:
    node.keys(
        "id sysid offset_enu_m initial estimates airframe",
        "link plant nominal_mass_kg nominal_inertia_kgm2 emulator",
    )
    _emulator_section(node.child("emulator"),
                      "autopilot origin_enu_m boot_position_enu_m autopilot_params")
    vehicle_id = node.child("id").integer(ge=1)
    sysid = node.child("sysid").integer(ge=1, le=255)
    ini = node.child("initial").keys(
        "position_enu_m", "velocity_enu_mps attitude_rpy_rad body_rates_radps"
    )
    est = node.child("estimates").keys("mhat inertia_kgm2", "mass_bound_kg")
    air = node.child("airframe").keys(
        "arm_length_m anti_torque_m rotor_thrust_max_n", "motor_time_constant_s"
    )
    link, default_link = node.child("link"), LinkConfig.px4_sitl(sysid)
    if not link.absent:
        link.keys("", "local_port remote_host remote_port learn_remote")
    learn = link.child("learn_remote").boolean(False)
    if learn and link.child("remote_port").absent and not link.child("remote_host").absent:
        link.child("remote_host").fail(
            "has no effect without remote_port: with learn_remote: true the vehicle's address is "
            "learned from its first message (give remote_port too to send there until then)"
        )
    plant = node.child("plant")
    if not plant.absent:
        plant.keys("mass_kg inertia_kgm2")
    vehicle = VehicleConfig(
        id=vehicle_id,
        sysid=sysid,
        offset_enu_m=node.child("offset_enu_m").vec3(),
        initial=InitialState(
            *(
                ini.child(k).vec3(ZERO3 if k != "position_enu_m" else _MISSING)
                for k in (
                    "position_enu_m",
                    "velocity_enu_mps",
                    "attitude_rpy_rad",
                    "body_rates_radps",
                )
            )
        ),
        estimates=_estimates(est, plant, gains),
        airframe=Airframe(
            *(
                air.child(k).number(gt=0.0)
                for k in ("arm_length_m", "anti_torque_m", "rotor_thrust_max_n")
            ),
            air.child("motor_time_constant_s").number(0.0, ge=0.0),
        ),
        link=LinkConfig(
            link.child("local_port").integer(default_link.local_port, ge=0, le=65535),
            link.child("remote_host").string(
                None if learn and link.child("remote_port").absent else default_link.remote_host
            ),
            link.child("remote_port").integer(
                None if learn else default_link.remote_port, ge=1, le=65535
            ),
            learn,
        ),
        plant=None
        if plant.absent
        else PlantParams(
            plant.child("mass_kg").number(gt=0.0), plant.child("inertia_kgm2").vec3(gt=0.0)
        ),
        nominal_mass_kg=node.child("nominal_mass_kg").number(None, gt=0.0),
        nominal_inertia_kgm2=node.child("nominal_inertia_kgm2").vec3(None, gt=0.0),
    )
    who = f"vehicle {vehicle.id}, sysid {sysid}"
    if vehicle.plant is not None:
        m = vehicle.plant.mass_kg
        if vehicle.estimates.mass_bound_kg is not None and vehicle.estimates.mass_bound_kg < m:
            est.child("mass_bound_kg").fail(
                f"expected >= plant.mass_kg {m!r}, got {vehicle.estimates.mass_bound_kg!r} ({who})"
            )
        need = THRUST_MARGIN * m * GRAVITY_MPS2
        if vehicle.airframe.max_thrust_n < need:
            air.child("rotor_thrust_max_n").fail(
                f"max collective thrust 4 * {vehicle.airframe.rotor_thrust_max_n:g} = "
                f"{vehicle.airframe.max_thrust_n:g} N is below {THRUST_MARGIN:g} m g = "
                f"{THRUST_MARGIN:g} * {m:g} * {GRAVITY_MPS2:g} = {need:.4g} N; "
                f"need rotor_thrust_max_n >= {need / 4:.4g} ({who})"
            )
    least = proposition2_min_mhat(vehicle, gains)
    if (least is not None and not vehicle.estimates.from_hover
            and vehicle.estimates.mhat < least * (1.0 - 1e-12)):
        source = "mass_bound_kg" if vehicle.estimates.mass_bound_kg is not None else "plant mass"
        est.child("mhat").fail(
            f"Proposition 2 needs mhat(0) >= (phi(0) - 1) mbar / alpha_m = "
            f"({initial_phi(vehicle, gains):.6g} - 1) * {vehicle.mass_bound_kg:g} / "
            f"{gains.alpha_m:g} = {least:.6g} (mbar = {source}), got {vehicle.estimates.mhat!r} "
            f"({who})"
        )
    return vehicle


def _unique(nodes: list[_Node], key: str, values: list[Any], what: str) -> None:
    seen: dict[Any, int] = {}
    for k, value in enumerate(values):
        if value is None:
            continue
        if value in seen:
            nodes[k].child(key).fail(f"duplicate {what} {value} (also vehicles[{seen[value]}])")
        seen[value] = k


def _graph(node: _Node, ids: list[int]) -> GraphConfig:
    node.keys("edges")
    edges: list[Edge] = []
    seen: dict[frozenset[int], int] = {}
    for e in node.child("edges").items("edges [i, j] or [i, j, weight]"):
        if isinstance(e.value, dict):
            e.keys("i j", "weight")
            ends, weight = [e.child("i"), e.child("j")], e.child("weight").number(1.0, gt=0.0)
        elif isinstance(e.value, list | tuple) and len(e.value) in (2, 3):
            ends = [e.item(0), e.item(1)]
            weight = e.item(2).number(gt=0.0) if len(e.value) == 3 else 1.0
        else:
            e.fail(f"expected an edge [i, j] or [i, j, weight], got {_kind(e.value)}")
        i, j = (end.integer() for end in ends)
        for end, vid in zip(ends, (i, j), strict=True):
            if vid not in ids:
                end.fail(f"unknown vehicle id {vid}; ids are {', '.join(map(str, ids))}")
        if i == j:
            e.fail(f"self loop on vehicle {i}")
        k = seen.setdefault(frozenset((i, j)), len(edges))
        if k != len(edges):
            e.fail(f"duplicate edge {i}-{j} (also graph.edges[{k}])")
        edges.append(Edge(i, j, weight))
    reached, frontier = {ids[0]}, [ids[0]]
    while frontier:
        here = frontier.pop()
        for edge in edges:
            for a, b in ((edge.i, edge.j), (edge.j, edge.i)):
                if a == here and b not in reached:
                    reached.add(b)
                    frontier.append(b)
    unreached = [vid for vid in ids if vid not in reached]
    if unreached:
        node.child("edges").fail(
            f"the graph is disconnected (Assumption 2): vehicle{'s' * (len(unreached) > 1)} "
            f"{', '.join(map(str, unreached))} cannot be reached from vehicle {ids[0]}"
        )
    return GraphConfig(tuple(edges))


def _fault(node: _Node, ids: list[int], duration_s: float) -> Fault:
    """Common keys kind, vehicle, at_s, then the kind's own keys (table below)."""
    if not isinstance(node.value, dict):
        node.fail(f"expected a mapping with keys kind, vehicle, at_s, ..., got {_kind(node.value)}")
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
_FAULT_KINDS: dict[str, tuple[type, str, str, Callable[[_Node], tuple[Any, ...]]]] = {
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


def _fly_mode(node: _Node, default: FlyModeConfig) -> FlyModeConfig:
    if node.absent:
        return default
    node.keys("", "tick_rate_hz alpha_eps alpha_omega max_rate_radps max_yaw_rate_radps k_eps "
                  "k_eps_yaw alpha_p c_p alpha_rho")
    return FlyModeConfig(
        node.child("tick_rate_hz").number(default.tick_rate_hz, gt=0.0, le=1000.0),
        node.child("alpha_eps").number(None, gt=0.0),
        node.child("alpha_omega").number(None, gt=0.0),
        node.child("max_rate_radps").number(default.max_rate_radps, gt=0.0),
        node.child("max_yaw_rate_radps").number(default.max_yaw_rate_radps, gt=0.0),
        node.child("k_eps").number(None, gt=0.0),
        node.child("k_eps_yaw").number(None, gt=0.0),
        node.child("alpha_p").number(None, gt=0.0),
        node.child("c_p").number(None, gt=0.0),
        node.child("alpha_rho").number(None, gt=0.0),
    )


def _position_mode(node: _Node, default: PositionModeConfig) -> PositionModeConfig:
    """fly.position: the baseline runs no law, so its block has no gains, only its tick rate."""
    if node.absent:
        return default
    node.keys("", "tick_rate_hz")
    return PositionModeConfig(
        node.child("tick_rate_hz").number(default.tick_rate_hz, gt=0.0, le=1000.0))


def _response(node: _Node) -> ResponseConfig | None:
    if node.absent:
        return None
    node.keys(" ".join(RESPONSE_KEYS))
    values = {k: node.child(k).number(ge=0.0 if k.endswith("dead_time_s") else None,
                                      gt=None if k.endswith("dead_time_s") else 0.0)
              for k in RESPONSE_KEYS}
    return ResponseConfig(**values)


def _formation_check(node: _Node, d: FormationCheckConfig) -> FormationCheckConfig:
    if node.absent:
        return d
    node.keys("", "after_s max_error_m max_fraction")
    return FormationCheckConfig(
        node.child("after_s").number(d.after_s, ge=0.0),
        node.child("max_error_m").number(d.max_error_m, gt=0.0),
        node.child("max_fraction").number(d.max_fraction, gt=0.0),
    )


def _go_to_start(node: _Node, d: GoToStartConfig) -> GoToStartConfig:
    """fly.go_to_start (docs/configuration.md); `enabled` is auto, true or false."""
    if node.absent:
        return d
    node.keys("", "enabled tolerance_m max_speed_mps settle_s timeout_s cruise_speed_mps "
                  "min_altitude_m")
    enabled_node = node.child("enabled")
    if enabled_node.absent:
        enabled = d.enabled
    elif isinstance(enabled_node.value, bool):
        enabled = "true" if enabled_node.value else "false"
    else:
        enabled = enabled_node.string(choices=GO_TO_START_ENABLED)
    return GoToStartConfig(
        enabled,
        node.child("tolerance_m").number(d.tolerance_m, gt=0.0),
        node.child("max_speed_mps").number(d.max_speed_mps, gt=0.0),
        node.child("settle_s").number(d.settle_s, ge=0.0),
        node.child("timeout_s").number(d.timeout_s, gt=0.0),
        node.child("cruise_speed_mps").number(d.cruise_speed_mps, gt=0.0, le=20.0),
        node.child("min_altitude_m").number(d.min_altitude_m, gt=0.0),
    )


def check_go_to_start(team: TeamConfig) -> None:
    """`gcs fly` with go-to-start on: every start position (`initial.position_enu_m`) must be a
    safe place to fly to, at or above fly.go_to_start.min_altitude_m and inside fly.geofence;
    raises ConfigError naming the key path and the vehicle. (`gcs sim` starts its plants there
    whatever the altitude, so the reader itself does not ask for this.)"""
    g = team.fly.go_to_start
    if g.enabled == "false":
        return
    for k, v in enumerate(team.vehicles):
        p = v.initial.position_enu_m
        key, name = f"vehicles[{k}].initial.position_enu_m", f"vehicle {v.id} (sysid {v.sysid})"
        if p[2] < g.min_altitude_m:
            raise ConfigError(team.source_path, key, (
                f"{name}: start altitude z = {p[2]:g} m is below fly.go_to_start.min_altitude_m "
                f"{g.min_altitude_m:g}: the go-to-start phase flies every vehicle to its start "
                "position; set it higher, or fly.go_to_start.enabled: false to start the law "
                "where the vehicles are"))
        fence = team.fly.geofence
        for axis in range(3) if fence is not None else ():
            if not fence.min_enu_m[axis] < p[axis] < fence.max_enu_m[axis]:
                raise ConfigError(team.source_path, key, (
                    f"{name}: start position {'xyz'[axis]} = {p[axis]:g} m is outside "
                    f"fly.geofence [{fence.min_enu_m[axis]:g}, {fence.max_enu_m[axis]:g}] m"))


def _heading(node: _Node) -> str | float:
    """fly.heading: 'hold', 'paper', or a compass heading in degrees."""
    if node.absent:
        return "hold"
    if isinstance(node.value, str):
        if node.value not in FLY_HEADINGS:
            node.fail(f"expected 'hold', 'paper' or a compass heading in degrees, got "
                      f"{node.value!r}")
        return node.value
    return node.number(ge=-360.0, le=360.0)


def _fly(node: _Node) -> FlyConfig:
    """The optional `fly:` section (every key optional; see docs/configuration.md)."""
    d = FlyConfig()
    if node.absent:
        return d
    node.keys(
        "",
        "mode rates actuators attitude position heading start takeoff_altitude_m end_action "
        "abort_action link_loss_action stale_after_s link_lost_after_s link_timeout_s "
        "max_tilt_rad geofence log_rate_hz connect_timeout_s takeoff_timeout_s land_timeout_s "
        "takeoff_tolerance_m arm_timeout_s arm_retry_s mode_timeout_s formation_check response "
        "link_delay_s initial_mass go_to_start max_data_age_s timesync_period_s predict "
        "scheduling",
    )
    geofence = None
    g = node.child("geofence")
    if not g.absent:
        g.keys("min_enu_m max_enu_m")
        geofence = GeofenceConfig(g.child("min_enu_m").vec3(), g.child("max_enu_m").vec3())
        for k, axis in enumerate("xyz"):
            if not geofence.min_enu_m[k] < geofence.max_enu_m[k]:
                g.child("max_enu_m").fail(
                    f"expected max > min on every axis, got {axis}: min "
                    f"{geofence.min_enu_m[k]!r} >= max {geofence.max_enu_m[k]!r}"
                )
    fly = FlyConfig(
        control_mode=node.child("mode").string(d.control_mode, FLY_MODES),
        rates=_fly_mode(node.child("rates"), d.rates),
        actuators=_fly_mode(node.child("actuators"), d.actuators),
        attitude=_fly_mode(node.child("attitude"), d.attitude),
        position=_position_mode(node.child("position"), d.position),
        heading=_heading(node.child("heading")),
        start=node.child("start").string(d.start, FLY_STARTS),
        takeoff_altitude_m=node.child("takeoff_altitude_m").number(
            d.takeoff_altitude_m, ge=0.5, le=1000.0
        ),
        end_action=node.child("end_action").string(d.end_action, FLY_ACTIONS),
        abort_action=node.child("abort_action").string(d.abort_action, FLY_ACTIONS),
        link_loss_action=node.child("link_loss_action").string(d.link_loss_action, FLY_ACTIONS),
        stale_after_s=node.child("stale_after_s").number(d.stale_after_s, gt=0.0),
        link_lost_after_s=node.child("link_lost_after_s").number(d.link_lost_after_s, gt=0.0),
        link_timeout_s=node.child("link_timeout_s").number(d.link_timeout_s, gt=0.0),
        max_data_age_s=node.child("max_data_age_s").number(d.max_data_age_s, gt=0.0, le=10.0),
        timesync_period_s=node.child("timesync_period_s").number(d.timesync_period_s, ge=0.0,
                                                                 le=60.0),
        predict=node.child("predict").boolean(d.predict),
        scheduling=node.child("scheduling").string(d.scheduling, FLY_SCHEDULING),
        max_tilt_rad=node.child("max_tilt_rad").number(d.max_tilt_rad, gt=0.0, le=math.pi),
        geofence=geofence,
        log_rate_hz=node.child("log_rate_hz").number(d.log_rate_hz, gt=0.0),
        connect_timeout_s=node.child("connect_timeout_s").number(d.connect_timeout_s, gt=0.0),
        takeoff_timeout_s=node.child("takeoff_timeout_s").number(d.takeoff_timeout_s, gt=0.0),
        land_timeout_s=node.child("land_timeout_s").number(d.land_timeout_s, gt=0.0),
        takeoff_tolerance_m=node.child("takeoff_tolerance_m").number(
            d.takeoff_tolerance_m, gt=0.0),
        arm_timeout_s=node.child("arm_timeout_s").number(d.arm_timeout_s, gt=0.0),
        arm_retry_s=node.child("arm_retry_s").number(d.arm_retry_s, ge=0.1),
        mode_timeout_s=node.child("mode_timeout_s").number(d.mode_timeout_s, gt=0.0),
        formation_check=_formation_check(node.child("formation_check"), d.formation_check),
        response=_response(node.child("response")),
        link_delay_s=node.child("link_delay_s").number(d.link_delay_s, ge=0.0, le=1.0),
        initial_mass=node.child("initial_mass").string(d.initial_mass, FLY_INITIAL_MASSES),
        go_to_start=_go_to_start(node.child("go_to_start"), d.go_to_start),
    )
    if not fly.takeoff_tolerance_m < fly.takeoff_altitude_m:
        node.child("takeoff_tolerance_m").fail(
            f"expected < takeoff_altitude_m {fly.takeoff_altitude_m!r}, got "
            f"{fly.takeoff_tolerance_m!r}")
    if not fly.link_lost_after_s > fly.stale_after_s:
        node.child("link_lost_after_s").fail(
            f"expected > stale_after_s {fly.stale_after_s!r}, got {fly.link_lost_after_s!r}"
        )
    for name in FLY_CONTROL_MODES:
        rate = fly.tick_rate_hz(name)
        ratio = rate / fly.log_rate_hz
        if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * ratio:
            node.child("log_rate_hz").fail(
                f"must divide fly.{name}.tick_rate_hz {rate:g} (a whole number of ticks per "
                f"sample), got {fly.log_rate_hz:g}"
            )
    return fly


def _frame(node: _Node) -> FrameConfig:
    """The optional `frame:` section (docs/configuration.md)."""
    d = FrameConfig()
    if node.absent:
        return d
    node.keys("", "origin vehicles max_origin_distance_m")
    origin = node.child("origin")
    if origin.absent:
        lat_lon_alt = d.origin
    else:
        lat_lon_alt = origin.vec3()
        for k, (name, low, high) in enumerate((("latitude", -90.0, 90.0),
                                               ("longitude", -180.0, 180.0),
                                               ("altitude", -1000.0, 20000.0))):
            if not low <= lat_lon_alt[k] <= high:
                origin.fail(f"[lat_deg, lon_deg, alt_m]: {name} {lat_lon_alt[k]!r} outside "
                            f"[{low:g}, {high:g}]")
    return FrameConfig(
        lat_lon_alt,
        node.child("vehicles").string(d.vehicles, FRAME_VEHICLES),
        node.child("max_origin_distance_m").number(d.max_origin_distance_m, gt=0.0),
    )


def _team(root: _Node) -> TeamConfig:
    root.keys(
        "name mission controller reference_velocity graph vehicles",
        "sim faults fly emulator frame",
    )
    _emulator_section(root.child("emulator"), "autopilot origin autopilot_params")
    name = root.child("name").string()
    mission = MissionConfig(
        root.child("mission").keys("duration_s").child("duration_s").number(gt=0.0)
    )
    sim_node = root.child("sim")
    if not sim_node.absent:
        sim_node.keys("", "plant_rate_hz controller_rate_hz")
    sim = SimConfig(
        sim_node.child("plant_rate_hz").number(1000.0, gt=0.0),
        sim_node.child("controller_rate_hz").number(1000.0, gt=0.0),
    )
    ratio = sim.plant_rate_hz / sim.controller_rate_hz
    if round(ratio) < 1 or abs(ratio - round(ratio)) > 1e-9 * ratio:
        sim_node.child("controller_rate_hz").fail(
            f"must divide plant_rate_hz {sim.plant_rate_hz:g} (an integer number of plant steps "
            f"per control tick), got {sim.controller_rate_hz:g} (ratio {ratio:.6g})"
        )
    ctrl_node = root.child("controller")
    controller = _controller(ctrl_node)
    d = controller.derivative
    if d.method == "levant" and d.levant_substep_s > sim.controller_dt_s:
        ctrl_node.child("derivative.levant_substep_s").fail(
            f"expected <= the control period 1/{sim.controller_rate_hz:g} Hz = "
            f"{sim.controller_dt_s:g} s, got {d.levant_substep_s!r}"
        )
    ref_node = root.child("reference_velocity").keys("x y z")
    reference = ReferenceVelocity(*(_axis(ref_node.child(a)) for a in "xyz"))
    gains, varrho = controller.gains, reference.max_abs_acceleration_z()
    bound = (GRAVITY_MPS2 - varrho) / (2.0 * gains.sigma_a)
    if not gains.alpha_p < bound:
        ctrl_node.child("gains.alpha_p").fail(
            f"needs alpha_p < (g - varrho)/(2 sigma_a) = ({GRAVITY_MPS2:g} - {varrho:.6g})/"
            f"(2 * {gains.sigma_a:g}) = {bound:.6g} with varrho = sup|v_r,z'|, "
            f"got {gains.alpha_p!r}"
        )

    nodes = root.child("vehicles").items("vehicles", min_len=1)
    vehicles = tuple(_vehicle(node, gains) for node in nodes)
    _unique(nodes, "id", [v.id for v in vehicles], "vehicle id")
    _unique(nodes, "sysid", [v.sysid for v in vehicles], "sysid")
    # Vehicles with the same local_port share that GCS port, told apart by their (unique) sysids;
    # a fixed remote endpoint is still one vehicle's (the emulator binds it).
    remotes = [
        (v.link.remote_host, v.link.remote_port) if v.link.remote_port is not None else None
        for v in vehicles
    ]
    seen_remote: dict[Any, int] = {}
    for k, remote in enumerate(remotes):
        if remote is None:
            continue
        if remote in seen_remote:
            nodes[k].child("link.remote_port").fail(
                f"duplicate remote endpoint {remote} (also vehicles[{seen_remote[remote]}]); "
                "vehicles behind one router or relay share its address: set learn_remote: true "
                "and leave remote_port out"
            )
        seen_remote[remote] = k
    _unique(nodes, "offset_enu_m", [v.offset_enu_m for v in vehicles], "offset (collision)")
    _unique(
        nodes,
        "initial.position_enu_m",
        [v.initial.position_enu_m for v in vehicles],
        "initial position (collision)",
    )
    if controller.law == "baseline":
        for node, v in zip(nodes, vehicles, strict=True):
            if v.nominal_mass_kg is None:
                node.child("nominal_mass_kg").fail(
                    f"required by the baseline law (vehicle {v.id}, sysid {v.sysid})"
                )
    ids = [v.id for v in vehicles]
    graph = _graph(root.child("graph"), ids)

    faults = [_fault(f, ids, mission.duration_s) for f in root.child("faults").items("faults")]
    fly = _fly(root.child("fly"))
    frame = _frame(root.child("frame"))
    return TeamConfig(
        name,
        root.source,
        mission,
        controller,
        reference,
        graph,
        sim,
        vehicles,
        tuple(faults),
        fly,
        frame,
    )


# --------------------------------------------------------------------------------------------
# Public entry points.


def team_from_dict(data: Any, source: str = "<dict>") -> TeamConfig:
    """Validate an already-parsed config (a dict as yaml.safe_load gives it)."""
    return _team(_Node(source, "", data, None))


def team_from_yaml(text: str, source: str = "<string>") -> TeamConfig:
    """Parse and validate YAML text."""
    data = _parse_yaml(text, source)
    if not isinstance(data, dict):
        got = "an empty document" if data is None else _kind(data)
        raise ConfigError(source, "(top level)", f"expected a mapping of sections, got {got}", 1)
    return team_from_dict(data, source)


def load_team(path: str | os.PathLike[str]) -> TeamConfig:
    """Read and validate a team config file; every problem raises ConfigError."""
    source = os.fspath(path)
    try:
        text = Path(source).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(source, "(file)", f"cannot read: {exc}") from None
    return team_from_yaml(text, source)


def team_to_dict(team: TeamConfig) -> dict[str, Any]:
    """Plain data that team_from_dict reads back to an equal TeamConfig (None fields left out)."""

    def plain(x: Any) -> Any:
        if isinstance(x, LawGains):
            return {name: getattr(x, name) for name in GAIN_NAMES}
        if isinstance(x, Estimates):
            out = {"mhat": "from_hover" if x.from_hover else x.mhat,
                   "inertia_kgm2": plain(x.inertia_kgm2)}
            return out | ({} if x.mass_bound_kg is None else {"mass_bound_kg": x.mass_bound_kg})
        if dataclasses.is_dataclass(x):
            return {
                f.name: plain(getattr(x, f.name))
                for f in dataclasses.fields(x)
                if getattr(x, f.name) is not None
            }
        return [plain(v) for v in x] if isinstance(x, tuple) else x

    data = plain(team)
    del data["source_path"]
    fly = data["fly"]
    data["fly"] = {"mode": fly.pop("control_mode")} | fly  # the field's YAML key
    return data


def team_to_yaml(team: TeamConfig) -> str:
    """`team_to_dict` as YAML text that `team_from_yaml` reads back to the same team."""
    return yaml.dump(team_to_dict(team), Dumper=_Dumper, sort_keys=False)
