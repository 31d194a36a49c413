"""Small network programs that the testbed tests start inside host namespaces: a UDP echo and
its pinger, a Zenoh publisher and subscriber, a MAVLink heartbeat reader.

``python tests/integration/netns_tools.py COMMAND ...``; each prints ``ready`` on stdout once
its socket is bound or its session open (the test waits for that line, never for a time), then
one JSON line of results, and exits by itself within its ``--timeout-s``. Delays are measured
on CLOCK_MONOTONIC, which every network namespace shares (no time namespace is involved): a
timestamp taken by the sender in one namespace and the receiver's in another give the one-way
delay directly. ``wait_ready`` and ``result_of`` are the test side's.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

TOOLS = str(Path(__file__).resolve())
# SCHED_FIFO priority of the tools where permitted: they are the measuring instruments, and one
# below the userspace impairment's (tests/netns_relay.py, 20). Normally scheduled beside a busy
# loop per core, a tool woken by a datagram waited up to 140 ms for a core.
RT_PRIORITY = 19

PING = struct.Struct("!Id")  # sequence number, sender's send time (monotonic s)
PONG = struct.Struct("!Idd")  # the same, and the echo's receive time (monotonic s)


def wait_ready(proc: subprocess.Popen, what: str, timeout_s: float = 60.0) -> None:
    """Return once ``proc`` (started with ``stdout=PIPE, text=True``) printed its ``ready``
    line; TimeoutError naming ``what``, the line it printed instead and its exit status."""
    assert proc.stdout is not None
    readable, _, _ = select.select([proc.stdout], [], [], timeout_s)
    line = proc.stdout.readline() if readable else ""
    if line.strip() != "ready":
        raise TimeoutError(f"{what}: no ready line within {timeout_s} s (got {line!r}, exit "
                           f"{proc.poll()})")


def result_of(proc: subprocess.Popen, what: str, timeout_s: float = 60.0) -> dict:
    """The JSON line ``proc`` prints last, once it has exited 0 (AssertionError otherwise)."""
    out, _ = proc.communicate(timeout=timeout_s)
    assert proc.returncode == 0, f"{what} exited {proc.returncode}"
    return json.loads(out.strip().splitlines()[-1])


def endpoint(text: str) -> tuple[str, int]:
    """``ADDRESS:PORT`` -> (address, port)."""
    address, _, port = text.rpartition(":")
    return address, int(port)


def ready() -> None:
    print("ready", flush=True)


def udp_echo(args: argparse.Namespace) -> dict:
    """Answer each datagram with its sequence number, its send time and the receive time; exit
    once nothing came for ``--idle-s`` after the first, or at ``--timeout-s``."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(endpoint(args.bind))
    ready()
    received = 0
    deadline = time.monotonic() + args.timeout_s
    last = None
    while (now := time.monotonic()) < deadline:
        wait = deadline - now if last is None else min(deadline - now, last + args.idle_s - now)
        if wait <= 0:
            break
        readable, _, _ = select.select([sock], [], [], wait)
        if not readable:
            continue
        data, peer = sock.recvfrom(2048)
        t_recv = time.monotonic()
        last = t_recv
        seq, t_send = PING.unpack(data)
        received += 1
        sock.sendto(PONG.pack(seq, t_send, t_recv), peer)
    return {"received": received}


