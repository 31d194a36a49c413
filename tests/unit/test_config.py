"""Team config loader: shipped scenarios, every validation message, Hypothesis properties."""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gcs.config import (
    GRAVITY_MPS2,
    THRUST_MARGIN,
    ConfigError,
    FaultConfig,
    LinkConfig,
    LinkLossFault,
    MotorEfficiencyFault,
    PacketLossFault,
    TeamConfig,
    describe,
    load_team,
    team_from_dict,
    team_from_yaml,
    team_to_dict,
    team_to_yaml,
)

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
SQUARE4 = CONFIGS / "square4.yaml"
MASSDROP = CONFIGS / "square4_massdrop.yaml"
MASSES = (0.85, 1.2, 0.35, 3.4)  # Table I
DELETE = object()


def base() -> dict[str, Any]:
    """The paper's Scenario I as plain data, independent of the shipped file."""
    inertias = (
        (0.04856, 0.04856, 0.08801),
        (0.1522, 0.1522, 0.3),
        (0.0256, 0.0256, 0.052),
        (0.354, 0.354, 0.654),
    )
    offsets = ((2.0, 2.0, 0.0), (2.0, -2.0, 0.0), (-2.0, -2.0, 0.0), (-2.0, 2.0, 0.0))
    starts = ((4.0, 4.0, 9.0), (3.0, -4.0, 11.0), (-5.0, -4.0, 12.0), (-1.0, 3.0, 8.0))
    rotor = (6.0, 8.0, 3.0, 20.0)
    return {
        "name": "square4",
        "mission": {"duration_s": 60.0},
        "controller": {
            "law": "adaptive",
            "mode": "rates",
            "gains": {
                "c_p": 4.0,
                "alpha_p": 2.0,
                "alpha_m": 1.0,
                "sigma_a": 1.0,
                "alpha_eps": 32.0,
                "alpha_omega": 32.0,
                "c_eps": 0.5,
                "alpha_rho": 0.5,
                "k_eps": 8.0,
            },
            "derivative": {"method": "model"},
        },
        "reference_velocity": {
            "x": {"constant": 0.0, "cosines": [{"amplitude": 0.3, "period_s": 23.0}]},
            "y": {"constant": 0.0, "cosines": [{"amplitude": 0.3, "period_s": 11.5}]},
            "z": {"constant": 0.2},
        },
        "graph": {"edges": [[1, 2], [2, 3], [3, 4], [4, 1]]},
        "sim": {"plant_rate_hz": 1000, "controller_rate_hz": 1000},
        "vehicles": [
            {
                "id": k + 1,
                "sysid": k + 1,
                "offset_enu_m": list(offsets[k]),
                "initial": {"position_enu_m": list(starts[k])},
                "estimates": {"mhat": (1.0, 4.0, 1.0, 4.0)[k], "inertia_kgm2": [0.08] * 3},
                "nominal_mass_kg": MASSES[k],
                "airframe": {
                    "arm_length_m": 0.2,
                    "anti_torque_m": 0.016,
                    "rotor_thrust_max_n": rotor[k],
                },
                "plant": {"mass_kg": MASSES[k], "inertia_kgm2": list(inertias[k])},
            }
            for k in range(4)
        ],
    }


def edit(data: dict[str, Any], dotted: str, value: Any) -> dict[str, Any]:
    """Set (or with DELETE remove) the value at "a.b.2.c" in data; returns data."""
    *parents, last = dotted.split(".")
    node: Any = data
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node.setdefault(key, {})
    if value is DELETE:
        del node[int(last) if isinstance(node, list) else last]
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return data


def raises_at(data: dict[str, Any], match: str) -> ConfigError:
    with pytest.raises(ConfigError, match=match) as info:
        team_from_dict(data)
    message = str(info.value)
    assert "\n" not in message and message.startswith("<dict>: ")
    return info.value


# ------------------------------------------------------------------------------------------------
# The shipped configs.


def test_square4_is_the_papers_scenario_one():
    # GIVEN the shipped Scenario I WHEN loaded
    team = load_team(SQUARE4)
    # THEN four vehicles with Table I masses on the unit-weight ring 1-2-3-4-1
    assert team.n == 4 and team.ids() == (1, 2, 3, 4) and team.sysids() == (1, 2, 3, 4)
    assert team.name == "square4" and team.source_path.endswith("square4.yaml")
    np.testing.assert_allclose(team.true_masses_kg(), MASSES)
    ring = np.array([[0, 1, 0, 1], [1, 0, 1, 0], [0, 1, 0, 1], [1, 0, 1, 0]], dtype=float)
    np.testing.assert_array_equal(team.adjacency(), ring)
    np.testing.assert_array_equal(team.laplacian(), 2 * np.eye(4) - ring)
    # AND the offsets reproduce the paper's Theta_x, Theta_y (a 4 m square), Theta_z = 0
    theta = team.offsets_enu_m()
    theta_ij = theta[:, None, :] - theta[None, :, :]
    theta_x = [[0, 0, 4, 4], [0, 0, 4, 4], [-4, -4, 0, 0], [-4, -4, 0, 0]]
    theta_y = [[0, 4, 4, 0], [-4, 0, 0, -4], [-4, 0, 0, -4], [0, 4, 4, 0]]
    np.testing.assert_array_equal(theta_ij[:, :, 0], theta_x)
    np.testing.assert_array_equal(theta_ij[:, :, 1], theta_y)
    np.testing.assert_array_equal(theta_ij[:, :, 2], np.zeros((4, 4)))
    # AND the paper's initial positions shifted 10 m up, mhat(0) = (1, 4, 1, 4), Jhat(0) = 0.08 I
    np.testing.assert_array_equal(
        team.initial_positions_enu_m(), [[4, 4, 9], [3, -4, 11], [-5, -4, 12], [-1, 3, 8]]
    )
    np.testing.assert_array_equal(team.initial_velocities_enu_mps(), np.zeros((4, 3)))
    np.testing.assert_array_equal(team.initial_mhat(), [1, 4, 1, 4])
    np.testing.assert_array_equal(team.initial_inertia_estimates_kgm2(), np.full((4, 3), 0.08))
    np.testing.assert_allclose(team.true_inertias_kgm2()[3], [0.354, 0.354, 0.654])
    np.testing.assert_array_equal(team.max_thrusts_n(), [24, 32, 12, 80])
    # AND the section V gains, derivative settings (1.0e4 read as a number) and rates
    g = team.controller.gains
    assert (g.c_p, g.alpha_p, g.alpha_m, g.alpha_eps, g.c_eps, g.alpha_rho) == (
        4.0,
        2.0,
        1.0,
        32.0,
        0.5,
        0.5,
    )
    assert team.controller.law == "adaptive" and team.controller.mode in ("rates", "actuators")
    assert team.controller.derivative.levant_lipschitz == 1e4
    assert team.sim.plant_steps_per_tick == 1 and team.mission.duration_s == 60.0
    assert team.faults == ()
    assert team.vehicle(3).link == LinkConfig(14542, "127.0.0.1", 14582)


