"""The link's hot path (gcs.link.fastpath): batch decode against pymavlink's, the slow path's
share of what it does not accept, sequence counting as SequenceTracker's, and the team's setpoints
packed byte for byte as pymavlink packs them; then a shared port over real UDP sockets."""

from __future__ import annotations

import asyncio
import contextlib
import math
import socket
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from gcs.fly.telemetry import team_sample
from gcs.link import HotTable, MavlinkPort, TlogWriter, VehicleLinkConfig, VehicleProxy
from gcs.link.fastpath import (
    ANY_ADDRESS,
    ATTQ,
    EXTENDED_SYS_STATE,
    GLOBAL_POSITION_INT,
    IMU,
    LANDED_STATE,
    LPN,
    RELATIVE_ALT_M,
    SENSORS_HEALTH,
    SENSORS_PRESENT,
    SYS_STATUS,
    TABLE_NAMES,
    TARGET_THRUST,
    UNLEARNED,
    Datagrams,
    HotRow,
    Routing,
    crc_extra_table,
    encode_set_attitude_target,
    kind_table,
    scan,
    warm_up,
)
from gcs.link.port import HOT_NOTICE_S
from gcs.link.setpoints import TeamSetpoints
from gcs.link.telemetry import SequenceStats, SequenceTracker, TypeStats


def _sender(sysid: int = 3, compid: int = 1) -> mavlink.MAVLink:
    return mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)


def _pack(mav: mavlink.MAVLink, msg: mavlink.MAVLink_message) -> bytes:
    data = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return data


