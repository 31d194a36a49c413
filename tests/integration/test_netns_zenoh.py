"""Zenoh between two host namespaces of the network testbed (tests/netns.py): a publisher in host
1 and a subscriber in host 2, peers on explicit TCP endpoints on the testbed's addresses with
multicast scouting off (as the per-vehicle agents of issue 30 will exchange neighbour state),
with 20 ms +- 5 ms and 10 % loss on the links."""

from __future__ import annotations

import statistics
import subprocess
import sys

import pytest

from tests.integration.netns_tools import TOOLS, result_of, wait_ready
from tests.netns import BETWEEN_AGENTS

pytestmark = [pytest.mark.integration, pytest.mark.timeout(180)]

# a dependency soon (issue 30); until pyproject names it, a clone without it says so here
pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed (pip install "
                    "'eclipse-zenoh>=1.10,<1.11')")

PY = sys.executable
COUNT = 200
INTERVAL_S = 0.02  # 50 Hz, a neighbour-state rate


def test_zenoh_samples_cross_from_host_1_to_host_2_with_the_link_delay(testbed,
                                                                       record_property):
    # GIVEN two hosts whose links send with 20 ms +- 5 ms (normal) and 10 % loss
    bed = testbed(2, BETWEEN_AGENTS)
    pub_ep = f"{bed.address(1)}:{bed.host(1).free_port('tcp')}"
    sub_ep = f"{bed.address(2)}:{bed.host(2).free_port('tcp')}"
    # AND a Zenoh peer in each: the publisher listens on host 1's address, the subscriber
    # listens on host 2's and connects to the publisher's (tcp, multicast scouting off)
    sub = bed.host(2).popen([PY, TOOLS, "zenoh-sub", "--listen", sub_ep, "--connect", pub_ep,
                             "--count", COUNT, "--timeout-s", "60"],
                            stdout=subprocess.PIPE, text=True)
    pub = bed.host(1).popen([PY, TOOLS, "zenoh-pub", "--listen", pub_ep, "--count", COUNT,
                             "--interval-s", INTERVAL_S, "--timeout-s", "30"],
                            stdout=subprocess.PIPE, text=True)
    wait_ready(sub, "zenoh-sub")
    wait_ready(pub, "zenoh-pub")
    # WHEN the publisher, once the subscriber matches, puts 200 samples at 50 Hz
    published = result_of(pub, "zenoh-pub", timeout_s=90)
    received = result_of(sub, "zenoh-sub", timeout_s=90)["samples"]
    one_way_ms = [s[1] * 1e3 for s in received]
    q = statistics.quantiles(one_way_ms, n=10)
    figures = (
        f"{bed.describe()}: matched after {published['matched_after_s']:.2f} s; "
        f"{len(received)} of {COUNT} samples; one-way ms: median "
        f"{statistics.median(one_way_ms):.1f} p10 {q[0]:.1f} p90 {q[-1]:.1f} max "
        f"{max(one_way_ms):.1f}; over 100 ms: {sum(d > 100 for d in one_way_ms)}")
    record_property("zenoh_20ms_5ms_10pct", figures)
    print(f"zenoh_20ms_5ms_10pct: {figures}")
    # THEN every sample arrives, in order (Zenoh's default reliability: TCP retransmits the
    # lost segments)
    assert [s[0] for s in received] == list(range(COUNT))
    if not bed.impaired:  # loopback: stated by the fixture's warning; no link delay there
        assert statistics.median(one_way_ms) < 5.0
        return
    # AND a typical sample takes the link's 20 ms (TCP's in-order delivery holds some behind a
    # retransmitted segment: the upper quantiles grow, the median does not move much)
    # (idle and busy machine: medians 23.5-28.6 ms, 4-20 % of samples over 100 ms)
    assert 18.0 < statistics.median(one_way_ms) < 40.0
    assert q[0] > 10.0  # a normal's p10 is 20 - 1.28 * 5 = 13.6 ms; without impairment < 1 ms
