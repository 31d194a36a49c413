"""Layer boundaries: the pure layers do no I/O and read no clock; the emulator never imports gcs."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
IMPURE = {"asyncio", "socket", "time", "pymavlink", "mavsdk", "select", "threading", "subprocess"}
PURE_MODULES = sorted((ROOT / "gcs" / "control").glob("*.py")) + [
    ROOT / "flightkit" / "physics.py",
    ROOT / "flightkit" / "fleet_protocol.py",
    ROOT / "gcs" / "frames.py",
    ROOT / "gcs" / "geodesy.py",
]


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


@pytest.mark.parametrize("path", PURE_MODULES, ids=lambda p: str(p.relative_to(ROOT)))
def test_pure_layers_do_no_io(path):
    found = imported_roots(path)
    assert not found & IMPURE, f"{path.name} imports {sorted(found & IMPURE)}"
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
    # gcs starts the emulator only as a program (`python -m vehicle_emulator.cli`)
    ("gcs", {"vehicle_emulator"}),
    # what both programs share imports neither
    ("flightkit", {"gcs", "vehicle_emulator"}),
])
def test_no_package_imports_a_program_it_must_not(package, forbidden):
    assert importers(package, forbidden) == {}


def test_the_boundary_check_can_fail(tmp_path):
    # GIVEN a module that reads the clock THEN the import walk sees it
    bad = tmp_path / "bad.py"
    bad.write_text("import numpy as np\nfrom time import monotonic\n")
    assert "time" in imported_roots(bad)
