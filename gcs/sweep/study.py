"""A study file: a base team, distributions over its keys, how many runs, one root seed.

Run k's team is a pure function of the study and k (`Study.run`): its random numbers come from
`SeedSequence(seed, spawn_key=(k,))`, drawn parameter by parameter in file order and, within a
parameter, vehicle by vehicle in team order. So a run is the same whichever process, machine or
executor flies it, and `gcs sim --study FILE --run K` flies it again (docs/sweep.md).

Key paths name team-file keys with dots; `vehicles[*]` is every vehicle, `vehicles[ID]` the
vehicle with that id: `vehicles[*].plant.mass_kg`, `controller.gains.c_p`, `graph.edges`.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gcs.config import ConfigError, TeamConfig, load_team, team_from_dict, team_to_dict
from gcs.config.yamlnode import Node, kind_of, parse_yaml, read_text

DISTRIBUTIONS = ("uniform", "normal", "log_uniform", "choice")
OPERATIONS = ("value", "scale", "add")
_SEGMENT = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*)(?:\[(?P<index>\*|\d+)\])?$")


@dataclass(frozen=True, slots=True)
class Distribution:
    kind: str  # one of DISTRIBUTIONS
    args: tuple  # uniform / log_uniform: (lo, hi); normal: (mean, std); choice: the values

    def draw(self, rng: np.random.Generator, size: int | None) -> Any:
        if self.kind == "uniform":
            return rng.uniform(self.args[0], self.args[1], size)
        if self.kind == "normal":
            return rng.normal(self.args[0], self.args[1], size)
        if self.kind == "log_uniform":
            return np.exp(rng.uniform(math.log(self.args[0]), math.log(self.args[1]), size))
        picks = rng.integers(0, len(self.args), size)
        if size is None:
            return copy.deepcopy(self.args[int(picks)])
        return [copy.deepcopy(self.args[int(k)]) for k in picks]


@dataclass(frozen=True, slots=True)
class Parameter:
    """One swept key: `operation` (value / scale / add) of a draw onto the base value.

    per: "vehicle" draws for each vehicle the key names, "shared" once for all of them;
    each: "value" one draw per value, "component" one per component of a vector value;
    around_slot: initial positions only: the base value is the vehicle's formation slot
    (offset_enu_m) plus this point, so positions scatter around the formation (a derived key).
    """

    key: str
    operation: str
    distribution: Distribution
    per: str
    each: str
    around_slot: tuple[float, float, float] | None
    line: int | None


@dataclass(frozen=True, slots=True)
class StudyMetrics:
    window_from_s: float  # max / mean formation error over t >= this
    converged_below_m: float
    log_rate_hz: float
    heatmap: tuple[str, str] | None = None  # two parameter columns (without "param.")


@dataclass(frozen=True, slots=True)
class Study:
    name: str
    source: str  # the study file's path
    team_path: str
    base: dict  # the base team as a plain dict, with `set` applied
    parameters: tuple[Parameter, ...]
    runs: int
    seed: int
    metrics: StudyMetrics
    batch_runs: int
    fingerprint: str  # sha256 of the study's text and its base team's: what a resume checks

    def rng(self, run: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(run,)))

    def run_seed(self, run: int) -> int:
        """A 63-bit number naming run `run`'s random stream (recorded per row)."""
        state = np.random.SeedSequence(self.seed, spawn_key=(run,)).generate_state(1, np.uint64)
        return int(state[0] >> np.uint64(1))

    def draw(self, run: int) -> tuple[dict, dict[str, Any]]:
        """Run `run`'s team as a plain dict and its parameters by column name."""
        if not 0 <= run < self.runs:
            raise ValueError(f"run {run}: the study has runs 0..{self.runs - 1}")
        team = copy.deepcopy(self.base)
        # the losses of gcs sim's link model are the run's own (a parameter may still set it)
        team.setdefault("sim", {})["link_seed"] = self.run_seed(run)
        rng = self.rng(run)
        values: dict[str, Any] = {}
        for p in self.parameters:
            _apply(p, team, rng, values)
        return team, values

    def team(self, run: int) -> tuple[TeamConfig, dict[str, Any]]:
        """Run `run`'s team (Proposition 2 is recorded, not refused: gcs.sweep.measure)."""
        data, values = self.draw(run)
        return team_from_dict(data, f"{self.source} run {run}", proposition2=False), values


