"""The team file's `network:` section (gcs/config/network_schema.py): defaults that keep every
shipped team's meaning, endpoints, vehicle ids and the rules between the keys."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from gcs.config import ConfigError, describe, load_team, team_from_dict, team_from_yaml
from gcs.config.modes import ClockMode, NetworkMode
from gcs.config.network_schema import (
    AgentNetwork,
    NetworkConfig,
    SupervisorNetwork,
    endpoint_problem,
    key_chunk,
)
from gcs.config.reader import team_to_dict, team_to_yaml

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def base() -> dict[str, Any]:
    """Scenario I (vehicles 1..4) as plain data, without a network section."""
    data = team_to_dict(load_team(CONFIGS / "square4.yaml"))
    del data["network"]
    return data


def raises_at(data: dict[str, Any], match: str) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        team_from_dict(data)
    assert "\n" not in str(info.value) and str(info.value).startswith("<dict>: ")


TEAMS = sorted(p for p in CONFIGS.glob("*.yaml") if not p.name.startswith("study_"))


@pytest.mark.parametrize("path", TEAMS, ids=lambda p: p.name)
def test_every_shipped_team_reads_with_the_default_network(path):
    # GIVEN a shipped team file (none has a network: section) WHEN read
    team = load_team(path)
    # THEN its network is the default: peer mode, the base port's endpoints, scouting off
    assert team.network == NetworkConfig()
    ids = team.ids()
    assert team.network.supervisor_listen() == ("tcp/127.0.0.1:7450",)
    assert [team.network.agent_listen(i) for i in ids] == [(f"tcp/127.0.0.1:{7450 + i}",)
                                                           for i in ids]
    assert team.network.key_root(team.name) == f"formation/{key_chunk(team.name)}"
    # AND gcs check says so
    assert "network: peer mode, keys formation/" in describe(team)


def test_a_full_network_section_reads_and_round_trips():
    # GIVEN every key of the section set
    data = base()
    data["network"] = {
        "key_prefix": "lab/flights", "mode": "client", "router": "tcp/127.0.0.1:7447",
        "multicast_scouting": True, "base_port": 9000,
        "agents": {2: {"listen": ["tcp/192.0.2.2:7000", "udp/[::1]:7001"]},
                   4: {"listen": ["quic/uav4.local:7002"]}},
        "supervisor": {"listen": ["tcp/0.0.0.0:7010"]},
        "stale_after_s": 0.5, "supervisor_lost_after_s": 2.0, "clocks": "disciplined",
        "clock_tolerance_s": 0.002,
    }
    net = team_from_dict(data).network
    # THEN each value is read, the explicit endpoints replace the defaults and the others stay
    assert net == NetworkConfig(
        key_prefix="lab/flights", mode=NetworkMode.CLIENT, router="tcp/127.0.0.1:7447",
        multicast_scouting=True, base_port=9000,
        agents=(AgentNetwork(2, ("tcp/192.0.2.2:7000", "udp/[::1]:7001")),
                AgentNetwork(4, ("quic/uav4.local:7002",))),
        supervisor=SupervisorNetwork(("tcp/0.0.0.0:7010",)),
        stale_after_s=0.5, supervisor_lost_after_s=2.0, clocks=ClockMode.DISCIPLINED,
        clock_tolerance_s=0.002)
    assert net.agent_listen(1) == ("tcp/127.0.0.1:9001",)
    assert net.agent_listen(4) == ("quic/uav4.local:7002",)
    assert net.supervisor_listen() == ("tcp/0.0.0.0:7010",)
    # AND it is written back as the mapping it was read from, through dicts and YAML
    team = team_from_dict(data)
    assert team_to_dict(team)["network"]["agents"] == data["network"]["agents"]
    assert team_from_dict(team_to_dict(team)) == team
    assert team_from_yaml(team_to_yaml(team)).network == team.network


def test_the_team_name_becomes_one_key_chunk():
    assert key_chunk("square4") == "square4"
    assert key_chunk("my team/*#1") == "my_team___1"
    assert NetworkConfig().key_root("a b") == "formation/a_b"


@pytest.mark.parametrize(("text", "problem"), [
    ("tcp/127.0.0.1:7447", None),
    ("udp/[fe80::1]:9", None),
    ("quic/host-1.example.org:65535", None),
    ("tcp/127.0.0.1", "expected an endpoint"),
    ("http/127.0.0.1:80", "expected an endpoint"),
    ("tcp/127.0.0.1:0", "port 0 of 'tcp/127.0.0.1:0' is outside 1..65535"),
    ("tcp/127.0.0.1:70000", "port 70000"),
    ("tcp/a b:1", "expected an endpoint"),
    ("udp/10.0.0.2:7447?rel=1;mixed_rel=1", None),
    ("tcp/10.0.0.2:7447#so_sndbuf=65000", None),
    ("udp/10.0.0.2:7447?rel", "expected an endpoint"),
    ("udp/10.0.0.2:7447?rel=1;", "expected an endpoint"),
    (7447, "got int 7447"),
])
def test_endpoint_forms(text, problem):
    found = endpoint_problem(text)
    assert found is None if problem is None else problem in found


NETWORK_ERRORS = [
    # (the network section, where the error is, message)
    ({"mode": "router"}, r"network\.mode: expected one of 'peer', 'client', got string 'router'"),
    ({"mode": "client"}, r"network\.router: required by mode client"),
    ({"router": "tcp/localhost"}, r"network\.router: expected an endpoint \(tcp/HOST:PORT"),
    ({"key_prefix": "a/*/b"}, r"network\.key_prefix: expected chunks .* got 'a/\*/b'"),
    ({"key_prefix": "a//b"}, r"network\.key_prefix: expected chunks"),
    ({"base_port": 0}, r"network\.base_port: expected a value in \[1, 65535\], got 0"),
    ({"base_port": 65534}, r"network\.base_port: vehicle 2's default port 65534 \+ 2 = 65536 is "
                           r"above 65535"),
    ({"multicast_scouting": "yes"}, r"network\.multicast_scouting: expected true or false"),
    ({"stale_after_s": 0}, r"network\.stale_after_s: expected > 0"),
    ({"supervisor_lost_after_s": -1}, r"network\.supervisor_lost_after_s: expected > 0"),
    ({"agents": {7: {"listen": ["tcp/127.0.0.1:1"]}}},
     r"network\.agents\.7: unknown vehicle id 7; ids are 1, 2, 3, 4"),
    ({"agents": {"2": {"listen": ["tcp/127.0.0.1:1"]}}},
     r"network\.agents\.2: expected a vehicle id \(an integer\), got str '2'"),
    ({"agents": [{"listen": ["tcp/127.0.0.1:1"]}]}, r"network\.agents: expected a mapping"),
    ({"agents": {2: {}}}, r"network\.agents\.2\.listen: required key is missing"),
    ({"agents": {2: {"listen": []}}}, r"network\.agents\.2\.listen: expected a list of endpoints"),
    ({"agents": {2: {"listen": ["tcp/127.0.0.1:1", "tcp/127.0.0.1:1"]}}},
     r"network\.agents\.2\.listen\[1\]: duplicate endpoint 'tcp/127.0.0.1:1' "
     r"\(also network\.agents\.2\.listen\[0\]\)"),
    ({"agents": {2: {"listen": ["tcp/127.0.0.1:7451"]}}},
     r"network\.agents\.2\.listen\[0\]: tcp/127\.0\.0\.1:7451 is vehicle 2's listen endpoint "
     r"and also vehicle 1 \(default: base_port \+ 1\)'s"),
    ({"agents": {1: {"listen": ["tcp/127.0.0.1:7452"]}}},
     r"network\.base_port: tcp/127\.0\.0\.1:7452 is vehicle 2 \(default: base_port \+ 2\)'s "
     r"listen endpoint and also vehicle 1's"),
    ({"agents": {1: {"listen": ["udp/10.0.0.1:7000?rel=1;mixed_rel=1"]},
                 2: {"listen": ["udp/10.0.0.1:7000"]}}},
     r"network\.agents\.2\.listen\[0\]: udp/10\.0\.0\.1:7000 is vehicle 2's listen endpoint "
     r"and also vehicle 1's"),
    ({"supervisor": {"listen": ["tcp/127.0.0.1:7453"]}},
     r"network\.base_port: tcp/127\.0\.0\.1:7453 is vehicle 3 .* also the supervisor's"),
    ({"supervisor": {"listen": "tcp/127.0.0.1:1"}}, r"network\.supervisor\.listen: expected a list"),
    ({"supervisor": {"lisen": []}}, r"network\.supervisor\.lisen: unknown key; did you mean "
                                    r"'listen'\?"),
    ({"agnets": {}}, r"network\.agnets: unknown key; did you mean 'agents'\?"),
    ({"clocks": "synced"}, r"network\.clocks: expected one of 'measured', 'disciplined', 'one-host', "
                            r"got string 'synced'"),
    ({"clock_tolerance_s": 0}, r"network\.clock_tolerance_s: expected a value in \(0, 1\]"),
    ({"clock_sync": False}, r"network\.clock_sync: unknown key"),
]


@pytest.mark.parametrize(("section", "match"), NETWORK_ERRORS)
def test_each_network_problem_is_one_config_error_naming_the_key(section, match):
    data = base()
    data["network"] = section
    raises_at(data, match)


def test_a_bad_network_value_in_a_file_names_its_line(tmp_path):
    # GIVEN square4 with a network section whose vehicle 9 does not exist, on line 3 of it
    text = (CONFIGS / "square4.yaml").read_text()
    text += "\nnetwork:\n  mode: peer\n  agents:\n    9: {listen: [tcp/127.0.0.1:9]}\n"
    path = tmp_path / "t.yaml"
    path.write_text(text)
    line = text.splitlines().index("    9: {listen: [tcp/127.0.0.1:9]}") + 1
    # THEN the error names the key and that line
    with pytest.raises(ConfigError, match=rf"network\.agents\.9: unknown vehicle id 9; ids are "
                                          rf"1, 2, 3, 4 \(line {line}\)"):
        load_team(path)


def test_a_huge_vehicle_id_without_a_network_section_still_reads():
    # GIVEN a vehicle id whose default agent port would be above 65535, and no network section
    data = base()
    data["vehicles"][3]["id"] = 60_000
    data["graph"]["edges"] = [[1, 2], [2, 3], [3, 60_000], [60_000, 1]]
    team = team_from_dict(data)
    # THEN the file reads as before, and only asking for that agent's endpoint says why not
    with pytest.raises(ConfigError, match=r"network\.base_port: vehicle 60000's default port"):
        team.network.agent_listen(60_000)
    # AND a network section naming its endpoint makes it valid
    data["network"] = {"agents": {60_000: {"listen": ["tcp/127.0.0.1:5000"]}}}
    assert team_from_dict(data).network.agent_listen(60_000) == ("tcp/127.0.0.1:5000",)