def test_square4_reference_velocity_is_the_papers_and_its_arrays_evaluate_it():
    # GIVEN Scenario I's v_r = [0.3 cos(2 pi t/23), 0.3 cos(4 pi t/23), 0.2]
    ref = load_team(SQUARE4).reference_velocity
    constant, amplitude, omega, phase = ref.as_arrays()
    assert amplitude.shape == omega.shape == phase.shape == (3, 1) and constant.shape == (3,)
    assert ref.max_abs_acceleration_z() == 0.0
    for t in (0.0, 3.7, 41.0):
        want = [0.3 * math.cos(2 * math.pi * t / 23), 0.3 * math.cos(4 * math.pi * t / 23), 0.2]
        np.testing.assert_allclose(ref.evaluate(t), want, atol=1e-15)
        # AND its derivatives match central differences
        for order in (1, 2, 3):
            h = 1e-4
            fd = (ref.evaluate(t + h, order - 1) - ref.evaluate(t - h, order - 1)) / (2 * h)
            np.testing.assert_allclose(ref.evaluate(t, order), fd, atol=1e-7)


def test_massdrop_is_square4_plus_the_scenario_two_changes():
    # GIVEN both shipped configs WHEN loaded
    one, two = load_team(SQUARE4), load_team(MASSDROP)
    # THEN Scenario II has v_r,z = 0, 80 s and the 30 % drop on UAV 1 at 40 s
    assert two.name == "square4_massdrop" and two.mission.duration_s == 80.0
    assert two.reference_velocity.z.constant == 0.0 and not two.reference_velocity.z.cosines
    assert two.faults == (FaultConfig("mass_drop", 1, 40.0, 0.3),)
    # AND nothing else differs
    a, b = team_to_dict(one), team_to_dict(two)
    for d in (a, b):
        del d["name"], d["mission"], d["reference_velocity"]["z"], d["faults"]
    assert a == b
    # AND `gcs check` describes the drop with the true masses
    assert "mass_drop: vehicle 1 loses 30% of its mass at t = 40 s (0.85 -> 0.595 kg)" in describe(
        two
    )


def test_describe_reports_what_it_understood_and_the_sufficient_conditions():
    text = describe(team_from_dict(base(), "scenario1"))
    assert "team 'square4' (scenario1): 4 vehicles, mission 60 s" in text
    assert "graph: 4 undirected edge(s) 1-2, 2-3, 3-4, 4-1; connected, lambda_2(L) = 2" in text
    assert "2 < (9.81 - 0)/(2 * 1) = 4.905: OK, margin 2.905" in text
    assert "vehicle 1: 1 >= (2 - 1) * 0.85 / 1 = 0.85: OK, margin 0.15" in text
    assert "vehicle 4: 80 N >= 40.02 N: OK" in text
    assert "vehicle 4 (Jbar 0.654): 0.5 < min(4.9462, 14.1248, 3.1172) = 3.117: OK" in text
    # GIVEN controller.mode attitude (a gcs fly mode) THEN it is described, not a crash
    text = describe(team_from_dict(edit(base(), "controller.mode", "attitude")))
    assert "adaptive law, attitude mode (thrust + attitude; gcs fly only" in text
    # GIVEN a vehicle without plant THEN masses are not shown and the mass checks are skipped
    data = edit(base(), "vehicles.0.plant", DELETE)
    text = describe(team_from_dict(data))
    assert "no plant (true mass unknown)" in text and "vehicle 1: skipped" in text
    assert "plant 0.85 kg" not in text


def test_defaults_optional_keys_and_explicit_link():
    data = base()
    del data["sim"], data["controller"]["derivative"]
    edit(data, "vehicles.1.link", {"local_port": 0, "remote_host": "10.0.0.2"})
    edit(data, "vehicles.2.plant", None)  # null on an optional key means "not given"
    team = team_from_dict(data)
    assert team.sim.plant_rate_hz == team.sim.controller_rate_hz == 1000.0
    assert team.controller.derivative.method == "model"
    assert team.vehicles[1].link == LinkConfig(0, "10.0.0.2", 14581)
    assert team.vehicles[0].link == LinkConfig(14540, "127.0.0.1", 14580, learn_remote=False)
    assert team.vehicles[2].plant is None and not team.has_plants()
    assert team.vehicles[0].initial.attitude_rpy_rad == (0.0, 0.0, 0.0)
    with pytest.raises(ConfigError, match=r"vehicles\[2\]\.plant: missing: the true mass"):
        team.true_masses_kg()
    # AND weighted edges in list or mapping form
    edit(
        data,
        "graph.edges",
        [[1, 2, 0.5], {"i": 2, "j": 3, "weight": 2.0}, {"i": 3, "j": 4}, [4, 1]],
    )
    a = team_from_dict(data).adjacency()
    assert a[0, 1] == a[1, 0] == 0.5 and a[1, 2] == 2.0 and a[2, 3] == a[3, 0] == 1.0


def test_shared_ports_and_learned_addresses():
    # GIVEN four vehicles sending to one GCS port (a router, or SITL told to), whose addresses
    # are learned, one of them with a first address to send to until it is heard
    data = base()
    for k in range(4):
        edit(data, f"vehicles.{k}.link", {"local_port": 14550, "learn_remote": True})
    edit(data, "vehicles.3.link.remote_port", 14583)
    team = team_from_dict(data)
    # THEN they share the port; the learned links have no address until heard
    assert [v.link.local_port for v in team.vehicles] == [14550] * 4
    assert team.vehicles[0].link == LinkConfig(14550, None, None, learn_remote=True)
    assert team.vehicles[3].link == LinkConfig(14550, "127.0.0.1", 14583, learn_remote=True)
    # AND gcs check says so
    text = describe(team)
    assert "link udp :14550 (shared with 2, 3, 4, by sysid) -> the address its first message " \
           "comes from;" in text
    assert "-> the address its first message comes from (until then 127.0.0.1:14583)" in text
    # AND it round-trips
    assert team_from_dict(team_to_dict(team)) == team


def test_with_law_switches_and_checks_the_baseline():
    team = team_from_dict(base())
    assert team.with_law("baseline").controller.law == "baseline"
    np.testing.assert_allclose(team.with_law("baseline").nominal_masses_kg(), MASSES)
    bare = team_from_dict(edit(base(), "vehicles.3.nominal_mass_kg", DELETE))
    with pytest.raises(ConfigError, match=r"vehicles\[3\]\.nominal_mass_kg: missing: the baseline"):
        bare.with_law("baseline")
    with pytest.raises(ConfigError, match=r"controller\.law: expected one of"):
        team.with_law("pid")


def test_config_error_accepts_a_plain_message():
    assert str(ConfigError("controller rate 300 Hz must divide 1000 Hz")) == (
        "controller rate 300 Hz must divide 1000 Hz"
    )
    err = ConfigError("a.yaml", "mission.duration_s", "expected > 0, got 0.0", 7)
    assert str(err) == "a.yaml: mission.duration_s: expected > 0, got 0.0 (line 7)"
    assert (err.path, err.line) == ("mission.duration_s", 7) and isinstance(err, ValueError)


# ------------------------------------------------------------------------------------------------
# Every check, pinned by its message.

