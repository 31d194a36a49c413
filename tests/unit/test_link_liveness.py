"""gcs.link.liveness: the link state and HEARTBEAT staleness of one vehicle, on given times."""

from __future__ import annotations

import logging
import math

from gcs.link.enums import LinkState
from gcs.link.liveness import LinkLiveness

NONE = -math.inf


def test_the_link_waits_lives_and_is_lost_by_any_message_counted_once():
    live = LinkLiveness("vehicle 1", link_timeout_s=3.0, heartbeat_timeout_s=2.0, now_s=0.0)
    assert live.link_state(5.0, NONE) is LinkState.WAITING  # nothing heard: waiting, not lost
    live.check(5.0, 4.9, NONE)
    assert live.state is LinkState.ALIVE and live.alive_since_s == 5.0
    assert live.link_state(7.9, 4.9) is LinkState.ALIVE  # 3.0 s without a message: still up
    for now in (8.0, 8.5, 9.0):  # lost once, however often the monitor looks
        live.check(now, 4.9, NONE)
    assert live.state is LinkState.LOST and live.counts()["link_lost_events"] == 1
    live.check(20.0, 19.9, NONE)  # back: alive again, staleness counted from its return
    assert live.state is LinkState.ALIVE and live.alive_since_s == 20.0


def test_heartbeat_silence_counts_from_the_later_of_its_last_beat_and_the_links_return(caplog):
    live = LinkLiveness("vehicle 2", link_timeout_s=3.0, heartbeat_timeout_s=2.0, now_s=0.0)
    # a ground station that listened long before the vehicle came up: no stale call at once
    live.check(10.0, 10.0, NONE)
    assert not live.heartbeat_stale(11.5, 11.4, NONE)
    # telemetry flows, no HEARTBEAT for more than 2 s after the link came alive: stale, once
    with caplog.at_level(logging.WARNING, logger="gcs.link.proxy"):
        for now in (12.1, 12.5, 13.0):
            live.check(now, now - 0.01, NONE)
    assert live.counts()["heartbeat_stale_events"] == 1
    assert "vehicle 2: no HEARTBEAT for > 2.00 s while its other messages arrive" in caplog.text
    # a HEARTBEAT ends it; a new silence is a new event
    live.check(13.5, 13.5, 13.5)
    assert not live.heartbeat_stale(13.6, 13.6, 13.5)
    live.check(15.6, 15.6, 13.5)
    assert live.counts()["heartbeat_stale_events"] == 2
