"""The tick's team sample read from the hot table (gcs.fly.telemetry): the compiled gather
against a row-by-row reference written from what each column means."""

from __future__ import annotations

import math
import time

import numpy as np

from gcs.fly.telemetry import Gathered, _from_table, team_sample
from gcs.link.fastpath import ATTQ, IMU, LPN, HotTable


class _Proxy:
    """What team_sample asks of a proxy: its table row, and its cache (empty here)."""

    def __init__(self, slot: int | None) -> None:
        self.slot = slot

    def sample(self, kind: type) -> None:
        return None


def _reference(table: HotTable, own: list[bool], i: int) -> dict:
    """Row i as _from_table must fill it: each message the table has (and the row is the
    proxy's own) gives its fields, its receive time and when the vehicle took it on the
    ground station's clock (the stamp through the clock line, never after arrival; the
    receive time without a line or a stamp)."""
    def taken(stamp: float, rx: float) -> float:
        a, b, t_ref, least = (float(x) for x in table.clock_line[i])
        if not (math.isfinite(a) and math.isfinite(stamp)):
            return rx
        t = stamp + a + b * (stamp - t_ref) - least
        return math.nan if math.isnan(t) or math.isnan(rx) else min(rx, t)

    out: dict = {"need": [True, True, True]}
    if own[i] and table.count[i, LPN] > 0:
        row = table.lpn[i]
        out.update(pos=row[1:4].tolist(), vel=row[4:7].tolist(), prx=table.rx_s[i, LPN],
                   ptaken=taken(row[0], table.rx_s[i, LPN]))
        out["need"][0] = False
    if own[i] and table.count[i, ATTQ] > 0:
        row = table.attq[i]
        quat = row[1:5].tolist()
        good = all(math.isfinite(x) for x in quat) and sum(x * x for x in quat) > 1e-6
        out.update(q=quat if good else None, have_q=good, rates=row[5:8].tolist(),
                   arx=table.rx_s[i, ATTQ], ataken=taken(row[0], table.rx_s[i, ATTQ]))
        out["need"][1] = False
    if own[i] and table.count[i, IMU] > 0:
        out.update(force=table.imu[i, 1:4].tolist(), irx=table.rx_s[i, IMU])
        out["need"][2] = False
    return out


def _same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


def test_the_gather_fills_every_row_the_table_has_as_the_reference_does() -> None:
    # GIVEN a table of 60 rows: messages present or not, proxies on their own rows or not,
    # good, non-finite and near-zero quaternions, clock lines whole, missing or with a NaN
    # slope, stamps that are NaN, and samples taken before or (by the line) after arrival
    rng = np.random.default_rng(7)
    n = 60
    table = HotTable(n)
    table.count[:, :3] = rng.integers(0, 2, size=(n, 3))
    table.lpn[:] = rng.normal(size=table.lpn.shape)
    table.attq[:] = rng.normal(size=table.attq.shape)
    table.imu[:] = rng.normal(size=table.imu.shape)
    table.rx_s[:, :3] = 100.0 + rng.uniform(-0.05, 0.05, size=(n, 3))
    table.lpn[:, 0] = table.attq[:, 0] = 3.0 + rng.uniform(-0.1, 0.1, size=n)
    table.clock_line[:] = np.column_stack([
        np.full(n, 97.0), rng.normal(0.0, 1e-4, n), np.full(n, 3.0), np.full(n, 0.002)])
    table.attq[3, 2] = math.nan
    table.attq[4, 1:5] = 1e-4
    table.attq[5, 1] = math.inf
    table.clock_line[6] = math.nan
    table.clock_line[7, 1] = math.nan
    table.lpn[8, 0] = table.attq[8, 0] = math.nan
    table.clock_line[9, 0] = 200.0  # the line puts the sample after its arrival
    table.count[3:10, :2] = 1
    own = [i % 11 != 10 for i in range(n)]
    proxies = [_Proxy(i if own[i] else None) for i in range(n)]
    pos, vel, rates, force = (np.full((n, 3), -7.0) for _ in range(4))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    prx, arx, ptaken, ataken, irx = (np.full(n, -math.inf) for _ in range(5))
    have_q = np.zeros(n, dtype=bool)
    # WHEN the team's rows are gathered
    need = _from_table(proxies, table, Gathered(pos, vel, q, rates, force, prx, arx, ptaken,
                                                 ataken, irx, have_q))
    # THEN every row is what the reference says, and untouched where the table has nothing
    for i in range(n):
        ref = _reference(table, own, i)
        assert [i in need[k] for k in range(3)] == ref["need"], i
        if not ref["need"][0]:
            assert pos[i].tolist() == ref["pos"] and vel[i].tolist() == ref["vel"]
            assert prx[i] == ref["prx"] and _same(ptaken[i], ref["ptaken"]), i
        else:
            assert (pos[i] == -7.0).all() and prx[i] == -math.inf
        if not ref["need"][1]:
            assert have_q[i] == ref["have_q"], i
            assert q[i].tolist() == (ref["q"] or [1.0, 0.0, 0.0, 0.0]), i
            assert rates[i].tolist() == ref["rates"] and arx[i] == ref["arx"]
            assert _same(ataken[i], ref["ataken"]), i
        else:
            assert not have_q[i] and ataken[i] == -math.inf
        if not ref["need"][2]:
            assert force[i].tolist() == ref["force"] and irx[i] == ref["irx"]
        else:
            assert (force[i] == -7.0).all() and irx[i] == -math.inf
    # AND the special rows did what they are there for
    assert not have_q[3] and not have_q[4] and not have_q[5]
    assert ataken[6] == arx[6] and math.isnan(ataken[7]) and ptaken[8] == prx[8]
    assert ptaken[9] == prx[9] and ataken[9] == arx[9]
    assert ptaken[0] < prx[0] or table.count[0, LPN] == 0


def test_the_team_sample_takes_a_row_from_the_table_only_for_the_proxy_on_it() -> None:
    # GIVEN two proxies on one table, the second not on its own row (no hot path)
    table = HotTable(2)
    table.count[:, :3] = 1
    table.lpn[:] = [[1.0, 1.0, 2.0, -3.0, 0.0, 0.0, 0.0]] * 2
    table.attq[:] = [[1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]] * 2
    table.imu[:] = [[1.0, 0.0, 0.0, -9.81]] * 2
    table.rx_s[:, :3] = time.monotonic()
    s = team_sample([_Proxy(0), _Proxy(None)], time.monotonic(), table=table)
    # THEN the first vehicle's sample is the table's (ENU), the second has none
    assert s.position_m[0].tolist() == [2.0, 1.0, 3.0] and s.finite.tolist() == [True, False]
