"""How the operating system schedules `gcs fly`: the best priority it permits (`fly.scheduling`).

The control tick and the links share one asyncio thread (docs/architecture.md, "The tick"), so
the process's priority is the tick's: a busy machine (a compile, a browser, other vehicles'
simulators) that preempts the ground station makes its ticks late, and a late tick is a delayed
setpoint. Policies:

* ``realtime``: SCHED_FIFO at priority `RT_PRIORITY`. It preempts every normally scheduled
  process the moment a datagram or a tick deadline wakes it. The kernel's real-time throttling
  (sched_rt_runtime_us, 95 % of each second by default) still leaves the rest of the machine 5 %
  should the ground station ever spin. Child processes (the `--emulators` fleet) start normally
  scheduled (SCHED_RESET_ON_FORK).
* ``raised``: a nice value of `RAISED_NICE` (normal scheduling, a larger share under load).
* ``normal``: as started.
* ``auto`` (the default): realtime where permitted, else raised where permitted, else normal,
  saying which and how to grant more.

Permission: root, or the capability CAP_SYS_NICE on the Python binary
(``sudo setcap cap_sys_nice+ep "$(readlink -f .venv/bin/python)"``), or for realtime alone an
RLIMIT_RTPRIO of at least `RT_PRIORITY` (``/etc/security/limits.conf``: ``<user> - rtprio 20``,
then log in again); raised alone: an RLIMIT_NICE that allows it (``<user> - nice -10``).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

POLICIES = ("auto", "realtime", "raised", "normal")
#: SCHED_FIFO priority of `realtime` (1-99; low: above every normal process, below the kernel's
#: own real-time threads, which run at 50 and up).
RT_PRIORITY = 10
#: nice value of `raised`.
RAISED_NICE = -10
GRANT = ("grant it with root, `sudo setcap cap_sys_nice+ep \"$(readlink -f .venv/bin/python)\"`"
         f", or an rtprio limit of {RT_PRIORITY} (docs/gcs.md, \"Scheduling\")")


class SchedulingError(RuntimeError):
    """The team file asked for a policy the operating system does not permit; one line."""


@dataclass(frozen=True, slots=True)
class Scheduling:
    """What the process got: the policy in force and a line for the log and the report."""

    policy: str
    detail: str


def _realtime() -> str | None:
    """Switch to SCHED_FIFO; None if done, else why not."""
    if not hasattr(os, "sched_setscheduler") or not hasattr(os, "SCHED_FIFO"):
        return "this operating system has no SCHED_FIFO"
    flags = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
    try:
        os.sched_setscheduler(0, flags, os.sched_param(RT_PRIORITY))
    except OSError as exc:
        return f"SCHED_FIFO refused ({exc.strerror or exc})"
    return None


def _raised() -> str | None:
    """Lower the nice value to RAISED_NICE; None if done (or already there), else why not."""
    try:
        if os.getpriority(os.PRIO_PROCESS, 0) <= RAISED_NICE:
            return None
        os.setpriority(os.PRIO_PROCESS, 0, RAISED_NICE)
    except OSError as exc:
        return f"nice {RAISED_NICE} refused ({exc.strerror or exc})"
    return None


def apply_scheduling(policy: str) -> Scheduling:
    """Put this process under `policy` (module docstring). `realtime` or `raised` that the
    operating system refuses raise SchedulingError; `auto` falls back and says so."""
    if policy not in POLICIES:
        raise ValueError(f"fly.scheduling {policy!r}: expected one of {', '.join(POLICIES)}")
    if policy == "normal":
        return Scheduling("normal", "normal scheduling (fly.scheduling: normal)")
    refused = []
    if policy in ("auto", "realtime"):
        why = _realtime()
        if why is None:
            return Scheduling("realtime", f"real-time scheduling: SCHED_FIFO priority "
                                          f"{RT_PRIORITY}")
        if policy == "realtime":
            raise SchedulingError(f"fly.scheduling realtime: {why}; {GRANT}")
        refused.append(why)
    why = _raised()
    if why is None:
        return Scheduling("raised", f"raised priority: nice {os.getpriority(os.PRIO_PROCESS, 0)}"
                          + (f" ({refused[0]})" if refused else ""))
    if policy == "raised":
        raise SchedulingError(f"fly.scheduling raised: {why}; {GRANT}")
    refused.append(why)
    return Scheduling("normal", f"normal scheduling: {'; '.join(refused)}; a busy machine can "
                                f"make ticks late: {GRANT}")
