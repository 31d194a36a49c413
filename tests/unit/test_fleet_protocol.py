"""The emulator fleet's ready line: what vehicle-emu prints is what gcs fly reads back."""

from __future__ import annotations

from flightkit.fleet_protocol import READY_PREFIX, ready_line, ready_personalities


def test_the_ready_line_names_each_vehicles_personality_and_reads_back():
    # GIVEN a mixed fleet of three vehicles, one ArduPilot vehicle on an ephemeral port
    line = ready_line([1, 2, 7], [(1, "px4"), (2, "ardupilot"), (3, "nominal")],
                      "ephemeral ports (ArduPilot SITL udpclient): sysid 2 sends from x to y")
    # THEN it starts with the prefix a parent waits for, and names every vehicle's personality
    assert line.startswith(READY_PREFIX + " 3 vehicles (sysid 1, 2, 7) personalities ")
    assert ready_personalities(line) == {1: "px4", 2: "ardupilot", 3: "nominal"}


def test_a_ready_line_without_personalities_reads_as_none():
    # GIVEN one vehicle's line as an older emulator printed it THEN no personality is made up
    assert ready_personalities(f"{READY_PREFIX} 1 vehicle (sysid 1)") == {}
    assert ready_line([1], [(1, "px4")]) == f"{READY_PREFIX} 1 vehicle (sysid 1) personalities 1:px4"
