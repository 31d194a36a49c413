"""`gcs fly` over links with delay: true ages from the vehicles' own stamps, a delay step handled
by the delay rule (docs/gcs.md, "Link delay"), round trips in the report."""

from __future__ import annotations

import pytest
import yaml
from test_fly_emulator import Gcs, emulators, team_file

from vehicle_emulator.testing import free_udp_port_block

pytestmark = [pytest.mark.integration, pytest.mark.timeout(300)]


def test_a_half_second_delay_step_on_one_vehicle_stops_the_formation_naming_it(tmp_path):
    # GIVEN Scenario I in formation, vehicle 2's link both ways delayed by 0.5 s from t = 8 s
    # for 2 s (a radio link's queue filling up); link_lost_after_s 1 s as for a radio link, so
    # the 0.5 s without packets at the step's onset is not a lost link
    base = free_udp_port_block(4)
    step = [{"kind": "packet_loss", "vehicle": 2, "at_s": 8.0, "duration_s": 2.0,
             "latency_ms": 500.0}]
    team = team_file(tmp_path, base, duration_s=30.0, faults=step)
    data = yaml.safe_load(team.read_text())
    data["fly"]["link_lost_after_s"] = 1.0
    team.write_text(yaml.safe_dump(data, sort_keys=False))
    with emulators(team, base, tmp_path):
        gcs = Gcs(team, tmp_path / "run", "--mode", "rates")
        code, out = gcs.finish(180)
    log = gcs.log_path.read_text()
    # THEN the delay rule stops the formation, naming the vehicle and the late data; every
    # vehicle, the delayed one included, is landed (fly.abort_action)
    assert code == 1, log[-3000:]
    assert "vehicle 2 (sysid 2): link delay: its position/attitude arrive 0.5" in log
    assert "after they were taken (limit 0.3 s, fly.max_data_age_s)" in log
    assert "link lost" not in log
    report = gcs.report()
    assert report["extra"]["outcome"]["reason"].startswith("vehicle 2 (sysid 2): link delay")
    t_end = report["t_s"][-1]
    assert 6.5 <= t_end <= 9.5  # stopped within the step's first second (fault clock: OFFBOARD)
    # AND the report shows the true ages: vehicle 2's data was up to half a second old, the
    # others' a few milliseconds, while their receive ages stayed alike
    link = report["link"]
    assert link["2"]["telemetry_age_max_ms"] >= 300.0
    for vid in ("1", "3", "4"):
        assert link[vid]["telemetry_age_max_ms"] < 60.0, link[vid]
        assert link[vid]["round_trip"]["n"] >= 10 and link[vid]["round_trip"]["p50_ms"] < 10.0
        assert link[vid]["clock"]["synced"] and link[vid]["clock"]["restarts"] == 0
    # the step's round trips (1 s: 0.5 s each way) are in vehicle 2's record
    assert link["2"]["round_trip"]["max_ms"] >= 900.0
