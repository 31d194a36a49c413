"""Layer boundaries: the pure layers do no I/O and read no clock; the emulator never imports gcs,
gcs never imports the emulator, flightkit imports neither; importing a package does no work."""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
IMPURE = {"asyncio", "socket", "time", "pymavlink", "mavsdk", "select", "threading", "subprocess"}
OWN = ("flightkit", "gcs", "vehicle_emulator")

#: Every module that does no I/O and reads no clock (time is an argument), as a glob of files
#: and what they are. Not listed, though their imports would pass: vehicle_emulator/config/team.py
#: (`load_team` reads the file), flightkit/sched.py (changes the process's scheduling). The link's
#: other sans-IO parts import pymavlink (codec.py, statustext.py) or a default clock (codec.py,
#: telemetry.py), or the UDP layer's address type (address.py).
PURE = {
    "gcs/control/*.py": "the paper's law, the formation slots, the law's stability over a link",
    "gcs/mission/*.py": "the flight sequence as a state machine, safety checks",
    "gcs/frames.py": "NED/FRD <-> ENU/FLU conversions",
    "gcs/geodesy.py": "one team frame from the vehicles' origins",
    "gcs/link/clock.py": "a vehicle's clock and true sample times",
    "gcs/link/enums.py": "MAVLink enumerations and mode encodings",
    "gcs/link/liveness.py": "link and HEARTBEAT staleness, every time an argument",
    "gcs/link/samples.py": "typed samples of the messages read above the link",
    "gcs/agent/wire.py": "the agents' state sample as bytes",
    "gcs/agent/control.py": "the agents' and supervisor's control messages as JSON",
    "gcs/agent/clocks.py": "a peer's clock offset from four timestamps",
    "gcs/agent/table.py": "the latest sample per sender, per-edge figures, every time an argument",
    "flightkit/physics.py": "the rigid-body model both programs simulate",
    "flightkit/fleet_protocol.py": "the emulator fleet's ready line",
    "vehicle_emulator/physics/plant.py": "the fleet's physics step: inner loops, mixer, motors, RK4",
    "vehicle_emulator/physics/inner.py": "PX4-like inner loops",
    "vehicle_emulator/physics/onboard.py": "the calibrated personalities' onboard estimate and rate loops",
    "vehicle_emulator/physics/sensors.py": "IMU noise and filters",
    "vehicle_emulator/config/personality.py": "the personalities' parameters",
    "vehicle_emulator/physics/frames.py": "the emulator's frame conversions",
    "vehicle_emulator/physics/geodesy.py": "WGS-84 <-> team-frame ENU",
    "vehicle_emulator/mavlink/gnss.py": "GPS_RAW_INT rows",
    "vehicle_emulator/autopilots/px4/logic.py": "the PX4-like state machine",
    "vehicle_emulator/autopilots/ardupilot/logic.py": "the ArduCopter-like state machine",
    "vehicle_emulator/autopilots/ardupilot/boot.py": "ArduCopter's boot as recorded",
    "vehicle_emulator/autopilots/ardupilot/flight.py": "how the ardupilot personality flies in GUIDED",
    "vehicle_emulator/autopilots/ardupilot/modes.py": "ArduCopter's flight modes",
    "vehicle_emulator/autopilots/ardupilot/targets.py": "attitude and position targets as ArduCopter reads them",
    "vehicle_emulator/autopilots/setpoints.py": "setpoint checks (type_mask rules)",
    "vehicle_emulator/config/params.py": "the parameter table",
    "vehicle_emulator/config/faults.py": "fault clock and schedule, link impairments",
    "vehicle_emulator/mavlink/fleet_status.py": "the fleet's status arrays",
    "vehicle_emulator/mavlink/payloads.py": "telemetry payload builders",
    "vehicle_emulator/calibration/metrics.py": "the recordings' figures",
}
#: Modules that, like the law, reach nothing of gcs outside gcs.control.
LAW_LAYER = ("gcs/control/*.py", "gcs/frames.py", "gcs/geodesy.py", "flightkit/physics.py",
             "flightkit/fleet_protocol.py")


def expand(globs) -> list[Path]:
    return sorted({p for pattern in globs for p in ROOT.glob(pattern)})