class _Scanner:
    """A table of ``n`` slots and the arrays scan needs; sysid s -> slot s - 1."""

    def __init__(self, n: int = 4, compid: int = 1, address: int = ANY_ADDRESS) -> None:
        self.t = HotTable(n)
        self.slot_of_sysid = np.full(256, -1, dtype=np.int64)
        for k in range(n):
            self.slot_of_sysid[k + 1] = k
        self.t.compid_of_slot[:] = compid
        self.t.addr_of_slot[:] = address
        self.crc, self.kinds = crc_extra_table(), kind_table()

    def __call__(self, datagrams: list[bytes], rx_s: float = 10.0,
                 codes: list[int] | None = None) -> tuple[list[tuple[int, bytes, int]], bytes]:
        """Slow ranges as (datagram, bytes, seq_counted) and the tlog bytes."""
        buf = b"".join(datagrams)
        offs = np.cumsum([0] + [len(d) for d in datagrams[:-1]]).astype(np.int64)
        lens = np.array([len(d) for d in datagrams], dtype=np.int64)
        addr = np.array(codes if codes is not None else [0] * len(datagrams), dtype=np.int64)
        tlog = np.zeros(2 * len(buf) + 64, dtype=np.uint8)
        slow = np.zeros((len(buf) // 12 + len(datagrams), 4), dtype=np.int64)
        t = self.t
        n_slow, t_len, _ = scan(
            Datagrams(np.frombuffer(buf, dtype=np.uint8), offs, lens, addr,
                      np.full(len(datagrams), rx_s), 1_700_000_000_000_000),
            Routing(self.slot_of_sysid, t.compid_of_slot, t.addr_of_slot, self.crc, self.kinds),
            t.arrays, tlog, slow)
        return ([(int(d), buf[s:e], int(c)) for d, s, e, c in slow[:n_slow]],
                tlog[:t_len].tobytes())


def test_the_hot_messages_decode_as_pymavlink_decodes_them() -> None:
    rng = np.random.default_rng(7)
    mav = _sender()
    scanner = _Scanner()
    for _ in range(20):
        v = rng.normal(size=12).astype(np.float32).tolist()
        boot = int(rng.integers(0, 2**32))
        q = np.asarray(v[:4]) / np.linalg.norm(v[:4])
        msgs = [mavlink.MAVLink_local_position_ned_message(boot, *v[:6]),
                mavlink.MAVLink_attitude_quaternion_message(boot, *q, *v[4:7], [0.0] * 4),
                mavlink.MAVLink_highres_imu_message(int(rng.integers(0, 2**50)), *v[6:9],
                                                    *([0.0] * 10), 0, 0),
                mavlink.MAVLink_extended_sys_state_message(0, int(rng.integers(0, 5))),
                mavlink.MAVLink_sys_status_message(int(rng.integers(0, 2**31)), 0,
                                                   int(rng.integers(0, 2**31)), *([0] * 9), 0),
                mavlink.MAVLink_global_position_int_message(boot, 1, 2, 3,
                                                            int(rng.integers(-10**6, 10**6)),
                                                            0, 0, 0, 0),
                mavlink.MAVLink_attitude_target_message(boot, 7, list(q), 0.0, 0.0, 0.0,
                                                        float(rng.random()))]
        frames = [_pack(mav, m) for m in msgs]
        slow, _ = scanner([b"".join(frames)])
        assert slow == []
        t = scanner.t
        parser = mavlink.MAVLink(None)
        lpn, attq, imu, ess, sys, gpi, at = (parser.decode(bytearray(f)) for f in frames)
        np.testing.assert_array_equal(t.lpn[2], [lpn.time_boot_ms * 1e-3, lpn.x, lpn.y, lpn.z,
                                                  lpn.vx, lpn.vy, lpn.vz])
        np.testing.assert_array_equal(t.attq[2], [attq.time_boot_ms * 1e-3, attq.q1, attq.q2,
                                                   attq.q3, attq.q4, attq.rollspeed,
                                                   attq.pitchspeed, attq.yawspeed])
        np.testing.assert_array_equal(t.imu[2], [imu.time_usec * 1e-6, imu.xacc, imu.yacc,
                                                  imu.zacc])
        assert t.misc[2, LANDED_STATE] == ess.landed_state
        assert t.misc[2, SENSORS_PRESENT] == sys.onboard_control_sensors_present
        assert t.misc[2, SENSORS_HEALTH] == sys.onboard_control_sensors_health
        assert t.misc[2, RELATIVE_ALT_M] == pytest.approx(gpi.relative_alt * 1e-3, abs=1e-12)
        assert t.misc[2, TARGET_THRUST] == at.thrust
        for k, f in zip((LPN, ATTQ, IMU, EXTENDED_SYS_STATE, SYS_STATUS, GLOBAL_POSITION_INT),
                        frames, strict=False):
            assert t.frame(2, k) == f
    assert t.count[2, :7].tolist() == [20] * 7
    assert t.count[[0, 1, 3]].sum() == 0


def test_a_row_reads_as_its_vehicles_telemetry_once_its_address_is_learned() -> None:
    scanner, mav = _Scanner(), _sender()
    row = HotRow(scanner.t, 2, compid=1, learn_remote=True)

    def position(x_m: float, rx_s: float) -> bytes:
        frame = _pack(mav, mavlink.MAVLink_local_position_ned_message(int(rx_s * 1e3), x_m, 0,
                                                                      0, 0, 0, 0))
        slow, _ = scanner([frame], rx_s=rx_s)
        return frame if not slow else b""

    # GIVEN a row bound to a vehicle whose address is to be learned: nothing is held for it
    assert position(1.0, 10.0) == b""
    assert row.latest("LOCAL_POSITION_NED") is None and row.accepted() == 0
    assert row.rate_hz("LOCAL_POSITION_NED") is None and row.last_any_rx_s() == -math.inf
    # WHEN its address is learned and three positions arrive 0.1 s apart
    row.learned(0)
    frames = [position(x, 10.1 + 0.1 * x) for x in (1.0, 2.0, 3.0)]
    # THEN the latest is the last frame decoded, with its receive time, decoded once
    got = row.latest("LOCAL_POSITION_NED")
    assert got is not None and got.rx_time_s == pytest.approx(10.4) and got.msg.x == 3.0
    assert bytes(got.msg.get_msgbuf()) == frames[-1]
    assert row.latest("LOCAL_POSITION_NED") is got
    # AND a kind the table does not hold, or one not arrived, is for the proxy's cache
    assert row.latest("HEARTBEAT") is None and row.latest("SYS_STATUS") is None
    assert row.rate_hz("HEARTBEAT") is None
    assert row.rate_hz("LOCAL_POSITION_NED") == pytest.approx(10.0)
    assert row.accepted() == 3 and row.last_any_rx_s() == pytest.approx(10.4)
    # AND its counts add to the slow path's
    assert row.sequence_stats(SequenceStats(2, 1, 0, 0)) == SequenceStats(5, 1, 0, 0)
    slow = {"LOCAL_POSITION_NED": TypeStats(1, 11.0, 1.0), "HEARTBEAT": TypeStats(2, 9.0, 1.0)}
    merged = row.type_stats(slow)
    assert merged["HEARTBEAT"] == slow["HEARTBEAT"]
    assert merged["LOCAL_POSITION_NED"].count == 4
    assert merged["LOCAL_POSITION_NED"].last_rx_s == 11.0
    assert merged["LOCAL_POSITION_NED"].rate_hz == pytest.approx(10.0)
    # AND the clock filter is given the stamps of the messages since the last notice
    samples: list[tuple[float, float]] = []
    row.feed_clock(lambda t_s, rx_s: samples.append((t_s, rx_s)))
    assert samples[-1] == pytest.approx((10.4, 10.4))
    # WHEN its rate is restarted, THEN it is unknown until measured again
    row.restart_rate("LOCAL_POSITION_NED")
    assert math.isnan(row.rate_hz("LOCAL_POSITION_NED"))


def test_frames_it_does_not_accept_go_to_the_slow_path_whole_and_untouched() -> None:
    good = _pack(_sender(), mavlink.MAVLink_local_position_ned_message(1, 1, 2, 3, 0, 0, 0))
    heartbeat = _pack(_sender(), mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3))
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    other_comp = _pack(_sender(3, 2), mavlink.MAVLink_local_position_ned_message(1, 0, 0, 0,
                                                                                 0, 0, 0))
    stranger = _pack(_sender(99), mavlink.MAVLink_local_position_ned_message(1, 0, 0, 0, 0, 0,
                                                                             0))
    v1 = mavlink.MAVLink_local_position_ned_message(1, 0, 0, 0, 0, 0, 0).pack(
        _sender(), force_mavlink1=True)
    cut = good[:-5]
    scanner = _Scanner()
    slow, tlog = scanner([good + heartbeat, bytes(bad_crc), other_comp + stranger, v1, cut,
                          b"garbage" + good])
    assert slow == [(0, heartbeat, 1), (1, bytes(bad_crc), 0), (2, other_comp + stranger, 0),
                    (3, v1, 0), (4, cut, 0), (5, b"garbage" + good, 0)]
    assert scanner.t.count[2, LPN] == 1  # the first datagram's, nothing else
    assert tlog[8:] == good  # big-endian microseconds, then the frame
    assert int.from_bytes(tlog[:8], "big") == 1_700_000_000_000_000


def test_an_unlearned_or_other_address_goes_the_slow_way() -> None:
    lpn = _pack(_sender(), mavlink.MAVLink_local_position_ned_message(1, 1, 2, 3, 0, 0, 0))
    scanner = _Scanner(address=UNLEARNED)
    slow, _ = scanner([lpn])
    assert slow == [(0, lpn, 0)]
    scanner.t.addr_of_slot[2] = 5
    slow, _ = scanner([lpn, lpn], codes=[4, 5])
    assert slow == [(0, lpn, 0)]
    assert scanner.t.count[2, LPN] == 1


def test_a_vehicles_timesync_request_is_kept_and_a_reply_goes_to_the_proxy() -> None:
    mav = _sender()
    request = _pack(mav, mavlink.MAVLink_timesync_message(0, 123))
    reply = _pack(mav, mavlink.MAVLink_timesync_message(456, 123))
    scanner = _Scanner()
    slow, _ = scanner([request, reply])
    assert slow == [(1, reply, 1)]
    assert scanner.t.count[2, TABLE_NAMES.index("TIMESYNC")] == 1


def test_sequence_numbers_are_counted_as_the_sequence_tracker_counts_them() -> None:
    rng = np.random.default_rng(3)
    seqs = np.cumsum(rng.choice([1, 1, 1, 2, 5, 0, -3], size=400)) % 256
    mav = _sender()
    scanner = _Scanner()
    tracker = SequenceTracker()
    datagrams = []
    for s in seqs.tolist():
        mav.seq = s
        datagrams.append(mavlink.MAVLink_local_position_ned_message(1, 0, 0, 0, 0, 0, 0)
                         .pack(mav))
        tracker.update(s)
    scanner(datagrams)
    got = tracker.stats()
    assert scanner.t.seq[2].tolist() == [got.received, got.lost, got.duplicates, got.reordered]
    assert got.lost > 0 and got.duplicates > 0 and got.reordered > 0


@pytest.mark.parametrize("type_mask", [128, 7, 0])
def test_the_teams_setpoints_are_packed_as_pymavlink_packs_them(type_mask: int) -> None:
    rng = np.random.default_rng(type_mask)
    n = 8
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rates = rng.normal(size=(n, 3))
    thrust = rng.random(n)
    rates[0], thrust[0], q[0] = 0.0, 0.0, (1.0, 0.0, 0.0, 0.0)  # trailing zeros trimmed
    seq = rng.integers(0, 256, n).astype(np.uint8)
    boot = rng.integers(0, 2**32, n)
    target = rng.integers(1, 255, n)
    out = np.zeros((n, 51), dtype=np.uint8)
    lengths = np.zeros(n, dtype=np.int64)
    encode_set_attitude_target(seq, 255, 190, boot, target, np.ones(n, np.int64), type_mask,
                               q, rates, thrust, out, lengths)
    for i in range(n):
        mav = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
        mav.seq = int(seq[i])
        want = mavlink.MAVLink_set_attitude_target_message(
            int(boot[i]), int(target[i]), 1, type_mask, q[i].tolist(), *rates[i].tolist(),
            float(thrust[i])).pack(mav)
        assert out[i, : lengths[i]].tobytes() == want


def _udp(port_to: int) -> tuple[socket.socket, int]:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.connect(("127.0.0.1", port_to))
    return s, s.getsockname()[1]


def test_a_shared_port_fills_the_table_and_the_proxies_read_it(tmp_path) -> None:  # noqa: ANN001
    asyncio.run(asyncio.wait_for(_shared_port(tmp_path), 20.0))
    log = mavutil.mavlink_connection(str(tmp_path / "t.tlog"))
    kinds = []
    while (m := log.recv_match()) is not None:
        kinds.append((m.get_srcSystem(), m.get_type()))
    assert kinds.count((1, "LOCAL_POSITION_NED")) == 6  # the stranger's included
    assert kinds.count((2, "LOCAL_POSITION_NED")) == 5
    assert kinds.count((2, "HEARTBEAT")) == 5


async def _shared_port(tmp_path) -> None:  # noqa: ANN001
    table = HotTable(2)
    with TlogWriter(tmp_path / "t.tlog") as tlog:
        async with MavlinkPort(0, table=table, tlog=tlog) as port:
            gcs_port = port.local_address[1]
            a, a_port = _udp(gcs_port)
            b, b_port = _udp(gcs_port)
            cfgs = [VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=gcs_port,
                                      remote_port=None, learn_remote=True),
                    VehicleLinkConfig(vehicle_id=2, sysid=2, local_port=gcs_port,
                                      remote_port=b_port)]
            async with (VehicleProxy(cfgs[0], port=port, slot=0, tlog=tlog) as p1,
                        VehicleProxy(cfgs[1], port=port, slot=1, tlog=tlog) as p2):
                m1, m2 = _sender(1), _sender(2)
                waiter = asyncio.create_task(p2.wait_message("LOCAL_POSITION_NED", 2.0))
                await asyncio.sleep(0.01)
                for k in range(5):
                    a.send(_pack(m1, mavlink.MAVLink_local_position_ned_message(
                        k, float(k), 0, 0, 0, 0, 0)))
                    b.send(_pack(m2, mavlink.MAVLink_local_position_ned_message(
                        k, 0, float(k), 0, 0, 0, 0)) + _pack(m2, mavlink.MAVLink_heartbeat_message(
                            2, 12, 0, 0, 0, 3)))
                    await asyncio.sleep(0.02)
                got = await waiter
                assert got.msg.get_type() == "LOCAL_POSITION_NED"
                # vehicle 1: its first message took the slow way and taught its address
                assert p1.remote == ("127.0.0.1", a_port)
                assert p1.latest("LOCAL_POSITION_NED").msg.x == 4.0
                assert table.count[0, LPN] == 4
                assert p2.latest("LOCAL_POSITION_NED").msg.y == 4.0
                assert table.count[1, LPN] == 5
                assert p2.latest("HEARTBEAT") is not None  # the slow path still runs
                s1, s2 = p1.stats(), p2.stats()
                assert s1.proxy.messages_accepted == 5
                assert s1.sequence.received == 5 and s1.sequence.lost == 0
                assert s2.sequence.received == 10 and s2.sequence.lost == 0
                assert s2.by_type["LOCAL_POSITION_NED"].count == 5
                # a stranger with vehicle 1's sysid: neither the table nor the cache takes it
                c, _ = _udp(gcs_port)
                c.send(_pack(_sender(1), mavlink.MAVLink_local_position_ned_message(
                    9, 99.0, 0, 0, 0, 0, 0)))
                await asyncio.sleep(0.05)
                assert p1.latest("LOCAL_POSITION_NED").msg.x == 4.0
                assert p1.stats().proxy.stranger_address == 1
                for s in (a, b, c):
                    s.close()


