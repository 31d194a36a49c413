"""Team configuration reader: the team-level sections (controller, reference velocity, vehicles,
graph, frame) -> the schema's dataclasses; the public entry points. The YAML layer and the
value checks are in yamlnode, the `fly:` section in fly_section, `faults:` in fault_section."""

from __future__ import annotations

import dataclasses
import enum
import os
from pathlib import Path
from typing import Any

import yaml

from gcs.config.fault_section import read_fault
from gcs.config.fly_section import read_fly
from gcs.config.modes import DERIVATIVE_METHODS, LAWS, MODES, ControlMode
from gcs.config.schema import (
    FRAME_VEHICLES,
    GAIN_NAMES,
    GRAVITY_MPS2,
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
    FrameConfig,
    Gains,
    GraphConfig,
    InitialState,
    LinkConfig,
    MissionConfig,
    PlantParams,
    ReferenceVelocity,
    SimConfig,
    TeamConfig,
    VehicleConfig,
    initial_phi,
    proposition2_min_mhat,
    whole_ratio,
)
from gcs.config.yamlnode import MISSING, Dumper, Node, kind_of, parse_yaml
from gcs.control.gains import LawGains

# --------------------------------------------------------------------------------------------
# Sections.


def _controller(node: Node) -> ControllerConfig:
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
        ControlMode(node.child("mode").string(choices=MODES)),
        gains,
        derivative,
    )


def _axis(node: Node) -> AxisReference:
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


def _vehicle(node: Node, gains: Gains) -> VehicleConfig:
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
                ini.child(k).vec3(ZERO3 if k != "position_enu_m" else MISSING)
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


def _unique(nodes: list[Node], key: str, values: list[Any], what: str) -> None:
    seen: dict[Any, int] = {}
    for k, value in enumerate(values):
        if value is None:
            continue
        if value in seen:
            nodes[k].child(key).fail(f"duplicate {what} {value} (also vehicles[{seen[value]}])")
        seen[value] = k


def _graph(node: Node, ids: list[int]) -> GraphConfig:
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


def _frame(node: Node) -> FrameConfig:
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


def _team(root: Node) -> TeamConfig:
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
    if whole_ratio(sim.plant_rate_hz, sim.controller_rate_hz) is None:
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

    faults = [read_fault(f, ids, mission.duration_s) for f in root.child("faults").items("faults")]
    fly = read_fly(root.child("fly"))
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
    return _team(Node(source, "", data, None))


def team_from_yaml(text: str, source: str = "<string>") -> TeamConfig:
    """Parse and validate YAML text."""
    data = parse_yaml(text, source)
    if not isinstance(data, dict):
        got = "an empty document" if data is None else kind_of(data)
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
    """Plain data that team_from_dict reads back to an equal TeamConfig (None fields left out;
    a mode or an action as its string)."""

    def plain(x: Any) -> Any:
        if isinstance(x, enum.Enum):
            return x.value
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
    return yaml.dump(team_to_dict(team), Dumper=Dumper, sort_keys=False)
