"""Who a process's Zenoh session listens on and connects to, its keys and its neighbours, from
the team file (gcs/agent/session.py, gcs/agent/bus.py); no session is opened here."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from gcs.agent.bus import NeighbourBus, graph_neighbours
from gcs.agent.session import (
    Endpoints,
    Keys,
    agent_endpoints,
    supervisor_endpoints,
    zenoh_config,
)
from gcs.agent.supervisor import SupervisorBus
from gcs.agent.wire import SUPERVISOR_ID
from gcs.config import load_team, team_from_dict, team_to_dict
from gcs.config.modes import NetworkMode
from gcs.config.network_schema import NetworkConfig

SQUARE4 = Path(__file__).resolve().parents[2] / "configs" / "square4.yaml"


def test_the_default_endpoints_of_an_agent_and_the_supervisor():
    net, ids = NetworkConfig(), (1, 2, 3, 4)
    # GIVEN vehicle 2's agent THEN it listens on 7452 and connects to the agent of the
    # vehicle before it and to the supervisor: one link per pair of processes
    assert agent_endpoints(net, ids, [2]) == Endpoints(
        NetworkMode.PEER, ("tcp/127.0.0.1:7452",),
        ("tcp/127.0.0.1:7451", "tcp/127.0.0.1:7450"), False)
    assert agent_endpoints(net, ids, [4]).connect == (
        "tcp/127.0.0.1:7451", "tcp/127.0.0.1:7452", "tcp/127.0.0.1:7453", "tcp/127.0.0.1:7450")
    # AND one process serving 1 and 3 listens on both and connects to the supervisor only
    # (vehicles 2 and 4 connect to it)
    ep = agent_endpoints(net, ids, [1, 3])
    assert ep.listen == ("tcp/127.0.0.1:7451", "tcp/127.0.0.1:7453")
    assert ep.connect == ("tcp/127.0.0.1:7450",)
    # AND the supervisor listens on the base port; every agent connects to it
    assert supervisor_endpoints(net, ids) == Endpoints(
        NetworkMode.PEER, ("tcp/127.0.0.1:7450",), (), False)


def test_shared_endpoints_a_router_and_client_mode():
    # GIVEN vehicles 3 and 4 behind one listener (one process for both) and a router
    data = team_to_dict(load_team(SQUARE4))
    data["network"] = {"router": "tcp/192.0.2.1:7447", "multicast_scouting": True,
                       "agents": {3: {"listen": ["tcp/192.0.2.3:7000"]},
                                  4: {"listen": ["udp/192.0.2.4:7000"]}}}
    net, ids = team_from_dict(data).network, (1, 2, 3, 4)
    # THEN an agent connects to each endpoint before its own once, the router last;
    # scouting as asked
    ep = agent_endpoints(net, ids, [4])
    assert ep.connect == ("tcp/127.0.0.1:7451", "tcp/127.0.0.1:7452", "tcp/192.0.2.3:7000",
                          "tcp/127.0.0.1:7450", "tcp/192.0.2.1:7447")
    assert ep.multicast_scouting
    # AND in client mode every process only connects to the router
    data["network"]["mode"] = "client"
    net = team_from_dict(data).network
    for ep in (agent_endpoints(net, ids, [1]), supervisor_endpoints(net, ids)):
        assert ep == Endpoints(NetworkMode.CLIENT, (), ("tcp/192.0.2.1:7447",), True)


def test_the_zenoh_config_says_mode_endpoints_and_scouting():
    config = zenoh_config(Endpoints(NetworkMode.PEER, ("tcp/127.0.0.1:7451",),
                                    ("tcp/127.0.0.1:7452",), False))
    assert json.loads(config.get_json("mode")) == "peer"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7451"]
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7452"]
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False


def test_keys_neighbours_and_the_bus_before_it_opens():
    team = load_team(SQUARE4)  # the ring 1-2-3-4-1
    keys = Keys(team.network.key_root(team.name))
    assert (keys.state(2), keys.status(2), keys.supervisor) == (
        "formation/square4/state/2", "formation/square4/agent/2/status",
        "formation/square4/supervisor")
    assert graph_neighbours(team, [1]) == {2, 4}
    assert graph_neighbours(team, [1, 2]) == {1, 2, 3, 4}
    bus = NeighbourBus.for_team(team, [1])
    assert bus.neighbour_ids == (2, 4) and bus.table.senders == (2, 4, SUPERVISOR_ID)
    assert bus.rows([2], 0.0).finite.tolist() == [False]
    assert bus.supervisor_age_s(5.0) == float("inf") and bus.supervisor_lost(5.0)
    with pytest.raises(ValueError, match=r"vehicle 1 is not served by this bus \(own ids 1\), "
                                         r"or the bus is not open"):
        bus.publish(1, 0.0, (0, 0, 0), (0, 0, 0), (0, 0, 0), (1, 0, 0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match=r"must be vehicles of the team"):
        NeighbourBus(team.network, team.name, team.ids(), [9], {1})
    with pytest.raises(ValueError, match=r"must be vehicles of the team"):
        NeighbourBus(team.network, team.name, team.ids(), [], {1})
    sup = SupervisorBus.for_team(team)
    assert sup.table.senders == (1, 2, 3, 4) and sup.status_age_s(1, 0.0) == float("inf")
    with pytest.raises(RuntimeError, match="the bus is not open"):
        sup.heartbeat()