def test_a_stalled_event_loop_does_not_read_as_link_delay() -> None:
    """Receive times are the kernel's (Linux): a datagram that waited in the socket while the
    ground station was busy is stamped when it arrived, on the hot and the slow path alike."""
    asyncio.run(asyncio.wait_for(_stalled(), 20.0))


@contextlib.asynccontextmanager
async def _one_vehicle(**link: float):  # noqa: ANN202
    """A port with a hot table of one, its vehicle's proxy (sysid 1, `link` settings) and the
    vehicle's socket: (table, socket, proxy)."""
    table = HotTable(1)
    async with MavlinkPort(0, table=table) as port:
        gcs_port = port.local_address[1]
        a, a_port = _udp(gcs_port)
        cfg = VehicleLinkConfig(vehicle_id=1, sysid=1, local_port=gcs_port, remote_port=a_port,
                                **link)
        try:
            async with VehicleProxy(cfg, port=port, slot=0) as p:
                yield table, a, p
        finally:
            a.close()


async def _kernel_stamping(a: socket.socket, p: VehicleProxy, mav) -> None:  # noqa: ANN001
    """Wait until the kernel stamps datagrams as they arrive. Linux turns its receive stamps on
    for the whole machine when the first socket asks (SO_TIMESTAMPNS), from a work queue: until
    that has run, a datagram is stamped when it is read. Seen on a loaded machine (three test
    workers on two cores), never in a flight: the first telemetry arrives after it has run."""
    for _ in range(100):
        a.send(_pack(mav, mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3)))
        time.sleep(0.02)  # the loop is blocked: the probe waits in the socket
        read_from_s = time.monotonic()
        await asyncio.sleep(0.01)
        hb = p.latest("HEARTBEAT")
        if hb is not None and read_from_s - hb.rx_time_s > 0.015:
            return
    raise AssertionError("the kernel did not stamp datagrams on arrival within 3 s")


