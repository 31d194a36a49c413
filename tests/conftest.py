"""Suite-wide hooks.

The parallel stage (`make test`: pytest-xdist, `--dist loadfile`) hands whole files to the
workers in collection order, each to the first worker free. The files below fly in real time or
compile from an empty cache and take a minute to several minutes each; collected first, they
start at once and the many short files fill the gaps, instead of one of them starting last and
running alone at the end (the longest-first rule of scheduling). Figures: junit times of an idle
run, seconds per file.

numba's cache is pointed at the current sources here, before any test module imports compiled
code (flightkit/jitcache.py), as the programs' entry points do.
"""

from __future__ import annotations

import pytest

from flightkit import jitcache

jitcache.configure()

LONGEST_FIRST = (
    "tests/integration/test_first_run.py",  # 393 (empty-cache compiles)
    "tests/integration/test_fly_confirmed.py",  # 296
    "tests/integration/test_fly_emulator.py",  # 255
    "tests/integration/test_emulator_mavlink.py",  # 187
    "tests/integration/test_fly_attitude_mode.py",  # 134
    "tests/integration/test_fly_go_to_start.py",  # 130
    "tests/integration/test_fly_mixed.py",  # 98
    "tests/integration/test_fly_confirmed_ardupilot.py",  # 92
    "tests/integration/test_emulator_team_file.py",  # 84
    "tests/unit/test_calibration.py",  # 82
    "tests/integration/test_emulator_ardupilot.py",  # 79
    "tests/integration/test_fly_ardupilot.py",  # 70
)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {path: k for k, path in enumerate(LONGEST_FIRST)}
    last = len(LONGEST_FIRST)
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], last))
