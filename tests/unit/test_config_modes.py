"""Modes and actions as enums: the reader gives members, every file and message the plain strings."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from gcs.config import (
    AUTO_MODE,
    FLY_ACTIONS,
    FLY_MODES,
    MODES,
    ConfigError,
    ControlMode,
    FlyAction,
    load_team,
    team_from_dict,
    team_from_yaml,
    team_to_dict,
    team_to_yaml,
)
from gcs.config.modes import as_strings
from gcs.flightlog_csv import load_timeseries, save_timeseries
from gcs.fly.records import flight_log_builder
from gcs.fly.setup import FlightSetupError, FlyOptions, prepare
from gcs.report import build_report, write_report

SQUARE4 = Path(__file__).resolve().parents[2] / "configs" / "square4.yaml"
LINK_STATS = {"setpoints_sent": 10, "telemetry_received": 10, "telemetry_lost_pct": 0.0,
              "telemetry_age_p50_ms": 1.0, "telemetry_age_p99_ms": 2.0}
TICK_STATS = {"rate_hz": 100, "late_pct": 0.0, "lateness_p99_ms": 0.5}


def with_fly(**fly: object) -> dict:
    data = team_to_dict(load_team(SQUARE4))
    data["fly"] = {**data["fly"], **fly}
    return data


def test_the_members_are_the_team_file_strings():
    # GIVEN the enums THEN each member is its string: equal, same hash, formatted and joined as it
    assert MODES == ("rates", "actuators", "attitude")
    assert FLY_MODES == ("auto", "rates", "actuators", "attitude", "position")
    assert FLY_ACTIONS == ("land", "hold")
    assert ControlMode("attitude") is ControlMode.ATTITUDE and FlyAction("hold") is FlyAction.HOLD
    assert {"rates": 1}[ControlMode.RATES] == 1
    assert f"{ControlMode.POSITION} mode" == "position mode" and str(FlyAction.LAND) == "land"
    assert ", ".join(MODES) == "rates, actuators, attitude"
    # AND as_strings gives the plain strings a message lists (a member's repr names its class)
    assert repr(as_strings(FLY_ACTIONS)) == "('land', 'hold')"
    assert all(type(s) is str for s in as_strings(FLY_MODES))


@pytest.mark.parametrize("mode", ["rates", "actuators", "attitude", "position"])
def test_the_reader_gives_control_mode_and_fly_action_members(mode):
    # GIVEN a team file whose fly: section names a mode and the stop actions
    data = with_fly(mode=mode, end_action="hold", abort_action="land", link_loss_action="hold")
    # WHEN it is read
    team = team_from_dict(data)
    # THEN every mode and action is an enum member, not a bare string
    assert team.fly.control_mode is ControlMode(mode)
    assert type(team.controller.mode) is ControlMode
    assert (team.fly.end_action, team.fly.abort_action, team.fly.link_loss_action) == (
        FlyAction.HOLD, FlyAction.LAND, FlyAction.HOLD)
    assert all(type(a) is FlyAction for a in (team.fly.end_action, team.fly.abort_action,
                                              team.fly.link_loss_action))


def test_fly_mode_auto_stays_the_auto_string_and_the_defaults_are_members():
    team = load_team(SQUARE4)
    assert team.fly.control_mode == AUTO_MODE == "auto"
    default = team_from_dict({k: v for k, v in team_to_dict(team).items() if k != "fly"})
    assert default.fly.end_action is FlyAction.LAND and default.fly.link_loss_action is FlyAction.HOLD


def test_a_config_dump_writes_the_plain_strings():
    # GIVEN a team read with modes and actions as members
    team = team_from_dict(with_fly(mode="attitude", end_action="hold"))
    # WHEN it is written as plain data, YAML and JSON
    data = team_to_dict(team)
    text = team_to_yaml(team)
    # THEN each mode and action is a plain str, and the texts hold the bare words
    for value in (data["controller"]["mode"], data["fly"]["mode"], data["fly"]["end_action"],
                  data["fly"]["abort_action"], data["fly"]["link_loss_action"]):
        assert type(value) is str
    assert "\nfly:\n  mode: attitude\n" in text and "  end_action: hold\n" in text
    assert "!!python" not in text and "ControlMode" not in text
    assert yaml.safe_dump(data) == yaml.safe_dump(json.loads(json.dumps(data)))
    assert '"mode": "attitude"' in json.dumps(data)
    # AND it reads back to the same team
    assert team_from_yaml(text, team.source_path) == team


def test_a_flight_log_and_report_write_the_mode_as_its_string(tmp_path):
    # GIVEN gcs fly's set-up for attitude mode: its mode is a member
    setup = prepare(load_team(SQUARE4), FlyOptions(out_dir=tmp_path, mode="attitude"))
    assert setup.mode is ControlMode.ATTITUDE and setup.plan.end_action is FlyAction.LAND
    # AND a flight log of two samples
    builder = flight_log_builder(setup, np.full((4, 3), 0.08), inertia_estimated=False)
    for t in (0.0, 0.1):
        builder.append(t_s=t, position_enu_m=np.zeros((4, 3)) + t,
                       velocity_enu_mps=np.zeros((4, 3)), reference_velocity_enu_mps=np.zeros(3))
    log = builder.build()
    # WHEN the time series and the report are written
    series = save_timeseries(log, tmp_path / "timeseries.csv")
    report = write_report(tmp_path / "report.json",
                          build_report(log, link={v: LINK_STATS for v in (1, 2, 3, 4)},
                                       tick=TICK_STATS))
    # THEN both hold the bare string, and read back as a plain str
    assert '"mode": "attitude"' in series.read_text() and '"mode": "attitude"' in report.read_text()
    back = json.loads(report.read_text())["extra"]["mode"]
    assert back == "attitude" and type(back) is str
    assert type(load_timeseries(series).extra["mode"]) is str


def test_choices_are_listed_as_plain_strings_in_messages(tmp_path):
    # GIVEN a bad fly.end_action in the file, and a bad --mode and --end-action on the command line
    with pytest.raises(ConfigError, match=r"fly\.end_action: expected one of 'land', 'hold', got "
                                          r"string 'crash'"):
        team_from_dict(with_fly(end_action="crash"))
    team = load_team(SQUARE4)
    with pytest.raises(FlightSetupError, match=r"^mode 'torque': expected one of \('auto', "
                                               r"'rates', 'actuators', 'attitude', 'position'\)$"):
        prepare(team, FlyOptions(out_dir=tmp_path, mode="torque"))
    with pytest.raises(FlightSetupError,
                       match=r"^end action 'crash': expected one of \('land', 'hold'\)$"):
        prepare(team, FlyOptions(out_dir=tmp_path, end_action="crash"))