async def _stalled() -> None:
    async with _one_vehicle() as (table, a, p):
        mav = _sender(1)
        await _kernel_stamping(a, p, mav)
        sent_s = time.monotonic()
        a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(1, 1.0, 0, 0, 0, 0, 0))
               + _pack(mav, mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3)))
        time.sleep(0.3)  # the event loop is blocked: nothing is read meanwhile
        await asyncio.sleep(0.05)
        lpn, hb = p.latest("LOCAL_POSITION_NED"), p.latest("HEARTBEAT")
        assert lpn is not None and hb is not None
        assert table.count[0, LPN] == 1
        assert lpn.rx_time_s - sent_s < 0.1
        assert hb.rx_time_s == lpn.rx_time_s


def test_team_setpoints_reach_each_vehicle_as_its_own_setpoint_would(tmp_path) -> None:  # noqa: ANN001
    with TlogWriter(tmp_path / "t.tlog") as tlog:
        asyncio.run(asyncio.wait_for(_team_setpoints(tlog), 20.0))
    log = mavutil.mavlink_connection(str(tmp_path / "t.tlog"))
    targets = []
    while (m := log.recv_match(type="SET_ATTITUDE_TARGET")) is not None:
        targets.append(m.target_system)
    assert sorted(targets) == [1, 1, 2, 2]  # the team's two in one block, vehicle 1's own, 2 again


