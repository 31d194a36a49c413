"""The agents' bus across an impaired network: how old a neighbour's state is when an agent's
law reads it, over Zenoh on TCP and on UDP with mixed reliability, and what it does to the
formation (docs/benchmarks.md, "The agents' bus across a lossy network").

    sudo python -m benchmarks.bench_bus [--seconds S] [--flights K] [--no-write]
    sudo python -m benchmarks.bench_bus --flights K --disciplined-only   # more of those pairs

Two stand-in agents (tests/integration/agent_peer.py: the product's NeighbourBus, no vehicle),
each in a network namespace of its own on one bridge (tests/netns.py), publish their state at
100 Hz and read each other's row at every tick, as an agent's law does. Every frame a host sends
is delayed 20 ms +- 5 ms (normal) and dropped with probability 0.1 (the agents' test's
impairment), or not impaired at all. Per transport and network: the age at use (median, p99,
max), the share of ticks at which the sample is older than fly.stale_after_s (0.1 s, where the
law drops the edge) and the samples lost. Then K pairs of flights, one through the plain network
and one through the impaired one in turn (tests/agents_across.py, as
tests/integration/test_agents_netns.py flies them), each agent measuring its neighbours' clock
offsets; over UDP also a pair with network.clocks disciplined (one kernel, one system clock: the
network's cost without the offsets estimated through it): formation error for t >= 30 s and each
edge's figures. Needs root (namespaces); elsewhere it says so and stops.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.docsection import publish
from tests.agents_across import ENDPOINTS, HOSTS, FlightFailed, error_after, fly_across
from tests.netns import BETWEEN_AGENTS, Mode, Testbed

ROOT = Path(__file__).resolve().parents[1]
HEADING = "## The agents' bus across a lossy network"
PEER = ROOT / "tests" / "integration" / "agent_peer.py"
RATE_HZ = 100
STALE_S = 0.1  # fly.stale_after_s's default
TRANSPORTS = {"TCP": "tcp", "UDP, mixed reliability": "udp-mixed"}
#: the flights per transport: name -> (impaired, network.clocks); over UDP also both networks
#: with clocks disciplined (the hosts share one kernel's system clock: the network's cost
#: without the clock offsets estimated through it); each impaired one is compared with the
#: plain one of its clocks
NETWORKS = {"plain": (False, "measured"), "impaired": (True, "measured")}
DISCIPLINED = {"plain, disciplined clocks": (False, "disciplined"),
               "impaired, disciplined clocks": (True, "disciplined")}


def exchange(endpoint, impaired: bool, seconds: float) -> dict:
    """Vehicles 1 and 2's stand-in agents in hosts 1 and 2, each the other's neighbour; returns
    each one's figures of the other (agent_peer's JSON)."""
    with tempfile.TemporaryDirectory(prefix="bench-bus-") as logs, Testbed(
            3, [BETWEEN_AGENTS if impaired else None] * 2 + [None], mode=Mode.NAMESPACES,
            log_dir=logs) as bed:
        agents = {v: [endpoint(bed.address(v), bed.host(v).free_port("udp"))] for v in (1, 2)}
        network = {"key_prefix": "bench", "agents": agents,
                   "supervisor": [endpoint(bed.address(3), bed.host(3).free_port("udp"))]}
        procs, outs = {}, {}
        for v, other in ((1, 2), (2, 1)):
            spec = {"network": network, "team": "bus", "ids": [1, 2], "own": v,
                    "neighbours": [other], "rate_hz": RATE_HZ, "seconds": seconds}
            outs[v] = tempfile.TemporaryFile("w+")  # noqa: SIM115 (closed below)
            # its standard input stays open: it stops when its time is up
            procs[v] = bed.host(v).popen([sys.executable, str(PEER), json.dumps(spec)],
                                         stdin=subprocess.PIPE, stdout=outs[v], text=True,
                                         env={**os.environ, "PYTHONPATH": str(ROOT)})
        out = {}
        for v, proc in procs.items():
            proc.wait(timeout=seconds + 60)
            proc.stdin.close()
            outs[v].seek(0)
            lines = outs[v].read().splitlines()
            outs[v].close()
            if proc.returncode != 0 or not lines:
                raise SystemExit(f"agent_peer of vehicle {v} exited {proc.returncode}")
            out[v] = json.loads(lines[-1])[str(3 - v)]
        return out


def row(name: str, network: str, figures: dict) -> str:
    ages = np.concatenate([np.array(f["ages_ms"], dtype=float) for f in figures.values()])
    received = sum(f["received"] for f in figures.values())
    lost = sum(f["lost"] for f in figures.values())
    return (f"| {name} | {network} | {np.median(ages):.0f} | {np.percentile(ages, 99):.0f} | "
            f"{ages.max():.0f} | {100 * np.mean(ages > STALE_S * 1e3):.1f} % | "
            f"{100 * lost / max(received + lost, 1):.1f} % |")


def flights(pairs: int, tmp: Path, disciplined_only: bool = False) -> str:
    """Per transport, `pairs` plain and impaired flights in turn; their table and the ratios of
    the medians."""
    rows, verdicts, failed = [], [], []
    for label, transport in TRANSPORTS.items():
        if disciplined_only and transport != "udp-mixed":
            continue
        networks = ({} if disciplined_only else NETWORKS) | (
            DISCIPLINED if transport == "udp-mixed" else {})
        runs: dict[str, list[dict]] = {name: [] for name in networks}
        for k in range(pairs):
            for name, (impaired, clocks) in networks.items():
                impairment = [BETWEEN_AGENTS] * len(HOSTS) + [None] if impaired else None
                try:
                    with Testbed(len(HOSTS) + 1, impairment, mode=Mode.NAMESPACES,
                                 log_dir=tmp) as bed:
                        report = fly_across(bed, tmp, f"{transport}-{name}-{k}".replace(" ", "-")
                                            .replace(",", ""), transport, clocks=clocks)
                except FlightFailed as exc:  # a result too: what the network did to it
                    failed.append(f"{label}, {name} flight {k + 1}: {exc.reason}")
                    print(failed[-1], flush=True)
                    rows.append(f"| {label} | {name} | {k + 1} | stopped (below) | | | | | |")
                    continue
                e = error_after(report)
                edges = report["extra"]["edges"].values()
                runs[name].append({
                    "mean": float(np.nanmean(e)), "max": float(np.nanmax(e)),
                    "p50": np.median([x["age_p50_ms"] for x in edges]),
                    "p99": max(x["age_p99_ms"] for x in edges),
                    "loss": [x["loss_fraction"] for x in edges],
                    "stale": sum(x["stale_ticks"] for x in edges),
                    "used": max(x["age_used_max_ms"] for x in edges),
                    "offset": max(abs(x["offset_s"]) for x in edges
                                  if x.get("offset_s") is not None)})
                r = runs[name][-1]
                print(f"{transport} {name} {k}: {1e3 * r['mean']:.2f} / {1e3 * r['max']:.2f} mm",
                      flush=True)
                rows.append(f"| {label} | {name} | {k + 1} | {1e3 * r['mean']:.2f} / "
                            f"{1e3 * r['max']:.2f} | "
                            f"{r['p50']:.0f} / {r['p99']:.0f} | "
                            f"{100 * min(r['loss']):.0f}-{100 * max(r['loss']):.0f} % | "
                            f"{r['stale']} | {r['used']:.0f} | {1e3 * r['offset']:.2f} |")
        med = {name: (np.median([r["mean"] for r in rs]), np.median([r["max"] for r in rs]))
               for name, rs in runs.items() if rs}
        for name, (impaired, clocks) in networks.items():
            if not impaired:
                continue
            plain = next(n for n, (i, c) in networks.items() if not i and c == clocks)
            if name not in med or plain not in med:
                verdicts.append(f"* {label}: {name}: no ratio (no completed flight of it or "
                                f"of {plain})")
                continue
            verdicts.append(f"* {label}: {name} against {plain}, medians over the flights: "
                            f"mean {med[name][0] / med[plain][0]:.2f}x, max "
                            f"{med[name][1] / med[plain][1]:.2f}x")
    return ("| transport | network | flight | formation error t >= 30 s, mean / max [mm] | age "
            "at use p50 / p99 [ms] | samples lost (per edge) | stale ticks (all edges) | "
            "oldest used [ms] | clock offset measured, largest edge [ms] |\n"
            "|---|---|---|---|---|---|---|---|---|\n" + "\n".join(rows)
            + "\n\n" + "\n".join(verdicts) + "\n"
            + "".join(f"\nStopped: {f}" for f in failed) + ("\n" if failed else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--flights", type=int, default=3, help="pairs of flights (0: none)")
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--disciplined-only", action="store_true",
                    help="fly only the UDP pairs with clocks disciplined and print their table "
                         "(more flights of the comparison nearest the noise floor; writes "
                         "nothing)")
    args = ap.parse_args()
    if args.disciplined_only:
        with tempfile.TemporaryDirectory(prefix="bench-bus-") as d:
            print(flights(args.flights, Path(d), disciplined_only=True))
        return
    rows = []
    for name, endpoint in TRANSPORTS.items():
        for impaired in (False, True):
            network = "20 +- 5 ms, 10 % loss" if impaired else "plain"
            rows.append(row(name, network, exchange(ENDPOINTS[endpoint], impaired,
                                                    args.seconds)))
            print(rows[-1], flush=True)
    flown = ""
    if args.flights > 0:
        with tempfile.TemporaryDirectory(prefix="bench-bus-") as d:
            flown = (f"\n### Flights through it\n\nScenario I (square4, nominal vehicles, "
                     f"rates at 50 Hz, 45 s, hold at the end) flown by two agent processes "
                     f"(vehicles 1 and 3 in one host, 2 and 4 in another, each beside its "
                     f"vehicles' `vehicle-emu --fleet`; every edge of the ring crosses the "
                     f"network), supervised from a third host; per transport "
                     f"{args.flights} flights through the plain network and "
                     f"{args.flights} through the impaired one (each agent host's frames), "
                     f"in turn, all on this machine's two cores, each agent estimating its "
                     f"neighbours' clock offsets (`network.clocks: measured`); over UDP also "
                     f"{args.flights} through each with `network.clocks: disciplined` (the "
                     f"samples carry the hosts' system clocks, the echoes only check them: "
                     f"the hosts are namespaces of one kernel, so their system clocks are one, "
                     f"as PTP keeps a mesh's; what the network costs without the offsets "
                     f"estimated through it). The agents' formation start is the "
                     f"supervisor's, converted by the median offset where offsets are "
                     f"measured (docs/agents.md, \"Clocks\"). The clock offset measured: "
                     f"the largest |offset| the echoes put on any edge at the end, whichever "
                     f"mode converts (the true one is 0: one kernel). Each record's positions "
                     f"are carried to its tick's instant, so the merged formation error is "
                     f"the flight's, not the agents' phase (docs/gcs.md, \"Records\").\n\n"
                     + flights(args.flights, Path(d)))
    text = (f"{HEADING}\n\n`python -m benchmarks.bench_bus` ({time.strftime('%Y-%m-%d')}, this "
            f"2-core machine, as root). Two stand-in agents (the product's bus, no vehicle) in "
            f"network namespaces of their own publish their state at {RATE_HZ} Hz for "
            f"{args.seconds:g} s and read each other's at every tick; each host's sent frames "
            f"delayed 20 ms +- 5 ms (normal) and 10 % dropped, or not impaired. Age at use: now "
            f"minus when the sample was taken, both agents' ticks (after the first 2 s); stale: "
            f"older than {STALE_S:g} s, where the law drops the edge; lost: sequence gaps (a sample "
            f"overtaken by a newer one, which a 5 ms jitter at a 10 ms period makes common, is "
            f"dropped on arrival and counts as lost: the latest wins).\n\n"
            "| transport | network | age p50 [ms] | p99 [ms] | max [ms] | ticks stale | "
            "samples lost |\n|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n\n"
            "Over TCP every sample arrives (no gap), but a lost segment holds every later sample "
            "until its retransmission, so ages pile up behind it. With mixed reliability "
            "(`udp/HOST:PORT?rel=1;mixed_rel=1`) the states, published best effort, travel as "
            "datagrams: a lost one is gone and the next replaces it, while statuses, gates and "
            "aborts keep their reliable QUIC streams.\n" + flown)
    publish(ROOT / "docs" / "benchmarks.md", HEADING, text, write=not args.no_write)


if __name__ == "__main__":
    main()
