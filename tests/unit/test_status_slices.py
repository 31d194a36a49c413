"""The mission's statuses: built whole for a small team, a slice per tick for a large one, and
`vehicle_statuses(rows=...)` is the whole call's rows."""

from __future__ import annotations

import asyncio
import socket

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from gcs.fly.measure import TeamSample
from gcs.fly.telemetry import STATUS_SLICED_ABOVE, StatusSlices, vehicle_statuses
from gcs.link import HotTable
from gcs.link.config import VehicleLinkConfig
from gcs.link.port import MavlinkPort
from gcs.link.proxy import VehicleProxy
from gcs.mission.safety import VehicleStatus


def _status(i: int, k: int) -> VehicleStatus:
    return VehicleStatus(vehicle_id=i + 1, sysid=i + 1, link="alive", tilt_rad=float(k))


def _run(slices: StatusSlices, n: int, ticks: int) -> list[tuple[int, list[VehicleStatus]]]:
    """Tick 0..ticks-1 building what `rows` asks (a status's tilt = the tick it was built at);
    returns (tick, statuses) of every check."""
    checks = []
    for k in range(ticks):
        rows = slices.rows(k)
        built_rows = range(n) if rows is None else rows
        slices.store(rows, [_status(i, k) for i in built_rows])
        if slices.due(k):
            checks.append((k, slices.latest()))
    return checks


def test_a_small_team_is_built_whole_at_each_check_and_not_between():
    n, every = STATUS_SLICED_ABOVE, 5
    slices = StatusSlices(n, every)
    assert [slices.rows(k) for k in range(1, every)] == [[]] * (every - 1)
    for k, statuses in _run(slices, n, 23):
        assert [s.vehicle_id for s in statuses] == list(range(1, n + 1))
        assert {s.tilt_rad for s in statuses} == {k}  # all built at the check itself


def test_a_large_team_is_built_a_slice_per_tick_and_checked_whole():
    n, every = 240, 5
    slices = StatusSlices(n, every)
    assert slices.rows(0) is None  # the first check: everyone
    slices.store(None, [_status(i, 0) for i in range(n)])
    built_at = {k: slices.rows(k) for k in range(1, every + 1)}
    assert sorted(i for k in range(1, every + 1) for i in built_at[k]) == list(range(n))
    assert all(len(r) == n // every for r in built_at.values())  # the same cost every tick
    checks = _run(StatusSlices(n, every), n, 31)
    assert [k for k, _ in checks] == [0, 5, 10, 15, 20, 25, 30]
    assert {s.tilt_rad for s in checks[0][1]} == {0}  # the first check: everyone at once
    for k, statuses in checks[1:]:
        assert [s.vehicle_id for s in statuses] == list(range(1, n + 1))
        ages = {k - s.tilt_rad for s in statuses}
        assert ages == set(range(every))  # each vehicle as of at most every - 1 ticks before


def test_a_check_before_every_status_was_built_is_an_error():
    slices = StatusSlices(40, 5)
    slices.store([0, 5], [_status(0, 1), _status(5, 1)])
    with pytest.raises(AssertionError, match="before every vehicle"):
        slices.latest()


def test_statuses_of_some_rows_are_those_rows_of_the_whole_team():
    asyncio.run(asyncio.wait_for(_rows_equal_whole(), 20.0))


async def _rows_equal_whole() -> None:
    n = 4
    table = HotTable(n)
    async with MavlinkPort(0, table=table) as port:
        gcs_port = port.local_address[1]
        socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
        for s in socks:
            s.bind(("127.0.0.1", 0))
        cfgs = [VehicleLinkConfig(vehicle_id=10 + i, sysid=i + 1, local_port=gcs_port,
                                  remote_port=socks[i].getsockname()[1]) for i in range(n)]
        proxies = [VehicleProxy(c, port=port, slot=i) for i, c in enumerate(cfgs)]
        for p in proxies:
            await p.__aenter__()
        try:
            for i, s in enumerate(socks):  # armed/disarmed, landed states and heights differ
                mav = mavlink.MAVLink(None, srcSystem=i + 1, srcComponent=1)
                for m in (mav.heartbeat_encode(2, 12, 1 | (128 if i % 2 else 0), 393216, 4),
                          mav.extended_sys_state_encode(0, 1 + i % 2),
                          mav.global_position_int_encode(1000, 0, 0, 0, 1000 * i, 0, 0, 0, 0)):
                    s.sendto(m.pack(mav), ("127.0.0.1", gcs_port))
            for _ in range(100):
                await asyncio.sleep(0.01)
                if all(p.latest("GLOBAL_POSITION_INT") is not None for p in proxies):
                    break
            rng = np.random.default_rng(1)
            sample = TeamSample(
                rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), np.zeros((n, 3)),
                np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.full(n, 0.01),
                np.full(n, 0.01), np.ones(n, dtype=bool), np.full(n, 0.02), np.full(n, 0.02),
                np.zeros(n), np.zeros(n))
            ids = [c.vehicle_id for c in cfgs]
            whole = vehicle_statuses(proxies, ids, sample, (), table=table)
            some = vehicle_statuses(proxies, ids, sample, (), table=table, rows=[3, 1])
            assert some == [whole[3], whole[1]]
            assert [s.armed for s in whole] == [False, True, False, True]
            assert [s.height_above_home_m for s in whole] == [0.0, 1.0, 2.0, 3.0]
        finally:
            for p in proxies:
                await p.__aexit__(None, None, None)
            for s in socks:
                s.close()