ERRORS = [
    # (key path, value, message)
    (
        "nmae",
        "x",
        r"^<dict>: nmae: unknown key; did you mean 'name'\? allowed keys: name, "
        r"mission, controller, reference_velocity, graph, vehicles, sim, faults, fly, frame, "
        r"network, emulator$",
    ),
    (
        "vehicles.2.plant.mas_kg",
        1.0,
        r"vehicles\[2\]\.plant\.mas_kg: unknown key; did you mean 'mass_kg'\?",
    ),
    ("vehicles.1.offset_enu_m", DELETE, r"vehicles\[1\]\.offset_enu_m: required key is missing"),
    ("controller.gains.k_eps", DELETE, r"controller\.gains\.k_eps: required key is missing"),
    ("mission", DELETE, r"^<dict>: mission: required key is missing$"),
    ("mission.duration_s", True, r"mission\.duration_s: expected a number, got bool True"),
    ("mission.duration_s", "60", r"mission\.duration_s: expected a number, got string '60'"),
    ("controller.gains", [1, 2], r"controller\.gains: expected a mapping with keys c_p, "),
    (
        "vehicles.0.initial.position_enu_m",
        [1.0, 2.0],
        r"vehicles\[0\]\.initial\.position_enu_m: expected a list of 3 numbers, got a list of 2",
    ),
    ("vehicles.0.offset_enu_m", "2 2 0", r"offset_enu_m: expected a list of 3 numbers, got str"),
    (
        "vehicles.0.offset_enu_m.1",
        None,
        r"vehicles\[0\]\.offset_enu_m\[1\]: expected a number, "
        r"got null",
    ),
    (
        "vehicles.1.plant.inertia_kgm2.2",
        math.nan,
        r"vehicles\[1\]\.plant\.inertia_kgm2\[2\]: expected a finite number, got nan",
    ),
    (
        "reference_velocity.x.cosines.0.amplitude",
        math.inf,
        r"reference_velocity\.x\.cosines\[0\]\.amplitude: expected a finite number, got inf",
    ),
    (
        "vehicles.2.plant.mass_kg",
        -1.0,
        r"^<dict>: vehicles\[2\]\.plant\.mass_kg: expected > 0, got -1\.0$",
    ),
    (
        "vehicles.0.plant.inertia_kgm2",
        [0.1, 0.0, 0.1],
        r"vehicles\[0\]\.plant\.inertia_kgm2\[1\]: expected > 0, got 0\.0",
    ),
    ("vehicles.0.estimates.inertia_kgm2.0", -0.08, r"estimates\.inertia_kgm2\[0\]: expected > 0"),
    ("vehicles.0.estimates.mhat", 0, r"vehicles\[0\]\.estimates\.mhat: expected > 0, got 0\.0"),
    ("vehicles.0.airframe.arm_length_m", 0.0, r"airframe\.arm_length_m: expected > 0, got 0\.0"),
    ("vehicles.3.airframe.rotor_thrust_max_n", -20, r"rotor_thrust_max_n: expected > 0, got -20"),
    ("sim.plant_rate_hz", 0, r"sim\.plant_rate_hz: expected > 0, got 0\.0"),
    ("mission.duration_s", -60.0, r"mission\.duration_s: expected > 0, got -60\.0"),
    ("controller.gains.c_eps", 0.0, r"controller\.gains\.c_eps: expected > 0, got 0\.0"),
    ("controller.gains.phi_horizontal", 1.5,
     r"controller\.gains\.phi_horizontal: expected a value in \[0, 1\], got 1\.5"),
    (
        "controller.law",
        "adaptiv",
        r"controller\.law: expected one of 'adaptive', 'baseline', got string 'adaptiv'",
    ),
    ("controller.mode", "torque", r"controller\.mode: expected one of 'rates', 'actuators'"),
    ("controller.derivative.method", "euler", r"derivative\.method: expected one of 'model', "),
    (
        "reference_velocity.z.cosines",
        [{"amplitude": 0.1, "period_s": 0.0}],
        r"reference_velocity\.z\.cosines\[0\]\.period_s: expected > 0, got 0\.0",
    ),
    ("reference_velocity.y", DELETE, r"reference_velocity\.y: required key is missing"),
    ("vehicles", [], r"vehicles: expected a list of vehicles \(at least 1\), got a list of 0"),
    ("vehicles.2.id", 2, r"vehicles\[2\]\.id: duplicate vehicle id 2 \(also vehicles\[1\]\)"),
    ("vehicles.0.id", 1.5, r"vehicles\[0\]\.id: expected an integer, got float 1\.5"),
    ("vehicles.0.id", 0, r"vehicles\[0\]\.id: expected >= 1, got 0"),
    ("vehicles.3.sysid", 1, r"vehicles\[3\]\.sysid: duplicate sysid 1 \(also vehicles\[0\]\)"),
    ("vehicles.3.sysid", 256, r"vehicles\[3\]\.sysid: expected a value in \[1, 255\], got 256"),
    ("vehicles.0.sysid", 0, r"vehicles\[0\]\.sysid: expected a value in \[1, 255\], got 0"),
    (
        "vehicles.3.sysid",
        3,
        r"vehicles\[3\]\.sysid: duplicate sysid 3 \(also vehicles\[2\]\)",
    ),
    (
        "vehicles.2.link",
        {"learn_remote": "yes"},
        r"vehicles\[2\]\.link\.learn_remote: expected true or false, got string 'yes'",
    ),
    (
        "vehicles.2.link",
        {"learn_remote": True, "remote_host": "10.0.0.2"},
        r"vehicles\[2\]\.link\.remote_host: has no effect without remote_port: with "
        r"learn_remote: true",
    ),
    (
        "vehicles.2.link",
        {"remote_port": 14580},
        r"vehicles\[2\]\.link\.remote_port: duplicate remote endpoint \('127\.0\.0\.1', 14580\) "
        r"\(also vehicles\[0\]\); vehicles behind one router or relay share its address: set "
        r"learn_remote: true and leave remote_port out$",
    ),
    (
        "vehicles.2.link",
        {"remote_port": 70000},
        r"link\.remote_port: expected a value in \[1, 65535",
    ),
    ("vehicles.2.link", {"host": "x"}, r"vehicles\[2\]\.link\.host: unknown key;"),
    (
        "vehicles.1.offset_enu_m",
        [2.0, 2.0, 0.0],
        r"vehicles\[1\]\.offset_enu_m: duplicate offset \(collision\) \(2\.0, 2\.0, 0\.0\)",
    ),
    (
        "vehicles.1.initial.position_enu_m",
        [4, 4, 9],
        r"vehicles\[1\]\.initial\.position_enu_m: duplicate initial position \(collision\)",
    ),
    ("graph.edges.1", [2, 7], r"graph\.edges\[1\]\[1\]: unknown vehicle id 7; ids are 1, 2, 3, 4"),
    ("graph.edges.1", [3, 3], r"graph\.edges\[1\]: self loop on vehicle 3"),
    ("graph.edges.1", [2, 1], r"graph\.edges\[1\]: duplicate edge 2-1 \(also graph\.edges\[0\]\)"),
    ("graph.edges.1", [2, 3, 0.0], r"graph\.edges\[1\]\[2\]: expected > 0, got 0\.0"),
    ("graph.edges.1", {"i": 2, "j": 3, "weight": -1}, r"graph\.edges\[1\]\.weight: expected > 0"),
    ("graph.edges.1", [2], r"graph\.edges\[1\]: expected an edge \[i, j\] or \[i, j, weight\]"),
    (
        "graph.edges",
        [[1, 2], [3, 4]],
        r"graph\.edges: the graph is disconnected \(Assumption 2\): "
        r"vehicles 3, 4 cannot be reached from vehicle 1",
    ),
    (
        "controller.gains.alpha_p",
        5.0,
        r"controller\.gains\.alpha_p: needs alpha_p < \(g - varrho\)/\(2 sigma_a\) = "
        r"\(9\.81 - 0\)/\(2 \* 1\) = 4\.905 with varrho = sup\|v_r,z'\|, got 5\.0",
    ),
    (
        "vehicles.0.estimates.mhat",
        0.8,
        r"vehicles\[0\]\.estimates\.mhat: Proposition 2 needs mhat\(0\) >= \(phi\(0\) - 1\) mbar / "
        r"alpha_m = \(2 - 1\) \* 0\.85 / 1 = 0\.85 \(mbar = plant mass\), got 0\.8 "
        r"\(vehicle 1, sysid 1\)",
    ),
    (
        "vehicles.0.estimates.mass_bound_kg",
        3.4,
        r"vehicles\[0\]\.estimates\.mhat: Proposition 2 needs .* = 3\.4 \(mbar = mass_bound_kg\), "
        r"got 1\.0",
    ),
    (
        "vehicles.0.initial.velocity_enu_mps",
        [1.0, 1.0, 1.0],
        r"vehicles\[0\]\.estimates\.mhat: Proposition 2 needs .* \(2\.76159 - 1\) \* 0\.85 / 1 = "
        r"1\.49736",
    ),
    (
        "vehicles.1.estimates.mass_bound_kg",
        1.0,
        r"vehicles\[1\]\.estimates\.mass_bound_kg: expected >= plant\.mass_kg 1\.2, got 1\.0",
    ),
    (
        "vehicles.0.airframe.rotor_thrust_max_n",
        2.0,
        r"vehicles\[0\]\.airframe\.rotor_thrust_max_n: max collective thrust 4 \* 2 = 8 N is below "
        r"1\.2 m g = 1\.2 \* 0\.85 \* 9\.81 = 10\.01 N; need rotor_thrust_max_n >= 2\.502 "
        r"\(vehicle 1, sysid 1\)",
    ),
    (
        "sim.controller_rate_hz",
        300,
        r"sim\.controller_rate_hz: must divide plant_rate_hz 1000 .* got 300 \(ratio 3\.33333\)",
    ),
    ("sim.controller_rate_hz", 2000, r"sim\.controller_rate_hz: must divide .* \(ratio 0\.5\)"),
    (
        "controller.derivative",
        {"method": "levant", "levant_substep_s": 0.01},
        r"controller\.derivative\.levant_substep_s: expected <= the control period 1/1000 Hz",
    ),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 9, "at_s": 40.0, "fraction": 0.3}],
        r"faults\[0\]\.vehicle: unknown vehicle id 9; ids are 1, 2, 3, 4",
    ),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 1, "at_s": 40.0, "fraction": 1.0}],
        r"faults\[0\]\.fraction: expected a value in \(0, 1\), got 1\.0",
    ),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 1, "at_s": 40.0, "fraction": 0}],
        r"faults\[0\]\.fraction: expected a value in \(0, 1\), got 0\.0",
    ),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 1, "at_s": 61.0, "fraction": 0.3}],
        r"faults\[0\]\.at_s: expected a value in \[0, 60\], got 61\.0",
    ),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 1, "at_s": -1.0, "fraction": 0.3}],
        r"faults\[0\]\.at_s: expected a value in \[0, 60\], got -1\.0",
    ),
    (
        "faults",
        [{"kind": "wind", "vehicle": 1, "at_s": 4.0}],
        r"faults\[0\]\.kind: expected one of 'mass_drop', 'link_loss', 'packet_loss', "
        r"'motor_efficiency', got string 'wind'",
    ),
    (
        "faults",
        [{"kind": "link_loss", "vehicle": 1, "at_s": 4.0}],
        r"faults\[0\]\.duration_s: required key is missing",
    ),
    (
        "faults",
        [{"kind": "link_loss", "vehicle": 1, "at_s": 4.0, "duration_s": 0}],
        r"faults\[0\]\.duration_s: expected > 0, got 0\.0",
    ),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 1, "at_s": 4.0, "fraction": 0.3, "duration_s": 1}],
        r"faults\[0\]\.duration_s: unknown key; .*allowed keys: kind, vehicle, at_s, fraction$",
    ),
    (
        "faults",
        [{"kind": "packet_loss", "vehicle": 2, "at_s": 4.0, "probability": 1.5}],
        r"faults\[0\]\.probability: expected a value in \[0, 1\], got 1\.5",
    ),
    (
        "faults",
        [{"kind": "motor_efficiency", "vehicle": 2, "at_s": 4.0, "motor": 5, "efficiency": 0.5}],
        r"faults\[0\]\.motor: expected a value in \[1, 4\], got 5",
    ),
    (
        "faults",
        [{"kind": "motor_efficiency", "vehicle": 2, "at_s": 4.0, "motor": 1, "efficiency": 1.2}],
        r"faults\[0\]\.efficiency: expected a value in \[0, 1\], got 1\.2",
    ),
    ("faults", [[1, 40.0]], r"faults\[0\]: expected a mapping with keys kind, vehicle, at_s"),
    (
        "faults",
        [{"kind": "mass_drop", "vehicle": 1, "at_s": 4.0, "fraction": 0.3, "x": 1}],
        r"faults\[0\]\.x: unknown key; allowed keys: kind, vehicle, at_s, fraction",
    ),
    ("faults", {"kind": "mass_drop"}, r"faults: expected a list of faults, got a mapping"),
    ("fly", [1], r"^<dict>: fly: expected a mapping with keys mode, rates, actuators, attitude, position, heading, start, "),
    ("fly.rates.tick_hz", 100, r"fly\.rates\.tick_hz: unknown key; did you mean 'tick_rate_hz'"),
    ("fly.rates.tick_rate_hz", 0, r"fly\.rates\.tick_rate_hz: expected a value in \(0, 1000\], "
     r"got 0\.0$"),
    ("fly.actuators.alpha_omega", -3, r"fly\.actuators\.alpha_omega: expected > 0, got -3\.0"),
    ("fly.actuators.alpha_rho", 0, r"fly\.actuators\.alpha_rho: expected > 0, got 0\.0"),
    ("fly.heading", "north", r"fly\.heading: expected 'hold', 'paper' or a compass heading in degrees, got 'north'"),
    ("fly.heading", 400, r"fly\.heading: expected a value in \[-360, 360\], got 400"),
    ("fly.rates.max_yaw_rate_radps", 0, r"fly\.rates\.max_yaw_rate_radps: expected > 0, got 0"),
    ("fly.attitude.tick_rate_hz", 2000, r"fly\.attitude\.tick_rate_hz: expected a value in "),
    ("fly.end_action", "crash",
     r"fly\.end_action: expected one of 'land', 'hold', got string 'crash'"),
    ("fly.start", "maybe", r"fly\.start: expected one of 'auto', 'in_air', 'takeoff'"),
    ("fly.link_timeout_s", 0, r"fly\.link_timeout_s: expected > 0, got 0\.0$"),
    ("fly.link_lost_after_s", 0.05, r"fly\.link_lost_after_s: expected > stale_after_s 0\.1, "
     r"got 0\.05$"),
    ("fly.geofence", {"min_enu_m": [0, 0, 5], "max_enu_m": [1, 1, 5]},
     r"fly\.geofence\.max_enu_m: expected max > min on every axis, got z: min 5\.0 >= max 5\.0"),
    ("fly.geofence", {"min_enu_m": [0, 0, 5]},
     r"fly\.geofence\.max_enu_m: required key is missing"),
    ("fly.log_rate_hz", 30, r"fly\.log_rate_hz: must divide fly\.rates\.tick_rate_hz 100 \(a "
     r"whole number of ticks per sample\), got 30$"),
    ("fly.arm_timeout_s", 0, r"fly\.arm_timeout_s: expected > 0, got 0"),
    ("fly.arm_retry_s", 0.01, r"fly\.arm_retry_s: expected >= 0\.1, got 0\.01"),
    ("fly.mode_timeout_s", -1, r"fly\.mode_timeout_s: expected > 0, got -1"),
    ("fly.takeoff_tolerance_m", 3.0, r"fly\.takeoff_tolerance_m: expected < takeoff_altitude_m "
     r"2\.5, got 3\.0"),
    ("fly.formation_check", {"max_fraction": 0}, r"fly\.formation_check\.max_fraction: expected "
     r"> 0, got 0"),
    ("fly.formation_check", {"after": 3}, r"fly\.formation_check\.after: unknown key; did you "
     r"mean 'after_s'"),
    ("fly.predict", "yes", r"fly\.predict: expected true or false, got string 'yes'"),
    ("fly.velocity_from_position_s", -1, r"fly\.velocity_from_position_s: expected a value in "
     r"\[0, 60\], got -1"),
    ("fly.acceleration_from_velocity_s", float("nan"), r"fly\.acceleration_from_velocity_s: "
     r"expected a finite number, got nan"),
    ("fly.scheduling", "fast", r"fly\.scheduling: expected one of 'auto', 'realtime', 'raised', "
     r"'normal', got string 'fast'"),
    ("fly.mode", "torque", r"fly\.mode: expected one of 'auto', 'rates', 'actuators', 'attitude', "
     r"'position', got string 'torque'"),
    # position mode runs no law: its block has a tick rate and nothing else
    ("fly.position", {"alpha_p": 1.0}, r"fly\.position\.alpha_p: unknown key; allowed keys: "
     r"tick_rate_hz$"),
    ("fly.position.tick_rate_hz", 0, r"fly\.position\.tick_rate_hz: expected a value in "
     r"\(0, 1000\], got 0\.0$"),
    ("fly.position.tick_rate_hz", 30, r"fly\.log_rate_hz: must divide "
     r"fly\.position\.tick_rate_hz 30 \(a whole number of ticks per sample\), got 50$"),
]


