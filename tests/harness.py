"""Test support: start ``vehicle-emu`` as a subprocess on free 127.0.0.1 ports, and a small
pymavlink client that waits for messages with timeouts (tests never sleep to synchronise).

Used by tests/integration/test_emulator_*.py and usable by other packages' integration tests.
Every wait raises ``TimeoutError`` naming what it waited for.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable, Coroutine, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

__all__ = [
    "MavClient",
    "RecordingLink",
    "run_until",
    "clients_on_port_block",
    "SetpointStreamer",
    "UdpPeer",
    "custom_main_mode",
    "custom_sub_mode",
    "free_udp_port",
    "hover_thrust",
    "rates_setpoint",
    "run_bounded",
    "run_emulator",
    "wait_until",
]

GCS_SYSID = 245
PREARM_CHECK = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK
GCS_COMPID = 190
HISTORY_MAX = 200_000


class RecordingLink:
    """An in-process stand-in for a UDP link: decodes and keeps everything the emulator sends
    (for tests of ``runner.Emulator`` without sockets)."""

    name = "recording"

    def __init__(self) -> None:
        from vehicle_emulator.mavlink.codec import PeerDecoder

        self.decoder = PeerDecoder()
        self.msgs: list = []

    def send(self, data: bytes, addr: Any = None) -> None:
        self.msgs.extend(self.decoder.feed(data, "emu"))

    def types(self) -> Counter:
        return Counter(m.get_type() for m in self.msgs)


def run_until(emu: Any, until_s: float, tick_s: float = 0.002) -> None:
    """Advance an in-process ``Emulator`` tick by tick to simulated time ``until_s``."""
    t = emu.now_s
    while t < until_s - 1e-9:
        t += tick_s
        emu.advance_to(t)


def run_bounded(coro: Coroutine[Any, Any, Any], timeout_s: float = 10.0) -> Any:
    """``asyncio.run(coro)``, raising TimeoutError after ``timeout_s`` (a test never hangs)."""

    async def bounded() -> Any:
        async with asyncio.timeout(timeout_s):
            return await coro

    return asyncio.run(bounded())


async def wait_until(condition: Callable[[], bool], timeout_s: float = 2.0) -> None:
    """Poll ``condition`` on the event loop every millisecond (no fixed sleeps); returns when it
    holds, raises TimeoutError after ``timeout_s``."""
    async with asyncio.timeout(timeout_s):
        while not condition():
            await asyncio.sleep(0.001)


class UdpPeer(asyncio.DatagramProtocol):
    """An asyncio UDP socket on an ephemeral 127.0.0.1 port for hand-written test peers
    (subclasses implement ``datagram_received``). Lifetime: ``async with Peer() as peer:``."""

    transport: asyncio.DatagramTransport | None = None

    async def __aenter__(self) -> Any:
        self.transport, _ = await asyncio.get_running_loop().create_datagram_endpoint(
            lambda: self, local_addr=("127.0.0.1", 0))
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self.transport is not None
        self.transport.close()

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) bound."""
        assert self.transport is not None
        host, port = self.transport.get_extra_info("sockname")[:2]
        return (str(host), int(port))


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago (bind to 0, read, close)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def free_udp_port_block(n: int, attempts: int = 200, kind: int = socket.SOCK_DGRAM) -> int:
    """A base port such that base .. base+n-1 on 127.0.0.1 were all free a moment ago (UDP;
    `kind` socket.SOCK_STREAM: TCP)."""
    rng = random.Random()
    for _ in range(attempts):
        base = rng.randrange(20000, 60000 - n)
        socks: list[socket.socket] = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, kind)
                socks.append(s)
                s.bind(("127.0.0.1", base + k))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise OSError(f"no block of {n} free ports found in {attempts} attempts")