async def _team_setpoints(tlog: TlogWriter) -> None:
    async with MavlinkPort(0, table=HotTable(2)) as port:
        gcs_port = port.local_address[1]
        socks = [_udp(gcs_port) for _ in range(2)]
        for s, _ in socks:
            s.setblocking(False)
        # no TIMESYNC requests: the sockets below are read for setpoints only, however slowly
        cfgs = [VehicleLinkConfig(vehicle_id=k + 1, sysid=k + 1, local_port=gcs_port,
                                  remote_port=socks[k][1], timesync_period_s=0.0)
                for k in range(2)]
        async with (VehicleProxy(cfgs[0], port=port, slot=0, tlog=tlog) as p1,
                    VehicleProxy(cfgs[1], port=port, slot=1, tlog=tlog) as p2):
            await asyncio.sleep(0.05)
            for s, _ in socks:  # the proxies' first HEARTBEATs
                while True:
                    try:
                        s.recv(512)
                    except BlockingIOError:
                        break
            rates = np.array([[0.1, -0.2, 0.3], [0.0, 0.5, -0.5]])
            thrust = np.array([0.4, 1.7])  # the second is clamped to 1 and counted
            TeamSetpoints([p1, p2]).send_rates_thrust([0, 1], rates, thrust)
            p1.setpoints.send_rates_thrust(rates[0], thrust[0])
            await asyncio.sleep(0.05)
            parser = mavlink.MAVLink(None)
            got = [[parser.decode(bytearray(s.recv(512))) for _ in range(n)]
                   for (s, _), n in zip(socks, (2, 1), strict=True)]
            team, one = got[0]
            assert (team.target_system, team.type_mask) == (1, 128)
            assert [team.body_roll_rate, team.body_pitch_rate, team.body_yaw_rate] == \
                pytest.approx([0.1, 0.2, -0.3])  # FLU -> FRD
            assert one.get_seq() == (team.get_seq() + 1) % 256
            for field in ("body_roll_rate", "body_pitch_rate", "body_yaw_rate", "thrust", "q"):
                assert getattr(one, field) == getattr(team, field)
            second = got[1][0]
            assert second.target_system == 2 and second.thrust == 1.0
            assert p2.stats().proxy.thrust_clamped == 1
            assert p1.stats().proxy.setpoints_sent == 2
            # fewer rows: the plan is rebuilt; vehicle 2's sequence goes on from its own
            team_setpoints = TeamSetpoints([p1, p2])
            team_setpoints.send_rates_thrust([1], rates, np.array([0.4, 0.2]))
            await asyncio.sleep(0.05)
            again = parser.decode(bytearray(socks[1][0].recv(512)))
            assert again.get_seq() == (second.get_seq() + 1) % 256 and again.thrust == \
                pytest.approx(0.2)
            assert p2.stats().proxy.setpoints_sent == 2
            with pytest.raises(ValueError, match="a row twice"):
                team_setpoints.send_rates_thrust([1, 1], rates, thrust)
            for s, _ in socks:
                s.close()


