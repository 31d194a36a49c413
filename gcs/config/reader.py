"""Team configuration reader: the whole file read by its declarations (declare.read_section),
with what depends on other sections worked out here (the vehicles with the gains, the graph and
the faults with the ids, a link's default ports, `mhat: from_hover`) and the rules between
sections; the public entry points. The YAML layer and the value checks are in yamlnode, the rules
between the `fly:` keys in fly_section, one fault in fault_section."""

from __future__ import annotations

import os
from typing import Any

import yaml

from gcs.config.declare import read_field, read_section, read_value, to_plain
from gcs.config.fault_section import read_fault
from gcs.config.fly_section import read_fly
from gcs.config.network_schema import read_network
from gcs.config.schema import (
    GAIN_NAMES,
    GRAVITY_MPS2,
    THRUST_MARGIN,
    ConfigError,
    Edge,
    Estimates,
    Gains,
    GraphConfig,
    LinkConfig,
    PlantParams,
    TeamConfig,
    VehicleConfig,
    initial_phi,
    proposition2_min_mhat,
    whole_ratio,
)
from gcs.config.yamlnode import Dumper, Node, kind_of, parse_yaml, read_text
from gcs.control.gains import LawGains

# --------------------------------------------------------------------------------------------
# Sections.


# vehicle-emu's personalities and origin rules (its `emulator:` sections; the ground station
# checks them so that `gcs check` catches a typo, and otherwise leaves them to the emulator)
EMULATOR_AUTOPILOTS = ("nominal", "px4", "ardupilot")
EMULATOR_ORIGINS = ("own", "shared")


def _emulator_section(node: Node, allowed: str) -> None:
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
                        f"{kind_of(params.value)}")
        for name in params.value:
            params.child(str(name)).number()


def _estimates(est: Node, plant: Node, gains: Gains) -> Estimates:
    """vehicles[].estimates; `mhat: from_hover` needs a mass for its stand-in and Proposition 2's
    mbar: the plant's mass_kg or mass_bound_kg."""
    node = est.child("mhat")
    if node.value != "from_hover":
        if isinstance(node.value, str):
            node.fail(f"expected a number > 0 or 'from_hover', got {node.value!r}")
        return read_section(est, Estimates, given={"mhat": lambda _: node.number(gt=0.0)})

    def stand_in(read: dict[str, Any]) -> float:
        """What the hover would give with v(0) = 0 (phi(0) = 2)."""
        mass = (read_section(plant, PlantParams).mass_kg if not plant.absent
                else read["mass_bound_kg"])
        if mass is None:
            node.fail("from_hover needs estimates.mass_bound_kg (Proposition 2's mbar, checked "
                      "against the hover estimate) or a plant")
        return 2.0 * mass / gains.alpha_m

    return read_section(est, Estimates, given={"mhat": stand_in, "from_hover": lambda _: True})


def _link(node: Node, sysid: int) -> LinkConfig:
    """vehicles[].link; absent keys: PX4 SITL's ports for the sysid, or with learn_remote the
    vehicle's address from its first message."""
    px4 = LinkConfig.px4_sitl(sysid)
    if node.absent:
        return px4
    learn = read_field(node, LinkConfig, "learn_remote")
    if learn and node.child("remote_port").absent and not node.child("remote_host").absent:
        node.child("remote_host").fail(
            "has no effect without remote_port: with learn_remote: true the vehicle's address is "
            "learned from its first message (give remote_port too to send there until then)"
        )
    if learn:
        host = None if node.child("remote_port").absent else px4.remote_host
        px4 = LinkConfig(px4.local_port, host, None, True)
    return read_section(node, LinkConfig, px4)


def _vehicle(node: Node, gains: Gains, proposition2: bool = True) -> VehicleConfig:
    _emulator_section(node.child("emulator"),
                      "autopilot origin_enu_m boot_position_enu_m autopilot_params")
    est, plant, air = node.child("estimates"), node.child("plant"), node.child("airframe")
    vehicle = read_section(node, VehicleConfig, extra_keys=("emulator",), given={
        "estimates": lambda _: _estimates(est, plant, gains),
        "link": lambda read: _link(node.child("link"), read["sysid"]),
    })
    sysid = vehicle.sysid
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
    if (proposition2 and least is not None and not vehicle.estimates.from_hover
            and vehicle.estimates.mhat < least * (1.0 - 1e-12)):
        source = "mass_bound_kg" if vehicle.estimates.mass_bound_kg is not None else "plant mass"
        est.child("mhat").fail(
            f"Proposition 2 needs mhat(0) >= (phi(0) - 1) mbar / alpha_m = "
            f"({initial_phi(vehicle, gains):.6g} - 1) * {vehicle.mass_bound_kg:g} / "
            f"{gains.alpha_m:g} = {least:.6g} (mbar = {source}), got {vehicle.estimates.mhat!r} "
            f"({who})"
        )
    return vehicle


def _unique(nodes: list[Node], key: str, values: list[Any], what: str) -> None:
    seen: dict[Any, int] = {}
    for k, value in enumerate(values):
        if value is None:
            continue
        if value in seen:
            nodes[k].child(key).fail(f"duplicate {what} {value} (also vehicles[{seen[value]}])")
        seen[value] = k


_WEIGHT = Edge.__dataclass_fields__["weight"]