def udp_ping(args: argparse.Namespace) -> dict:
    """Send ``--count`` datagrams at ``--interval-s`` to ``--to``; wait ``--wait-s`` after the
    last for late answers. Reports per answer [seq, forward_s, back_s, round_trip_s]."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("0.0.0.0", 0))
    to = endpoint(args.to)
    ready()
    answers: dict[int, list[float]] = {}
    start = time.monotonic()
    sent = 0
    end = start + args.count * args.interval_s + args.wait_s
    while (now := time.monotonic()) < end:
        if sent < args.count and now >= start + sent * args.interval_s:
            sock.sendto(PING.pack(sent, now), to)
            sent += 1
            continue
        next_send = start + sent * args.interval_s if sent < args.count else end
        readable, _, _ = select.select([sock], [], [], max(0.0, min(next_send, end) - now))
        if readable:
            data = sock.recv(2048)
            t_back = time.monotonic()
            seq, t_send, t_echo = PONG.unpack(data)
            answers[seq] = [seq, t_echo - t_send, t_back - t_echo, t_back - t_send]
    return {"sent": sent, "answers": sorted(answers.values())}


def zenoh_config(args: argparse.Namespace):
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("listen/endpoints", json.dumps([f"tcp/{args.listen}"]))
    config.insert_json5("connect/endpoints", json.dumps([f"tcp/{e}" for e in args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def zenoh_sub(args: argparse.Namespace) -> dict:
    """Subscribe to ``--key``; report per sample [seq, one_way_s] until ``--count`` arrived or
    ``--timeout-s``."""
    import zenoh

    samples: list[list[float]] = []
    with zenoh.open(zenoh_config(args)) as session:
        sub = session.declare_subscriber(args.key)
        ready()
        deadline = time.monotonic() + args.timeout_s
        while len(samples) < args.count and time.monotonic() < deadline:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.0005)
                continue
            t_recv = time.monotonic()
            seq, t_put = PING.unpack(bytes(sample.payload.to_bytes()))
            samples.append([seq, t_recv - t_put])
    return {"samples": samples}


def zenoh_pub(args: argparse.Namespace) -> dict:
    """Wait (``--timeout-s``) for a matching subscriber on ``--key``, then put ``--count``
    samples at ``--interval-s``, each carrying its sequence number and send time."""
    import zenoh

    with zenoh.open(zenoh_config(args)) as session:
        pub = session.declare_publisher(args.key)
        ready()
        deadline = time.monotonic() + args.timeout_s
        while not pub.matching_status.matching:
            if time.monotonic() > deadline:
                raise TimeoutError(f"no subscriber matched {args.key} within {args.timeout_s} s")
            time.sleep(0.01)
        matched_after_s = args.timeout_s - (deadline - time.monotonic())
        start = time.monotonic()
        for seq in range(args.count):
            while (now := time.monotonic()) < start + seq * args.interval_s:
                time.sleep(start + seq * args.interval_s - now)
            pub.put(PING.pack(seq, time.monotonic()))
        # the session's close waits for its queues; the subscriber reports what arrived
    return {"put": args.count, "matched_after_s": matched_after_s}


def mav_heartbeat(args: argparse.Namespace) -> dict:
    """Listen on 127.0.0.1:``--port`` for a vehicle's HEARTBEAT, then send it COMMAND_LONG
    (arm) and wait for its COMMAND_ACK: a MAVLink round trip on this namespace's loopback."""
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{args.port}", source_system=245,
                                      source_component=190, dialect="common")
    ready()
    hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=args.timeout_s)
    if hb is None:
        raise TimeoutError(f"no HEARTBEAT on 127.0.0.1:{args.port} within {args.timeout_s} s")
    sysid = hb.get_srcSystem()
    conn.mav.command_long_send(sysid, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    deadline = time.monotonic() + args.timeout_s
    while (left := deadline - time.monotonic()) > 0:
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=left)
        if ack is not None and ack.command == 400:
            peer = sorted(conn.clients)
            return {"sysid": sysid, "autopilot": hb.autopilot, "ack_result": ack.result,
                    "vehicle_address": [list(p) for p in peer]}
    raise TimeoutError(f"no COMMAND_ACK for arm from sysid {sysid} within {args.timeout_s} s")


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    echo = sub.add_parser("udp-echo")
    echo.add_argument("--bind", required=True)
    echo.add_argument("--idle-s", type=float, default=1.0)
    echo.add_argument("--timeout-s", type=float, default=60.0)
    ping = sub.add_parser("udp-ping")
    ping.add_argument("--to", required=True)
    ping.add_argument("--count", type=int, default=100)
    ping.add_argument("--interval-s", type=float, default=0.01)
    ping.add_argument("--wait-s", type=float, default=0.5)
    for name in ("zenoh-sub", "zenoh-pub"):
        z = sub.add_parser(name)
        z.add_argument("--listen", required=True, help="ADDRESS:PORT")
        z.add_argument("--connect", action="append", default=[], help="ADDRESS:PORT")
        z.add_argument("--key", default="netns/test")
        z.add_argument("--count", type=int, default=100)
        z.add_argument("--interval-s", type=float, default=0.02)
        z.add_argument("--timeout-s", type=float, default=30.0)
    mav = sub.add_parser("mav-heartbeat")
    mav.add_argument("--port", type=int, required=True)
    mav.add_argument("--timeout-s", type=float, default=60.0)
    return p.parse_args(argv)


COMMANDS = {"udp-echo": udp_echo, "udp-ping": udp_ping, "zenoh-sub": zenoh_sub,
            "zenoh-pub": zenoh_pub, "mav-heartbeat": mav_heartbeat}


def raise_priority() -> str:
    """SCHED_FIFO where permitted; says what the tool got."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except OSError as exc:
        return f"normal ({exc.strerror})"
    return f"SCHED_FIFO {RT_PRIORITY}"


def main(argv: list[str]) -> int:
    args = parse(argv)
    scheduling = raise_priority()
    print(json.dumps(COMMANDS[args.command](args) | {"scheduling": scheduling}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
