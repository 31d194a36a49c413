"""Team-file reading (tolerant, errors name the key path) and the parameter table."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from vehicle_emulator.config.params import (
    ParamError,
    ParamStore,
    ParamType,
    decode_value,
    encode_value,
)
from vehicle_emulator.config.team import TeamFileError, default_vehicle, load_team, parse_team

ROOT = Path(__file__).resolve().parents[2]


def test_square4_team_file():
    team = load_team(ROOT / "configs/square4.yaml")
    assert [v.sysid for v in team.vehicles] == [1, 2, 3, 4]
    v1 = team.vehicle(1)
    assert v1.mass_kg == 0.85 and v1.inertia_kgm2 == (0.04856, 0.04856, 0.08801)
    assert v1.rotor_thrust_max_n == 6.0 and v1.position_enu_m == (4.0, 4.0, 9.0)
    assert v1.starts_in_air and team.physics_rate_hz == 1000.0


def test_massdrop_team_file_has_the_scenario_ii_fault():
    team = load_team(ROOT / "configs/square4_massdrop.yaml")
    drops = [f for f in team.faults if f.kind == "mass_drop"]
    assert [(f.vehicle_id, f.at_s, f.fraction) for f in drops] == [(1, 40.0, 0.3)]


@pytest.mark.parametrize(
    "raw, message",
    [
        (
            {"vehicles": [{"id": 1, "plant": {"mass_kg": -1.0}}]},
            "vehicles[0].plant.mass_kg: expected > 0, got -1.0",
        ),
        (
            {"vehicles": [{"id": 1, "initial": {"position_enu_m": [1, 2]}}]},
            "vehicles[0].initial.position_enu_m: expected a list of 3 numbers",
        ),
        ({"vehicles": [{"id": 1}, {"id": 2, "sysid": 1}]}, "duplicate sysid"),
        ({"vehicles": [{"id": 1}], "faults": [{"kind": "meteor", "vehicle": 1}]}, "faults[0].kind"),
        (
            {"vehicles": [{"id": 1}], "faults": [{"kind": "mass_drop", "vehicle": 3}]},
            "faults[0].vehicle: no vehicle with id 3",
        ),
        (
            {"vehicles": [{"id": 1, "link": {"remote_port": "nowhere"}}]},
            "vehicles[0].link.remote_port",
        ),
        (
            {"vehicles": [{"id": 1, "initial": {"attitude_rpy_rad": [0.1, 0, 0]}}]},
            "vehicles[0].initial.attitude_rpy_rad: the emulator starts level",
        ),
    ],
)
def test_bad_values_name_the_key_path(raw, message):
    with pytest.raises(TeamFileError, match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_team(raw)


def test_defaults_and_tolerance():
    team = parse_team(
        {
            "vehicles": [
                {"id": 3, "extra": "ignored", "link": {"remote_port": 15000, "local_port": 15100}}
            ]
        }
    )
    v = team.vehicle(3)
    assert v == default_vehicle(3).__class__(**{**_fields(default_vehicle(3)), "link": v.link})
    assert v.link.bind == ("127.0.0.1", 15000) and v.link.remote == ("127.0.0.1", 15100)
    assert not v.starts_in_air


def _fields(v):
    return {name: getattr(v, name) for name in v.__slots__}


def test_params_set_refuse_and_int_encoding():
    p = ParamStore()
    assert p.set("COM_OF_LOSS_T", 2.0) == 2.0
    with pytest.raises(ParamError, match="unknown parameter 'NOPE'"):
        p.set("NOPE", 1.0)
    with pytest.raises(ParamError, match=r"outside \[0, 60\]"):
        p.set("COM_OF_LOSS_T", 100.0)
    with pytest.raises(ParamError, match="read-only"):
        p.set("MAV_SYS_ID", 3)
    with pytest.raises(ParamError, match="not finite"):
        p.set("COM_OF_LOSS_T", math.nan)
    wire = encode_value(ParamType.INT32, 4)
    assert struct.pack("<f", wire) == struct.pack("<i", 4)  # PX4: bytewise
    assert decode_value(ParamType.INT32, wire, 6) == 4.0
    assert decode_value(ParamType.INT32, 4.0, 6) == 4.0  # pymavlink-style plain float
    assert decode_value(ParamType.REAL32, 0.25, 9) == 0.25
