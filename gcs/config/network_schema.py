"""The team file's optional `network:` section: how `gcs agent` processes and their supervisor
find each other over Zenoh (gcs/agent/bus.py), its dataclasses and its reader.

Every key has a default, so a team file without the section keeps its meaning: each vehicle's
agent listens on tcp/127.0.0.1:<base_port + id>, the supervisor on tcp/127.0.0.1:<base_port>,
and every process connects to all the others' endpoints (peer mode, no multicast scouting).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gcs.config.declare import key, read_section
from gcs.config.errors import ConfigError
from gcs.config.modes import ClockMode, NetworkMode

if TYPE_CHECKING:
    from gcs.config.yamlnode import Node

#: A Zenoh endpoint this project accepts: protocol/host:port (host a name, IPv4 or [IPv6]),
#: then optionally Zenoh's link metadata `?key=value;...` and configuration `#key=value;...`
#: (e.g. `udp/10.0.0.2:7447?rel=1;mixed_rel=1`, docs/agents.md "The mesh").
ENDPOINT = re.compile(r"^(tcp|udp|quic)/"
                      r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9.-]*[A-Za-z0-9])?)"
                      r":([0-9]{1,5})"
                      r"(\?[A-Za-z0-9_]+=[A-Za-z0-9_.-]+(?:;[A-Za-z0-9_]+=[A-Za-z0-9_.-]+)*)?"
                      r"(#[A-Za-z0-9_]+=[A-Za-z0-9_.-]+(?:;[A-Za-z0-9_]+=[A-Za-z0-9_.-]+)*)?$")
ENDPOINT_FORMS = ("tcp/HOST:PORT, udp/HOST:PORT or quic/HOST:PORT, optionally followed by "
                  "?key=value;... metadata")
#: A key-expression chunk as the bus writes it: no '/', no Zenoh wildcard or reserved character.
_CHUNK = re.compile(r"^[A-Za-z0-9_.-]+$")
_NOT_CHUNK = re.compile(r"[^A-Za-z0-9_.-]")
DEFAULT_HOST = "127.0.0.1"


def endpoint_socket(text: str) -> str:
    """The socket an endpoint names (protocol/host:port), without Zenoh's metadata and
    configuration: two endpoints with the same one cannot both be listened on."""
    return text.split("?", 1)[0].split("#", 1)[0]


def endpoint_problem(text: Any) -> str | None:
    """Why `text` is not an endpoint this project accepts, or None."""
    if not isinstance(text, str):
        return f"expected an endpoint ({ENDPOINT_FORMS}), got {type(text).__name__} {text!r}"
    m = ENDPOINT.match(text)
    if m is None:
        return f"expected an endpoint ({ENDPOINT_FORMS}), got {text!r}"
    if not 1 <= int(m.group(3)) <= 65535:
        return f"port {int(m.group(3))} of {text!r} is outside 1..65535"
    return None


def _endpoint(node: Node, default: Any) -> str | None:
    if node.absent:
        return default
    if (problem := endpoint_problem(node.value)) is not None:
        node.fail(problem)
    return node.value


def _endpoints(node: Node, default: Any) -> tuple[str, ...] | None:
    """A list of at least one endpoint, each checked; `default` when absent."""
    if node.absent:
        return default
    items = node.items(f"endpoints ({ENDPOINT_FORMS})", min_len=1)
    out = tuple(_endpoint(item, None) for item in items)
    for k, (item, text) in enumerate(zip(items, out, strict=True)):
        if text in out[:k]:
            item.fail(f"duplicate endpoint {text!r} (also {node.path}[{out.index(text)}])")
    return out


def _key_prefix(node: Node, prefix: str) -> None:
    chunks = prefix.split("/")
    if not all(_CHUNK.match(c) for c in chunks):
        node.fail(f"expected chunks of letters, digits, '_', '.' or '-' joined by '/' (a Zenoh "
                  f"key without wildcards), got {prefix!r}")


def key_chunk(name: str) -> str:
    """`name` (a team name) as one chunk of a Zenoh key: every character that is not a letter, a
    digit, '_', '.' or '-' becomes '_'."""
    return _NOT_CHUNK.sub("_", name)


@dataclass(frozen=True, slots=True)
class AgentNetwork:
    """`network.agents.<id>`: the endpoints vehicle `vehicle_id`'s agent process listens on."""

    vehicle_id: int = key(internal=True)  # the mapping's key
    listen: tuple[str, ...] = key(read=_endpoints)


@dataclass(frozen=True, slots=True)
class SupervisorNetwork:
    """`network.supervisor`: the endpoints the supervisor (`gcs fly --agents`) listens on."""

    listen: tuple[str, ...] | None = key(None, read=_endpoints)  # None: base_port's


def _agents_plain(agents: tuple[AgentNetwork, ...]) -> dict[int, dict[str, list[str]]]:
    return {a.vehicle_id: {"listen": list(a.listen)} for a in agents}