def _count_notices(p) -> list[float]:
    """The times at which the port tells proxy ``p`` of its hot messages, from now on."""
    calls: list[float] = []
    on_hot = p._on_hot
    p._on_hot = lambda: (calls.append(time.monotonic()), on_hot())
    return calls


def test_a_proxy_hears_of_its_hot_messages_every_notice_period_not_every_batch() -> None:
    """Between notices the table keeps the batches' least-delayed stamp: the clock filter still
    gets it, and a waiting command is woken at the batch that brings its message."""
    asyncio.run(asyncio.wait_for(_notices(), 20.0))


async def _notices() -> None:
    async with _one_vehicle(timesync_period_s=0.0) as (table, a, p):
        calls = _count_notices(p)
        mav = _sender(1)
        t0 = time.monotonic()
        for k in range(20):  # one datagram every 5 ms, stamped as if 0-19 ms in transit
            stamp_ms = int((time.monotonic() - t0) * 1e3) + 1000 - (0 if k == 7 else 19)
            a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
                stamp_ms, float(k), 0, 0, 0, 0, 0)))
            await asyncio.sleep(0.005)
        await asyncio.sleep(HOT_NOTICE_S + 0.01)
        a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
            int((time.monotonic() - t0) * 1e3) + 1000 - 19, 20.0, 0, 0, 0, 0, 0)))
        await asyncio.sleep(0.01)
        assert table.count[0, LPN] == 21
        elapsed = calls[-1] - calls[0]
        assert 2 <= len(calls) <= 2 + elapsed / HOT_NOTICE_S  # not 21
        # the least-delayed sample (k = 7) set the envelope, though no notice came with it
        offset_7 = p.clock.estimate().offset_s
        assert offset_7 < t0 - 1.0 + 0.010  # k = 7's rx - stamp; the others' are 19 ms more
        waiter = asyncio.create_task(p.wait_message("LOCAL_POSITION_NED", 1.0))
        await asyncio.sleep(0.005)
        sent_s = time.monotonic()
        a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
            int((sent_s - t0) * 1e3) + 1000 - 19, 21.0, 0, 0, 0, 0, 0)))
        got = await waiter
        assert got.msg.x == 21.0 and time.monotonic() - sent_s < HOT_NOTICE_S
        assert offset_7 == p.clock.estimate().offset_s


def test_a_wait_for_a_slow_path_message_does_not_make_every_batch_tell_the_proxy() -> None:
    """A mode confirmation waits for a HEARTBEAT: no hot message will answer it, so the hot
    stream keeps its notice period (240 vehicles confirming at once made every batch tell every
    vehicle: tens of milliseconds at the formation's start), and the HEARTBEAT still wakes it."""
    asyncio.run(asyncio.wait_for(_slow_wait(), 20.0))


