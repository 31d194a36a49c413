"""`gcs fly`: parse overrides, optionally start the emulator fleet, fly, print the summary."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

from flightkit.fleet_protocol import READY_PREFIX, ready_personalities
from gcs.config import TeamConfig, load_team
from gcs.config.modes import FLY_ACTIONS, FLY_MODES, as_strings
from gcs.fly.flight import Flight
from gcs.fly.sched import SchedulingError, apply_scheduling
from gcs.fly.setup import FlightSetupError, FlyOptions, prepare
from gcs.fly.status import StatusView
from gcs.fly.warmup import compile_law
from gcs.mission.plan import EXIT_ABORTED, EXIT_INTERRUPTED, EXIT_OK
from gcs.report import summary_table

logger = logging.getLogger(__name__)

EXIT_SETUP = 2


FLY_DESCRIPTION = """\
Fly the team of a team file in formation over MAVLink, then land it:
  connect    wait for every vehicle to be heard (up to fly.connect_timeout_s)
  preflight  link, streams, EKF origin, tilt, geofence and mode checks
  arm        arm and take off the vehicles on the ground (fly.start)
  go to      fly each vehicle to its start position (fly.go_to_start)
  offboard   stream setpoints, then switch every vehicle to its offboard mode
             (PX4 OFFBOARD, ArduPilot GUIDED_NOGPS; in position mode GUIDED)
  formation  fly the paper's law for mission.duration_s (position mode: each
             vehicle's formation slot as a position setpoint, no law)
  land       land every vehicle, or hold (fly.end_action)
Ctrl-C or the abort key (q or a) stops the flight with fly.abort_action (land
by default). The records (report.json, timeseries.csv, flight.tlog, figures)
are written to --out.
Defaults "the file's" are the team file's keys (docs/configuration.md)."""