def test_fly_section_is_optional_and_defaults_are_documented():
    # GIVEN no fly section THEN the documented defaults
    data = base()
    data.pop("fly", None)
    fly = team_from_dict(data).fly
    assert (fly.rates.tick_rate_hz, fly.actuators.tick_rate_hz) == (100.0, 250.0)
    assert fly.rates.max_rate_radps == 1.0 and fly.actuators.alpha_omega is None
    assert (fly.end_action, fly.abort_action, fly.link_loss_action) == ("land", "land", "hold")
    assert fly.geofence is None and fly.stale_after_s == 0.1 and fly.link_lost_after_s == 0.5
    assert (fly.arm_timeout_s, fly.arm_retry_s, fly.mode_timeout_s) == (60.0, 1.0, 3.0)
    assert fly.takeoff_tolerance_m == 0.3
    fc = fly.formation_check
    assert (fc.after_s, fc.max_error_m, fc.max_fraction) == (10.0, 1.0, 0.5)
    assert fly.link_timeout_s == 3.0  # tolerates a 1 Hz HEARTBEAT-only vehicle
    assert fly.predict is True  # delay compensation on (gcs/control/predict.py)
    assert fly.velocity_from_position_s == 0.2  # gcs/fly/consistent.py
    assert fly.acceleration_from_velocity_s == 0.5  # the same module
    assert fly.scheduling == "auto"  # the best the OS permits (gcs/fly/sched.py)
    assert fly.control_mode == "auto"  # gcs fly picks rates or attitude (gcs/fly/setup.py)
    assert team_from_dict(edit(base(), "fly.mode", "attitude")).fly.control_mode == "attitude"
    assert team_from_dict(edit(base(), "fly.predict", False)).fly.predict is False
    # AND the shipped file flies the criterion's torque gains
    shipped = load_team(SQUARE4).fly
    assert (shipped.actuators.alpha_eps, shipped.actuators.alpha_omega) == (2.0, 2.0)
    assert shipped.actuators.alpha_rho == 0.03 and shipped.rates.alpha_rho is None
    assert shipped.geofence is not None and shipped.mode("rates") is shipped.rates