@dataclass(frozen=True, slots=True)
class NetworkConfig:
    """The `network:` section. `agents` holds only the vehicles the file gives endpoints for;
    `agent_listen(id)` and `supervisor_listen()` resolve the defaults."""

    key_prefix: str = key("formation", check=_key_prefix)  # keys: <prefix>/<team name>/...
    mode: NetworkMode = key(NetworkMode.PEER)
    # client mode: the router every message goes through; peer mode: also connected to
    router: str | None = key(None, read=_endpoint)
    multicast_scouting: bool = key(False)  # find peers by UDP multicast besides the endpoints
    base_port: int = key(7450, ge=1, le=65535)  # defaults: supervisor base_port, agent + id
    agents: tuple[AgentNetwork, ...] = key((), write=_agents_plain)
    supervisor: SupervisorNetwork = key(SupervisorNetwork())
    # the supervisor takes a vehicle's state older than this as stale (its own clock)
    stale_after_s: float = key(1.0, gt=0.0)
    # an agent takes the supervisor as lost when it heard nothing from it for this long
    supervisor_lost_after_s: float = key(1.0, gt=0.0)
    # how neighbours' sample times reach an agent's clock (ClockMode; docs/agents.md, "Clocks")
    clocks: ClockMode = key(ClockMode.MEASURED)
    # with clocks disciplined: a peer whose clock the echoes prove further from ours than this
    # is not flown with (its samples' ages would be wrong by as much)
    clock_tolerance_s: float = key(0.005, gt=0.0, le=1.0)

    def agent_listen(self, vehicle_id: int) -> tuple[str, ...]:
        """The endpoints vehicle `vehicle_id`'s agent listens on: its `agents` entry, else
        tcp/127.0.0.1:<base_port + id>; ConfigError when that port is out of range."""
        for a in self.agents:
            if a.vehicle_id == vehicle_id:
                return a.listen
        if (problem := _default_port_problem(self.base_port, vehicle_id)) is not None:
            raise ConfigError(f"network.base_port: {problem}")
        return (f"tcp/{DEFAULT_HOST}:{self.base_port + vehicle_id}",)

    def supervisor_listen(self) -> tuple[str, ...]:
        """The endpoints the supervisor listens on (default tcp/127.0.0.1:<base_port>)."""
        if self.supervisor.listen is not None:
            return self.supervisor.listen
        return (f"tcp/{DEFAULT_HOST}:{self.base_port}",)

    def key_root(self, team_name: str) -> str:
        """`<key_prefix>/<team name as one key chunk>`: where every key of the team starts."""
        return f"{self.key_prefix}/{key_chunk(team_name)}"


def _default_port_problem(base_port: int, vehicle_id: int) -> str | None:
    port = base_port + vehicle_id
    if port <= 65535:
        return None
    return (f"vehicle {vehicle_id}'s default port {base_port} + {vehicle_id} = {port} is above "
            f"65535; give network.agents.{vehicle_id}.listen or a lower base_port")


def _read_agents(node: Node, ids: Sequence[int]) -> tuple[AgentNetwork, ...]:
    if node.absent:
        return ()
    if not isinstance(node.value, dict):
        node.fail(f"expected a mapping of vehicle ids to {{listen: [endpoints]}}, got "
                  f"{type(node.value).__name__}")
    out = []
    for vid in node.value:
        entry = node.entry(vid)
        if not isinstance(vid, int) or isinstance(vid, bool):
            entry.fail(f"expected a vehicle id (an integer), got {type(vid).__name__} {vid!r}")
        if vid not in ids:
            entry.fail(f"unknown vehicle id {vid}; ids are {', '.join(map(str, ids))}")
        out.append(read_section(entry, AgentNetwork, given={"vehicle_id": lambda _, v=vid: v}))
    return tuple(out)


def read_network(node: Node, ids: Sequence[int]) -> NetworkConfig:
    """The optional `network:` section for a team of vehicles `ids`, with the rules between its
    keys: client mode needs a router; no two processes listen on one endpoint; every default
    port is in range."""
    if node.absent:
        return NetworkConfig()
    net = read_section(node, NetworkConfig, NetworkConfig(),
                       given={"agents": lambda _: _read_agents(node.child("agents"), ids)})
    if net.mode == NetworkMode.CLIENT and net.router is None:
        node.child("router").fail("required by mode client: a client reaches the others only "
                                  "through a router (e.g. tcp/127.0.0.1:7447)")
    owners: dict[str, str] = {}

    def claim(endpoints: tuple[str, ...], who: str, nodes: list[Node]) -> None:
        for text, where in zip(endpoints, nodes, strict=True):
            socket = endpoint_socket(text)
            if socket in owners:
                where.fail(f"{socket} is {who}'s listen endpoint and also {owners[socket]}'s; "
                           "each process needs its own")
            owners[socket] = who

    base = node.child("base_port")
    sup = node.child("supervisor.listen")
    sup_nodes = [sup.item(k) for k in range(len(sup.value))] if not sup.absent else [base]
    claim(net.supervisor_listen(), "the supervisor" + (" (default: base_port)" * sup.absent),
          sup_nodes)
    explicit = {a.vehicle_id for a in net.agents}
    for vid in ids:
        if vid in explicit:
            listen = node.child("agents").entry(vid).child("listen")
            claim(net.agent_listen(vid), f"vehicle {vid}",
                  [listen.item(k) for k in range(len(listen.value))])
        elif (problem := _default_port_problem(net.base_port, vid)) is not None:
            base.fail(problem)
        else:
            claim(net.agent_listen(vid), f"vehicle {vid} (default: base_port + {vid})", [base])
    return net
