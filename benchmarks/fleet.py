"""The benchmarks' fleet runner: one `vehicle-emu --fleet` for a team file, started as a
subprocess and waited for until it prints its ready line (flightkit.fleet_protocol), and
`gcs fly` flown against it, its report.json read back.

    with fleet(team, "--stats-json", str(stats)) as emu:   # returns once the fleet is ready
        flight = fly(team, out, "--mode", "rates", "--end-action", "hold")
    flight.exit, flight.report, flight.cpu_s, ...

Both programs run as `python -m` in the interpreter running the benchmark; nothing is sent
anywhere but the team file's ports (127.0.0.1 in every benchmark's team).
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flightkit.fleet_protocol import READY_PREFIX

#: the longest a fleet may take to print its ready line (it compiles first on an empty cache)
READY_TIMEOUT_S = 300.0


@dataclass
class Fleet:
    """A running `vehicle-emu --fleet` that has printed its ready line."""

    proc: subprocess.Popen
    ready_line: str

    @property
    def pid(self) -> int:
        return self.proc.pid


@contextlib.contextmanager
def fleet(team: Path, *options: str, log: Path | int | None = subprocess.DEVNULL,
          cwd: Path | None = None, python: Sequence[str] = (sys.executable,),
          log_level: str = "WARNING", ready_timeout_s: float = READY_TIMEOUT_S,
          stop_timeout_s: float = 30.0) -> Iterator[Fleet]:
    """`PYTHON -m vehicle_emulator --fleet --team TEAM --log-level LOG_LEVEL OPTIONS...` for the
    ``with`` body, entered once the fleet has printed its ready line on stdout (SystemExit if it
    exits or stays silent for ``ready_timeout_s``, with the end of its stderr). Its stderr: the
    file ``log`` (a Path), else as Popen's ``stderr`` (DEVNULL: discarded once the fleet is
    ready; None: this process's). ``cwd`` is the checkout
    whose vehicle_emulator runs (`-m` imports from the working directory first; None: this
    one). ``python`` may add interpreter options (``-m cProfile -o FILE``). On exit SIGTERM (the
    fleet then writes its --stats-json), killed after ``stop_timeout_s``."""
    cmd = [*python, "-m", "vehicle_emulator", "--fleet", "--team", str(team),
           "--log-level", log_level, *options]
    with contextlib.ExitStack() as stack:
        if isinstance(log, Path):
            err = stack.enter_context(open(log, "w+"))
        elif log == subprocess.DEVNULL:  # kept until the end to say why a fleet never got ready
            err = stack.enter_context(tempfile.TemporaryFile("w+", errors="replace"))
        else:
            err = log
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=err, text=True, cwd=cwd)
        try:
            line = _wait_ready(proc, ready_timeout_s, err)
            yield Fleet(proc, line)
        finally:
            proc.terminate()
            try:
                proc.wait(stop_timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _wait_ready(proc: subprocess.Popen, timeout_s: float, err: Any) -> str:
    """The fleet's ready line. A thread reads its stdout to the end, so a fleet that prints
    more never blocks on a full pipe. SystemExit with the end of ``err`` (its stderr, when a
    file) if none comes."""
    found: list[str] = []
    ready = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            if not ready.is_set() and line.startswith(READY_PREFIX):
                found.append(line.rstrip("\n"))
                ready.set()
        ready.set()  # end of output: the fleet exited (found stays empty if it never got ready)

    threading.Thread(target=read, daemon=True).start()
    if not ready.wait(timeout_s) or not found:
        state = "running" if proc.poll() is None else f"exited {proc.returncode}"
        tail = ""
        if hasattr(err, "seek"):
            err.seek(0)
            tail = ":\n" + "\n".join(err.read().splitlines()[-10:])
        raise SystemExit(f"vehicle-emu --fleet printed no ready line ({state}){tail}")
    return found[0]


@dataclass
class Flight:
    """One `gcs fly` run: exit status, what it printed, its resources, the report."""

    exit: int
    stdout: str  # stdout and stderr interleaved when flown with merged=True
    stderr: str
    wall_s: float  # from the process start to its exit
    cpu_s: float  # user + system CPU of gcs fly
    rss_mb: float  # its largest resident set
    out: Path
    report: dict | None  # out/report.json, None when gcs fly wrote none


def fly(team: Path, out: Path, *options: str, merged: bool = False,
        timeout_s: float = 900.0) -> Flight:
    """`python -m gcs.cli fly --team TEAM --out OUT --no-figures --status off OPTIONS...` to its
    exit (killed, and subprocess.TimeoutExpired raised, after ``timeout_s``). Its output goes to
    unnamed files, never a pipe read at the end: a flight that stops 240 vehicles logs more than
    a pipe holds, and a writer blocked on a full pipe stops flying."""
    cmd = [sys.executable, "-m", "gcs.cli", "fly", "--team", str(team), "--out", str(out),
           "--no-figures", "--status", "off", *options]
    with (tempfile.TemporaryFile("w+", errors="replace") as stdout,
          tempfile.TemporaryFile("w+", errors="replace") as stderr):
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, stdout=stdout,
                                stderr=subprocess.STDOUT if merged else stderr)
        killed = threading.Event()

        def kill() -> None:
            killed.set()
            proc.kill()

        timer = threading.Timer(timeout_s, kill)
        timer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)  # its rusage, which Popen.wait drops
        finally:
            timer.cancel()
        wall = time.monotonic() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here, not by Popen
        if killed.is_set():
            raise subprocess.TimeoutExpired(cmd, timeout_s)
        stdout.seek(0)
        stderr.seek(0)
        printed, logged = stdout.read(), stderr.read()
    report = out / "report.json"
    return Flight(exit=proc.returncode, stdout=printed, stderr=logged, wall_s=wall,
                  cpu_s=usage.ru_utime + usage.ru_stime, rss_mb=usage.ru_maxrss / 1024.0,
                  out=out, report=json.loads(report.read_text()) if report.exists() else None)