@pytest.mark.parametrize(("path", "value", "match"), ERRORS, ids=[e[0] for e in ERRORS])
def test_each_problem_raises_one_config_error_naming_the_key_path(path, value, match):
    # GIVEN the valid Scenario I with one thing wrong WHEN validated THEN one precise error
    raises_at(edit(base(), path, value), match)


def test_alpha_p_bound_uses_the_vertical_reference_acceleration():
    # GIVEN v_r,z = cos(t) (varrho = 1) THEN alpha_p must be < (9.81 - 1)/2 = 4.405
    data = edit(
        base(), "reference_velocity.z.cosines", [{"amplitude": -1.0, "period_s": 2 * math.pi}]
    )
    assert team_from_dict(edit(data, "controller.gains.alpha_p", 4.4)).reference_velocity
    raises_at(
        edit(data, "controller.gains.alpha_p", 4.41),
        r"alpha_p: needs .* = \(9\.81 - 1\)/\(2 \* 1\) = 4\.405 .* got 4\.41",
    )


def test_proposition2_is_per_uav_and_skipped_without_any_mass():
    # GIVEN UAV 1 with mhat(0) = 1 and no plant and no bound THEN nothing to check
    data = edit(base(), "vehicles.0.plant", DELETE)
    assert team_from_dict(edit(data, "vehicles.0.estimates.mhat", 0.01)).n == 4
    # GIVEN a bound that is only just met THEN it loads
    data = edit(base(), "vehicles.0.estimates.mass_bound_kg", 1.0)
    assert team_from_dict(data).vehicles[0].mass_bound_kg == 1.0


