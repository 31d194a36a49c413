"""A link's TIMESYNC round trips (VehicleProxy): replies that a stopped vehicle held and then
sent together measure the stop, not the link, and stay out of the link's record."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as mavlink
from test_proxy_heartbeat import VEHICLE, _Clock, _receive

from gcs.link.config import VehicleLinkConfig
from gcs.link.proxy import VehicleProxy


def test_replies_released_together_after_a_stop_leave_the_links_round_trips():
    clock = _Clock()
    proxy = VehicleProxy(VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=0,
                                           remote_port=VEHICLE[1]), clock=clock)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)

    def request(at_s: float) -> int:  # what the proxy's timesync task sends, every 0.5 s
        clock.t_s = at_s
        ts1 = proxy.port.claim_timesync(VEHICLE, at_s, 0.5)
        assert ts1 is not None
        return ts1

    def reply(ts1: int, at_s: float) -> None:
        clock.t_s = at_s
        _receive(proxy, clock, mav.timesync_encode(1, ts1).pack(mav))

    # GIVEN a link of 4 ms round trips
    for k in range(3):
        reply(request(100.0 + 0.5 * k), 100.004 + 0.5 * k)
    # WHEN the vehicle stops for 4 s: eight requests go unanswered, then it answers them all
    # within 8 ms of each other
    held = [request(101.5 + 0.5 * k) for k in range(8)]
    for k, ts1 in enumerate(held):
        reply(ts1, 105.6 + 0.001 * k)
    # AND the link is answered as before
    for k in range(2):
        reply(request(106.0 + 0.5 * k), 106.005 + 0.5 * k)
    # THEN the link's round trips are its own five, in the clock's record and the report's
    assert list(proxy.clock.round_trips_s()) == pytest.approx([0.004] * 3 + [0.005] * 2)
    assert list(proxy.round_trips_s()) == pytest.approx([0.004] * 3 + [0.005] * 2)
    assert proxy.stats().proxy.timesync_bunched == 8
