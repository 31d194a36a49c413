"""Each team-file key is declared once, by its dataclass field (gcs/config/declare.py): what the
reader allows, requires, checks and writes back all derive from that declaration."""

from __future__ import annotations

import dataclasses
import re
import typing
from pathlib import Path

import pytest

from gcs.config import ConfigError, load_team, team_from_dict, team_to_dict
from gcs.config.declare import _strip_none, section_keys, yaml_name
from gcs.config.fault_schema import (
    FaultConfig,
    LinkLossFault,
    MotorEfficiencyFault,
    PacketLossFault,
)
from gcs.config.fly_schema import FlyConfig, GoToStartConfig
from gcs.config.schema import TeamConfig

ROOT = Path(__file__).resolve().parents[2]
FAULTS = (FaultConfig, LinkLossFault, MotorEfficiencyFault, PacketLossFault)


def _sections() -> list[type]:
    """Every dataclass the team file is read into, from TeamConfig down."""
    seen: list[type] = []
    todo = [TeamConfig, *FAULTS]
    while todo:
        cls = todo.pop()
        if cls in seen:
            continue
        seen.append(cls)
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            hint = _strip_none(hints[f.name])
            if typing.get_origin(hint) is tuple:
                hint = typing.get_args(hint)[0]
            if dataclasses.is_dataclass(hint):
                todo.append(hint)
    return seen


SECTIONS = _sections()


@pytest.mark.parametrize("cls", SECTIONS, ids=[c.__name__ for c in SECTIONS])
def test_every_field_of_every_section_is_a_declared_key(cls):
    # GIVEN a section's dataclass THEN each field was made with key(): its bounds, choices and
    # name are declared where the field is, not in a reader
    undeclared = [f.name for f in dataclasses.fields(cls) if "bounds" not in f.metadata]
    assert not undeclared, f"{cls.__name__}: fields without key(...): {undeclared}"


@pytest.mark.parametrize("cls", SECTIONS, ids=[c.__name__ for c in SECTIONS])
def test_every_declared_key_is_documented(cls):
    # GIVEN the declared keys THEN docs/configuration.md names each one
    doc = (ROOT / "docs" / "configuration.md").read_text(encoding="utf-8")
    required, optional = section_keys(cls)
    missing = [k for k in required + optional if not re.search(rf"\b{k}\b", doc)]
    assert not missing, f"{cls.__name__}: keys not in docs/configuration.md: {missing}"


def test_a_declared_bound_is_the_one_the_reader_enforces():
    # GIVEN fly.go_to_start.cruise_speed_mps, declared key(2.0, gt=0.0, le=20.0)
    cruise = GoToStartConfig.__dataclass_fields__["cruise_speed_mps"]
    assert cruise.metadata["bounds"] == {"gt": 0.0, "le": 20.0}
    data = team_to_dict(load_team(ROOT / "configs" / "square4.yaml"))
    # WHEN the file asks for more than the upper bound THEN the reader refuses it by that bound
    data.setdefault("fly", {})["go_to_start"] = {"cruise_speed_mps": 20.5}
    with pytest.raises(ConfigError, match=r"fly\.go_to_start\.cruise_speed_mps: expected .*20"):
        team_from_dict(data)
    # AND at the bound it reads, and writes back under the same name
    data["fly"]["go_to_start"] = {"cruise_speed_mps": 20.0}
    team = team_from_dict(data)
    assert team.fly.go_to_start.cruise_speed_mps == 20.0
    assert team_to_dict(team)["fly"]["go_to_start"]["cruise_speed_mps"] == 20.0


def test_a_key_declared_under_another_name_is_read_and_written_under_it():
    # GIVEN FlyConfig.control_mode, declared with the YAML name `mode`
    assert yaml_name(FlyConfig.__dataclass_fields__["control_mode"]) == "mode"
    team = load_team(ROOT / "configs" / "square4_px4sih.yaml")
    # THEN the written team has `mode` and no `control_mode`, and reads back equal
    fly = team_to_dict(team)["fly"]
    assert "mode" in fly and "control_mode" not in fly
    assert team_from_dict(team_to_dict(team), team.source_path) == team
