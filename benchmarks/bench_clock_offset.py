"""How well the agents' clock filter finds a peer's offset through a jittery network
(docs/benchmarks.md, "The agents' clock offset through jitter").

    sudo python -m benchmarks.bench_clock_offset [--seconds S] [--no-write]

Two hosts in network namespaces of their own (tests/netns.py), each host's sent frames delayed
20 ms +- 5 ms (normal) and 10 % dropped, as between the agents in their tests. One pinger per
host sends a UDP datagram every 20 ms carrying its send time, an echo of the peer's latest
message (what the bus echoed until 2026-12-06) and an echo of every peer message received since
its last send (what it echoes now, gcs/agent/table.py). Both hosts share one kernel, so the
true offset is 0 and each datagram's one-way delay is measured exactly. Host 1's exchanges are
then fed, in order, to the least-round-trip rule over a window (the former estimate) and to
`gcs.agent.clocks.OffsetEstimator` (the present one); the table gives each one's error over the
run, sampled every 10 exchanges once its window is full. Needs root (namespaces).
"""

from __future__ import annotations

import argparse
import json
import select
import shutil
import socket
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.docsection import publish
from gcs.agent.clocks import OffsetEstimator
from tests.netns import BETWEEN_AGENTS, Mode, Testbed, TestbedError

ROOT = Path(__file__).resolve().parents[1]
HEADING = "## The agents' clock offset through jitter"
PERIOD_S = 0.02
PORT = 15301
_HEAD = struct.Struct("<dddH")  # sent_s, latest echo (t1, held_s), number of echoes after
_ECHO = struct.Struct("<dd")  # t1, held_s


