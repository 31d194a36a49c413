"""Vehicles booted at different places fly one formation: each emulated vehicle's
LOCAL_POSITION_NED is relative to its own EKF origin (up to 50 m from the team frame's origin),
and `gcs fly` ties every local frame to the team frame through the GPS_GLOBAL_ORIGIN it reads
(docs/gcs.md, "One team frame"). The same Scenario I figures as with one shared origin."""

from __future__ import annotations

import re

import pytest
import yaml
from test_fly_emulator import Gcs, check_scenario_one, emulators, team_file

from vehicle_emulator.testing import free_udp_port_block

#: each vehicle's EKF origin in the team frame [m]: up to 50 m apart, one 3 m below the others
ORIGINS_ENU_M = ([25.0, 0.0, 0.0], [-25.0, 0.0, 0.0], [0.0, 40.0, -3.0], [10.0, -10.0, 0.0])


def test_vehicles_with_origins_50_m_apart_fly_the_scenario_one_formation(tmp_path):
    base = free_udp_port_block(4)
    team = team_file(tmp_path, base, duration_s=32.0)
    data = yaml.safe_load(team.read_text())
    data["emulator"]["origin"] = "own"
    for v, origin in zip(data["vehicles"], ORIGINS_ENU_M, strict=True):
        v["emulator"] = {"origin_enu_m": origin}
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    with emulators(team, base, tmp_path):
        gcs = Gcs(team, tmp_path / "run", "--mode", "rates", "--end-action", "hold")
        code, out = gcs.finish(180)
    log = gcs.log_path.read_text()
    # THEN each vehicle was tied through its own origin, printed with its team-frame offset
    # (GPS_GLOBAL_ORIGIN's 1e-7 deg is about 1 cm)
    for k, origin in enumerate(ORIGINS_ENU_M, start=1):
        line = re.search(rf"vehicle {k} \(sysid {k}\): origin .* \(GPS_GLOBAL_ORIGIN\): at "
                         r"\(([-\d.]+), ([-\d.]+), ([-\d.]+)\) m in the team frame", log)
        assert line is not None, log[-3000:]
        assert [float(g) for g in line.groups()] == pytest.approx(origin, abs=0.02)
    # AND the formation is Scenario I's, as with a shared origin
    check_scenario_one(gcs.report(), code, out)
