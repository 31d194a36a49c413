"""`gcs agent` (one vehicle's share of the law, or a few vehicles') and `gcs fly --agents`
(the supervisor, which starts or finds the agents)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from gcs.agent.merge import MergeError, merge_records
from gcs.agent.runtime import fly_agent
from gcs.agent.session import BusError
from gcs.agent.supervise import Supervisor, SupervisorOutcome
from gcs.config import ConfigError, TeamConfig, load_team
from gcs.config.modes import FLY_MODES, as_strings
from gcs.fly.command import EmulatorFleetError, emulator_fleet
from gcs.fly.records import TIMESERIES_NAME
from gcs.fly.sched import (
    POLICIES,
    SchedulingError,
    apply_scheduling,
    leave_realtime,
    share_with_threads,
)
from gcs.fly.setup import FlightSetupError, FlyOptions, prepare
from gcs.fly.warmup import compile_law
from gcs.mission.plan import EXIT_ABORTED, EXIT_INTERRUPTED
from gcs.report import summary_table

__all__ = ["add_parser", "run_agent", "run_fly_agents", "run_supervised"]

logger = logging.getLogger("gcs.agent")

EXIT_SETUP = 2
#: the supervisor's own account: every agent's outcome and the events it saw and sent
SUPERVISOR_NAME = "supervisor.json"

AGENT_DESCRIPTION = """\
Fly one vehicle's share of the team's formation law (or a few vehicles'), as one agent of a
team with no central computer: hold the MAVLink link to the agent's own vehicles only, run
their rows of the law on their own telemetry and their graph neighbours' states from the
neighbour bus (Zenoh, the team file's network: section), and follow the supervisor's
sequence (`gcs fly --agents`). The records (report.json, timeseries.csv, flight.tlog) are
the agent's own vehicles'; the supervisor merges the team's. docs/agents.md."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("agent", help="fly one vehicle's share of the law (an agent of the team)",
                       description=AGENT_DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--team", required=True, type=Path, metavar="FILE", help="team config (YAML)")
    p.add_argument("--id", dest="ids", type=int, action="append", required=True, metavar="N",
                   help="a vehicle id of the team this agent flies (repeat for several)")
    p.add_argument("--mode", choices=as_strings(FLY_MODES), default=None,
                   help="as gcs fly --mode (every agent of a team must fly the same)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="formation phase length (default: the file's mission.duration_s)")
    p.add_argument("--out", type=Path, default=None, metavar="DIR",
                   help="output directory (default: runs/<name>-agent-<ids>)")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--status", choices=("auto", "rich", "plain", "off"), default="off",
                   help="live status of the agent's vehicles (default: off)")
    p.add_argument("--log-level", default="WARNING",
                   help="Python logging level on stderr (default: WARNING)")
    p.add_argument("--scheduling", choices=POLICIES, default=None,
                   help="as the team file's fly.scheduling, which it overrides")


def _options(team: TeamConfig, args: argparse.Namespace, out: Path) -> FlyOptions:
    return FlyOptions(out_dir=out, mode=args.mode, duration_s=args.duration_s,
                      figures=not args.no_figures, status=args.status, abort_key=False)


def run_agent(args: argparse.Namespace) -> int:
    """Entry of `gcs agent`; exit statuses as gcs fly's."""
    logging.basicConfig(level=getattr(logging, str(args.log_level).upper(), logging.WARNING),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    team = load_team(args.team)
    own = tuple(args.ids)
    label = "-".join(str(v) for v in own)
    out = args.out if args.out is not None else Path("runs") / f"{team.name}-agent-{label}"
    options = _options(team, args, out)

    status = None
    if args.status != "off":
        from gcs.fly.status import StatusView

        def status(flight: Any) -> Any:
            return StatusView(flight, args.status)
    try:
        # the law compiles (first run only) before the process asks for real-time scheduling
        compile_law(force=False)
        scheduling = apply_scheduling(args.scheduling or team.fly.scheduling)
        logging.getLogger("gcs.agent").info("%s", scheduling.detail)
        result = asyncio.run(fly_agent(team, own, options, status, scheduling))
    except (FlightSetupError, BusError, ConfigError, SchedulingError) as exc:
        print(f"gcs agent: {exc}", file=sys.stderr)
        return EXIT_SETUP
    except KeyboardInterrupt:
        print("gcs agent: interrupted before connecting (exit 130)", file=sys.stderr)
        return EXIT_INTERRUPTED
    code, reason = result.outcome.exit_code, result.outcome.reason
    print(f"gcs agent {label}: {'done' if code == 0 else 'ABORTED'}: {reason} (exit {code})",
          file=sys.stderr if code else sys.stdout)
    return code


# --- the supervisor -------------------------------------------------------------------------------


def local_agents_scheduling(policy: str, agents: int, cores: int | None) -> str | None:
    """The scheduling `gcs fly --agents` starts `agents` agent processes with on a machine of
    `cores` (None: the team file's `policy`). `auto` asks for real time, ahead of every normal
    process; agents that are at least as many as the cores can then fill them all and starve
    what runs beside them (the vehicles' stand-ins, whose held rate setpoints tilt a vehicle
    before its late answers show), so they start normally scheduled, competing as equals."""
    if policy == "auto" and agents >= max(1, cores or 1):
        return "normal"
    return None


def agent_groups(team: TeamConfig, per_process: int) -> list[tuple[int, ...]]:
    """The team's vehicles in groups of `per_process` (team-file order): one agent each."""
    ids = team.ids()
    return [ids[k:k + per_process] for k in range(0, len(ids), per_process)]


class AgentProcesses:
    """The agents `gcs fly --agents` starts: `gcs agent` per group, output to its log file."""

    def __init__(self, team_path: Path, groups: list[tuple[int, ...]], out: Path,
                 args: argparse.Namespace, scheduling: str | None = None) -> None:
        self.procs: list[subprocess.Popen[bytes]] = []
        self.dirs = [out / "agents" / ("agent-" + "-".join(str(v) for v in g)) for g in groups]
        for g, d in zip(groups, self.dirs, strict=True):
            d.mkdir(parents=True, exist_ok=True)
            argv = [sys.executable, "-m", "gcs.cli", "agent", "--team", str(team_path),
                    "--out", str(d), "--log-level", "WARNING"]
            for v in g:
                argv += ["--id", str(v)]
            if args.mode is not None:
                argv += ["--mode", args.mode]
            if args.duration_s is not None:
                argv += ["--duration-s", str(args.duration_s)]
            if args.no_figures:
                argv.append("--no-figures")
            if scheduling is not None:
                argv += ["--scheduling", scheduling]
            log = open(d.with_suffix(".log"), "wb")  # noqa: SIM115 (the child keeps its own)
            self.procs.append(subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=log,
                                               stderr=subprocess.STDOUT,
                                               start_new_session=True))
            log.close()

    def exit_status(self, k: int) -> int | None:
        return self.procs[k].poll()

    def stop(self, timeout_s: float = 30.0) -> None:
        """Wait for each agent to end (it lands its vehicles first); SIGTERM, then SIGKILL."""
        for p in self.procs:
            try:
                p.wait(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGTERM)
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait(timeout=5)


def run_fly_agents(args: argparse.Namespace) -> int:
    """`gcs fly --agents [--emulators]`: the emulator fleet if asked, then `run_supervised`."""
    logging.basicConfig(level=getattr(logging, str(args.log_level).upper(), logging.WARNING),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if args.agents_per_process < 1:
        print("gcs fly: --agents-per-process must be >= 1", file=sys.stderr)
        return EXIT_SETUP
    team = load_team(args.team)
    out = args.out if args.out is not None else Path("runs") / f"{team.name}-fly"
    with emulator_fleet(args.team, args.emulators) as fleet:
        if fleet is not None:
            try:
                fleet.wait_ready(team.fly.connect_timeout_s)
            except EmulatorFleetError as exc:
                print(f"gcs fly: {exc}", file=sys.stderr)
                return EXIT_SETUP
        return run_supervised(args, team, out)


def run_supervised(args: argparse.Namespace, team: TeamConfig, out: Path) -> int:
    """`gcs fly --agents`: start the agents (unless --agents-running), supervise, merge."""
    from gcs.agent.supervisor import SupervisorBus

    options = FlyOptions(out_dir=out, mode=args.mode, duration_s=args.duration_s)
    try:
        setup = prepare(team, options)
    except FlightSetupError as exc:
        print(f"gcs fly: {exc}", file=sys.stderr)
        return EXIT_SETUP
    groups = agent_groups(team, args.agents_per_process)
    compile_law(force=False)  # once, here: the agents load it from the cache
    procs = None
    if not args.agents_running:
        local = local_agents_scheduling(team.fly.scheduling, len(groups), os.cpu_count())
        if local is not None:
            print(f"gcs fly: {len(groups)} agents on {os.cpu_count()} cores start with "
                  f"--scheduling {local} (fly.scheduling auto: real-time agents that fill "
                  "every core starve the vehicles beside them)", file=sys.stderr)
        procs = AgentProcesses(args.team, groups, out, args, local)

    def exits(k: int) -> int | None:
        return None if procs is None else procs.exit_status(k)

    async def supervise() -> SupervisorOutcome:
        async with SupervisorBus.for_team(team) as bus:
            share_with_threads()  # its bus's receive threads: the process's priority
            plan = setup.plan
            sup = Supervisor(team, bus, groups, exits, prime_s=plan.prime_s,
                             connect_timeout_s=plan.connect_timeout_s + 30.0,
                             follow=(plan.formation_check_s, plan.formation_max_error_m,
                                     plan.formation_max_fraction),
                             stream=sys.stderr)
            loop = asyncio.get_running_loop()
            with contextlib.suppress(NotImplementedError):
                loop.add_signal_handler(signal.SIGINT, sup.interrupt)
                loop.add_signal_handler(signal.SIGTERM, sup.interrupt)
            return await sup.run()

    # the supervisor's heartbeats and its hearing of the agents are the team's liveness: the
    # ground station's priority (fly.scheduling), as the agents have
    try:
        scheduling = apply_scheduling(team.fly.scheduling)
    except SchedulingError as exc:
        print(f"gcs fly: {exc}", file=sys.stderr)
        if procs is not None:
            procs.stop(timeout_s=0.0)
        return EXIT_SETUP
    logger.info("%s", scheduling.detail)
    print(f"gcs fly: {setup.mode_choice}; {len(groups)} agents "
          f"({'found' if procs is None else 'started'}), the law runs in them", file=sys.stderr)
    try:
        outcome = asyncio.run(supervise())
        leave_realtime()  # merging the records is no timed work (gcs/fly/flight.py, the same)
    except BusError as exc:
        print(f"gcs fly: {exc}", file=sys.stderr)
        if procs is not None:
            procs.stop(timeout_s=0.0)
        return EXIT_SETUP
    finally:
        if procs is not None:
            procs.stop()
    # the agents' records: where the supervisor put them, or where each one says it wrote them
    dirs = (procs.dirs if procs is not None
            else [Path(a.records or "") for a in outcome.agents])
    agents: dict[str, Any] = {}
    present: list[Path] = []
    for a, d in zip(outcome.agents, dirs, strict=True):
        has = (d / TIMESERIES_NAME).is_file()
        agents[a.name] = {"vehicles": list(a.vehicles), "outcome": a.outcome,
                          "exit_status": a.exited, "records": str(d) if has else None}
        # found agents name their records per vehicle: a process of several, one directory
        if has and d not in present:
            present.append(d)
    summary = {"outcome": {"exit_code": outcome.exit_code, "reason": outcome.reason},
               "agents": agents, "events": outcome.events}
    out.mkdir(parents=True, exist_ok=True)
    (out / SUPERVISOR_NAME).write_text(json.dumps(summary, indent=1, default=str))
    flown = {v for a, d in zip(outcome.agents, dirs, strict=True)
             if (d / TIMESERIES_NAME).is_file() for v in a.vehicles}
    order = [v for v in team.ids() if v in flown]
    try:
        log, _ = merge_records(present, order, out, team.name,
                               {**agents, "supervisor": {"events": outcome.events}},
                               figures=not args.no_figures,
                               pairs=[(e.i, e.j) for e in team.graph.edges
                                      if e.i in order and e.j in order])
        print(summary_table(log))
        lacking = [v for v in team.ids() if v not in flown]
        print(f"  records of each agent in {out / 'agents'}/, the team's in {out}/"
              + (f" (no records of vehicles {lacking})" if lacking else ""))
    except MergeError as exc:
        print(f"gcs fly: no merged records: {exc}; the supervisor's account is in "
              f"{out / SUPERVISOR_NAME}", file=sys.stderr)
        if outcome.exit_code == 0:
            return EXIT_ABORTED
    code = outcome.exit_code
    print(f"gcs fly: {'done' if code == 0 else 'ABORTED'}: {outcome.reason} (exit {code})",
          file=sys.stderr if code else sys.stdout)
    return code
