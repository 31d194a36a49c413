"""The latest sample per sender and what each edge received (gcs/agent/table.py), with every
time an argument: latest wins, loss from gaps, duplicates, corrupt bytes, restarts, clock
offsets from echoes and the rows the law reads."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.agent.control import MAX_TEXT
from gcs.agent.table import CHECK_EXCHANGES, ECHO_BACKLOG, SampleTable
from gcs.agent.wire import SUPERVISOR_ID, Echo, StateSample, encode
from gcs.config.modes import ClockMode


def sample(vid: int, seq: int, *, epoch: int = 1, taken_s: float = 0.0, sent_s: float = 0.0,
           x: float = 0.0, echoes: tuple[Echo, ...] = ()) -> bytes:
    return encode(StateSample(vid, epoch, seq, taken_s, sent_s, (x, 2.0, 3.0), (0.1, 0.2, 0.3),
                              (0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.1), echoes))


def test_the_latest_sample_wins_and_older_or_repeated_ones_are_counted():
    # GIVEN vehicle 1's table of its neighbours 2 and 3
    table = SampleTable((2, 3), local_ids=(1,), team_ids=(1, 2, 3), clocks=ClockMode.ONE_HOST)
    # WHEN vehicle 2 sends seq 5, then 5 again, then 4, then 6
    assert table.receive(2, sample(2, 5, x=5.0), 10.0) is not None
    assert table.receive(2, sample(2, 5, x=55.0), 10.1) is None
    assert table.receive(2, sample(2, 4, x=4.0), 10.2) is None
    assert table.receive(2, sample(2, 6, x=6.0), 10.3).seq == 6
    # THEN seq 6 is the one held, two were duplicates, none lost, nothing from 3
    assert table.latest(2).position_enu_m[0] == 6.0
    f = table.figures(2)
    assert (f.received, f.duplicates, f.lost, f.corrupt, f.restarts) == (2, 2, 0, 0, 0)
    assert table.latest(3) is None and table.figures(3).received == 0


def test_gaps_in_seq_are_lost_samples():
    table = SampleTable((2,), local_ids=(1,))
    for seq in (0, 1, 4, 5, 9):
        table.receive(2, sample(2, seq), 0.0)
    f = table.figures(2)
    assert (f.received, f.lost) == (5, 5) and f.loss_fraction == 0.5


def test_a_new_epoch_is_a_restart_not_a_duplicate():
    # GIVEN vehicle 2 at seq 100, then its process restarted (epoch 2) from seq 0
    table = SampleTable((2,), local_ids=(1,))
    table.receive(2, sample(2, 100, epoch=1), 0.0)
    assert table.receive(2, sample(2, 0, epoch=2, x=9.0), 1.0) is not None
    table.receive(2, sample(2, 1, epoch=2), 1.1)
    f = table.figures(2)
    assert (f.received, f.duplicates, f.lost, f.restarts) == (3, 0, 0, 1)


def test_corrupt_bytes_are_counted_with_the_last_reason_never_raised():
    table = SampleTable((2, 3), local_ids=(1,), team_ids=(1, 2, 3))
    assert table.receive(2, b"garbage", 0.0) is None
    assert table.receive(2, b"XMST" + sample(2, 0)[4:], 0.0) is None
    # a sample of vehicle 3 on vehicle 2's key, one from a stranger, a too long reason
    assert table.receive(2, sample(3, 0), 0.0) is None
    assert table.receive(3, sample(9, 0), 0.0) is None
    f2, f3 = table.figures(2), table.figures(3)
    assert (f2.corrupt, f2.received) == (3, 0)
    assert f2.corrupt_reason == "vehicle id 3 on the key of vehicle 2"
    assert (f3.corrupt, f3.corrupt_reason) == (1, "vehicle id 9 is no vehicle of the team")
    table.corrupt(3, "x" * 1000)
    assert len(table.figures(3).corrupt_reason) == MAX_TEXT


def test_rows_before_and_after_the_first_sample():
    # GIVEN one process's clock as the others' (one host) and a sample of 2 only
    table = SampleTable((2, 3), local_ids=(1,), clocks=ClockMode.ONE_HOST)
    table.receive(2, sample(2, 0, taken_s=99.5, sent_s=99.6, x=7.0), 99.7)
    rows = table.rows([3, 2], now_s=100.0)
    # THEN vehicle 3's row is NaN with -inf times and infinite age; vehicle 2's is its sample
    assert rows.ids == (3, 2) and rows.finite.tolist() == [False, True]
    assert np.isnan(rows.position_enu_m[0]).all() and rows.taken_local_s[0] == -np.inf
    assert rows.received_s[0] == -np.inf and rows.age_s[0] == np.inf
    np.testing.assert_array_equal(rows.position_enu_m[1], [7.0, 2.0, 3.0])
    np.testing.assert_array_equal(rows.velocity_enu_mps[1], [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(rows.acceleration_enu_mps2[1], [0.0, 0.0, 0.5])
    np.testing.assert_array_equal(rows.attitude_wxyz[1], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(rows.omega_flu_radps[1], [0.0, 0.0, 0.1])
    assert (rows.taken_local_s[1], rows.received_s[1]) == (99.5, 99.7)
    assert rows.age_s[1] == pytest.approx(0.5)
    assert rows.fresh(0.6).tolist() == [False, True] and not rows.fresh(0.4).any()
    assert rows.position_enu_m.shape == (2, 3) and rows.attitude_wxyz.shape == (2, 4)
    with pytest.raises(KeyError, match=r"vehicle 4 is not heard here \(senders: 2, 3\)"):
        table.rows([4], 0.0)


def test_echoes_give_each_sender_its_offset_and_convert_its_times():
    # GIVEN vehicle 1 here and vehicle 2 whose clock reads ours + 50 s, 1 ms each way
    here = SampleTable((2,), local_ids=(1,), team_ids=(1, 2))
    there = SampleTable((1,), local_ids=(2,), team_ids=(1, 2))
    offset, leg = 50.0, 0.001
    # WHEN 1 sends at t = 10 (ours), 2 receives it, holds 20 ms and sends a sample echoing it
    there.receive(1, sample(1, 0, taken_s=9.99, sent_s=10.0), 10.0 + leg + offset)
    sent2 = 10.0 + leg + offset + 0.020
    echoes = there.echoes(sent2, 2)
    assert echoes == (Echo(1, 10.0, pytest.approx(0.020)),)
    # AND before the echo arrives here the sample has no known time
    here.receive(2, sample(2, 0, taken_s=sent2 - 0.005, sent_s=sent2), sent2 - offset + leg)
    assert here.offset(2) is None and not here.rows([2], 10.1).finite[0]
    here.receive(2, sample(2, 1, taken_s=sent2 - 0.005, sent_s=sent2, echoes=echoes),
                 sent2 - offset + leg)
    # THEN here knows 2's offset, and its sample's time on our clock
    assert here.offset(2) == pytest.approx(offset, abs=1e-9)
    assert here.figures(2).uncertainty_s == pytest.approx(leg, abs=1e-9)
    rows = here.rows([2], now_s=10.1)
    assert rows.finite[0] and rows.taken_local_s[0] == pytest.approx(10.016, abs=1e-9)
    assert rows.age_s[0] == pytest.approx(0.084, abs=1e-9)


def test_echoes_of_other_ids_and_the_supervisor_are_kept_apart():
    # GIVEN the supervisor's table (its own id 0) and vehicle 2 echoing vehicle 3 and the
    # supervisor's heartbeat sent at 5.0, held 0.1 s
    sup = SampleTable((2, 3), local_ids=(SUPERVISOR_ID,), team_ids=(2, 3))
    data = sample(2, 0, sent_s=8.0, echoes=(Echo(3, 1.0, 0.0), Echo(SUPERVISOR_ID, 5.0, 0.1)))
    sup.receive(2, data, 5.2)
    # THEN only the supervisor's echo is an exchange: rtt (5.2 - 5) - 0.1 = 0.1, offset
    # ((7.9 - 5) + (8 - 5.2)) / 2 = 2.85
    assert sup.figures(2).offset_s == pytest.approx(2.85)
    assert sup.figures(2).uncertainty_s == pytest.approx(0.05)
    assert sup.figures(3).offset_s is None
    # AND a heartbeat-like message records what to echo, held until now
    sup.heard(3, 4.0, 5.5)
    assert sup.echoes(6.0, SUPERVISOR_ID) == (Echo(2, 8.0, pytest.approx(0.8)),
                                              Echo(3, 4.0, 0.5))
    assert sup.last_heard_s(3) == 5.5
    # AND a heartbeat (one echo per vehicle) echoes the newest of those heard since
    sup.heard(3, 6.0, 6.5)
    sup.heard(3, 7.0, 7.5)
    assert sup.echoes(8.0, SUPERVISOR_ID, 1) == (Echo(3, 7.0, 0.5),)
    assert sup.last_heard_s(3) == 7.5


def test_each_message_is_echoed_once_by_each_publisher():
    # GIVEN an agent process publishing vehicles 1 and 3, hearing vehicle 2
    table = SampleTable((2,), local_ids=(1, 3), team_ids=(1, 2, 3))
    table.receive(2, sample(2, 0, sent_s=1.00), 1.02)
    table.receive(2, sample(2, 1, sent_s=1.02), 1.05)
    # WHEN vehicle 1 publishes THEN it echoes both messages heard since, each held till now
    assert table.echoes(1.06, 1) == (Echo(2, 1.00, pytest.approx(0.04)),
                                     Echo(2, 1.02, pytest.approx(0.01)))
    # AND vehicle 3, publishing after it, echoes the same two (each publisher's sender needs
    # its own exchanges), and neither echoes them again: a repeated echo would weigh the
    # message that was followed by a slow one twice
    assert [e.sent_s for e in table.echoes(1.07, 3)] == [1.00, 1.02]
    assert table.echoes(1.08, 1) == () and table.echoes(1.08, 3) == ()
    table.receive(2, sample(2, 2, sent_s=1.04), 1.09)
    assert table.echoes(1.10, 1) == (Echo(2, 1.04, pytest.approx(0.01)),)
    # AND a publisher that fell behind echoes the newest ECHO_BACKLOG only
    for k in range(3, 3 + ECHO_BACKLOG + 5):
        table.receive(2, sample(2, k, sent_s=1.0 + 0.02 * k), 1.03 + 0.02 * k)
    echoed = table.echoes(2.0, 1)
    assert len(echoed) == ECHO_BACKLOG and echoed[-1].sent_s == pytest.approx(1.0 + 0.02 * 23)
    # AND a sender that restarted is echoed from its new process's messages on
    table.receive(2, sample(2, 0, sent_s=5.0, epoch=9), 5.01)
    assert [e.sent_s for e in table.echoes(5.02, 3)] == [5.0]


def test_an_agreed_instant_is_converted_by_the_median_offset():
    # GIVEN the supervisor's echoes of two exchanges: one symmetric (offset 3 s exactly, rtt
    # 2 ms) and one whose uplink took 9 ms (offset 3.004 s, rtt 10 ms)
    table = SampleTable((SUPERVISOR_ID,), local_ids=(1,), team_ids=(1,))
    assert table.to_local_agreed(SUPERVISOR_ID, 50.0) == -np.inf
    for t1, up in ((10.0, 0.001), (11.0, 0.009)):
        t2 = t1 + up + 3.0
        table.heard(SUPERVISOR_ID, t2 + 0.05, t2 + 0.05 - 3.0 + 0.001,
                    (Echo(1, t1, 0.05),))
    clock = table.clock(SUPERVISOR_ID)
    # THEN the faster half (the symmetric one) gives both the bounded and the median offset
    assert clock.offset_s == pytest.approx(3.0) == clock.median_offset_s
    assert table.to_local_agreed(SUPERVISOR_ID, 50.0) == pytest.approx(47.0)
    # AND one host's clocks (network.clocks one-host) convert by 0 whatever was measured
    one_host = SampleTable((SUPERVISOR_ID,), local_ids=(1,), team_ids=(1,),
                           clocks=ClockMode.ONE_HOST)
    one_host.heard(SUPERVISOR_ID, 13.05, 10.05, (Echo(1, 10.0, 0.05),))
    assert one_host.to_local_agreed(SUPERVISOR_ID, 50.0) == 50.0


def exchange_between(here: SampleTable, there: SampleTable, t_s: float, *, skew_s: float,
                     up_s: float, down_s: float, shift_here: float,
                     shift_there: float) -> None:
    """One exchange between vehicle 1 (`here`, monotonic t_s) and vehicle 2 (`there`, whose
    monotonic clock is ours + 100 s): 1 sends at t_s, 2 holds 5 ms and answers. Each stamps
    its wire clock, its monotonic one plus its shift; 2's system clock is ours + `skew_s`
    (so its shift is ours + skew - 100 s)."""
    mono2 = t_s + 100.0
    wire1 = t_s + shift_here
    there.receive(1, sample(1, int(t_s * 1e3), taken_s=wire1, sent_s=wire1), mono2 + up_s)
    sent2 = mono2 + up_s + 0.005
    echoes = there.echoes(sent2, 2)
    wire2 = sent2 + shift_there
    here.receive(2, sample(2, int(t_s * 1e3), taken_s=wire2 - 0.002, sent_s=wire2,
                           echoes=echoes), t_s + up_s + 0.005 + down_s)


@pytest.mark.parametrize(("skew_s", "up_s", "down_s", "problem"), [
    (0.0, 0.004, 0.006, None),
    (0.0015, 0.004, 0.006, None),
    # the clocks agree but the path is 20 ms slower one way: the estimate reads 10 ms, the
    # interval every exchange allows still holds 0
    (0.0, 0.024, 0.004, None),
    (0.030, 0.004, 0.006, "vehicle 2's clock is at least 24.0 ms ahead of ours by 16 echoes"),
    (-0.030, 0.004, 0.006, "vehicle 2's clock is at least 26.0 ms behind ours by 16 echoes"),
])
def test_disciplined_clocks_convert_by_the_system_clock_and_check_it(skew_s, up_s, down_s,
                                                                     problem):
    # GIVEN vehicle 1 and vehicle 2 with monotonic clocks 100 s apart (two hosts' boots) and
    # system clocks `skew_s` apart, clocks disciplined (tolerance 5 ms), up_s and down_s legs
    shift_here, shift_there = 1.7e9, 1.7e9 - 100.0 + skew_s
    here = SampleTable((2,), local_ids=(1,), team_ids=(1, 2), clocks=ClockMode.DISCIPLINED,
                       wire_shift=lambda: shift_here)
    there = SampleTable((1,), local_ids=(2,), team_ids=(1, 2), clocks=ClockMode.DISCIPLINED,
                        wire_shift=lambda: shift_there)
    legs = {"skew_s": skew_s, "up_s": up_s, "down_s": down_s, "shift_here": shift_here,
            "shift_there": shift_there}
    # WHEN the first sample arrives, before any exchange
    exchange_between(here, there, 10.0, **legs)
    # THEN its time is on our monotonic clock at once, through the system clocks (2 took it
    # 2 ms before sending, 5 ms after receiving ours, sent at 10.0, up_s later plus skew)
    rows = here.rows([2], now_s=10.020)
    assert rows.taken_local_s[0] == pytest.approx(10.0 + up_s + 0.003 + skew_s, abs=1e-6)
    # AND the offset used is 0, but the clock is not yet known to agree (too few exchanges)
    assert here.offset(2) == 0.0 and not here.clock_known(2)
    for k in range(1, CHECK_EXCHANGES):
        exchange_between(here, there, 10.0 + 0.02 * k, **legs)
    # THEN the echoes measure the system clocks' skew, less half the legs' difference
    assert here.clock(2).median_offset_s == pytest.approx(skew_s + (up_s - down_s) / 2,
                                                          abs=1e-6)
    if problem is None:
        assert here.clock_known(2) and here.clock_problem(2) is None
        assert here.offset(2) == 0.0 and here.rows([2], 10.4).finite[0]
    else:
        # a clock 30 ms off: named, and its samples get no time here (stale, never flown on)
        assert not here.clock_known(2) and here.offset(2) is None
        assert here.clock_problem(2) == (
            f"{problem} (network.clocks disciplined, tolerance 5 ms): synchronise the hosts' "
            "clocks (PTP, chrony) or set network.clocks measured")
        assert not here.rows([2], 10.4).finite[0]
        assert here.to_local_agreed(2, 1.7e9) == -np.inf


def test_the_wire_shift_is_ignored_unless_clocks_are_disciplined():
    # GIVEN a table with a shift given but clocks measured, and one with clocks one-host
    for mode in (ClockMode.MEASURED, ClockMode.ONE_HOST):
        table = SampleTable((2,), local_ids=(1,), clocks=mode, wire_shift=lambda: 1e9)
        # THEN the wire clock is the monotonic one, and nothing is checked
        assert table.wire_shift() == 0.0 and table.clock_problem(2) is None
    assert SampleTable((2,), local_ids=(1,), clocks=ClockMode.ONE_HOST).clock_known(2)
