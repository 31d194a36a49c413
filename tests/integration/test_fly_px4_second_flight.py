"""`gcs fly` from the ground twice in a row against the same px4 fleet (issue 28, item 2's second
flight): after an OFFBOARD flight and NAV_LAND, PX4 sits disarmed in OFFBOARD and sends no
ATTITUDE_TARGET (docs/emulator.md, "After a landing"); the second flight's preflight must leave
that mode before it waits for the stream `initial_mass: from_hover` needs.

The real `gcs` CLI against one real `vehicle-emu --fleet` process of the px4 personality over
127.0.0.1 UDP (the set-up and helpers of test_fly_confirmed.py). Short formations: what is tested
is the sequence, not the figures.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from test_fly_confirmed import commands_sent, fly_once, px4_team
from test_fly_emulator import Gcs, emulators

pytestmark = [pytest.mark.integration, pytest.mark.timeout(400)]


def test_px4_from_the_ground_twice_leaves_offboard_before_waiting_for_attitude_target(
        tmp_path: Path) -> None:
    # GIVEN Scenario I's team on the ground, px4 personality, every mass from the hover
    # (ATTITUDE_TARGET required in preflight), a 12 s formation; fly.arm_timeout_s 30 s (ample
    # on the emulator) so that a preflight that waits in vain ends sooner
    team = px4_team(tmp_path, duration_s=12.0, z_shift=-5.0, fly={"arm_timeout_s": 30.0})
    assert yaml.safe_load(team.read_text())["fly"]["initial_mass"] == "from_hover"
    first = Gcs(team, tmp_path / "first", "--mode", "rates")
    first.wait_for("INFO gcs.app: rates mode with", 120)
    with emulators(team, 0, tmp_path):
        code1, out1 = first.finish(200)
        log1 = first.log_path.read_text()
        # THEN the first flight flies and lands every vehicle: exit 0
        assert code1 == 0, log1[-3000:]
        assert "gcs fly: done: formation complete (exit 0)" in out1
        # WHEN flown again against the same vehicles (landed from OFFBOARD, disarmed)
        code2, out2, log2 = fly_once(team, tmp_path / "second")
        # THEN no stream shortfall stops it (what real PX4 got: "vehicle 1 (sysid 1):
        # ATTITUDE_TARGET at 0.0 Hz, need >= 5 Hz (asked 10)", then "not ready within ... s")
        assert "ATTITUDE_TARGET at 0.0 Hz" not in log2, log2[-3000:]
        # AND its preflight finds each disarmed in OFFBOARD without ATTITUDE_TARGET, and
        # commands Hold before it judges the streams
        for k in range(1, 5):
            assert (f"vehicle {k} (sysid {k}): disarmed in OFFBOARD: PX4 sends no "
                    "ATTITUDE_TARGET there: commanding AUTO_LOITER first") in log2, log2[-3000:]
        # AND it arms, flies and lands: exit 0 again
        assert code2 == 0, log2[-3000:]
        assert "gcs fly: done: formation complete (exit 0)" in out2
        # AND Hold was the first command, once, then the arming and the takeoff
        for k in range(1, 5):
            sent = commands_sent(tmp_path / "second" / "flight.tlog", k)
            assert sent[:3] == [(176, 4.0, 3.0), (400, 0.0, 0.0), (22, 0.0, 0.0)], sent
