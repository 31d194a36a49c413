"""How the operating system schedules `gcs fly`: the best priority it permits (`fly.scheduling`).

The control tick and the links share one asyncio thread (docs/architecture.md, "The tick"), so
the process's priority is the tick's: a busy machine (a compile, a browser, other vehicles'
simulators) that preempts the ground station makes its ticks late, and a late tick is a delayed
setpoint. The policies (auto, realtime, raised, normal) and the ways to grant them are
flightkit/sched.py's; the ground station asks for SCHED_FIFO priority `RT_PRIORITY` or
nice `RAISED_NICE`, one step above what `vehicle-emu` asks for, so that on a shared core the
tick preempts the vehicles' stand-in. Child processes (the `--emulators` fleet) start normally
scheduled (SCHED_RESET_ON_FORK) and ask for their own.
"""

from __future__ import annotations

from flightkit.sched import (
    POLICIES,
    Request,
    Scheduling,
    SchedulingError,
    leave_realtime,
    share_with_threads,
)
from flightkit.sched import apply_scheduling as _apply

__all__ = ["GRANT", "POLICIES", "RAISED_NICE", "RT_PRIORITY", "Scheduling", "SchedulingError",
           "apply_scheduling", "leave_realtime", "share_with_threads"]

#: SCHED_FIFO priority of `realtime` (1-99; low: above every normal process, below the kernel's
#: own real-time threads, which run at 50 and up).
RT_PRIORITY = 10
#: nice value of `raised`.
RAISED_NICE = -10
GRANT = ("grant it with root, `sudo setcap cap_sys_nice+ep \"$(readlink -f .venv/bin/python)\"`"
         f", or an rtprio limit of {RT_PRIORITY} (docs/gcs.md, \"Scheduling\")")
_REQUEST = Request("fly.scheduling", RT_PRIORITY, RAISED_NICE, GRANT, "ticks")


def apply_scheduling(policy: str) -> Scheduling:
    """Put this process under `policy`. `realtime` or `raised` that the operating system
    refuses raise SchedulingError; `auto` falls back and says so."""
    return _apply(policy, _REQUEST)
