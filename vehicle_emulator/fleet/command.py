"""``vehicle-emu``: run one emulated PX4-like quadrotor (``--id N``) or a whole team (``--fleet``).

Ports follow PX4 SITL instance i = N-1: bind 127.0.0.1:14580+i, send to 127.0.0.1:14540+i
(instances above 9 send to 14549), sysid N; ``--gcs`` adds a second link bound to 18570+i that
sends to 14550. Team-file ``link`` keys override the defaults, command-line flags override both.
An ``ardupilot`` vehicle sends from an ephemeral port instead (ArduPilot SITL's udpclient), unless
``--bind`` / ``--bind-base`` (``--gcs-bind``) force one; the ready line names the port.
Ctrl-C / SIGTERM stop it cleanly (exit status 0).

Start-up: the physics kernels are compiled (announced on stderr when the cache is cold, see
flightkit/jitcache.py), then the links open and one line ``vehicle-emu: ready: ...`` goes to
stdout; a parent process (``gcs fly --emulators``) waits for that line. ``--compile-only``
compiles and exits.

Scheduling (``--scheduling``): at start the process asks for a raised priority where the
operating system permits it (flightkit/sched.py: nice `EMU_RAISED_NICE`; SCHED_FIFO
`EMU_RT_PRIORITY`, one below the ground station's, by name). The vehicles it stands in for each
have a processor of their own: a stand-in that a busy machine preempts answers late, and a test
flown against it measures the machine rather than the ground station.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import gc
import json
import logging
import resource
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from flightkit.fleet_protocol import ready_line
from flightkit.jitcache import compiling
from flightkit.latecompile import watch_late_compiles
from flightkit.sched import (
    EMU_RAISED_NICE,
    EMU_RT_PRIORITY,
    EMULATOR,
    POLICIES,
    SchedulingError,
    apply_scheduling,
)
from vehicle_emulator.autopilots.node import VehicleNode
from vehicle_emulator.config.personality import (
    AUTOPILOT_NAMES,
    DEFAULT_AUTOPILOT,
    personality_of,
)
from vehicle_emulator.config.team import (
    TeamFileError,
    TeamSpec,
    VehicleSpec,
    default_vehicle,
    load_team,
)
from vehicle_emulator.fleet.runner import STREAM_MODES, Emulator, LinkPlan, RealtimeClock, RunStats

log = logging.getLogger("vehicle_emulator")

__all__ = ["main", "link_plan", "parse_address"]

#: PX4 SITL instance 0's ports: it binds 14580 and sends to 14540 (instance i: + i).
DEFAULT_BIND_BASE = 14580
DEFAULT_REMOTE_BASE = 14540
#: First-run compile of the physics on this 2-core machine (docs/benchmarks.md).
COMPILE_ESTIMATE_S = 35.0  # every personality, quiet 2-core machine (docs/benchmarks.md)


def parse_address(text: str) -> tuple[str, int]:
    """``host:port`` or ``port`` -> (host, port); host defaults to 127.0.0.1."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = "127.0.0.1", text
    try:
        p = int(port)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected host:port, got {text!r}") from None
    if not 0 <= p <= 65535:
        raise argparse.ArgumentTypeError(f"port {p} out of range 0..65535")
    return (host or "127.0.0.1", p)


