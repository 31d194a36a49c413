"""The network testbed's impairment (tests/netns.py) as netem and relay arguments, its checks,
and the names it gives and sweeps: no namespace is created here."""

from __future__ import annotations

import pytest

from tests import netns
from tests.netns import BETWEEN_AGENTS, Distribution, Impairment


def test_between_agents_is_20_ms_normal_jitter_5_ms_and_10_percent_loss_as_netem_args():
    # GIVEN issue 30's link WHEN written for tc THEN netem's own syntax, microseconds
    assert BETWEEN_AGENTS.netem_args() == ["delay", "20000us", "5000us", "distribution",
                                           "normal", "loss", "10%"]
    assert BETWEEN_AGENTS.describe() == "20 ms +- 5 ms (normal), 10 % loss"
    # AND a round trip crosses two senders' links: 1 - 0.9**2 lost
    assert BETWEEN_AGENTS.round_trip_loss == pytest.approx(0.19)


def test_uniform_jitter_is_netems_default_and_a_plain_delay_has_no_jitter_field():
    assert Impairment(0.02, 0.005).netem_args() == ["delay", "20000us", "5000us"]
    assert Impairment(0.0125).netem_args() == ["delay", "12500us"]
    # a normal distribution without jitter is a plain delay (netem refuses the bare keyword)
    assert Impairment(0.01, 0.0, 0.005, "normal").netem_args() == [
        "delay", "10000us", "loss", "0.5%"]


def test_relay_args_carry_the_same_impairment():
    assert BETWEEN_AGENTS.relay_args() == ["--delay-s", "0.02", "--jitter-s", "0.005",
                                           "--distribution", "normal", "--loss", "0.1"]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"delay_s": -0.001}, r"impairment delay_s: expected >= 0, got -0.001"),
        ({"jitter_s": float("nan")}, r"impairment jitter_s: expected >= 0, got nan"),
        ({"loss": 1.0}, r"impairment loss: expected in \[0, 1\), got 1.0"),
        ({"distribution": "pareto"}, r"'pareto' is not a valid Distribution"),
    ],
)
def test_a_bad_impairment_names_the_field_and_the_value(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Impairment(**kwargs)


def test_a_testbed_checks_its_arguments_before_creating_anything():
    with pytest.raises(ValueError, match=r"testbed hosts: expected 1..250, got 0"):
        netns.Testbed(0)
    with pytest.raises(ValueError, match=r"expected one per host \(3\), got 2"):
        netns.Testbed(3, [BETWEEN_AGENTS, None])
    with pytest.raises(ValueError, match=r"testbed mode: expected auto, namespaces or "
                                         r"loopback, got 'docker'"):
        netns.Testbed(2, mode="docker")


def test_names_carry_the_pid_namespace_and_pid_and_only_ours_match():
    # GIVEN a name this process would give WHEN parsed THEN its pid namespace and pid
    name = f"{netns._base_name()}-h3"
    m = netns.NAME_RE.match(name)
    assert m is not None
    assert (int(m.group(1)), int(m.group(2))) == (netns._pid_namespace(), netns.os.getpid())
    # AND other namespaces' names never match (the sweep never touches them)
    for other in ("px4net", "fktb-1-2-3", "fktb-1-2-3-h1x", "xfktb-1-2-3-br"):
        assert netns.NAME_RE.match(other) is None
    assert Distribution("normal") is Distribution.NORMAL