def test_every_fault_kind_loads_into_its_own_dataclass():
    # GIVEN one fault of each kind the emulator implements
    faults = [
        {"kind": "mass_drop", "vehicle": 1, "at_s": 40.0, "fraction": 0.3},
        {"kind": "link_loss", "vehicle": 2, "at_s": 10.0, "duration_s": 2.5},
        {"kind": "packet_loss", "vehicle": 3, "at_s": 0.0, "probability": 0.1},
        {"kind": "motor_efficiency", "vehicle": 4, "at_s": 60.0, "motor": 3, "efficiency": 0.8},
    ]
    team = team_from_dict(edit(base(), "faults", faults))
    # THEN each keeps its own fields, and describe() says what each does
    assert team.faults == (
        FaultConfig("mass_drop", 1, 40.0, 0.3),
        LinkLossFault("link_loss", 2, 10.0, 2.5),
        PacketLossFault("packet_loss", 3, 0.0, 0.1, 0.0),
        MotorEfficiencyFault("motor_efficiency", 4, 60.0, 3, 0.8),
    )
    text = describe(team)
    assert "link_loss: vehicle 2 link down for 2.5 s at t = 10 s" in text
    assert "packet_loss: vehicle 3 loses 10% of packets, +0 ms latency, from t = 0 s" in text
    assert "motor_efficiency: vehicle 4 motor 3 at 80% efficiency from t = 60 s" in text
    assert team_from_dict(team_to_dict(team)) == team


def test_baseline_law_requires_nominal_masses():
    data = edit(base(), "controller.law", "baseline")
    assert team_from_dict(data).controller.law == "baseline"
    raises_at(
        edit(data, "vehicles.2.nominal_mass_kg", DELETE),
        r"vehicles\[2\]\.nominal_mass_kg: required by the baseline law \(vehicle 3, sysid 3",
    )


def test_top_level_must_be_a_mapping():
    with pytest.raises(ConfigError, match=r"^<dict>: \(top level\): expected a mapping with keys"):
        team_from_dict([1, 2])  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------
# Files: YAML problems carry the file and line.


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "team.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_yaml_syntax_error_names_file_and_line(tmp_path):
    path = write(tmp_path, "name: x\nmission: {duration_s: [1, 2\nvehicles: []\n")
    with pytest.raises(
        ConfigError,
        match=r"team\.yaml: YAML syntax error at line 2, column 23 \(the flow sequence opened "
        r"there is not closed; the parser gave up at line 3\): expected ',' or '\]'",
    ) as e:
        load_team(path)
    assert e.value.line == 2


def break_line(text: str, line: int, old: str, new: str) -> str:
    """`text` with `old` replaced by `new` on 1-based `line` (which must hold it)."""
    lines = text.splitlines(keepends=True)
    assert old in lines[line - 1], lines[line - 1]
    lines[line - 1] = lines[line - 1].replace(old, new, 1)
    return "".join(lines)


@pytest.mark.parametrize(
    ("fault", "old", "new", "match"),
    [
        # an unclosed flow sequence: pyyaml gives up at the next key, 10 lines below (a comment)
        (
            "  edges: [[1, 2]",
            "[4, 1]]",
            "[4, 1]",
            r"square4\.yaml: YAML syntax error at line {line}, column 10 \(the flow sequence "
            r"opened there is not closed; the parser gave up at line (\d+)\): expected ','",
        ),
        # an unclosed flow mapping
        (
            "  rates: {tick_rate_hz",
            "c_p: 2.0}",
            "c_p: 2.0",
            r"square4\.yaml: YAML syntax error at line {line}, column 10 \(the flow mapping "
            r"opened there is not closed; the parser gave up at line (\d+)\)",
        ),
        # bad indentation: pyyaml's context_mark is the enclosing block, the fault its own line
        (
            "  takeoff_altitude_m:",
            "  takeoff",
            "     takeoff",
            r"square4\.yaml: YAML syntax error at line {line}, column 6 \(in the block mapping "
            r"that starts at line (\d+)\): expected <block end>",
        ),
    ],
)
def test_yaml_syntax_error_names_the_faulty_line_not_where_the_parser_gave_up(
    tmp_path, fault, old, new, match
):
    # GIVEN square4.yaml with one line broken
    text = SQUARE4.read_text()
    line = 1 + next(k for k, s in enumerate(text.splitlines()) if s.startswith(fault))
    lines = text.splitlines(keepends=True)
    assert old in lines[line - 1]
    lines[line - 1] = lines[line - 1].replace(old, new, 1)
    broken = tmp_path / "square4.yaml"
    broken.write_text("".join(lines))
    # WHEN loaded THEN the error names the broken line, and where the parser gave up (below
    # it) or the block it is in (above it)
    with pytest.raises(ConfigError, match=match.format(line=line)) as e:
        load_team(broken)
    assert e.value.line == line
    other = int(re.search(match.format(line=line), str(e.value))[1])
    assert other > line if "gave up" in match else other < line


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "- a\n- b\n",
            r"team\.yaml: \(top level\): expected a mapping of sections, got a list of 2 "
            r"items \(line 1\)$",
        ),
        ("", r"\(top level\): expected a mapping of sections, got an empty document"),
        ("42\n", r"\(top level\): expected a mapping of sections, got int 42"),
        (
            "name: a\nmission: {}\nname: b\n",
            r"team\.yaml: invalid YAML at line 3, column 1: duplicate "
            r"key 'name' \(first on line 1\)",
        ),
        ("? [1, 2]\n: x\n", r"invalid YAML at line 1, column 3: a key must be a plain scalar"),
    ],
)
def test_non_mapping_top_level_and_duplicate_keys(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_team(write(tmp_path, text))


def test_value_errors_in_a_file_carry_the_line(tmp_path):
    # GIVEN square4.yaml with UAV 3's true mass made negative
    text = SQUARE4.read_text().replace("      mass_kg: 0.35", "      mass_kg: -1.0")
    line = 1 + text.split("mass_kg: -1.0")[0].count("\n")
    # WHEN loaded THEN file, key path, problem and line
    with pytest.raises(
        ConfigError,
        match=rf"team\.yaml: vehicles\[2\]\.plant\.mass_kg: expected "
        rf"> 0, got -1\.0 \(line {line}\)$",
    ):
        load_team(write(tmp_path, text))


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match=r"nope\.yaml: \(file\): cannot read: .*No such file"):
        load_team(tmp_path / "nope.yaml")


def test_exponent_floats_are_numbers_in_yaml():
    # GIVEN YAML 1.1's trap: 1e4 / 1.0e4 are strings for plain yaml.safe_load
    assert yaml.safe_load("x: 1.0e4") == {"x": "1.0e4"}
    data = team_to_dict(team_from_dict(base()))
    data["controller"]["derivative"] = {"method": "levant"}
    text = yaml.safe_dump(data).replace(
        "method: levant", "method: levant\n    levant_lipschitz: 1e4\n    levant_substep_s: 1.0e-5"
    )
    d = team_from_yaml(text).controller.derivative
    assert (d.levant_lipschitz, d.levant_substep_s) == (1e4, 1e-5)


# ------------------------------------------------------------------------------------------------
# Properties.

junk = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=6,
)


def paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    items = (
        node.items()
        if isinstance(node, dict)
        else enumerate(node)
        if isinstance(node, list)
        else ()
    )
    for key, child in items:
        out += paths(child, (*prefix, key))
    return out


ALL_PATHS = paths(base())[1:]