def link_plan(spec: VehicleSpec, args: argparse.Namespace, single: bool) -> LinkPlan:
    """Addresses of a vehicle: PX4 SITL defaults < team file < command line. An ardupilot
    vehicle binds port 0 (ephemeral, connected to its remote) unless the command line forces a
    bind; the team file's bind (its ``link.remote_port``) does not apply to it."""
    i = spec.vehicle_id - 1
    udpclient = personality_of(spec.autopilot).protocol.family == "ardupilot"
    forced = args.bind is not None if single else args.bind_base is not None
    bind = ("127.0.0.1", DEFAULT_BIND_BASE + i)
    remote = ("127.0.0.1", DEFAULT_REMOTE_BASE + min(i, 9))
    gcs_bind = ("127.0.0.1", 18570 + i)
    gcs_remote = ("127.0.0.1", 14550)
    lk = spec.link
    bind = lk.bind or bind
    remote = lk.remote or remote
    if not single:  # the bases are command-line flags: they override the team file's ports
        if args.bind_base is not None:
            bind = (bind[0], args.bind_base + i)
        if args.remote_base is not None:
            remote = (remote[0], args.remote_base + min(i, 9))
    if single:
        bind = args.bind or bind
        remote = args.remote or remote
        gcs_bind = args.gcs_bind or gcs_bind
        gcs_remote = args.gcs_remote or gcs_remote
    use_gcs = args.gcs or args.gcs_bind is not None
    if udpclient:
        if not forced:
            bind = (bind[0], 0)
        if args.gcs_bind is None:
            gcs_bind = (gcs_bind[0], 0)
    return LinkPlan(bind, remote, gcs_bind if use_gcs else None, gcs_remote if use_gcs else None,
                    connect=udpclient)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="vehicle-emu",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="""\
Emulated quadrotors that a ground station reaches over MAVLink 2 / UDP as it
would reach SITL instances: modes, COMMAND_ACKs, arming, streams, ports,
parameters, the paper's rigid-body model at 1 kHz. Each vehicle has a
personality (--autopilot, or the team file's emulator.autopilot):
  px4        (default) behaves like PX4 v1.16.0 SITL (SIH) as recorded: OFFBOARD,
             its rate loop, motors, EKF-like estimate wander, own EKF origin
  ardupilot  behaves like ArduCopter 4.7.0-dev SITL as recorded: GUIDED_NOGPS,
             ephemeral source port, its fitted rate response and noise
  nominal    the paper's nominal model, not an autopilot: PX4's protocol, stiff
             drag-free loops, noise-free, actuator setpoints honoured
One vehicle per process (--id N: sysid N, PX4 SITL instance N-1's ports) or a
whole team (--fleet --team FILE). docs/emulator.md describes every detail.""",
        epilog="""\
examples:
  vehicle-emu --id 1                        Table I UAV 1 on the ground, PX4 ports
  vehicle-emu --id 2 --team configs/square4.yaml
                                            UAV 2 of the team, in the air
  vehicle-emu --fleet --team configs/square4.yaml
                                            the whole team in one process
  vehicle-emu --fleet --team configs/square4.yaml --autopilot ardupilot
                                            the same team as ArduCopter vehicles
  vehicle-emu --fleet --team configs/square4.yaml --autopilot nominal
                                            the paper's model (its figures)

exit status: 0 stopped (Ctrl-C, SIGTERM, --duration); 2 bad team file or a
--scheduling refused; 3 a port is taken.""",
    )
    who = ap.add_mutually_exclusive_group(required=True)
    who.add_argument("--id", type=int, help="vehicle id N (sysid N, PX4 SITL instance N-1)")
    who.add_argument("--fleet", action="store_true", help="run every vehicle of --team")
    who.add_argument("--compile-only", action="store_true",
                     help="compile the physics kernels into the on-disk cache and exit")
    ap.add_argument("--team", help="team YAML file (airframes, plant, initial state, faults)")
    ap.add_argument(
        "--autopilot",
        choices=AUTOPILOT_NAMES,
        help=f"personality of every vehicle (default: the team file's, else {DEFAULT_AUTOPILOT})",
    )
    ap.add_argument("--bind", type=parse_address, help="local UDP address (default 14580+N-1)")
    ap.add_argument("--remote", type=parse_address, help="initial peer (default 14540+N-1)")
    ap.add_argument("--gcs", action="store_true", help="second link: bind 18570+i, send to 14550")
    ap.add_argument("--gcs-bind", type=parse_address, help="second link's local address")
    ap.add_argument("--gcs-remote", type=parse_address, help="second link's peer")
    ap.add_argument("--bind-base", type=int, default=None,
                    help=f"fleet: vehicle i binds BASE+i-1 (default: the team file's ports, else "
                    f"{DEFAULT_BIND_BASE}+i-1; forces a bind for ardupilot)")
    ap.add_argument("--remote-base", type=int, default=None,
                    help=f"fleet: vehicle i sends to BASE+min(i-1, 9) (default: the team file's "
                    f"ports, else {DEFAULT_REMOTE_BASE}+min(i-1, 9))")
    ap.add_argument("--in-air", action="store_true", help="without --team: start at 10 m, holding")
    ap.add_argument(
        "--message-intervals",
        metavar="FILE",
        help="ardupilot: ArduPilot's message-intervals file (lines 'msgid interval_ms'), the "
        "streams its vehicles send from boot",
    )
    ap.add_argument(
        "--streams",
        choices=STREAM_MODES,
        default="default",
        help="default: each personality's streams from boot (px4: PX4's onboard set); "
        "requested: HEARTBEAT only, every other stream off until a SET_MESSAGE_INTERVAL (or a "
        "REQUEST_MESSAGE, once) asks for it, as a PX4 MAVLink instance in a mode without "
        "streams (large fleets: only what the ground station reads is built and sent)",
    )
    pace = ap.add_mutually_exclusive_group()
    pace.add_argument(
        "--lockstep",
        action="store_true",
        help="while armed in OFFBOARD, advance one tick per setpoint received (see docs)",
    )
    pace.add_argument(
        "--realtime-factor",
        type=float,
        default=1.0,
        help="simulated seconds per wall second (default 1)",
    )
    ap.add_argument("--physics-rate", type=float, default=None, help="physics rate Hz (1000)")
    ap.add_argument(
        "--tick-ms",
        type=float,
        default=2.0,
        help="loop period [ms]: setpoints are sampled and telemetry sent per tick",
    )
    ap.add_argument("--seed", type=int, default=0, help="seed of noise and packet loss")
    ap.add_argument(
        "--scheduling",
        choices=POLICIES,
        default="auto",
        help=f"the operating system's priority for the vehicles (default auto: nice "
        f"{EMU_RAISED_NICE}, else normal; realtime: SCHED_FIFO priority {EMU_RT_PRIORITY}, one "
        "below gcs fly; realtime/raised: exit 2 if refused)",
    )
    ap.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a parameter at start (repeatable)",
    )
    ap.add_argument(
        "--duration", type=float, default=None, help="stop after this many simulated seconds"
    )
    ap.add_argument("--stats-json", help="write pacing/CPU figures here at exit")
    ap.add_argument("--log-level", default="INFO",
                    help="Python logging level on stderr; INFO logs every command and its result "
                         "(default: INFO)")
    return ap


