"""The `gcs` command line: sim, fly, agent, sweep, check, plot (print lives here, not below).

`main` points numba's cache at the current sources (flightkit.jitcache) before it imports a
compiled module, so this module imports none at its top."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from flightkit import jitcache
from gcs.config import ConfigError, describe, load_team

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gcs",
        description="Adaptive distributed formation control of heterogeneous multirotors.",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("sim", help="simulate the team in-process and write records")
    source = sim.add_mutually_exclusive_group(required=True)
    source.add_argument("--team", type=Path, help="team config (YAML)")
    source.add_argument("--study", type=Path,
                        help="study file (YAML) of gcs sweep: fly its run --run again")
    sim.add_argument("--run", type=int, default=None,
                     help="with --study: the run to fly (as numbered in the sweep's table)")
    sim.add_argument(
        "--controller",
        choices=("adaptive", "baseline", "both"),
        default=None,
        help="law to run (default: the file's); 'both' runs adaptive and baseline and compares",
    )
    sim.add_argument(
        "--out", type=Path, default=None, help="output directory (default runs/<name>)"
    )
    sim.add_argument(
        "--mode",
        choices=("actuators", "rates", "attitude"),
        default=None,
        help="attitude loop: the paper's torque law, thrust + body rates, or thrust + attitude "
             "(an onboard P attitude loop on the rate loop)",
    )
    sim.add_argument(
        "--derivative",
        choices=("model", "levant"),
        default=None,
        help="how u', u'' are obtained (default: the file's)",
    )
    sim.add_argument("--controller-rate-hz", type=float, default=None)
    sim.add_argument("--plant-rate-hz", type=float, default=None)
    sim.add_argument("--duration-s", type=float, default=None)
    sim.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")

    from gcs.fly.command import add_parser as add_fly_parser

    add_fly_parser(sub)

    from gcs.agent.command import add_parser as add_agent_parser

    add_agent_parser(sub)

    from gcs.sweep.command import add_parser as add_sweep_parser

    add_sweep_parser(sub)

    comp = sub.add_parser(
        "compile",
        help="compile the law, the simulator and the emulator physics into the on-disk cache "
             "(make install runs it; otherwise the first run does, and says so)")
    comp.add_argument("--no-emulator", action="store_true",
                      help="only the ground station's parts (law and simulator)")

    check = sub.add_parser(
        "check", help="validate a team config and print what it says",
        usage="gcs check [-h] (FILE | --team FILE)")
    check.add_argument("file", nargs="?", type=Path, metavar="FILE", help="team config (YAML)")
    check.add_argument("--team", type=Path, default=None, metavar="FILE",
                       help="team config (YAML), as the other commands take it")
    check.set_defaults(check_parser=check)  # for the usage error of _check_file

    plot = sub.add_parser("plot", help="redraw the figures of a run directory")
    plot.add_argument("run_dir", type=Path)
    plot.add_argument("--out", type=Path, default=None, help="where to write (default: run_dir)")
    return parser


def _check_file(args: argparse.Namespace) -> Path:
    """The one team file `gcs check` was given, as FILE or as --team FILE; otherwise a usage
    error (exit 2) naming what was given."""
    parser: argparse.ArgumentParser = args.check_parser
    if args.file is not None and args.team is not None:
        parser.error(f"give the team file once, as FILE or as --team FILE, not both "
                     f"(got {args.file} and --team {args.team})")
    if args.file is None and args.team is None:
        parser.error("a team file is required: gcs check FILE (or --team FILE)")
    return args.file if args.file is not None else args.team


def main(argv: Sequence[str] | None = None) -> int:
    # before build_parser: it imports `gcs fly`, whose modules hold numba's cached kernels
    jitcache.configure()
    args = build_parser().parse_args(argv)
    try:
        if args.command == "check":
            team = load_team(_check_file(args))
            print(describe(team))
            return EXIT_OK
        if args.command == "compile":
            from gcs.precompile import compile_all

            try:
                compile_all(emulator=not args.no_emulator)
            except RuntimeError as exc:
                print(f"gcs compile: {exc}", file=sys.stderr)
                return EXIT_FAILED
            return EXIT_OK
        if args.command == "sim" and args.study is not None:
            from gcs.sweep.replay import run_replay

            return run_replay(args)
        if args.command == "sim":
            if args.run is not None:
                print("gcs sim: --run needs --study (a sweep's study file)", file=sys.stderr)
                return EXIT_USAGE
            from gcs.sim.command import run_sim

            return run_sim(args)
        if args.command == "sweep":
            from gcs.sweep.command import run_sweep

            return run_sweep(args)
        if args.command == "agent":
            from gcs.agent.command import run_agent

            return run_agent(args)
        if args.command == "fly" and (args.agents or args.agents_running):
            from gcs.agent.command import run_fly_agents

            return run_fly_agents(args)
        if args.command == "fly":
            from gcs.fly.command import run_fly

            return run_fly(args)
        if args.command == "plot":
            from gcs.sim.command import run_plot

            return run_plot(args.run_dir, args.out)
    except ConfigError as exc:
        print(f"gcs: config error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("gcs: interrupted", file=sys.stderr)
        return 130
    return EXIT_USAGE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