def _targets(team: dict, key: str) -> list[tuple[str, dict, str]]:
    """(column prefix, container, last key) of every place `key` names in the team dict."""
    places: list[tuple[str, Any]] = [("", team)]
    segments = key.split(".")
    for depth, segment in enumerate(segments):
        m = _SEGMENT.match(segment)
        name, index = m["name"], m["index"]
        last = depth == len(segments) - 1
        nxt: list[tuple[str, Any]] = []
        for prefix, node in places:
            here = f"{prefix}.{name}" if prefix else name
            if last and index is None:
                nxt.append((prefix, (node, name)))
                continue
            child = node[name]
            if index is None:
                nxt.append((here, child))
                continue
            for item in child:
                if index == "*" or str(item.get("id")) == index:
                    nxt.append((f"{here}.{item.get('id')}", item))
        places = nxt
    return [(prefix, holder, name) for prefix, (holder, name) in places]


def _apply(p: Parameter, team: dict, rng: np.random.Generator, values: dict[str, Any]) -> None:
    targets = _targets(team, p.key)
    shared = None
    for prefix, holder, name in targets:
        if p.around_slot is not None:
            holder[name] = [o + c for o, c in zip(_slot(team, prefix), p.around_slot,
                                                  strict=True)]
        base = holder[name]
        size = len(base) if p.each == "component" else None
        if p.per == "shared":
            if shared is None:
                shared = p.distribution.draw(rng, size)
            drawn = shared
        else:
            drawn = p.distribution.draw(rng, size)
        holder[name] = _combine(p.operation, base, drawn)
        column = f"param.{prefix}.{name}" if prefix else f"param.{name}"
        new = holder[name]
        if isinstance(new, list) and all(isinstance(x, float | int) for x in new) and new:
            for k, x in enumerate(new):
                values[f"{column}.{k}"] = float(x)
        elif isinstance(new, float | int) and not isinstance(new, bool):
            values[column] = float(new)
        else:
            values[column] = json.dumps(new)


def _slot(team: dict, prefix: str) -> list[float]:
    vehicle_id = prefix.split(".")[1]
    for v in team["vehicles"]:
        if str(v.get("id")) == vehicle_id:
            return list(v["offset_enu_m"])
    raise KeyError(prefix)


def _combine(operation: str, base: Any, drawn: Any) -> Any:
    if operation == "value":
        return drawn.tolist() if isinstance(drawn, np.ndarray) else _plain(drawn)
    op: Callable[[float, float], float] = (lambda a, b: a * b) if operation == "scale" \
        else (lambda a, b: a + b)
    if isinstance(base, list):
        d = np.broadcast_to(np.asarray(drawn, dtype=float), (len(base),))
        return [op(float(a), float(b)) for a, b in zip(base, d, strict=True)]
    return op(float(base), float(drawn))


def _plain(x: Any) -> Any:
    return x.item() if isinstance(x, np.generic) else x


# ------------------------------------------------------------------------------------------
# Reading a study file


def _distribution(node: Node, operation: str) -> Distribution:
    node.keys("", " ".join(DISTRIBUTIONS))
    given = [k for k in DISTRIBUTIONS if k in node.value]
    if len(given) != 1:
        node.fail(f"expected exactly one distribution of {', '.join(DISTRIBUTIONS)}")
    kind = given[0]
    arg = node.child(kind)
    if kind == "choice":
        if operation != "value":
            arg.fail("choice draws whole values: use it with `value`, not scale or add")
        items = arg.items("values", min_len=1)
        return Distribution(kind, tuple(i.value for i in items))
    items = arg.items("two numbers", min_len=2)
    if len(items) != 2:
        arg.fail(f"expected a list of two numbers, got {len(items)}")
    a, b = items[0].number(), items[1].number()
    if kind == "normal" and not b > 0:
        items[1].fail(f"the standard deviation must be > 0, got {b!r}")
    if kind in ("uniform", "log_uniform") and not a < b:
        arg.fail(f"expected low < high, got [{a!r}, {b!r}]")
    if kind == "log_uniform" and not a > 0:
        items[0].fail(f"log_uniform needs low > 0, got {a!r}")
    return Distribution(kind, (a, b))


def _check_key(node: Node, key: str, base: dict, operation: str, each: str) -> None:
    for segment in key.split("."):
        if not _SEGMENT.match(segment):
            node.fail(f"{segment!r} is not a key path segment (name, name[*] or name[ID])")
    try:
        targets = _targets(base, key)
    except (KeyError, TypeError, AttributeError):
        node.fail(f"the base team has no key {key!r}")
    if not targets:
        node.fail(f"{key!r} names no vehicle of the base team")
    for _, holder, name in targets:
        if not isinstance(holder, dict) or name not in holder:
            node.fail(f"the base team has no key {key!r}")
        value = holder[name]
        numeric = isinstance(value, int | float) and not isinstance(value, bool) or (
            isinstance(value, list) and value
            and all(isinstance(x, int | float) and not isinstance(x, bool) for x in value))
        if operation != "value" and not numeric:
            node.fail(f"{operation} needs a number or a list of numbers at {key!r}, "
                      f"the base team has {kind_of(value)}")
        if each == "component" and not isinstance(value, list):
            node.fail(f"each: component needs a list value at {key!r}, got {kind_of(value)}")