async def _slow_wait() -> None:
    async with _one_vehicle(timesync_period_s=0.0) as (table, a, p):
        calls = _count_notices(p)
        mav = _sender(1)
        # GIVEN a command waiting for the vehicle's HEARTBEAT
        waiter = asyncio.create_task(p.wait_message("HEARTBEAT", 2.0))
        await asyncio.sleep(0.005)
        assert not p.hot_waiting
        # WHEN 20 LOCAL_POSITION_NED datagrams arrive 5 ms apart
        t0 = time.monotonic()
        for k in range(20):
            a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
                int((time.monotonic() - t0) * 1e3) + 1000, float(k), 0, 0, 0, 0, 0)))
            await asyncio.sleep(0.005)
        # THEN the proxy heard of them a few times (the notice period is 50 ms; in a new
        # process the first batches come at once), not at each of the 20 batches
        assert table.count[0, LPN] == 20
        assert 1 <= len(calls) <= 6
        # and the HEARTBEAT, when it comes, ends the wait
        a.send(_pack(mav, mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3)))
        got = await waiter
        assert got.msg.get_type() == "HEARTBEAT" and not p.hot_waiting
        # while a wait for a hot message makes the proxy hear of every batch until it is met
        hot = asyncio.create_task(p.wait_message("LOCAL_POSITION_NED", 1.0))
        await asyncio.sleep(0.005)
        assert p.hot_waiting
        a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
            int((time.monotonic() - t0) * 1e3) + 1000, 99.0, 0, 0, 0, 0, 0)))
        assert (await hot).msg.x == 99.0 and not p.hot_waiting


def test_a_burst_of_slow_frames_is_routed_in_budgeted_passes_that_timers_interleave() -> None:
    asyncio.run(asyncio.wait_for(_slow_burst(), 20.0))


async def _slow_burst() -> None:
    # GIVEN 120 HEARTBEATs (a slow-path message: pymavlink decodes it) waiting in the socket at
    # once, as a fleet's in-phase heartbeats arrive, and a timer due 0.5 ms after the loop
    # resumes (the control tick's wake-up, say)
    async with _one_vehicle() as (_, a, p):
        mav = _sender(1)
        for _ in range(120):
            a.send(_pack(mav, mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3)))
        time.sleep(0.05)  # every datagram is queued before the loop reads any

        def heartbeats() -> int:
            seen = p.stats().by_type.get("HEARTBEAT")
            return 0 if seen is None else seen.count

        at_timer: list[int] = []
        asyncio.get_running_loop().call_later(5e-4, lambda: at_timer.append(heartbeats()))
        # WHEN the loop runs until every one is routed
        for _ in range(2000):
            await asyncio.sleep(0)
            if heartbeats() == 120:
                break
        # THEN the timer ran while part of the burst still waited: the slow path gave the loop
        # back after its budget instead of routing the burst in one callback
        assert len(at_timer) == 1 and 0 < at_timer[0] < 120, at_timer
        assert p.port.stats().slow_deferred >= 1
        # AND nothing was lost or reordered on the way
        assert heartbeats() == 120
        seq = p.stats().sequence
        assert seq.received == 120 and seq.lost == 0 and seq.reordered == 0


#: a turn of the test's 5 ms sending loop longer than this is a stop of the machine [s]
STOP_S = 0.02


def test_a_teams_hot_notices_spread_over_the_batches_at_each_proxys_own_phase() -> None:
    asyncio.run(asyncio.wait_for(_spread_notices(), 20.0))


