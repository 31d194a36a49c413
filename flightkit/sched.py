"""Process scheduling: the best priority the operating system permits, for a process whose timing
is what it delivers. The ground station's tick (gcs/fly/sched.py) and the emulator's vehicles (a
stand-in for autopilots that each have a processor of their own) both use it, the emulator one
step below the ground station.

Policies:

* ``realtime``: SCHED_FIFO at the caller's priority (with SCHED_RESET_ON_FORK: children start
  normally scheduled). It preempts every normally scheduled process the moment a datagram or a
  deadline wakes it. The kernel's real-time throttling (sched_rt_runtime_us, 95 % of each second
  by default) still leaves the rest of the machine 5 % should the process ever spin.
* ``raised``: the caller's nice value (normal scheduling, a larger share under load).
* ``normal``: as started.
* ``auto``: realtime where permitted (if the request says so: the ground station's does, the
  emulator's does not), else raised where permitted, else normal, saying which and how to grant
  more.

Permission: root, or the capability CAP_SYS_NICE on the Python binary
(``sudo setcap cap_sys_nice+ep "$(readlink -f .venv/bin/python)"``), or for realtime alone an
RLIMIT_RTPRIO of at least the priority (``/etc/security/limits.conf``: ``<user> - rtprio 20``,
then log in again); raised alone: an RLIMIT_NICE that allows it (``<user> - nice -10``).
"""

from __future__ import annotations

import contextlib
import os
import threading
from dataclasses import dataclass

POLICIES = ("auto", "realtime", "raised", "normal")


class SchedulingError(RuntimeError):
    """A policy asked for by name that the operating system does not permit; one line."""


@dataclass(frozen=True, slots=True)
class Scheduling:
    """What the process got: the policy in force and a line for the log and the report."""

    policy: str
    detail: str


@dataclass(frozen=True, slots=True)
class Request:
    """What a program asks for: ``option`` names its setting in messages (``fly.scheduling``);
    ``rt_priority`` the SCHED_FIFO priority of realtime (1-99), ``nice`` the value of raised,
    ``grant`` the end of a refusal: how to grant it; ``timing`` what a busy machine makes late
    without it; ``auto_realtime`` whether ``auto`` tries realtime first (else raised only)."""

    option: str
    rt_priority: int
    nice: int
    grant: str
    timing: str
    auto_realtime: bool = True


#: SCHED_FIFO priority of `vehicle-emu --scheduling realtime`: one below the ground station's (10),
#: so that on a shared core its tick preempts the emulator, and the emulator every normal process.
EMU_RT_PRIORITY = 9
#: nice value of `vehicle-emu --scheduling raised` (the ground station's is -10).
EMU_RAISED_NICE = -5
#: what `vehicle-emu` asks for (vehicle_emulator/fleet/command.py). Its `auto` is raised, not
#: realtime: beside other real-time processes (several flights of a test run, each ground station
#: at SCHED_FIFO 10) a SCHED_FIFO stand-in takes its core from everything normally scheduled, the
#: ground stations' own start-up and the tests' clients included, and same-priority FIFO tasks do
#: not share a core; realtime stays available by name.
EMULATOR = Request(
    "--scheduling", EMU_RT_PRIORITY, EMU_RAISED_NICE,
    "grant it with root, `sudo setcap cap_sys_nice+ep \"$(readlink -f .venv/bin/python)\"`, or "
    f"a nice limit of {EMU_RAISED_NICE} (an rtprio limit of {EMU_RT_PRIORITY} for realtime; "
    "docs/emulator.md, \"Scheduling\")",
    "the vehicles' answers",
    auto_realtime=False,
)


def _realtime(priority: int) -> str | None:
    """Switch to SCHED_FIFO at ``priority``; None if done, else why not."""
    if not hasattr(os, "sched_setscheduler") or not hasattr(os, "SCHED_FIFO"):
        return "this operating system has no SCHED_FIFO"
    flags = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
    try:
        os.sched_setscheduler(0, flags, os.sched_param(priority))
    except OSError as exc:
        return f"SCHED_FIFO refused ({exc.strerror or exc})"
    return None


def _raised(nice: int) -> str | None:
    """Lower the nice value to ``nice``; None if done (or already there), else why not."""
    try:
        if os.getpriority(os.PRIO_PROCESS, 0) <= nice:
            return None
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except OSError as exc:
        return f"nice {nice} refused ({exc.strerror or exc})"
    return None


def apply_scheduling(policy: str, request: Request) -> Scheduling:
    """Put this process under ``policy`` (module docstring). ``realtime`` or ``raised`` that the
    operating system refuses raise SchedulingError; ``auto`` falls back and says so."""
    if policy not in POLICIES:
        raise ValueError(f"{request.option} {policy!r}: expected one of {', '.join(POLICIES)}")
    if policy == "normal":
        return Scheduling("normal", f"normal scheduling ({request.option}: normal)")
    refused = []
    if policy == "realtime" or (policy == "auto" and request.auto_realtime):
        why = _realtime(request.rt_priority)
        if why is None:
            return Scheduling("realtime", "real-time scheduling: SCHED_FIFO priority "
                                          f"{request.rt_priority}")
        if policy == "realtime":
            raise SchedulingError(f"{request.option} realtime: {why}; {request.grant}")
        refused.append(why)
    why = _raised(request.nice)
    if why is None:
        return Scheduling("raised", f"raised priority: nice {os.getpriority(os.PRIO_PROCESS, 0)}"
                          + (f" ({refused[0]})" if refused else ""))
    if policy == "raised":
        raise SchedulingError(f"{request.option} raised: {why}; {request.grant}")
    refused.append(why)
    return Scheduling("normal", f"normal scheduling: {'; '.join(refused)}; a busy machine can "
                                f"make {request.timing} late: {request.grant}")


def share_with_threads() -> int:
    """Give every other thread of this process the calling thread's scheduling (policy and
    priority, nice value): threads a library started before or beside `apply_scheduling` (a
    network stack's receive threads) otherwise run at normal priority and wait behind every
    real-time process of a busy machine. Returns how many threads took it; 0 where the
    operating system lists no threads (/proc/self/task) or refuses."""
    try:
        tids = [int(t) for t in os.listdir("/proc/self/task")]
        policy = os.sched_getscheduler(0)
        param = os.sched_getparam(0)
        nice = os.getpriority(os.PRIO_PROCESS, 0)
    except (OSError, AttributeError):
        return 0
    me = threading.get_native_id()
    done = 0
    for tid in tids:
        if tid == me:
            continue
        try:
            os.sched_setscheduler(tid, policy, param)
            os.setpriority(os.PRIO_PROCESS, tid, nice)
        except OSError:  # the thread ended meanwhile, or the OS refuses
            continue
        done += 1
    return done


def leave_realtime() -> bool:
    """Put every thread of this process back under normal scheduling (SCHED_OTHER; the nice value
    stays) if the process is real-time: for the work after the timed part (records, figures),
    which at SCHED_FIFO would take a core from every normally scheduled process for as long as it
    computes. Returns whether it was real-time. Leaving real-time needs no permission."""
    try:
        policy = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
        if policy not in (os.SCHED_FIFO, os.SCHED_RR):
            return False
        tids = [int(t) for t in os.listdir("/proc/self/task")]
    except (OSError, AttributeError):
        return False
    for tid in tids:
        with contextlib.suppress(OSError):  # the thread ended meanwhile
            os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
    return True