@dataclass
class EmulatorProcess:
    """A running ``vehicle-emu`` subprocess and the ports it uses (``bind_port`` None: not
    forced, an ardupilot vehicle then sends from an ephemeral port)."""

    proc: subprocess.Popen
    bind_port: int | None
    remote_port: int
    log_path: str

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGTERM, wait; returns the exit status (kills after the timeout)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                return self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout_s)
                raise
        return int(self.proc.returncode)

    def log_text(self) -> str:
        """Everything the emulator wrote to stderr so far."""
        with open(self.log_path) as fh:
            return fh.read()

    def explain(self, error: BaseException, lines: int = 15) -> None:
        """Add the emulator's state and the tail of its log to ``error`` (a failed wait then
        says whether the emulator ran, exited or never got ready, and what it last did)."""
        code = self.proc.poll()
        state = "running" if code is None else f"exited with {code}"
        try:
            tail = self.log_text().splitlines()[-lines:]
        except OSError as exc:
            tail = [f"(log unreadable: {exc})"]
        error.add_note(f"vehicle-emu pid {self.proc.pid} {state}; {self.log_path} ends:\n"
                       + "\n".join(tail))


@contextlib.contextmanager
def _explained(emu: EmulatorProcess) -> Iterator[EmulatorProcess]:
    """Yield a started emulator; a failure in the block is explained from its log, and the
    emulator is stopped whatever happens."""
    try:
        yield emu
    except Exception as exc:
        emu.explain(exc)
        raise
    finally:
        emu.stop()


@contextlib.contextmanager
def run_emulator(
    args: Sequence[str],
    remote_port: int | None = None,
    bind_port: int | None = None,
    log_dir: str = "/tmp",
    bind: bool = True,
) -> Iterator[EmulatorProcess]:
    """``vehicle-emu ARGS --bind 127.0.0.1:B --remote 127.0.0.1:R`` for the ``with`` body;
    ``bind=False`` leaves ``--bind`` out (an ardupilot vehicle then binds an ephemeral port)."""
    bind_port = (bind_port or free_udp_port()) if bind else None
    remote_port = remote_port or free_udp_port()
    log_path = os.path.join(log_dir, f"vehicle-emu-{bind_port or remote_port}.log")
    cmd = [sys.executable, "-m", "vehicle_emulator", *args]
    if bind_port is not None:
        cmd += ["--bind", f"127.0.0.1:{bind_port}"]
    cmd += ["--remote", f"127.0.0.1:{remote_port}"]
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, stderr=log, stdout=log)
    with _explained(EmulatorProcess(proc, bind_port, remote_port, log_path)) as emu:
        yield emu


@contextlib.contextmanager
def run_emulator_ready(
    args: Sequence[str], remote_port: int, log_dir: str = "/tmp", timeout_s: float = 60.0
) -> Iterator[EmulatorProcess]:
    """``run_emulator`` that returns the moment the emulator prints its ready line on stdout
    (what ``gcs fly --emulators`` waits for); TimeoutError naming the log if it never does."""
    bind_port = free_udp_port()
    log_path = os.path.join(log_dir, f"vehicle-emu-{bind_port}.log")
    cmd = [sys.executable, "-m", "vehicle_emulator", *args,
           "--bind", f"127.0.0.1:{bind_port}", "--remote", f"127.0.0.1:{remote_port}"]
    with open(log_path, "w") as log:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=log, text=True)
    with _explained(EmulatorProcess(proc, bind_port, remote_port, log_path)) as emu:
        ready = threading.Event()

        def read_stdout() -> None:  # drains stdout to the end so the emulator never blocks
            assert proc.stdout is not None
            for line in proc.stdout:
                if line.startswith("vehicle-emu: ready:"):
                    ready.set()

        threading.Thread(target=read_stdout, daemon=True).start()
        if not ready.wait(timeout_s):
            raise TimeoutError(f"vehicle-emu printed no ready line within {timeout_s} s "
                               f"(log {log_path})")
        yield emu