async def _spread_notices() -> None:
    # GIVEN 16 vehicles on one port, each sending LOCAL_POSITION_NED every 5 ms for 0.4 s,
    # the hot path's kernels loaded first, as a flight's warm-up does (run alone, the test's
    # first batch compiled or loaded them: a stall after which every slot was due at once)
    warm_up()
    n = 16
    table = HotTable(n)
    async with MavlinkPort(0, table=table) as port, contextlib.AsyncExitStack() as stack:
        gcs_port = port.local_address[1]
        a, a_port = _udp(gcs_port)
        stack.callback(a.close)
        proxies = [await stack.enter_async_context(VehicleProxy(
            VehicleLinkConfig(vehicle_id=k + 1, sysid=k + 1, local_port=gcs_port,
                              remote_port=a_port, timesync_period_s=0.0), port=port, slot=k))
            for k in range(n)]
        batch = [0]
        handle = port._endpoint._on_batch_cb
        assert handle is not None

        def counted(*args) -> None:  # noqa: ANN002
            batch[0] += 1
            handle(*args)

        port._endpoint._on_batch_cb = counted
        notices: list[tuple[int, int]] = []  # (batch, slot)
        for k, p in enumerate(proxies):
            on_hot = p._on_hot
            p._on_hot = (lambda k=k, on_hot=on_hot:  # type: ignore[method-assign]
                         (notices.append((batch[0], k)), on_hot()))
        senders = [_sender(k + 1) for k in range(n)]
        base = time.monotonic()

        stopped = [0.0, 0]  # time and count of the machine's stops of this process
        last_turn = [time.monotonic()]  # one watch over every stream, the gaps between them too

        async def stream(seconds: float, send: bool = True) -> None:
            """Turns of 5 ms for `seconds`, each sending every vehicle's sample (`send`), and
            watching for the machine's stops all the while (the last datagrams' batches too)."""
            start = time.monotonic()
            while (now := time.monotonic()) - start < seconds:
                if now - last_turn[0] > STOP_S:  # a turn of 5 ms took longer: a stop
                    stopped[0] += now - last_turn[0] - 0.005
                    stopped[1] += 1
                last_turn[0] = now
                stamp_ms = int((now - base) * 1e3) + 1  # each sample newer
                for mav in senders if send else ():
                    a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
                        stamp_ms, 1.0, 0, 0, 0, 0, 0)))
                await asyncio.sleep(0.005)

        # (the first batch loads the hot path's compiled code: a stall after which every slot
        # is due at once; a few periods later the notices are back at their phases)
        await stream(0.15)
        notices.clear()
        stopped[:] = [0.0, 0]
        t0 = time.monotonic()
        await stream(0.4)
        await stream(0.02, send=False)  # the last samples' batches, still watched for stops
        elapsed = time.monotonic() - t0
    # THEN each proxy was told about every HOT_NOTICE_S (not at every batch) while samples
    # flowed (a machine whose every core is busy stops now and then for ~100 ms: no samples
    # come then, and one notice follows the stop) ...
    per_slot = np.bincount([k for _, k in notices], minlength=n)
    flowing = elapsed / HOT_NOTICE_S
    periods = (elapsed - stopped[0]) / HOT_NOTICE_S
    assert np.all(per_slot >= periods - 2) and np.all(per_slot <= flowing + 2), (
        per_slot, periods, flowing)
    # ... and no batch carried the whole team's notices: they came at the slots' own phases,
    # but for the first batch after each stop, when every slot is due at once
    per_batch = np.bincount([b for b, _ in notices])
    assert (per_batch > n // 2).sum() <= stopped[1], (per_batch, stopped)


def test_the_team_sample_reads_each_message_the_table_has_even_while_another_is_missing() -> None:
    asyncio.run(asyncio.wait_for(_sample_before_the_imu(), 20.0))


async def _sample_before_the_imu() -> None:
    # GIVEN a vehicle whose position and attitude streams are on, but not yet its IMU (the
    # preflight asks for the streams one by one)
    async with _one_vehicle() as (table, a, p):
        mav = _sender(1)
        a.send(_pack(mav, mavlink.MAVLink_local_position_ned_message(
            1000, 1.0, 2.0, -3.0, 0.5, 0, 0)))
        a.send(_pack(mav, mavlink.MAVLink_attitude_quaternion_message(
            1000, 1.0, 0, 0, 0, 0.1, 0, 0)))
        for _ in range(100):
            await asyncio.sleep(0.005)
            if table.count[0, LPN] and table.count[0, ATTQ]:
                break
        assert table.count[0, IMU] == 0
        asked: list[str] = []
        sample = p.sample
        p.sample = lambda kind: (asked.append(kind.MESSAGE), sample(kind))[1]  # type: ignore[method-assign]
        # WHEN the tick takes the team's sample
        s = team_sample([p], time.monotonic(), table=table)
        # THEN position and attitude come from the table's arrays (ENU/FLU), and only the
        # missing IMU is looked for in the proxy's cache, not all three decoded by pymavlink
        assert asked == ["HIGHRES_IMU"]
        assert s.position_m[0].tolist() == [2.0, 1.0, 3.0]
        assert s.velocity_mps[0].tolist() == [0.0, 0.5, 0.0]
        assert s.finite[0] and s.omega_radps[0].tolist() == pytest.approx([0.1, 0.0, 0.0])
        assert s.acceleration_mps2[0].tolist() == [0.0, 0.0, 0.0]  # no IMU yet: none assumed
        assert math.isinf(s.imu_age_s[0])
