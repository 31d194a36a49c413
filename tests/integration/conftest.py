"""Fixtures of the integration tests: ``testbed``, network testbeds (tests/netns.py) that fall
back loudly, never silently, to what the machine permits."""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from tests.netns import Impairer, Mode, Testbed, TestbedWarning, probe

#: ``namespaces`` or ``netem``: a testbed with less fails the test instead of falling back (for
#: CI on a kernel known to have network namespaces, or netem too).
REQUIRE_ENV = "NETNS_TESTBED_REQUIRE"
#: ``loopback``: every testbed in loopback mode (to see the fallback where namespaces work);
#: ``relay``: the userspace impairment even where tc netem works (to compare the two).
FORCE_ENV = "NETNS_TESTBED_FORCE"


@pytest.fixture
def testbed(record_property: Callable[[str, object], None], tmp_path: Any
            ) -> Iterator[Callable[..., Testbed]]:
    """``testbed(hosts, impairment=None, **kwargs)``: an entered ``Testbed`` (tests/netns.py),
    removed after the test whatever its outcome. Where namespaces may not be created it is a
    loopback testbed with the same interface, and where tc netem is missing the impairment is
    applied in user space: each such fallback is a ``TestbedWarning`` in pytest's warnings
    summary naming the reason, and every testbed's one-line description is recorded as the
    test's ``testbed`` property (junit XML). ``NETNS_TESTBED_REQUIRE=namespaces|netem`` turns a
    fallback into a failure; ``NETNS_TESTBED_FORCE=loopback|relay`` forces a fallback."""
    require = os.environ.get(REQUIRE_ENV, "")
    if require not in ("", "namespaces", "netem"):
        raise pytest.UsageError(f"{REQUIRE_ENV}: expected namespaces or netem, got {require!r}")
    force = os.environ.get(FORCE_ENV, "")
    forced = {"": {}, "loopback": {"mode": "loopback"}, "relay": {"impairer": "relay"}}
    if force not in forced:
        raise pytest.UsageError(f"{FORCE_ENV}: expected loopback or relay, got {force!r}")
    with contextlib.ExitStack() as stack:

        def make(hosts: int, impairment: Any = None, **kwargs: Any) -> Testbed:
            kwargs.setdefault("log_dir", tmp_path)
            kwargs.update(forced[force])
            bed = stack.enter_context(Testbed(hosts, impairment, **kwargs))
            record_property("testbed", bed.describe())
            if bed.mode is Mode.LOOPBACK or bed.impairer is Impairer.RELAY:
                record_property("testbed_capabilities", probe().describe())
            for note in bed.notes:
                warnings.warn(f"netns testbed: {note}", TestbedWarning, stacklevel=2)
            if require and bed.mode is not Mode.NAMESPACES:
                pytest.fail(f"{REQUIRE_ENV}={require}: {'; '.join(bed.notes)}")
            if require == "netem" and bed.impairer is Impairer.RELAY:
                pytest.fail(f"{REQUIRE_ENV}=netem: {'; '.join(bed.notes)}")
            return bed

        yield make
