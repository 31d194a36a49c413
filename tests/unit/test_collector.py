"""The tick's garbage-collection pacing (gcs/fly/collector.py)."""

from __future__ import annotations

import gc

from gcs.fly.collector import MAX_DEFER, MIN_SLACK_S, YOUNG_THRESHOLD, PacedCollector


class Node:
    def __init__(self) -> None:
        self.me = self  # a cycle: only the collector frees it


def _allocate(k: int) -> None:
    for _ in range(k):
        Node()


def test_the_collector_is_off_and_the_heap_frozen_for_the_flight_only():
    assert gc.isenabled()
    with PacedCollector():
        assert not gc.isenabled()
        assert gc.get_freeze_count() > 0
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_collections_wait_for_slack_but_not_forever():
    with PacedCollector() as c:
        _allocate(2 * YOUNG_THRESHOLD)
        c.after_tick(0.1 * MIN_SLACK_S, streaming=True)  # no time left: put off
        assert c.young == c.middle == 0 and gc.get_count()[0] >= YOUNG_THRESHOLD
        c.after_tick(2 * MIN_SLACK_S, streaming=True)  # time left: the young generation
        assert c.young == 1 and gc.get_count()[0] < YOUNG_THRESHOLD
        _allocate(MAX_DEFER * YOUNG_THRESHOLD)
        c.after_tick(0.0, streaming=True)  # put off too long: now, slack or not
        assert c.young == 2


def test_while_streaming_no_full_collection_runs_and_after_it_one_does():
    with PacedCollector() as c:
        for _ in range(30):
            _allocate(YOUNG_THRESHOLD)
            c.after_tick(1.0, streaming=True)
        assert c.middle >= 2 and c.full == 0
        for _ in range(200):
            _allocate(YOUNG_THRESHOLD)
            c.after_tick(1.0, streaming=False)
        assert c.full >= 1
