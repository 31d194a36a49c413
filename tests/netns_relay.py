"""A userspace stand-in for ``tc netem`` on one interface: delay, jitter and loss of every frame
the interface sends, for kernels built without sch_netem (tests/netns.py starts it).

Run inside a host namespace as ``python tests/netns_relay.py --dev eth0 --tap imp0 ...``. It
creates the TAP device ``--tap`` and prints ``netns-relay: ready``; the testbed then redirects
everything ``--dev`` sends to that TAP (``tc filter ... egress ... action mirred egress redirect
dev imp0``). Each frame read from the TAP is dropped with probability ``--loss`` or else sent on
``--dev`` through a packet socket that bypasses the qdisc (so it is not redirected again) once
its delay has passed: ``--delay-s`` plus a uniform jitter in [-J, +J] (netem's default) or a
normal one of standard deviation J (netem's ``distribution normal``), never below zero. Frames
leave in the order of their send times, so jitter reorders them as netem's does. At most
``--limit`` frames wait (netem's default limit, 1000); one more is dropped and counted.

Stdlib only (it starts in a fraction of a second). SIGTERM ends it; it then writes one JSON line
of counts on stderr: frames received, dropped for loss, dropped at the limit, sent, send errors.
"""

from __future__ import annotations

import argparse
import fcntl
import heapq
import json
import os
import random
import select
import signal
import socket
import struct
import sys
import time

TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000
SOL_PACKET = 263
PACKET_QDISC_BYPASS = 20
FRAME_MAX = 65536
# SCHED_FIFO priority: above the ground station's (10) and the emulator's (9). The relay stands
# for a wire, whose timing no process on the test machine should delay.
RT_PRIORITY = 20


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dev", required=True, help="interface whose sent frames are impaired")
    p.add_argument("--tap", required=True, help="TAP device to create and read frames from")
    p.add_argument("--delay-s", type=float, default=0.0)
    p.add_argument("--jitter-s", type=float, default=0.0)
    p.add_argument("--distribution", choices=("uniform", "normal"), default="uniform")
    p.add_argument("--loss", type=float, default=0.0, help="probability a frame is dropped")
    p.add_argument("--limit", type=int, default=1000, help="frames waiting at most")
    p.add_argument("--seed", type=int, default=None)
    return p.parse_args(argv)


def open_tap(name: str) -> int:
    """A TAP device ``name`` (created by this call, gone when the descriptor closes); returns
    its non-blocking descriptor."""
    fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
    fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", name.encode(), IFF_TAP | IFF_NO_PI))
    return fd


def raise_priority() -> str:
    """SCHED_FIFO where permitted; says what the relay got."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except OSError as exc:
        return f"normal scheduling (SCHED_FIFO {RT_PRIORITY} refused: {exc.strerror})"
    return f"SCHED_FIFO {RT_PRIORITY}"


def main(argv: list[str]) -> int:
    args = parse(argv)
    rng = random.Random(args.seed)
    counts = {"received": 0, "dropped_loss": 0, "dropped_limit": 0, "sent": 0,
              "send_errors": 0}

    def on_term(signum: int, frame: object) -> None:
        raise SystemExit(0)

    signal.signal(signal.SIGTERM, on_term)
    tap = open_tap(args.tap)
    out = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, 0)
    out.setsockopt(SOL_PACKET, PACKET_QDISC_BYPASS, 1)
    out.bind((args.dev, 0))
    scheduling = raise_priority()

    def delay_s() -> float:
        if args.jitter_s <= 0.0:
            return args.delay_s
        if args.distribution == "normal":
            return max(0.0, rng.gauss(args.delay_s, args.jitter_s))
        return max(0.0, args.delay_s + rng.uniform(-args.jitter_s, args.jitter_s))

    waiting: list[tuple[float, int, bytes]] = []  # (send time, arrival number, frame)
    print(f"netns-relay: {args.dev} via {args.tap}, {scheduling}", file=sys.stderr, flush=True)
    print("netns-relay: ready", flush=True)
    try:
        while True:
            now = time.monotonic()
            while waiting and waiting[0][0] <= now:
                frame = heapq.heappop(waiting)[2]
                try:
                    out.send(frame)
                    counts["sent"] += 1
                except OSError as exc:  # the interface went down: the frame is lost, as on a wire
                    counts["send_errors"] += 1
                    print(f"netns-relay: send on {args.dev}: {exc}", file=sys.stderr, flush=True)
            timeout = None if not waiting else max(0.0, waiting[0][0] - time.monotonic())
            ready, _, _ = select.select([tap], [], [], timeout)
            if not ready:
                continue
            while True:
                try:
                    frame = os.read(tap, FRAME_MAX)
                except BlockingIOError:
                    break
                counts["received"] += 1
                if args.loss > 0.0 and rng.random() < args.loss:
                    counts["dropped_loss"] += 1
                elif len(waiting) >= args.limit:
                    counts["dropped_limit"] += 1
                else:
                    heapq.heappush(waiting, (time.monotonic() + delay_s(), counts["received"],
                                             frame))
    finally:
        print(json.dumps(counts), file=sys.stderr, flush=True)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