def imported_roots(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    roots: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            roots.add(node.module.split(".")[0])
            if node.module.startswith("gcs.") and not node.module.startswith("gcs.control"):
                roots.add(node.module)
    return roots


def module_file(root: Path, name: str) -> Path | None:
    """The file of module `name` under `root` (a package's __init__.py), None if none."""
    base = root.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def own_imports(root: Path, path: Path, own: tuple[str, ...]) -> set[Path]:
    """The files of the repository's modules that `path` imports: `from a.b import c` is a.b's
    file, or c's where c is a module. A package's __init__ counts where it is imported from,
    not as the parent of a module imported."""
    found: set[Path] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{a.name}" if module_file(root, f"{node.module}.{a.name}")
                     else node.module for a in node.names]
        else:
            continue
        found |= {f for n in names if n.split(".")[0] in own and (f := module_file(root, n))}
    return found


def impure_reach(root: Path, path: Path, own: tuple[str, ...] = OWN) -> dict[str, list[str]]:
    """Per file reachable from `path` through the repository's own imports (`path` included),
    the IMPURE modules it imports; only files that import any."""
    seen, todo, found = {path}, [path], {}
    while todo:
        current = todo.pop()
        bad = imported_roots(current) & IMPURE
        if bad:
            found[str(current.relative_to(root))] = sorted(bad)
        for dep in own_imports(root, current, own) - seen:
            seen.add(dep)
            todo.append(dep)
    return found


@pytest.mark.parametrize("pattern", [*PURE, *LAW_LAYER])
def test_every_listed_pure_module_exists(pattern):
    assert list(ROOT.glob(pattern)), f"{pattern} matches no file"


@pytest.mark.parametrize("path", expand(PURE), ids=lambda p: str(p.relative_to(ROOT)))
def test_pure_layers_do_no_io(path):
    # GIVEN a module listed pure THEN neither it nor any module of ours that it imports (directly
    # or through others) imports I/O or a clock
    assert impure_reach(ROOT, path) == {}


@pytest.mark.parametrize("path", expand(LAW_LAYER), ids=lambda p: str(p.relative_to(ROOT)))
def test_the_law_layer_reaches_nothing_outside_gcs_control(path):
    found = imported_roots(path)
    assert not {m for m in found if m.startswith("gcs.")}, (
        f"{path.name} reaches outside gcs.control"
    )


def test_the_fly_set_up_policy_opens_nothing_and_imports_none_of_the_flight():
    # GIVEN gcs fly's set-up policy, decided before any link is opened (gcs/fly/setup.py)
    found = imported_roots(ROOT / "gcs" / "fly" / "setup.py")
    # THEN it imports no I/O or clock, no link, and none of the modules that fly
    flying = ("gcs.link", "gcs.fly.flight", "gcs.fly.tick", "gcs.fly.commander",
              "gcs.fly.setpoints", "gcs.fly.records")
    assert not found & IMPURE, sorted(found & IMPURE)
    assert not [m for m in found if m.startswith(flying)]


def importers(package: str, forbidden: set[str]) -> dict[str, list[str]]:
    """The modules of ``package`` that import any of ``forbidden`` (top-level names)."""
    found = {str(p.relative_to(ROOT)): sorted(imported_roots(p) & forbidden)
             for p in (ROOT / package).rglob("*.py")}
    return {path: names for path, names in found.items() if names}


@pytest.mark.parametrize(("package", "forbidden"), [
    # the emulator is an independent peer of the ground station
    ("vehicle_emulator", {"gcs"}),
    # gcs starts the emulator only as a program (`python -m vehicle_emulator`)
    ("gcs", {"vehicle_emulator"}),
    # what both programs share imports neither
    ("flightkit", {"gcs", "vehicle_emulator"}),
    # the test harness (tests/harness.py) and the benchmarks are not part of the product
    ("vehicle_emulator", {"tests", "benchmarks"}),
    ("gcs", {"tests", "benchmarks"}),
    ("flightkit", {"tests", "benchmarks"}),
])
def test_no_package_imports_a_program_it_must_not(package, forbidden):
    assert importers(package, forbidden) == {}


_IMPORT_ALL = """
import importlib, json, os, pkgutil, sys
before = dict(os.environ)
import flightkit, gcs, gcs.control, gcs.link, gcs.mission, vehicle_emulator
names = []
for package in (flightkit, gcs.control, gcs.link, gcs.mission, vehicle_emulator):
    for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
        importlib.import_module(info.name)
        names.append(info.name)
after = dict(os.environ)
changed = {k: [before.get(k), after.get(k)] for k in before.keys() | after.keys()
           if before.get(k) != after.get(k)}
print(json.dumps({"modules": names, "environ_changed": changed}))
"""