@settings(max_examples=400, deadline=None)
@given(st.sampled_from(ALL_PATHS), st.sampled_from(["replace", "delete", "add"]), junk)
def test_random_garbage_raises_only_config_error(path, action, value):
    # GIVEN Scenario I with a random value replaced, removed, or a random key added
    data = base()
    parent = data
    for key in path[:-1]:
        parent = parent[key]
    if action == "replace":
        parent[path[-1]] = value
    elif action == "delete":
        del parent[path[-1]]
    elif isinstance(parent[path[-1]], dict):
        parent[path[-1]]["zz_unknown"] = value
    # WHEN validated THEN it loads (and describes) or raises a one-line ConfigError
    try:
        team = team_from_dict(data)
    except ConfigError as exc:
        assert str(exc).startswith("<dict>: ") and "\n" not in str(exc)
    else:
        assert isinstance(describe(team), str)


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=40))
def test_random_yaml_text_raises_only_config_error(text):
    try:
        team_from_yaml(text, "t.yaml")
    except ConfigError as exc:
        assert str(exc).startswith("t.yaml: ") and "\n" not in str(exc)


@st.composite
def valid_teams(draw) -> dict[str, Any]:
    """Random valid teams: any size, ids, graph, gains, initial state, plants present or not."""
    n = draw(st.integers(1, 6))
    ids = draw(st.lists(st.integers(1, 10_000), min_size=n, max_size=n, unique=True))
    sysids = draw(st.lists(st.integers(1, 255), min_size=n, max_size=n, unique=True))
    coord = st.floats(-500.0, 500.0, allow_nan=False)
    vec = st.tuples(coord, coord, coord)
    offsets = draw(st.lists(vec, min_size=n, max_size=n, unique=True))
    starts = draw(st.lists(vec, min_size=n, max_size=n, unique=True))
    pos = lambda lo, hi: st.floats(lo, hi, allow_nan=False)  # noqa: E731
    gains = {
        k: draw(pos(0.01, 50.0))
        for k in ("c_p", "alpha_m", "alpha_eps", "alpha_omega", "c_eps", "alpha_rho", "k_eps")
    }
    gains["sigma_a"] = sigma = draw(pos(0.2, 5.0))
    cosines = st.lists(
        st.fixed_dictionaries(
            {"amplitude": pos(-1.0, 1.0), "period_s": pos(5.0, 100.0)},
            optional={"phase_rad": pos(-4.0, 4.0)},
        ),
        max_size=2,
    )
    ref = {a: {"constant": draw(pos(-2.0, 2.0)), "cosines": draw(cosines)} for a in "xyz"}
    varrho = sum(abs(c["amplitude"]) * 2 * math.pi / c["period_s"] for c in ref["z"]["cosines"])
    gains["alpha_p"] = (GRAVITY_MPS2 - varrho) / (2 * sigma) * draw(pos(0.01, 0.99))
    ctrl_hz = draw(st.sampled_from([50.0, 100.0, 250.0, 500.0, 1000.0]))
    law = draw(st.sampled_from(["adaptive", "baseline"]))
    vehicles = []
    for k in range(n):
        m = draw(pos(0.05, 20.0))
        plant = draw(st.booleans())
        bound = m * draw(pos(1.0, 2.0)) if draw(st.booleans()) or not plant else None
        v0 = draw(st.tuples(pos(-3, 3), pos(-3, 3), pos(-3, 3)))
        phi0 = 2 + sum(sigma * math.tanh(x / sigma) for x in v0) / (3 * sigma)
        mbar = bound if bound is not None else m
        vehicle = {
            "id": ids[k],
            "sysid": sysids[k],
            "offset_enu_m": list(offsets[k]),
            "initial": {"position_enu_m": list(starts[k]), "velocity_enu_mps": list(v0)},
            "estimates": {
                "mhat": (phi0 - 1) * mbar / gains["alpha_m"] * draw(pos(1.0, 3.0)),
                "inertia_kgm2": [draw(pos(1e-3, 1.0)) for _ in range(3)],
            },
            "airframe": {
                "arm_length_m": draw(pos(0.05, 1.0)),
                "anti_torque_m": 0.016,
                "rotor_thrust_max_n": THRUST_MARGIN * m * GRAVITY_MPS2 / 4 * draw(pos(1.01, 5.0)),
            },
        }
        if plant:
            vehicle["plant"] = {"mass_kg": m, "inertia_kgm2": [draw(pos(1e-3, 1.0))] * 3}
        if bound is not None:
            vehicle["estimates"]["mass_bound_kg"] = bound
        if law == "baseline" or draw(st.booleans()):
            vehicle["nominal_mass_kg"] = m
        vehicles.append(vehicle)
    edges = [[ids[k], ids[draw(st.integers(0, k - 1))]] for k in range(1, n)]  # spanning tree
    for a, b in draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)))):
        if a != b and {ids[a], ids[b]} not in [set(e[:2]) for e in edges]:
            edges.append([ids[a], ids[b], draw(pos(0.1, 10.0))])
    duration = draw(pos(1.0, 600.0))
    return {
        "name": draw(st.text(min_size=1, max_size=10).filter(str.strip)),
        "mission": {"duration_s": duration},
        "controller": {
            "law": law,
            "mode": draw(st.sampled_from(["rates", "actuators"])),
            "gains": gains,
            "derivative": {
                "method": draw(st.sampled_from(["model", "levant"])),
                "levant_lipschitz": draw(pos(1.0, 1e6)),
                "levant_substep_s": 1 / ctrl_hz * draw(pos(0.01, 1.0)),
            },
        },
        "reference_velocity": ref,
        "graph": {"edges": edges},
        "sim": {"plant_rate_hz": ctrl_hz * draw(st.integers(1, 4)), "controller_rate_hz": ctrl_hz},
        "vehicles": vehicles,
        "faults": [
            {
                "vehicle": draw(st.sampled_from(ids)),
                "at_s": draw(pos(0.0, duration)),
                **draw(
                    st.sampled_from(
                        [
                            {"kind": "mass_drop", "fraction": 0.3},
                            {"kind": "link_loss", "duration_s": 2.0},
                            {"kind": "packet_loss", "probability": 0.2, "latency_ms": 30.0},
                            {"kind": "motor_efficiency", "motor": 2, "efficiency": 0.7},
                        ]
                    )
                ),
            }
            for _ in range(draw(st.integers(0, 3)))
        ],
    }


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(valid_teams(), st.floats(0.1, 10.0))
def test_valid_teams_load_round_trip_and_rescale(data, scale):
    # GIVEN a random valid team WHEN loaded THEN its arrays are consistent
    team = team_from_dict(data, "gen")
    a = team.adjacency()
    assert a.shape == (team.n, team.n) and np.array_equal(a, a.T)
    np.testing.assert_allclose(team.laplacian().sum(axis=1), 0.0, atol=1e-9)
    assert team.offsets_enu_m().shape == team.initial_positions_enu_m().shape == (team.n, 3)
    assert all(team.index_of(vid) == k for k, vid in enumerate(team.ids()))
    # AND writing it out and reading it back (as data and as YAML) gives the same team
    assert team_from_dict(team_to_dict(team), "gen") == team
    assert team_from_yaml(team_to_yaml(team), "gen") == team
    # AND scaling every mass, mass estimate and thrust by the same factor keeps it valid
    scaled = copy.deepcopy(data)
    for v in scaled["vehicles"]:
        for section, key in (
            ("estimates", "mhat"),
            ("estimates", "mass_bound_kg"),
            ("plant", "mass_kg"),
            ("airframe", "rotor_thrust_max_n"),
        ):
            if key in v.get(section, {}):
                v[section][key] *= scale
        if "nominal_mass_kg" in v:
            v["nominal_mass_kg"] *= scale
    rescaled = team_from_dict(scaled, "gen")
    assert isinstance(rescaled, TeamConfig)
    if team.has_plants():
        np.testing.assert_allclose(rescaled.true_masses_kg(), scale * team.true_masses_kg())
    assert isinstance(describe(team), str)


