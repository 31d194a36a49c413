"""Live status formatting of `gcs fly`: the plain line and the rich table."""

from __future__ import annotations

import io
import math

from rich.console import Console

from gcs.fly.status import StatusSnapshot, VehicleLine, plain_line, render_table


def _snapshot(lost: bool = False) -> StatusSnapshot:
    vehicles = (
        VehicleLine(1, 1, "OFFBOARD", True, "alive", 340.0, 7.0, 12.345, 0.8512, 8.3, True),
        VehicleLine(2, 2, "AUTO_LOITER", True, "lost" if lost else "alive", math.nan, math.nan,
                    9.8, 1.2, 11.8, False),
    )
    return StatusSnapshot(phase="formation", t_s=12.34, duration_s=60.0, formation_error_m=0.0123,
                          late_pct=0.2, vehicles=vehicles, note="vehicle 2 (sysid 2): link lost")


def test_plain_line_names_phase_time_error_and_every_vehicle():
    # GIVEN a snapshot WHEN formatted for a non-TTY stream
    line = plain_line(_snapshot())
    # THEN it is one line with the phase, formation time and error, and per-vehicle fields
    assert "\n" not in line
    assert line.startswith("[formation] t=12.3/60s form_err=0.0123m late=0.2%")
    assert "1:OFFBOARD*/a/7ms/z=12.3/m=0.851" in line
    # AND unknown values print as '-' instead of nan
    assert "2:AUTO_LOITER*/a/-ms/z=9.8/m=1.200" in line and "nan" not in line


def test_rich_table_shows_every_vehicle_and_the_note():
    # GIVEN a snapshot with a lost link WHEN rendered as a rich table
    console = Console(file=io.StringIO(), record=True, width=160)
    console.print(render_table(_snapshot(lost=True)))
    text = console.export_text()
    # THEN the header, each vehicle's row and the latest note are visible
    assert "gcs fly: formation" in text and "formation error 0.0123 m" in text
    assert "OFFBOARD" in text and "AUTO_LOITER" in text and "lost" in text
    assert "0.851" in text and "12.35" in text
    assert "link lost" in text


def test_while_connecting_the_status_shows_who_was_heard_instead_of_the_table_fields():
    # GIVEN the CONNECT phase with the machine's progress text
    text = ("connecting 12/60 s: heard 1/2 (1); waiting for vehicle 2 (sysid 2) on "
            "udp 127.0.0.1:14541")
    snap = StatusSnapshot(phase="connect", t_s=None, duration_s=60.0, formation_error_m=math.nan,
                          late_pct=0.0, vehicles=_snapshot().vehicles, note="", connecting=text)
    # THEN the plain line is that progress, and the table's caption carries it whole
    assert plain_line(snap) == f"[connect] {text}"
    console = Console(file=io.StringIO(), record=True, width=200)
    console.print(render_table(snap))
    assert "waiting for vehicle 2 (sysid 2) on udp 127.0.0.1:14541" in console.export_text()