def pinger(bind: str, peer: str, seconds: float, out: Path) -> None:
    """Run one host's side (module docstring) for `seconds`; write what it measured to `out`."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((bind, PORT))
    sock.setblocking(False)
    clock = time.monotonic
    one_way, exchanges = [], {"latest": [], "every": []}
    since: list[tuple[float, float]] = []  # (peer's sent_s, our arrival) since our last send
    latest: tuple[float, float] | None = None
    start = due = clock()
    while clock() - start < seconds:
        now = clock()
        if now >= due:
            t1, held = (latest[0], now - latest[1]) if latest else (-1.0, -1.0)
            echoes = b"".join(_ECHO.pack(sent, now - arrived) for sent, arrived in since)
            sock.sendto(_HEAD.pack(now, t1, held, len(since)) + echoes, (peer, PORT))
            since = []
            due += PERIOD_S
        if not select.select([sock], [], [], max(0.0, due - clock()))[0]:
            continue
        while True:
            try:
                data = sock.recv(4096)
            except BlockingIOError:
                break
            t4 = clock()
            t3, t1, held, n = _HEAD.unpack_from(data)
            one_way.append(t4 - t3)
            since.append((t3, t4))
            latest = (t3, t4)
            if t1 >= 0.0:
                exchanges["latest"].append((t1, t3 - held, t3, t4))
            for k in range(n):
                t1, held = _ECHO.unpack_from(data, _HEAD.size + _ECHO.size * k)
                exchanges["every"].append((t1, t3 - held, t3, t4))
    out.write_text(json.dumps({"one_way_s": one_way, **exchanges}))


def least_rtt_errors(exchanges: np.ndarray, window: int) -> np.ndarray:
    """The former rule: the offset of the least round trip of the last `window` exchanges."""
    t1, t2, t3, t4 = exchanges.T
    offset, rtt = ((t2 - t1) + (t3 - t4)) / 2.0, (t4 - t1) - (t3 - t2)
    return np.array([offset[k - window:k][np.argmin(rtt[k - window:k])]
                     for k in range(window, len(offset) + 1, 10)])


def estimator_errors(exchanges: np.ndarray, window: int) -> np.ndarray:
    """The present rule (gcs.agent.clocks.OffsetEstimator) fed the exchanges in order."""
    est = OffsetEstimator(window=window)
    errors = []
    for k, exchange in enumerate(exchanges, start=1):
        est.add(*exchange)
        if k >= window and (k - window) % 10 == 0:
            errors.append(est.offset_s)
    return np.array(errors)


def _cell(errors_s: np.ndarray) -> str:
    e = np.abs(errors_s) * 1e3
    return f"{e.mean():.2f} / {np.percentile(e, 95):.2f}" if e.size else "-"


def main() -> int:
    if len(sys.argv) > 1 and sys.argv[1] == "--pinger":
        bind, peer, seconds, out = sys.argv[2:6]
        pinger(bind, peer, float(seconds), Path(out))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-clock-"))
    try:
        with Testbed(2, BETWEEN_AGENTS, mode=Mode.NAMESPACES, log_dir=tmp) as bed:
            a, b = bed.address(1), bed.address(2)
            argv = [sys.executable, "-m", "benchmarks.bench_clock_offset", "--pinger"]
            procs = [bed.host(1).popen([*argv, a, b, str(args.seconds), str(tmp / "1.json")],
                                       cwd=ROOT),
                     bed.host(2).popen([*argv, b, a, str(args.seconds), str(tmp / "2.json")],
                                       cwd=ROOT)]
            for p in procs:
                p.wait(args.seconds + 60)
            described = bed.describe()
        here, there = (json.loads((tmp / f"{k}.json").read_text()) for k in (1, 2))
    except TestbedError as exc:
        print(f"bench_clock_offset: needs network namespaces (root): {exc}", file=sys.stderr)
        return 1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    lines = [
        HEADING, "",
        f"`python -m benchmarks.bench_clock_offset` ({time.strftime('%Y-%m-%d')}, "
        f"{args.seconds:.0f} s, as root): {described}. Two pingers, one per host, a datagram "
        f"every {PERIOD_S * 1e3:.0f} ms each way; the true offset is 0 (one kernel). One-way "
        "delay, mean / std: host 2 -> 1 "
        f"{np.mean(here['one_way_s']) * 1e3:.1f} / {np.std(here['one_way_s']) * 1e3:.1f} ms, "
        f"host 1 -> 2 {np.mean(there['one_way_s']) * 1e3:.1f} / "
        f"{np.std(there['one_way_s']) * 1e3:.1f} ms. Host 1's estimate of host 2's offset, "
        "|error| mean / p95 [ms]:", "",
        "| echoes | exchanges | single exchange | least round trip of 64 | of 512 | "
        "OffsetEstimator, window 64 | window 512 |",
        "|---|---|---|---|---|---|---|",
    ]
    for kind, name in (("latest", "the latest message, repeated until a newer one"),
                       ("every", "every message once (the bus now)")):
        ex = np.array(here[kind])
        t1, t2, t3, t4 = ex.T
        single = ((t2 - t1) + (t3 - t4)) / 2.0
        lines.append(f"| {name} | {len(ex)} | {_cell(single)} | "
                     f"{_cell(least_rtt_errors(ex, 64))} | {_cell(least_rtt_errors(ex, 512))} | "
                     f"{_cell(estimator_errors(ex, 64))} | {_cell(estimator_errors(ex, 512))} |")
        print(lines[-1])
    bias = []
    for kind in ("latest", "every"):
        t1, t2, t3, t4 = np.array(here[kind]).T
        bias.append(f"{np.mean((t2 - t1) + (t3 - t4)) / 2.0 * 1e3:+.2f} ms ({kind})")
    lines += ["", "With normal jitter on both legs the difference of the legs does not depend "
              "on their sum, so the least round trip errs as a single exchange does; a median "
              "converges. Echoing only the latest message biases every rule: a message followed "
              "by a slow one is echoed twice, and a slow one overtaken before the next echo "
              "never (gcs/agent/clocks.py). The single exchanges' mean offset shows it: "
              f"{', '.join(bias)}."]
    publish(ROOT / "docs" / "benchmarks.md", HEADING, "\n".join(lines) + "\n",
            not args.no_write)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