@dataclass
class MavClient:
    """pymavlink UDP client listening on 127.0.0.1:``port`` (the emulator's remote). Like
    MAVProxy's ``udpin``, it answers the addresses packets come from (``peers``), so it reaches
    a vehicle on an ephemeral port (ArduPilot SITL's udpclient) once it has heard it."""

    port: int
    target_system: int = 1
    conn: Any = field(init=False)
    lock: threading.Lock = field(default_factory=threading.Lock, init=False)
    # every message received so far (waits skip what they do not look for; this keeps it)
    history: collections.deque = field(
        default_factory=lambda: collections.deque(maxlen=HISTORY_MAX), init=False
    )

    def __post_init__(self) -> None:
        # imported here: pymavlink.mavutil sets MAVLINK_DIALECT when imported, and importing
        # this module sets no environment variable
        from pymavlink import mavutil

        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{self.port}",
            source_system=GCS_SYSID,
            source_component=GCS_COMPID,
            dialect="common",
        )

    def close(self) -> None:
        """Close the socket."""
        self.conn.close()

    @property
    def peers(self) -> set[tuple[str, int]]:
        """The (host, port) addresses packets came from (pymavlink's udpin sends to them)."""
        return {(str(a[0]), int(a[1])) for a in self.conn.clients}

    def send(self, msg: Any) -> None:
        """Send a pymavlink message object (thread-safe)."""
        with self.lock:
            self.conn.mav.send(msg)

    def recv(self, timeout_s: float) -> Any | None:
        """Next message or None after the timeout (also kept in ``history``)."""
        m = self.conn.recv_match(blocking=True, timeout=timeout_s)
        if m is not None:
            self.history.append(m)
        return m

    def seen(self, mtype: str) -> list[Any]:
        """Messages of ``mtype`` from the target received so far (``history``)."""
        return [m for m in self.history
                if m.get_type() == mtype and m.get_srcSystem() == self.target_system]

    def wait(
        self,
        mtype: str | Sequence[str],
        timeout_s: float = 5.0,
        cond: Callable[[Any], bool] | None = None,
    ) -> Any:
        """First message of ``mtype`` (satisfying ``cond``) from the target; TimeoutError."""
        types = {mtype} if isinstance(mtype, str) else set(mtype)
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no {sorted(types)} within {timeout_s} s")
            m = self.recv(min(left, 0.5))
            if m is None or m.get_type() not in types:
                continue
            if m.get_srcSystem() != self.target_system:
                continue
            if cond is None or cond(m):
                return m

    def wait_ready_to_arm(self, timeout_s: float = 10.0) -> Any:
        """The first SYS_STATUS whose pre-arm check (MAV_SYS_STATUS_PREARM_CHECK) is healthy:
        how a ground station knows a PX4 vehicle may be armed. TimeoutError."""
        return self.wait("SYS_STATUS", timeout_s, lambda m: m.onboard_control_sensors_health
                         & PREARM_CHECK)

    def wait_text(
        self, timeout_s: float = 5.0, cond: Callable[[str], bool] | None = None
    ) -> tuple[int, str]:
        """(severity, text) of the first STATUSTEXT from the target whose text satisfies
        ``cond``; chunks with the same id != 0 are joined first (MAVLink 2: a chunk of 50 bytes
        is continued, a shorter one ends the text). TimeoutError."""
        deadline = time.monotonic() + timeout_s
        parts: dict[int, list[str]] = {}
        while True:
            m = self.wait("STATUSTEXT", deadline - time.monotonic())
            if m.id == 0:
                text = m.text
            else:
                parts.setdefault(m.id, []).append(m.text)
                if len(m.text.encode()) == 50:
                    continue
                text = "".join(parts.pop(m.id))
            if cond is None or cond(text):
                return int(m.severity), text

    def collect(self, duration_s: float, mtype: str | Sequence[str] | None = None) -> list[Any]:
        """Every message (of ``mtype``) from the target for ``duration_s``."""
        types = None if mtype is None else ({mtype} if isinstance(mtype, str) else set(mtype))
        out = []
        deadline = time.monotonic() + duration_s
        while (left := deadline - time.monotonic()) > 0:
            m = self.recv(min(left, 0.2))
            if m is None or m.get_srcSystem() != self.target_system:
                continue
            if types is None or m.get_type() in types:
                out.append(m)
        return out

    def command(self, command: int, *params: float, timeout_s: float = 5.0) -> int:
        """COMMAND_LONG; returns the MAV_RESULT of its first COMMAND_ACK (TimeoutError if none)."""
        return self.command_acks(command, *params, count=1, timeout_s=timeout_s)[0]

    def command_acks(
        self, command: int, *params: float, count: int, timeout_s: float = 5.0
    ) -> list[int]:
        """COMMAND_LONG; the MAV_RESULTs of its first ``count`` COMMAND_ACKs in arrival order
        (PX4 v1.16.0 answers DO_SET_MODE twice: ACCEPTED, then the result). TimeoutError if
        fewer arrive within ``timeout_s``; returns as soon as ``count`` have arrived."""
        p = list(params) + [0.0] * (7 - len(params))
        self.send(mavlink.MAVLink_command_long_message(self.target_system, 1, command, 0, *p))
        deadline = time.monotonic() + timeout_s
        results: list[int] = []
        while len(results) < count:
            left = deadline - time.monotonic()
            try:
                ack = self.wait("COMMAND_ACK", left, lambda m: m.command == command)
            except TimeoutError:
                raise TimeoutError(
                    f"command {command}: {len(results)} of {count} COMMAND_ACKs {results} "
                    f"within {timeout_s} s"
                ) from None
            results.append(int(ack.result))
        return results

    def set_param(self, name: str, value: float, ptype: int = 9, timeout_s: float = 5.0) -> Any:
        """PARAM_SET; returns the PARAM_VALUE echoed for ``name``."""
        self.send(
            mavlink.MAVLink_param_set_message(self.target_system, 1, name.encode(), value, ptype)
        )
        return self.wait("PARAM_VALUE", timeout_s, lambda m: m.param_id == name)

    def get_param(self, name: str, timeout_s: float = 5.0) -> Any:
        """PARAM_REQUEST_READ by name; returns the PARAM_VALUE."""
        self.send(
            mavlink.MAVLink_param_request_read_message(self.target_system, 1, name.encode(), -1)
        )
        return self.wait("PARAM_VALUE", timeout_s, lambda m: m.param_id == name)