def test_a_name_that_reads_as_a_number_round_trips_through_yaml():
    # GIVEN a team named like a YAML 1.2 float ("0E0": the loader reads 1e4 as a number)
    data = {**team_to_dict(load_team(CONFIGS / "square4.yaml")), "name": "0E0"}
    team = team_from_dict(data, "gen")
    # WHEN written with team_to_yaml THEN the name is quoted and reads back as the same string
    text = team_to_yaml(team)
    assert "name: '0E0'" in text
    assert team_from_yaml(text, "gen") == team


@pytest.mark.parametrize("heading", ["hold", "paper", 90.0, -45.0])
def test_fly_heading_and_the_attitude_mode_load_and_round_trip(heading):
    data = edit(edit(base(), "fly.heading", heading), "fly.attitude.tick_rate_hz", 50)
    team = team_from_dict(data)
    assert team.fly.heading == heading and team.fly.mode("attitude").tick_rate_hz == 50.0
    assert team_from_yaml(team_to_yaml(team), "<rt>").fly == team.fly
    chosen = team_from_dict(edit(data, "fly.mode", "attitude"))
    assert "\nfly:\n  mode: attitude\n" in team_to_yaml(chosen)  # the key the file uses
    assert team_from_yaml(team_to_yaml(chosen), "<rt>").fly.control_mode == "attitude"
    # the defaults: hold the heading, yaw rate limited on its own to 0.5 rad/s
    default = team_from_dict(base()).fly
    assert default.heading == "hold" and default.rates.max_yaw_rate_radps == 0.5


def test_fly_position_block_defaults_loads_and_round_trips():
    # GIVEN no fly.position THEN position mode ticks at 50 Hz (the log rate's multiple)
    default = team_from_dict(base()).fly
    assert default.position.tick_rate_hz == 50.0 and default.tick_rate_hz("position") == 50.0
    assert default.tick_rate_hz("rates") == default.rates.tick_rate_hz
    # WHEN the file chooses position mode and a rate THEN both are read and written back
    data = edit(edit(base(), "fly.mode", "position"), "fly.position.tick_rate_hz", 100)
    team = team_from_dict(data)
    assert (team.fly.control_mode, team.fly.position.tick_rate_hz) == ("position", 100.0)
    text = team_to_yaml(team)
    assert "\n  position:\n    tick_rate_hz: 100.0\n" in text
    assert team_from_yaml(text, "<rt>").fly == team.fly
    # AND gcs check says what the mode does
    assert "position 100 Hz (the baseline, only by fly.mode or --mode: " in describe(team)


def test_a_bad_position_block_in_a_file_names_its_line(tmp_path):
    # GIVEN square4.yaml with a position block whose rate is negative
    text = SQUARE4.read_text().replace(
        "  attitude: {tick_rate_hz: 100, alpha_p: 1.5, c_p: 0.6}\n",
        "  attitude: {tick_rate_hz: 100, alpha_p: 1.5, c_p: 0.6}\n  position: {tick_rate_hz: -5}\n")
    line = 1 + text.split("position: {tick_rate_hz: -5}")[0].count("\n")
    # WHEN loaded THEN file, key path, problem and line
    with pytest.raises(ConfigError, match=rf"team\.yaml: fly\.position\.tick_rate_hz: expected a "
                       rf"value in \(0, 1000\], got -5\.0 \(line {line}\)$"):
        load_team(write(tmp_path, text))


def test_mhat_from_hover_needs_a_mass_and_round_trips():
    data = edit(base(), "vehicles.0.estimates.mhat", "from_hover")
    team = team_from_dict(data)
    v = team.vehicles[0]
    # the stand-in (what gcs sim flies) is the plant's hover: phi(0) m / alpha_m
    assert v.estimates.from_hover and v.estimates.mhat == pytest.approx(
        2.0 * v.plant.mass_kg / team.controller.gains.alpha_m)
    assert team_from_yaml(team_to_yaml(team), "<rt>").vehicles == team.vehicles
    # without a plant it needs mass_bound_kg; a word other than from_hover is refused
    del data["vehicles"][0]["plant"]
    raises_at(data, r"vehicles\[0\]\.estimates\.mhat: from_hover needs estimates\.mass_bound_kg")
    raises_at(edit(base(), "vehicles.0.estimates.mhat", "hover"),
              r"vehicles\[0\]\.estimates\.mhat: expected a number > 0 or 'from_hover', got 'hover'")


def test_the_frame_section_defaults_to_own_origins_at_px4_sitl_home_and_checks_its_values():
    team = team_from_dict(base())
    assert team.frame.vehicles == "own" and team.frame.origin == (47.397742, 8.545594, 488.0)
    data = edit(edit(base(), "frame.origin", [52.0, 4.5, 3.0]), "frame.vehicles", "shared")
    frame = team_from_dict(data).frame
    assert frame.origin == (52.0, 4.5, 3.0) and frame.vehicles == "shared"
    assert team_from_yaml(team_to_yaml(team_from_dict(data)), "<rt>").frame == frame
    raises_at(edit(base(), "frame.origin", [95.0, 4.5, 3.0]),
              r"frame\.origin: \[lat_deg, lon_deg, alt_m\]: latitude 95\.0 outside \[-90, 90\]")
    raises_at(edit(base(), "frame.vehicles", "mine"), r"frame\.vehicles: expected one of")


@settings(max_examples=50, deadline=None)
@given(st.tuples(*(st.floats(-20.0, 20.0),) * 3), st.floats(0.0, 1.0), st.floats(0.5, 2.0))
def test_proposition2s_phi0_is_the_laws_phi(velocity, horizontal, sigma_a):
    # GIVEN a vehicle starting at any velocity, any estimator weight and saturation bound
    from gcs.config.schema import initial_phi
    from gcs.control.position import phi

    data = base()
    data["controller"]["gains"].update(phi_horizontal=horizontal, sigma_a=sigma_a, alpha_p=1.0)
    data["vehicles"][0]["initial"]["velocity_enu_mps"] = list(velocity)
    data["vehicles"][0]["estimates"]["mhat"] = 10.0  # Proposition 2 holds at any phi(0) < 3
    team = team_from_dict(data)
    # THEN the phi(0) the config checks Proposition 2 with is the one the law computes
    law = phi(np.array([velocity]), sigma_a, horizontal)[0]
    assert initial_phi(team.vehicles[0], team.controller.gains) == pytest.approx(law, rel=1e-12)
