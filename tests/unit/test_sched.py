"""Process scheduling (flightkit/sched.py) as the ground station (gcs/fly/sched.py) and
`vehicle-emu` (vehicle_emulator/fleet/command.py) ask for it, applied in a child process (never to the test runner), as the
user running the tests and, where the tests run as root, as an unprivileged user (setpriv), for
whom the operating system refuses both raises."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from flightkit.sched import EMU_RAISED_NICE, EMU_RT_PRIORITY
from gcs.fly.sched import POLICIES, RAISED_NICE, RT_PRIORITY, apply_scheduling

PROBE = """
import json, os, sys
from gcs.fly.sched import SchedulingError, apply_scheduling
from flightkit import sched
try:
    if sys.argv[2] == "gcs":
        s = apply_scheduling(sys.argv[1])
    else:
        s = sched.apply_scheduling(sys.argv[1], sched.EMULATOR)
    out = {"policy": s.policy, "detail": s.detail}
except SchedulingError as exc:
    out = {"error": str(exc)}
out["fifo"] = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0) == os.SCHED_FIFO
out["priority"] = os.sched_getparam(0).sched_priority
out["nice"] = os.getpriority(os.PRIO_PROCESS, 0)
print(json.dumps(out))
"""
ROOT = os.geteuid() == 0


def probe(policy: str, *, unprivileged: bool = False, program: str = "gcs") -> dict:
    cmd = [sys.executable, "-c", PROBE, policy, program]
    if unprivileged:  # nobody, no capabilities, no rtprio limit
        cmd = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", "--inh-caps=-all",
               *cmd]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=60, env=env, check=True)
    return json.loads(done.stdout)


def test_each_policy_gets_what_it_says():
    out = probe("auto")
    if out["policy"] == "realtime":
        assert out["fifo"] and out["priority"] == RT_PRIORITY
        assert out["detail"] == f"real-time scheduling: SCHED_FIFO priority {RT_PRIORITY}"
    elif out["policy"] == "raised":
        assert not out["fifo"] and out["nice"] <= RAISED_NICE
    else:
        assert not out["fifo"] and "grant it with root" in out["detail"]
    if ROOT:
        assert out["policy"] == "realtime", out  # root may
    normal = probe("normal")
    assert normal["policy"] == "normal" and not normal["fifo"]
    assert normal["nice"] == os.getpriority(os.PRIO_PROCESS, 0)


@pytest.mark.skipif(not (ROOT and shutil.which("setpriv")),
                    reason="needs root to run a child as an unprivileged user")
def test_an_unprivileged_user_falls_back_and_is_told_how_to_grant_more():
    out = probe("auto", unprivileged=True)
    assert out["policy"] == "normal" and not out["fifo"]
    assert out["detail"].startswith("normal scheduling: SCHED_FIFO refused (Operation not "
                                    "permitted); nice -10 refused (Permission denied)")
    assert "setcap cap_sys_nice+ep" in out["detail"]
    # asked for explicitly, a refusal is an error naming the policy and the way to grant it
    out = probe("realtime", unprivileged=True)
    assert out["error"].startswith("fly.scheduling realtime: SCHED_FIFO refused (Operation "
                                   "not permitted); grant it with root")
    assert probe("raised", unprivileged=True)["error"].startswith(
        "fly.scheduling raised: nice -10 refused (Permission denied)")


def test_an_unknown_policy_is_a_value_error():
    assert POLICIES == ("auto", "realtime", "raised", "normal")
    with pytest.raises(ValueError, match=r"fly.scheduling 'fast': expected one of auto, "):
        apply_scheduling("fast")


def test_the_emulator_asks_one_step_below_the_ground_station():
    # the ground station's tick preempts the vehicles' stand-in on a shared core, and the
    # stand-in preempts (or outweighs) every normally scheduled process
    assert 1 <= EMU_RT_PRIORITY < RT_PRIORITY
    assert RAISED_NICE < EMU_RAISED_NICE < 0
    # auto is raised, never real-time (sched.EMULATOR); realtime only by name
    out = probe("auto", program="emulator")
    assert not out["fifo"] and out["policy"] in ("raised", "normal"), out
    if ROOT:
        assert out["policy"] == "raised" and out["nice"] == EMU_RAISED_NICE, out
        assert out["detail"] == f"raised priority: nice {EMU_RAISED_NICE}"
        fifo = probe("realtime", program="emulator")
        assert fifo["policy"] == "realtime" and fifo["fifo"], fifo
        assert fifo["priority"] == EMU_RT_PRIORITY
        assert fifo["detail"] == f"real-time scheduling: SCHED_FIFO priority {EMU_RT_PRIORITY}"


@pytest.mark.skipif(not (ROOT and shutil.which("setpriv")),
                    reason="needs root to run a child as an unprivileged user")
def test_the_emulators_refusals_name_its_option_and_how_to_grant_it():
    out = probe("auto", unprivileged=True, program="emulator")
    assert out["policy"] == "normal" and not out["fifo"]
    assert out["detail"].startswith(
        "normal scheduling: nice -5 refused (Permission denied); a busy machine can make the "
        "vehicles' answers late: grant it with root")
    out = probe("realtime", unprivileged=True, program="emulator")
    assert out["error"].startswith("--scheduling realtime: SCHED_FIFO refused (Operation not "
                                   "permitted); grant it with root")
    assert "a nice limit of -5 (an rtprio limit of 9 for realtime; docs/emulator.md" in out["error"]


LEAVE = """
import json, os, threading
from gcs.fly.sched import apply_scheduling, leave_realtime
first = apply_scheduling("auto").policy
stop = threading.Event()
worker = threading.Thread(target=stop.wait)
worker.start()
from flightkit.sched import share_with_threads
share_with_threads()
def fifo(tid):
    return os.sched_getscheduler(tid) & ~getattr(os, "SCHED_RESET_ON_FORK", 0) == os.SCHED_FIFO
before = [fifo(t) for t in (0, worker.native_id)]
left = leave_realtime()
after = [fifo(t) for t in (0, worker.native_id)]
stop.set()
worker.join()
print(json.dumps({"first": first, "before": before, "left": left, "after": after,
                  "again": leave_realtime()}))
"""


def test_leaving_realtime_puts_every_thread_back_under_normal_scheduling():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    done = subprocess.run([sys.executable, "-c", LEAVE], capture_output=True, text=True,
                          timeout=60, env=env, check=True)
    out = json.loads(done.stdout)
    # a process that was real-time (both its threads) is normal after, and says so once
    assert out["after"] == [False, False] and out["again"] is False, out
    assert out["left"] == (out["first"] == "realtime") == all(out["before"]), out
    if ROOT:
        assert out["first"] == "realtime" and out["left"], out