def _parameter(node: Node, base: dict) -> Parameter:
    node.keys("key", "value scale add per each around_slot")
    key = node.child("key").string()
    ops = [k for k in OPERATIONS if k in node.value]
    if len(ops) != 1:
        node.fail(f"expected exactly one of {', '.join(OPERATIONS)}")
    operation = ops[0]
    dist = _distribution(node.child(operation), operation)
    per = node.child("per").string("vehicle", choices=("vehicle", "shared"))
    each = node.child("each").string("value", choices=("value", "component"))
    around = node.child("around_slot")
    slot = None if around.absent else around.vec3()
    if slot is not None and not key.endswith(".initial.position_enu_m"):
        around.fail("around_slot applies to vehicles[...].initial.position_enu_m only")
    _check_key(node.child("key"), key, base, operation, each)
    return Parameter(key, operation, dist, per, each, slot, node.line)


def _set_key(node: Node, base: dict, key: str, value: Any) -> None:
    _check_key(node, key, base, "value", "value")
    for _, holder, name in _targets(base, key):
        holder[name] = copy.deepcopy(value)


def load_study(path: str | os.PathLike[str]) -> Study:
    """Read and check a study file; every problem is one ConfigError naming key and line."""
    source, text = read_text(path)
    data = parse_yaml(text, source)
    root = Node(source, "", data, None)
    if not isinstance(data, dict):
        root.fail(f"expected a mapping, got {kind_of(data)}")
    root.keys("name team runs seed parameters", "set metrics batch_runs")
    team_node = root.child("team")
    team_path = str(Path(source).parent / team_node.string())
    try:
        team_text = Path(team_path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        team_node.fail(f"cannot read the base team {team_path}: {exc}")
    base = team_to_dict(load_team(team_path))
    set_node = root.child("set")
    if not set_node.absent:
        if not isinstance(set_node.value, dict):
            set_node.fail("expected a mapping of key paths to values, "
                          f"got {kind_of(set_node.value)}")
        lines = getattr(set_node.value, "lines", {})
        for k, value in set_node.value.items():
            _set_key(Node(source, f"set.{k}", value, lines.get(k, set_node.line)),
                     base, str(k), value)
        try:
            team_from_dict(copy.deepcopy(base), f"{source} (team with set)", proposition2=False)
        except ConfigError as exc:
            set_node.fail(f"the base team with these keys set is not a valid team: {exc}")
    params = tuple(_parameter(n, base) for n in root.child("parameters").items(
        "parameters", min_len=1))
    m = root.child("metrics")
    if not m.absent:
        m.keys("", "window_from_s converged_below_m log_rate_hz heatmap")
    metrics = StudyMetrics(
        window_from_s=m.child("window_from_s").number(30.0, ge=0.0),
        converged_below_m=m.child("converged_below_m").number(0.01, gt=0.0),
        log_rate_hz=m.child("log_rate_hz").number(20.0, gt=0.0),
        heatmap=_heatmap(m.child("heatmap")),
    )
    study = Study(
        name=root.child("name").string(),
        source=source,
        team_path=team_path,
        base=base,
        parameters=params,
        runs=root.child("runs").integer(ge=1, le=10_000_000),
        seed=root.child("seed").integer(ge=0),
        metrics=metrics,
        batch_runs=root.child("batch_runs").integer(32, ge=1, le=4096),
        fingerprint=hashlib.sha256(text.encode() + b"\0" + team_text.encode()).hexdigest(),
    )
    if metrics.heatmap is not None:
        columns = {c.removeprefix("param.") for c in study.draw(0)[1]}
        for k, name in enumerate(metrics.heatmap):
            if name not in columns:
                m.child("heatmap").item(k).fail(
                    f"{name!r} is no parameter column of this study; its columns: "
                    f"{', '.join(sorted(columns))}")
    return study


def _heatmap(node: Node) -> tuple[str, str] | None:
    if node.absent:
        return None
    items = node.items("two parameter columns", min_len=2)
    if len(items) != 2:
        node.fail(f"expected two parameter columns, got {len(items)}")
    return items[0].string(), items[1].string()
