"""The agent's watch over its neighbours' clocks (gcs/agent/runtime.py's TeamWatch) on a real
SampleTable: with clocks disciplined, a neighbour is not ready until its clock has been checked,
and one whose clock disagrees is named, before the gate and in flight."""

from __future__ import annotations

from types import SimpleNamespace

from gcs.agent.runtime import TeamWatch
from gcs.agent.table import CHECK_EXCHANGES, SampleTable
from gcs.agent.wire import SUPERVISOR_ID, Echo, StateSample, encode
from gcs.config.modes import ClockMode


def watch_of(table: SampleTable) -> TeamWatch:
    """A watch of vehicle 1 with neighbour 2 on `table`, its flight and team reduced to what
    the neighbour rules read (fly.link_lost_after_s 0.5 s)."""
    bus = SimpleNamespace(table=table, rows=table.rows)
    team = SimpleNamespace(fly=SimpleNamespace(link_lost_after_s=0.5))
    rows = SimpleNamespace(neighbour_ids=(2,), own_ids=(1,))
    return TeamWatch(SimpleNamespace(machine=None), bus, rows, team, clock=lambda: 0.0)


def hear(table: SampleTable, exchanges: int, skew_s: float) -> None:
    """`exchanges` samples of vehicle 2, each echoing one of ours sent 10 ms before it arrived,
    held 5 ms there; 2's clock is ours + skew_s, the legs symmetric."""
    for k in range(exchanges):
        t4 = 1.0 + 0.02 * k
        sent = t4 - 0.0025 + skew_s
        data = encode(StateSample(2, 1, k, sent - 0.001, sent, (0.0,) * 3, (0.0,) * 3,
                                  (0.0,) * 3, (1.0, 0.0, 0.0, 0.0), (0.0,) * 3,
                                  (Echo(1, t4 - 0.01, 0.005),)))
        table.receive(2, data, t4)


def test_a_disciplined_neighbour_is_ready_once_its_clock_is_checked():
    table = SampleTable((2,), local_ids=(1,), clocks=ClockMode.DISCIPLINED)
    watch = watch_of(table)
    # GIVEN a fresh sample of vehicle 2 but fewer exchanges than the check needs
    hear(table, CHECK_EXCHANGES - 1, skew_s=0.0005)
    now = 1.0 + 0.02 * (CHECK_EXCHANGES - 2) + 0.01
    # THEN it is not ready yet, for no problem; with one more exchange it is
    assert watch.unheard(now) == [2] and table.clock_problem(2) is None
    hear(table, CHECK_EXCHANGES, skew_s=0.0005)
    assert watch.unheard(now) == []


def test_a_neighbour_whose_clock_disagrees_is_named_and_never_ready():
    table = SampleTable((2,), local_ids=(1,), clocks=ClockMode.DISCIPLINED)
    watch = watch_of(table)
    # GIVEN vehicle 2's system clock 20 ms ahead of ours though called disciplined
    hear(table, CHECK_EXCHANGES, skew_s=0.020)
    now = 1.0 + 0.02 * CHECK_EXCHANGES
    # THEN it is not ready, and its lateness is the clock's problem, named
    assert watch.unheard(now) == [2]
    why = watch._lateness(2, float("inf"))
    assert why.startswith("vehicle 2's clock is at least 17.5 ms ahead of ours by 16 echoes"), why
    # AND clocks measured take the same skew as an offset and are ready
    measured = SampleTable((2,), local_ids=(1,), clocks=ClockMode.MEASURED)
    hear(measured, CHECK_EXCHANGES, skew_s=0.020)
    assert watch_of(measured).unheard(now) == []
    assert watch_of(measured)._lateness(2, float("inf")) == "never heard"


def test_a_sample_from_the_future_is_named_as_a_clock_that_disagrees():
    watch = watch_of(SampleTable((2,), local_ids=(1,), clocks=ClockMode.MEASURED))
    assert watch._lateness(2, -1.0) == ("its sample 1.00 s in the future: its clock disagrees "
                                        "with ours")
    assert watch._lateness(2, 0.61) == "0.61 s"


def test_a_supervisor_whose_clock_disagrees_keeps_the_agent_from_every_gate():
    # GIVEN clocks disciplined, neighbour 2's clock checked and agreeing, and the supervisor's
    # heartbeats proving its clock 30 ms behind ours (each echoing one of ours, 2 ms each way)
    table = SampleTable((2, SUPERVISOR_ID), local_ids=(1,), clocks=ClockMode.DISCIPLINED)
    watch = watch_of(table)
    hear(table, CHECK_EXCHANGES, skew_s=0.0)
    now = 1.0 + 0.02 * CHECK_EXCHANGES
    assert watch.not_ready(now) is None
    for k in range(CHECK_EXCHANGES):
        t4 = 2.0 + 0.1 * k
        table.heard(SUPERVISOR_ID, t4 - 0.002 - 0.030, t4, (Echo(1, t4 - 0.009, 0.005),))
    # THEN the agent is not ready, and says whose clock and by how much
    assert watch.not_ready(now).startswith(
        "the supervisor's clock is at least 28.0 ms behind ours by 16 echoes")
    # AND neighbours unheard are named when the clocks agree
    fresh = SampleTable((2, SUPERVISOR_ID), local_ids=(1,), clocks=ClockMode.DISCIPLINED)
    assert watch_of(fresh).not_ready(now) == "waiting for neighbours 2 on the bus"