def _graph(node: Node, ids: list[int]) -> GraphConfig:
    node.keys("edges")
    edges: list[Edge] = []
    seen: dict[frozenset[int], int] = {}
    for e in node.child("edges").items("edges [i, j] or [i, j, weight]"):
        if isinstance(e.value, dict):
            weight = read_section(e, Edge).weight
            ends = [e.child("i"), e.child("j")]
        elif isinstance(e.value, list | tuple) and len(e.value) in (2, 3):
            ends = [e.item(0), e.item(1)]
            weight = (read_value(e.item(2), float, _WEIGHT.metadata, _WEIGHT.default)
                      if len(e.value) == 3 else _WEIGHT.default)
        else:
            e.fail(f"expected an edge [i, j] or [i, j, weight], got {kind_of(e.value)}")
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


def _team(root: Node, proposition2: bool = True) -> TeamConfig:
    _emulator_section(root.child("emulator"), "autopilot origin autopilot_params")
    def vehicles(read: dict[str, Any]) -> tuple[VehicleConfig, ...]:
        nodes = root.child("vehicles").items("vehicles", min_len=1)
        out = tuple(_vehicle(node, read["controller"].gains, proposition2) for node in nodes)
        _check_vehicles(nodes, out, read["controller"].law)
        return out

    def faults(read: dict[str, Any]) -> tuple[Any, ...]:
        ids, duration_s = [v.id for v in read["vehicles"]], read["mission"].duration_s
        return tuple(read_fault(f, ids, duration_s) for f in root.child("faults").items("faults"))

    team = read_section(root, TeamConfig, extra_keys=("emulator",), given={
        "source_path": lambda _: root.source,
        "vehicles": vehicles,
        "graph": lambda read: _graph(root.child("graph"), [v.id for v in read["vehicles"]]),
        "faults": faults,
        "fly": lambda _: read_fly(root.child("fly")),
        "network": lambda read: read_network(root.child("network"),
                                             [v.id for v in read["vehicles"]]),
    })
    _check_rates(root, team)
    return team


def _check_rates(root: Node, team: TeamConfig) -> None:
    """The rules between the simulation's rates, the law's derivatives and gains and the
    reference velocity."""
    sim, d, gains = team.sim, team.controller.derivative, team.controller.gains
    ratio = sim.plant_rate_hz / sim.controller_rate_hz
    if whole_ratio(sim.plant_rate_hz, sim.controller_rate_hz) is None:
        root.child("sim.controller_rate_hz").fail(
            f"must divide plant_rate_hz {sim.plant_rate_hz:g} (an integer number of plant steps "
            f"per control tick), got {sim.controller_rate_hz:g} (ratio {ratio:.6g})"
        )
    if d.method == "levant" and d.levant_substep_s > sim.controller_dt_s:
        root.child("controller.derivative.levant_substep_s").fail(
            f"expected <= the control period 1/{sim.controller_rate_hz:g} Hz = "
            f"{sim.controller_dt_s:g} s, got {d.levant_substep_s!r}"
        )
    varrho = team.reference_velocity.max_abs_acceleration_z()
    bound = (GRAVITY_MPS2 - varrho) / (2.0 * gains.sigma_a)
    if not gains.alpha_p < bound:
        root.child("controller.gains.alpha_p").fail(
            f"needs alpha_p < (g - varrho)/(2 sigma_a) = ({GRAVITY_MPS2:g} - {varrho:.6g})/"
            f"(2 * {gains.sigma_a:g}) = {bound:.6g} with varrho = sup|v_r,z'|, "
            f"got {gains.alpha_p!r}"
        )


def _check_vehicles(nodes: list[Node], vehicles: tuple[VehicleConfig, ...], law: str) -> None:
    """The rules between the vehicles: unique ids, sysids, endpoints, offsets and starts; the
    baseline law's nominal masses."""
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
    if law == "baseline":
        for node, v in zip(nodes, vehicles, strict=True):
            if v.nominal_mass_kg is None:
                node.child("nominal_mass_kg").fail(
                    f"required by the baseline law (vehicle {v.id}, sysid {v.sysid})"
                )


# --------------------------------------------------------------------------------------------
# Public entry points.


def team_from_dict(data: Any, source: str = "<dict>", *, proposition2: bool = True) -> TeamConfig:
    """Validate an already-parsed config (a dict as yaml.safe_load gives it).

    proposition2=False reads a team whose mhat(0) breaks Proposition 2 (the sweep flies such
    teams on purpose and reports the condition, gcs.sweep.measure); every other check holds."""
    return _team(Node(source, "", data, None), proposition2)


def team_from_yaml(text: str, source: str = "<string>") -> TeamConfig:
    """Parse and validate YAML text."""
    data = parse_yaml(text, source)
    if not isinstance(data, dict):
        got = "an empty document" if data is None else kind_of(data)
        raise ConfigError(source, "(top level)", f"expected a mapping of sections, got {got}", 1)
    return team_from_dict(data, source)


def load_team(path: str | os.PathLike[str]) -> TeamConfig:
    """Read and validate a team config file; every problem raises ConfigError."""
    source, text = read_text(path)
    return team_from_yaml(text, source)


def team_to_dict(team: TeamConfig) -> dict[str, Any]:
    """Plain data that team_from_dict reads back to an equal TeamConfig (None fields left out;
    a mode or an action as its string; each key under its declared name)."""

    def special(x: Any) -> Any:
        if isinstance(x, LawGains):
            return {name: getattr(x, name) for name in GAIN_NAMES}
        if isinstance(x, Estimates):
            out = {"mhat": "from_hover" if x.from_hover else x.mhat,
                   "inertia_kgm2": list(x.inertia_kgm2)}
            return out | ({} if x.mass_bound_kg is None else {"mass_bound_kg": x.mass_bound_kg})
        return None

    return to_plain(team, special)


def team_to_yaml(team: TeamConfig) -> str:
    """`team_to_dict` as YAML text that `team_from_yaml` reads back to the same team."""
    return yaml.dump(team_to_dict(team), Dumper=Dumper, sort_keys=False)