def _team(args: argparse.Namespace) -> tuple[list[VehicleSpec], TeamSpec | None]:
    specs, team = _team_specs(args)
    if args.autopilot is not None:
        specs = [dataclasses.replace(s, autopilot=args.autopilot) for s in specs]
    return specs, team


def _team_specs(args: argparse.Namespace) -> tuple[list[VehicleSpec], TeamSpec | None]:
    if args.team is None:
        if args.fleet:
            raise SystemExit("vehicle-emu: --fleet needs --team FILE")
        return [default_vehicle(args.id, on_ground=not args.in_air)], None
    team = load_team(args.team)
    if args.fleet:
        return list(team.vehicles), team
    try:
        return [team.vehicle(args.id)], team
    except KeyError as exc:
        raise SystemExit(f"vehicle-emu: {exc.args[0]}") from None


def read_message_intervals(path: str) -> dict[int, float]:
    """ArduPilot's message-intervals file: one 'msgid interval_ms' a line ('#' comments);
    ValueError naming the file and line otherwise."""
    out: dict[int, float] = {}
    try:
        lines = Path(path).read_text().splitlines()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the message intervals: {exc}") from None
    for n, line in enumerate(lines, start=1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        try:
            msgid, ms = int(words[0]), float(words[1])
            if len(words) != 2 or msgid < 0 or not ms > 0:
                raise ValueError
        except (ValueError, IndexError):
            raise ValueError(f"{path}:{n}: expected 'msgid interval_ms', got {line!r}") from None
        out[msgid] = ms
    return out


def warm_up(emu: Emulator) -> None:
    """Compile (or load from the cache) every kernel the emulator runs; announced when cold."""
    with compiling("emulator", "the emulator physics", COMPILE_ESTIMATE_S, "vehicle-emu"):
        emu.warm_up()


async def _amain(args: argparse.Namespace) -> int:
    # first: a refusal is one line before anything is built (the compile then runs at the
    # priority granted)
    scheduling = apply_scheduling(args.scheduling, EMULATOR)
    (log.warning if scheduling.policy == "normal" and args.scheduling == "auto" else log.info)(
        "vehicle-emu: %s", scheduling.detail)
    specs, team = _team(args)
    overrides: dict[str, float] = {}
    for item in args.param:
        name, sep, value = item.partition("=")
        if not sep:
            raise SystemExit(f"vehicle-emu: --param expects NAME=VALUE, got {item!r}")
        overrides[name.strip()] = float(value)
    rate = args.physics_rate or (team.physics_rate_hz if team else 1000.0)
    intervals = read_message_intervals(args.message_intervals) if args.message_intervals else None
    emu = Emulator(
        specs,
        faults=team.faults if team else (),
        physics_rate_hz=rate,
        tick_s=args.tick_ms * 1e-3,
        seed=args.seed,
        param_overrides=overrides,
        message_intervals_ms=intervals,
        streams=args.streams,
        **({"origin_lla": team.origin_lla} if team and team.origin_lla else {}),
    )
    log.info("vehicle-emu: team frame origin %.7f, %.7f, %.2f m (%s)", *emu.telemetry.origin_lla,
             "the team file's frame.origin" if team and team.origin_lla else "PX4 SITL's home")
    warm_up(emu)
    late = watch_late_compiles("vehicle-emu", log)
    clock = RealtimeClock(args.realtime_factor)
    plans = [link_plan(s, args, single=not args.fleet) for s in specs]
    if args.fleet and team is not None:
        for flag, base, key in (("--bind-base", args.bind_base, "link.remote_port"),
                                ("--remote-base", args.remote_base, "link.local_port")):
            if base is not None:
                log.info("vehicle-emu: %s %d overrides the team file's %s: vehicle i uses "
                         "port %d+i-1", flag, base, key, base)
    await emu.open_links(plans, clock)
    ephemeral = []
    for node, plan in zip(emu.nodes, plans, strict=True):
        s = node.spec
        for link in node.links:
            host, port = link.local_address or plan.bind
            kind = "sends from an ephemeral port" if link.connected else "binds"
            log.info("vehicle %d sysid %d: %s %s:%d -> %s:%d", s.vehicle_id, s.sysid, kind,
                     host, port, *link.remote)
            if link.connected:
                ephemeral.append(f"sysid {s.sysid} sends from {host}:{port} to "
                                 f"{link.remote[0]}:{link.remote[1]}")
    udpclient = (f"ephemeral ports (ArduPilot SITL udpclient): {', '.join(ephemeral)}"
                 if ephemeral else "")
    # handlers first: a parent may stop the emulator the moment it reads the ready line
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    print(ready_line([s.sysid for s in specs], [(s.vehicle_id, s.autopilot) for s in specs],
                     udpclient), flush=True)
    if args.duration is not None:
        loop.call_later(args.duration / args.realtime_factor, stop.set)
    stats = RunStats()
    # what start-up built (the fleet, the imported libraries, the compiled kernels: ~130,000
    # objects at 240 vehicles) is never garbage: out of the collector's sight, a full collection
    # walks only what the run allocates, instead of pausing every vehicle for 20-90 ms
    gc.collect()
    gc.freeze()
    collections0 = [g["collections"] for g in gc.get_stats()]
    cpu0, wall0 = time.process_time(), time.monotonic()
    try:
        if args.lockstep:
            await emu.run_lockstep(clock, stop, stats)
        else:
            await emu.run(clock, stop, stats)
    finally:
        emu.close_links()
    wall = time.monotonic() - wall0
    cpu = time.process_time() - cpu0
    summary = {
        "vehicles": len(specs),
        "scheduling": scheduling.detail,
        "wall_s": wall,
        "sim_s": emu.now_s,
        "cpu_s": cpu,
        "cpu_fraction": cpu / wall if wall > 0 else 0.0,
        "ticks": stats.ticks,
        "late_mean_ms": 1e3 * stats.late_sum_s / max(stats.ticks, 1),
        "late_max_ms": 1e3 * stats.late_max_s,
        "late_p99_ms": 1e3 * _percentile(stats.lateness_samples, 99.0),
        "late_over_1ms": stats.late_over_1ms,
        "dropped_sim_s": stats.dropped_s,
        "lockstep_timeouts": stats.lockstep_timeouts,
        "telemetry_msgs": int(emu.telemetry.sent.sum()),
        "telemetry_by_type": dict(
            zip(emu.telemetry.names, emu.telemetry.sent.tolist(), strict=True)
        ),
        "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "gc_frozen_objects": gc.get_freeze_count(),
        "gc_collections": [g["collections"] - c0
                           for g, c0 in zip(gc.get_stats(), collections0, strict=True)],
        # the most datagrams one socket held at a wake-up (a backlog: the fleet fell behind)
        "deepest_backlog": emu.poller.deepest if emu.poller is not None else 0,
        "read_budget_stops": emu.poller.budget_stops if emu.poller is not None else 0,
        # numba compiles after the ready line (each silenced every link while it ran)
        "compiled_after_ready": late.compiled,
        "by_vehicle": [_vehicle_summary(node) for node in emu.nodes],
    }
    if args.stats_json:
        with open(args.stats_json, "w") as fh:
            json.dump(summary, fh, indent=1)
    print(
        f"vehicle-emu: stopped after {emu.now_s:.1f} s simulated, "
        f"cpu {summary['cpu_fraction']:.0%}, tick lateness mean "
        f"{summary['late_mean_ms']:.2f} ms max {summary['late_max_ms']:.1f} ms",
        file=sys.stderr,
    )
    return 0


def _vehicle_summary(node: VehicleNode) -> dict[str, object]:
    """What a vehicle ended in and what it made of its input (``--stats-json``)."""
    ap, c = node.autopilot, node.counters
    return {
        "sysid": node.sysid,
        "autopilot": node.personality.name,
        "mode": ap.mode_name,
        "armed": bool(ap.armed),
        "setpoints_taken": node.setpoints_taken,
        # read with a newer one of the same stream and not handled (server.py, latest wins)
        "setpoints_superseded": sum(getattr(link, "superseded", 0) for link in node.links),
        "setpoints_rejected": c.setpoints_rejected,
        "setpoints_ignored": c.setpoints_ignored,
        "setpoints_by_mode": dict(c.setpoints_by_mode),
        "guided_timeouts": getattr(ap, "guided_timeouts", None),
    }


def _percentile(xs: list[float], q: float) -> float:
    if not xs:
        return 0.0
    s = sorted(xs)
    return s[min(len(s) - 1, int(len(s) * q / 100.0))]


def main(argv: Sequence[str] | None = None) -> int:
    """``vehicle-emu`` after its entry point (cli.py) configured numba's cache."""
    args = _parser().parse_args(argv)
    logging.basicConfig(
        level=getattr(logging, str(args.log_level).upper(), logging.INFO),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        if args.compile_only:
            # every personality, so that any team's fleet finds its kernels in the cache
            warm_up(Emulator([dataclasses.replace(default_vehicle(k + 1, on_ground=True),
                                                  autopilot=name)
                              for k, name in enumerate(AUTOPILOT_NAMES)]))
            return 0
        return asyncio.run(_amain(args))
    except (TeamFileError, SchedulingError) as exc:
        print(f"vehicle-emu: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"vehicle-emu: {exc}", file=sys.stderr)
        return 3
    except ValueError as exc:  # bad --param etc.
        print(f"vehicle-emu: {exc}", file=sys.stderr)
        return 2