def test_importing_the_packages_sets_no_environment_variable_and_writes_no_file(tmp_path):
    # GIVEN a fresh home and cache directory, and no NUMBA_CACHE_DIR
    home, cache = tmp_path / "home", tmp_path / "cache"
    home.mkdir()
    cache.mkdir()
    unset = ("NUMBA_CACHE_DIR", "XDG_CONFIG_HOME", "MPLCONFIGDIR")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    env.update(HOME=str(home), XDG_CACHE_HOME=str(cache),
               PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]))
    # WHEN a process imports flightkit, gcs, vehicle_emulator and every module of flightkit,
    # gcs.control, gcs.link, gcs.mission and vehicle_emulator
    out = subprocess.run([sys.executable, "-c", _IMPORT_ALL], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=240, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    # THEN it imported them all, left its environment as it was and wrote nothing under the
    # home or the cache directory
    assert {"flightkit.jitcache", "gcs.control.law", "gcs.link.proxy", "gcs.mission.machine",
            "vehicle_emulator.fleet.cli", "vehicle_emulator.physics.plant"} <= set(result["modules"])
    assert result["environ_changed"] == {}
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == ["cache", "home"]


#: The emulator's rooms, lowest first: a room imports only the rooms before it (and the
#: package's top-level modules import any room; nothing imports them).
EMULATOR_ROOMS = ("config", "physics", "mavlink", "autopilots", "fleet", "calibration")


def upward_imports(package: Path, rooms: tuple[str, ...]) -> dict[str, list[str]]:
    """The modules of ``package`` (a folder of rooms) that import a room after their own or a
    top-level module of the package."""
    name = package.name
    found: dict[str, list[str]] = {}
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package).parts
        if len(parts) == 1:
            continue  # a top-level module: may import any room
        own = rooms.index(parts[0])
        bad = set()
        for node in ast.walk(ast.parse(path.read_text())):
            modules = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                       [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
            for module in modules:
                head = module.split(".")
                if head[0] != name or len(head) < 2:
                    continue
                if head[1] not in rooms or rooms.index(head[1]) > own:
                    bad.add(module)
        if bad:
            found[str(path.relative_to(package.parent))] = sorted(bad)
    return found


def test_each_emulator_room_imports_only_the_rooms_below_it():
    # GIVEN vehicle_emulator's rooms THEN every room is one of them and none imports upward
    rooms = {p.name for p in (ROOT / "vehicle_emulator").iterdir()
             if p.is_dir() and (p / "__init__.py").exists()}
    assert rooms == set(EMULATOR_ROOMS)
    assert upward_imports(ROOT / "vehicle_emulator", EMULATOR_ROOMS) == {}


#: gcs's layers, top first: a module imports only layers below its own (a package's modules may
#: import each other). cli composes the commands; precompile compiles through fly and sim; the
#: sweep, which flies sim's runs in batches, and the agents, which fly `gcs fly`'s flight over
#: their bus; the two programs' packages; what they share (the flight sequence, records,
#: figures); the link and the log; the team file and the metrics; the law; the frames.
GCS_LAYERS = (
    ("cli",),
    ("precompile",),
    ("sweep", "agent"),
    ("fly", "sim"),
    ("mission", "plots", "report", "flightlog_builder", "flightlog_csv"),
    ("flightlog", "link"),
    ("metrics", "config"),
    ("control",),
    ("frames", "geodesy"),
)


def gcs_unit(module: str, names: list[str]) -> list[str]:
    """The gcs units (a package or a top-level module) that an import of ``module`` reaches."""
    parts = module.split(".")
    if parts[0] != "gcs":
        return []
    return [parts[1]] if len(parts) > 1 else names


def gcs_upward_imports(package: Path, layers: tuple[tuple[str, ...], ...]) -> dict[str, list[str]]:
    """The modules of ``package`` that import a unit of their own layer (other than their own
    unit) or of a layer above it."""
    rank = {unit: k for k, layer in enumerate(layers) for unit in layer}
    found: dict[str, list[str]] = {}
    for path in sorted(package.rglob("*.py")):
        own = path.relative_to(package).parts[0].removesuffix(".py")
        if own == "__init__":
            continue
        bad = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                reached = [u for a in node.names for u in gcs_unit(a.name, [])]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                reached = gcs_unit(node.module, [a.name for a in node.names])
            else:
                continue
            bad |= {u for u in reached if u != own and rank.get(u, -1) <= rank[own]}
        if bad:
            found[str(path.relative_to(package.parent))] = sorted(bad)
    return found


def test_gcs_imports_only_downward():
    # GIVEN gcs's layers THEN every unit is in one and no module imports across or upward
    units = {p.name.removesuffix(".py") for p in (ROOT / "gcs").iterdir()
             if (p.suffix == ".py" or (p / "__init__.py").exists()) and p.name != "__init__.py"}
    assert units == {u for layer in GCS_LAYERS for u in layer}
    assert gcs_upward_imports(ROOT / "gcs", GCS_LAYERS) == {}


def test_the_gcs_layer_check_can_fail(tmp_path):
    # GIVEN a status module in mission that imports fly, and a fly module that imports the CLI
    (tmp_path / "gcs" / "mission").mkdir(parents=True)
    (tmp_path / "gcs" / "fly").mkdir()
    (tmp_path / "gcs" / "mission" / "status.py").write_text("from gcs.fly import stats\n")
    (tmp_path / "gcs" / "fly" / "command.py").write_text(
        "def f():\n    from gcs import cli\n    import gcs.sim.runner\n")
    # THEN both are named, each with what it reaches
    assert gcs_upward_imports(tmp_path / "gcs", GCS_LAYERS) == {
        "gcs/fly/command.py": ["cli", "sim"], "gcs/mission/status.py": ["fly"]}


def flightkit_users(package: Path) -> set[tuple[str, str]]:
    """(flightkit module, file relative to ``package``) for every import of flightkit in it."""
    found = set()
    for path in package.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                parts = node.module.split(".")
                if parts[0] != "flightkit":
                    continue
                names = [parts[1]] if len(parts) > 1 else [a.name for a in node.names]
                found |= {(name, str(path.relative_to(package))) for name in names}
    return found


def documented_imports(text: str) -> tuple[dict[str, set[tuple[str, str]]], tuple[str, ...]]:
    """From docs/architecture.md's package diagram: per program, (flightkit module, file) as
    drawn (left column gcs, right column vehicle_emulator), and the rooms in drawn order
    (each imports only those to its right)."""
    block = text[text.index("   gcs ---"):text.index("   vehicle_emulator's rooms")].splitlines()
    split = block[0].index("<")
    drawn: dict[str, set[tuple[str, str]]] = {"gcs": set(), "vehicle_emulator": set()}
    for line in block[1:]:
        for m in re.finditer(r"(\w+) \(([^)]*)\)", line):
            program = "gcs" if m.start() < split else "vehicle_emulator"
            drawn[program] |= {(m.group(1), f.strip()) for f in m.group(2).split(",")}
    chain = re.search(r"^\s+(\w+/(?: -> \w+/)+)\s*$", text, re.MULTILINE)
    assert chain is not None, "no rooms line in the diagram"
    rooms = tuple(r.strip().rstrip("/") for r in chain.group(1).split("->"))
    return drawn, rooms[::-1]


def test_the_architecture_diagram_matches_the_imports():
    drawn, rooms = documented_imports((ROOT / "docs" / "architecture.md").read_text())
    for program in ("gcs", "vehicle_emulator"):
        assert drawn[program] == flightkit_users(ROOT / program), program
    assert rooms == EMULATOR_ROOMS


def test_the_diagram_check_can_fail():
    # GIVEN the diagram with one importer moved and two rooms swapped THEN both are caught
    text = (ROOT / "docs" / "architecture.md").read_text()
    drawn, rooms = documented_imports(text.replace("physics (config/team.py)",
                                                   "physics (fleet/team.py)")
                                      .replace("fleet/ -> autopilots/", "autopilots/ -> fleet/"))
    assert ("physics", "config/team.py") not in drawn["vehicle_emulator"]
    assert drawn["vehicle_emulator"] != flightkit_users(ROOT / "vehicle_emulator")
    assert rooms != EMULATOR_ROOMS


def test_the_room_check_can_fail(tmp_path):
    # GIVEN a physics module that imports the fleet, and a config module that imports a top-level one
    for room in ("config", "physics", "fleet"):
        (tmp_path / "emu" / room).mkdir(parents=True)
    (tmp_path / "emu" / "physics" / "plant.py").write_text("from emu.fleet.runner import x\n")
    (tmp_path / "emu" / "config" / "team.py").write_text("import emu.tools\n")
    (tmp_path / "emu" / "fleet" / "runner.py").write_text("from emu.physics import plant\n")
    # THEN both are named, the downward import is not
    assert upward_imports(tmp_path / "emu", ("config", "physics", "fleet")) == {
        "emu/physics/plant.py": ["emu.fleet.runner"], "emu/config/team.py": ["emu.tools"]}


MAX_MODULE_LINES = 600
MAX_CLASS_LINES = 300


def oversized(paths: list[Path]) -> list[str]:
    """Modules over MAX_MODULE_LINES lines and classes over MAX_CLASS_LINES, with their size."""
    found = []
    for path in paths:
        text = path.read_text()
        if text.count("\n") > MAX_MODULE_LINES:
            found.append(f"{path.name}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                size = node.end_lineno - node.lineno + 1
                if size > MAX_CLASS_LINES:
                    found.append(f"{path.name}: class {node.name} {size} lines")
    return found


def message_reads(path: Path) -> list[str]:
    """Where a module reads a pymavlink message: ``x.msg`` or ``proxy.latest("TYPE")`` (the
    link's untyped view), as "file:line"."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Attribute) and node.attr == "msg" or (
                isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "latest" and node.args
                and isinstance(node.args[0], ast.Constant)):
            found.append(f"{path.name}:{node.lineno}")
    return found


def test_pymavlink_messages_stop_at_the_link():
    # the layers above gcs.link read typed samples (gcs.link.samples), never a pymavlink object
    above = [p for p in (ROOT / "gcs").rglob("*.py") if "link" not in p.relative_to(ROOT).parts]
    assert [hit for p in above for hit in message_reads(p)] == []
    assert not importers("gcs", {"pymavlink"}).keys() - {
        str(p.relative_to(ROOT)) for p in (ROOT / "gcs" / "link").glob("*.py")}


def test_the_message_read_check_can_fail(tmp_path):
    bad = tmp_path / "reader.py"
    bad.write_text("def f(p):\n    return p.latest('HEARTBEAT').msg.base_mode\n")
    assert message_reads(bad) == ["reader.py:2", "reader.py:2"]


def test_no_module_of_the_programs_is_over_600_lines_nor_a_class_over_300():
    paths = [p for package in OWN for p in (ROOT / package).rglob("*.py")]
    assert oversized(paths) == []


def test_the_size_check_can_fail(tmp_path):
    # GIVEN a class of 301 lines in a module of 601 THEN both are named
    body = "class Big:\n" + "    x = 1\n" * 300 + "\n" * 300
    (tmp_path / "big.py").write_text(body)
    assert oversized([tmp_path / "big.py"]) == ["big.py: 601 lines", "big.py: class Big 301 lines"]


def test_the_boundary_check_can_fail(tmp_path):
    # GIVEN a module that reads the clock THEN the import walk sees it
    bad = tmp_path / "bad.py"
    bad.write_text("import numpy as np\nfrom time import monotonic\n")
    assert "time" in imported_roots(bad)


def test_the_pure_check_follows_imports_through_other_modules(tmp_path):
    # GIVEN a module whose own imports are clean, but one of its modules imports another that
    # reads the clock (through a package's __init__ it imports names from)
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "law.py").write_text("import numpy as np\nfrom pkg.sub import helper\n")
    (pkg / "sub" / "__init__.py").write_text("from pkg.sub.clocked import now\n")
    (pkg / "sub" / "helper.py").write_text("from pkg import sub as _sub\n")
    (pkg / "sub" / "clocked.py").write_text("import time\nnow = time.monotonic\n")
    (pkg / "sub" / "plain.py").write_text("x = 1\n")
    (pkg / "clean.py").write_text("from pkg.sub.plain import x\n")
    # THEN the walk names the module that imports the clock
    assert impure_reach(tmp_path, pkg / "law.py", ("pkg",)) == {"pkg/sub/clocked.py": ["time"]}
    # AND a package's __init__ is not followed as the parent of a module imported from it
    assert impure_reach(tmp_path, pkg / "clean.py", ("pkg",)) == {}
