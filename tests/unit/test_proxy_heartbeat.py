"""A vehicle's HEARTBEAT staleness (VehicleProxy.heartbeat_stale), on the proxy's own clock: it
counts from the later of the last HEARTBEAT and the link's coming alive."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

from gcs.link.config import VehicleLinkConfig
from gcs.link.enums import LinkState
from gcs.link.proxy import VehicleProxy

VEHICLE = ("127.0.0.1", 14580)


class _Clock:
    def __init__(self) -> None:
        self.t_s = 100.0

    def now_s(self) -> float:
        return self.t_s


def _proxy() -> tuple[VehicleProxy, _Clock, mavlink.MAVLink]:
    clock = _Clock()
    proxy = VehicleProxy(VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=0,
                                           remote_port=VEHICLE[1]), clock=clock)
    return proxy, clock, mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def _receive(proxy: VehicleProxy, clock: _Clock, msg) -> None:
    proxy._on_datagram(msg, VEHICLE)
    proxy._monitor_pass()  # what the monitor does at its next pass


def test_a_link_that_comes_alive_long_after_the_start_is_not_stale_before_its_first_beat():
    proxy, clock, mav = _proxy()
    position = mav.local_position_ned_encode(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # GIVEN a ground station listening for 8 s before the vehicle's first message (its start,
    # or a long compile), WHEN telemetry arrives ahead of the first 1 Hz HEARTBEAT
    clock.t_s += 8.0
    _receive(proxy, clock, position.pack(mav))
    # THEN the HEARTBEAT is not yet missed: the link has only just come alive
    assert proxy._liveness.state == LinkState.ALIVE and not proxy.heartbeat_stale()
    # AND it is, once the link has been alive for the timeout with no HEARTBEAT at all
    for _ in range(6):
        clock.t_s += 1.0
        _receive(proxy, clock, position.pack(mav))
    assert proxy.heartbeat_stale()
    # WHEN one arrives, it is fresh again, and stale after the timeout with none since
    _receive(proxy, clock, mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav))
    assert not proxy.heartbeat_stale()
    clock.t_s += 4.9
    _receive(proxy, clock, position.pack(mav))
    assert not proxy.heartbeat_stale()
    clock.t_s += 0.2
    _receive(proxy, clock, position.pack(mav))
    assert proxy.heartbeat_stale()


def test_a_link_back_from_a_loss_counts_from_its_return_not_from_the_old_heartbeat():
    proxy, clock, mav = _proxy()
    _receive(proxy, clock, mav.heartbeat_encode(2, 12, 0, 0, 3).pack(mav))
    # GIVEN a link lost for 10 s (nothing at all arrived)
    clock.t_s += 10.0
    assert proxy.link_state() == LinkState.LOST
    proxy._monitor_pass()
    assert proxy._liveness.state == LinkState.LOST
    # WHEN its telemetry comes back before its next HEARTBEAT
    _receive(proxy, clock, mav.local_position_ned_encode(0, 0, 0, 0, 0, 0, 0).pack(mav))
    # THEN the HEARTBEAT is not called stale at once
    assert proxy._liveness.state == LinkState.ALIVE and not proxy.heartbeat_stale()
    clock.t_s += 5.1
    _receive(proxy, clock, mav.local_position_ned_encode(0, 0, 0, 0, 0, 0, 0).pack(mav))
    assert proxy.heartbeat_stale()