def fly_epilog() -> str:
    """`gcs fly --help`'s closing text: the exit statuses (from their constants) and examples."""
    return f"""\
exit status:
  {EXIT_OK:<3}  flown: the formation phase ran to its end and every vehicle landed
       (or holds, --end-action hold)
  {EXIT_ABORTED:<3}  aborted: a safety rule or a failed check stopped the flight; the
       vehicles got fly.abort_action; the reason is printed and in report.json
  {EXIT_SETUP:<3}  configuration or setup error: nothing was commanded (a bad team file,
       a GCS port in use, an emulator fleet that did not start, scheduling refused)
  {EXIT_INTERRUPTED:<3}  operator abort (Ctrl-C, SIGTERM, the abort key), after the vehicles
       are down

examples:
  gcs fly --team configs/square4.yaml --emulators
  gcs fly --team configs/square4.yaml --mode rates --end-action hold
  gcs fly --team configs/square4.yaml --mode position --emulators
  gcs fly --team configs/square4_massdrop.yaml --controller baseline --out runs/drop

docs/gcs.md describes the sequence, the modes and the safety rules."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fly", help="fly the team in formation over MAVLink and write records",
                       description=FLY_DESCRIPTION, epilog=fly_epilog(),
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--team", required=True, type=Path, metavar="FILE", help="team config (YAML)")
    p.add_argument("--mode", choices=as_strings(FLY_MODES), default=None,
                   help="setpoints sent to the vehicles: thrust + body rates, thrust + torque, "
                        "thrust + attitude, each vehicle's formation slot as a position "
                        "setpoint (position: no law, the autopilot's loops), or auto: rates, or "
                        "attitude where the link's delay needs it (default: the file's fly.mode, "
                        "auto)")
    p.add_argument("--controller", choices=("adaptive", "baseline"), default=None,
                   help="law (default: the file's controller.law; not with --mode position)")
    p.add_argument("--tick-rate-hz", type=float, default=None,
                   help="control tick (default: the file's fly.<mode>.tick_rate_hz)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="formation phase length (default: the file's mission.duration_s)")
    p.add_argument("--end-action", choices=as_strings(FLY_ACTIONS), default=None,
                   help="after the formation phase (default: the file's fly.end_action, land)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="output directory (default: runs/<name>-fly)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--status", choices=("auto", "rich", "plain", "off"), default="auto",
                   help="live status: rich table on a terminal, one plain line otherwise "
                        "(default: auto)")
    p.add_argument("--emulators", action="store_true",
                   help="start `vehicle-emu --fleet --team FILE` for the flight and stop it after")
    p.add_argument("--agents", action="store_true",
                   help="no law here: start one `gcs agent` per vehicle (each holds its own "
                        "vehicle's link and runs its share of the law over the neighbour bus, "
                        "the team file's network: section) and supervise them (docs/agents.md)")
    p.add_argument("--agents-per-process", type=int, default=1, metavar="K",
                   help="with --agents: K vehicles per agent process (default: 1)")
    p.add_argument("--agents-running", action="store_true",
                   help="with --agents: start none, supervise the agents already running")
    p.add_argument("--connect-timeout-s", type=float, default=None,
                   help="wait this long for every vehicle to be heard (default: the file's "
                        "fly.connect_timeout_s, 60 s)")
    p.add_argument("--log-level", default="WARNING",
                   help="Python logging level on stderr (default: WARNING)")


class EmulatorFleetError(RuntimeError):
    """The emulator fleet that `--emulators` started did not become ready; one line."""


class EmulatorFleet:
    """`vehicle-emu --fleet --team FILE` run for one flight (`--emulators`).

    The fleet reports ready on its stdout (`vehicle-emu: ready: ...`) once its physics is
    compiled and its links are open; `wait_ready` waits for that line, not a fixed time, and
    fails at once, with its exit status, if the process dies first. A fleet that exits on its
    own later is reported on stderr as soon as it happens (the flight's link checks then see
    its vehicles fall silent). Its stderr (the compile notice, warnings) passes through.
    """

    def __init__(self, team_path: Path, stream: TextIO | None = None) -> None:
        self.team_path = team_path
        self.stream = stream if stream is not None else sys.stderr
        self.proc: subprocess.Popen[str] | None = None
        self.ready_line = ""
        self._ready = threading.Event()
        self._stopping = False

    def start(self) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "vehicle_emulator", "--fleet", "--team",
             str(self.team_path), "--log-level", "WARNING"],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True, bufsize=1,
        )
        threading.Thread(target=self._read, name="emulator fleet stdout", daemon=True).start()
        threading.Thread(target=self._watch, name="emulator fleet exit", daemon=True).start()

    def _read(self) -> None:
        assert self.proc is not None and self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith(READY_PREFIX) and not self._ready.is_set():
                self.ready_line = line.strip()
                self._ready.set()
            else:
                print(line.rstrip(), file=self.stream, flush=True)

    def _watch(self) -> None:
        assert self.proc is not None
        code = self.proc.wait()
        if self._ready.is_set() and not self._stopping:
            print(f"gcs fly: the emulator fleet (pid {self.proc.pid}) exited with status {code} "
                  "during the flight; its vehicles fall silent", file=self.stream, flush=True)

    def wait_ready(self, timeout_s: float, poll_s: float = 0.1,
                   report_every_s: float = 5.0) -> float:
        """Block until the fleet reported ready; returns the seconds waited here."""
        assert self.proc is not None
        t0 = time.monotonic()
        next_report = t0 + report_every_s
        while not self._ready.wait(poll_s):
            now = time.monotonic()
            code = self.proc.poll()
            if code is not None and not self._ready.is_set():
                raise EmulatorFleetError(
                    f"the emulator fleet (vehicle-emu --fleet --team {self.team_path}) exited "
                    f"with status {code} before it was ready; its messages are above")
            if now - t0 > timeout_s:
                raise EmulatorFleetError(
                    f"the emulator fleet (pid {self.proc.pid}) did not report ready within "
                    f"{timeout_s:g} s")
            if now >= next_report:
                print(f"gcs fly: waiting for the emulator fleet to report ready "
                      f"({now - t0:.0f} s)", file=self.stream, flush=True)
                next_report = now + report_every_s
        return time.monotonic() - t0

    def stop(self) -> None:
        """SIGTERM, then wait (kill after 10 s)."""
        if self.proc is None:
            return
        self._stopping = True
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(timeout=5)


def emulated_personalities(ready: str) -> dict[int, str]:
    """Per vehicle id, 'vehicle-emu <personality>', as the fleet that `--emulators` started
    names them in its ready line."""
    return {vid: f"vehicle-emu {name}" for vid, name in ready_personalities(ready).items()}


@contextlib.contextmanager
def emulator_fleet(team_path: Path, enabled: bool) -> Iterator[EmulatorFleet | None]:
    """Run the bundled emulator fleet for the team while flying (stopped on exit)."""
    if not enabled:
        yield None
        return
    fleet = EmulatorFleet(team_path)
    fleet.start()
    try:
        yield fleet
    finally:
        fleet.stop()


def run_fly(args: argparse.Namespace) -> int:
    """Entry of `gcs fly`; returns the exit status (0 flown, 1 aborted, 2 setup, 130 operator)."""
    logging.basicConfig(level=getattr(logging, str(args.log_level).upper(), logging.WARNING),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    team: TeamConfig = load_team(args.team)
    out = args.out if args.out is not None else Path("runs") / f"{team.name}-fly"
    options = FlyOptions(
        out_dir=out, mode=args.mode, law=args.controller, tick_rate_hz=args.tick_rate_hz,
        duration_s=args.duration_s, end_action=args.end_action, figures=not args.no_figures,
        status=args.status, connect_timeout_s=args.connect_timeout_s,
    )

    def status(flight: Flight) -> StatusView:
        return StatusView(flight, args.status)

    try:
        setup = prepare(team, options)
        print(f"gcs fly: {setup.mode_choice}", file=sys.stderr, flush=True)
        with emulator_fleet(args.team, args.emulators) as fleet:
            # the law compiles (first run only) while the fleet boots and compiles beside it
            compile_law(force=False)
            flight = Flight(setup, options, status)
            if fleet is not None:
                fleet.wait_ready(setup.plan.connect_timeout_s)
                up = fleet.ready_line.removeprefix(READY_PREFIX).strip()
                print(f"gcs fly: emulator fleet up: {up}", file=sys.stderr, flush=True)
                flight.vehicle_notes = emulated_personalities(fleet.ready_line)
            # after the fleet started: the emulators ask for their own (vehicle-emu --scheduling)
            flight.scheduling = apply_scheduling(team.fly.scheduling)
            fell_back = team.fly.scheduling == "auto" and flight.scheduling.policy == "normal"
            logger.log(logging.WARNING if fell_back else logging.INFO, "%s",
                       flight.scheduling.detail)
            result = asyncio.run(flight.run())
    except (FlightSetupError, EmulatorFleetError, SchedulingError) as exc:
        print(f"gcs fly: {exc}", file=sys.stderr)
        return EXIT_SETUP
    except KeyboardInterrupt:  # before the links opened: nothing was commanded
        print("gcs fly: interrupted before connecting (exit 130)", file=sys.stderr)
        return EXIT_INTERRUPTED
    if result.log is not None:
        print(summary_table(result.log))
        tick = result.log.extra["tick"]
        print(f"  tick {tick['rate_hz']:g} Hz: {tick['ticks']} ticks, late {tick['late_pct']:.2f}%"
              f", lateness p99 {tick['lateness_p99_ms']:.2f} ms; records in {result.out_dir}/")
    code, reason = result.outcome.exit_code, result.outcome.reason
    first, _, details = reason.partition("\n")  # details: one line per vehicle, if any
    print(f"gcs fly: {'done' if code == 0 else 'ABORTED'}: {first.rstrip(':')} (exit {code})"
          + (f"\n{details}" if details else ""), file=sys.stderr if code else sys.stdout)
    return code
