"""`gcs fly`: parse overrides, optionally start the emulator fleet, fly, print the summary."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from gcs.app import Flight, FlightSetupError, FlyOptions, fly
from gcs.config import TeamConfig, load_team
from gcs.report import summary_table
from gcs.status import StatusView

EXIT_SETUP = 2


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fly", help="fly the team in formation over MAVLink and write records")
    p.add_argument("--team", required=True, type=Path, help="team config (YAML)")
    p.add_argument("--mode", choices=("rates", "actuators"), default=None,
                   help="attitude level sent to the vehicles (default: the file's)")
    p.add_argument("--controller", choices=("adaptive", "baseline"), default=None,
                   help="law (default: the file's)")
    p.add_argument("--tick-rate-hz", type=float, default=None,
                   help="control tick (default: fly.<mode>.tick_rate_hz)")
    p.add_argument("--duration-s", type=float, default=None, help="formation phase length")
    p.add_argument("--end-action", choices=("land", "hold"), default=None,
                   help="after the formation phase (default: fly.end_action)")
    p.add_argument("--out", type=Path, default=None,
                   help="output directory (default runs/<name>-fly)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--status", choices=("auto", "rich", "plain", "off"), default="auto",
                   help="live status: rich table on a terminal, one plain line otherwise")
    p.add_argument("--emulators", action="store_true",
                   help="start `vehicle-emu --fleet --team FILE` for the flight and stop it after")
    p.add_argument("--log-level", default="WARNING", help="Python logging level (stderr)")


@contextlib.contextmanager
def emulator_fleet(team_path: Path, enabled: bool) -> Iterator[None]:
    """Run the bundled emulator fleet for the team while flying (SIGTERM and wait on exit)."""
    if not enabled:
        yield
        return
    proc = subprocess.Popen(
        [sys.executable, "-m", "vehicle_emulator.cli", "--fleet", "--team", str(team_path),
         "--log-level", "WARNING"],
        stdin=subprocess.DEVNULL,
    )
    try:
        yield
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)


def run_fly(args: argparse.Namespace) -> int:
    """Entry of `gcs fly`; returns the exit status (0 flown, 1 aborted, 2 setup, 130 operator)."""
    logging.basicConfig(level=getattr(logging, str(args.log_level).upper(), logging.WARNING),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    team: TeamConfig = load_team(args.team)
    out = args.out if args.out is not None else Path("runs") / f"{team.name}-fly"
    options = FlyOptions(
        out_dir=out, mode=args.mode, law=args.controller, tick_rate_hz=args.tick_rate_hz,
        duration_s=args.duration_s, end_action=args.end_action, figures=not args.no_figures,
        status=args.status,
    )

    def status(flight: Flight) -> StatusView:
        return StatusView(flight, args.status)

    try:
        with emulator_fleet(args.team, args.emulators):
            result = asyncio.run(fly(team, options, status))
    except FlightSetupError as exc:
        print(f"gcs fly: {exc}", file=sys.stderr)
        return EXIT_SETUP
    if result.log is not None:
        print(summary_table(result.log))
        tick = result.log.extra["tick"]
        print(f"  tick {tick['rate_hz']:g} Hz: {tick['ticks']} ticks, late {tick['late_pct']:.2f}%"
              f", lateness p99 {tick['lateness_p99_ms']:.2f} ms; records in {result.out_dir}/")
    code, reason = result.outcome.exit_code, result.outcome.reason
    print(f"gcs fly: {'done' if code == 0 else 'ABORTED'}: {reason} (exit {code})",
          file=sys.stderr if code else sys.stdout)
    return code