class SetpointStreamer:
    """Background thread sending one setpoint message (a factory) at ``rate_hz``."""

    def __init__(self, client: MavClient, make: Callable[[], Any], rate_hz: float = 50.0):
        self.client = client
        self.make = make
        self.period_s = 1.0 / rate_hz
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> SetpointStreamer:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        """Stop sending (returns when the thread has ended)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5.0)

    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            self.client.send(self.make())
            self.sent += 1
            next_t += self.period_s
            self._stop.wait(max(0.0, next_t - time.monotonic()))


def rates_setpoint(
    target_system: int,
    roll_frd: float,
    pitch_frd: float,
    yaw_frd: float,
    thrust: float,
    type_mask: int = 128,
) -> Any:
    """SET_ATTITUDE_TARGET with body rates (FRD) + thrust: PX4's type_mask 128."""
    return mavlink.MAVLink_set_attitude_target_message(
        0,
        target_system,
        1,
        type_mask,
        [1.0, 0.0, 0.0, 0.0],
        roll_frd,
        pitch_frd,
        yaw_frd,
        thrust,
    )


def hover_thrust(mass_kg: float, rotor_thrust_max_n: float) -> float:
    """Normalised thrust that balances gravity: m g / (4 f_max)."""
    return mass_kg * 9.81 / (4.0 * rotor_thrust_max_n)


def custom_main_mode(custom_mode: int) -> int:
    """PX4 main mode of a HEARTBEAT custom_mode."""
    return (custom_mode >> 16) & 0xFF


def custom_sub_mode(custom_mode: int) -> int:
    """PX4 sub mode of a HEARTBEAT custom_mode."""
    return (custom_mode >> 24) & 0xFF


def clients_on_port_block(n: int, attempts: int = 50) -> list[MavClient]:
    """n MavClients on consecutive free ports (base, base+1, ...), client k for sysid k+1."""
    rng = random.Random()
    for _ in range(attempts):
        base = rng.randrange(20000, 60000 - n)
        clients: list[MavClient] = []
        try:
            for k in range(n):
                clients.append(MavClient(base + k, target_system=k + 1))
            return clients
        except OSError:
            for c in clients:
                c.close()
    raise OSError(f"no block of {n} free ports found in {attempts} attempts")
