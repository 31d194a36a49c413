"""A stand-in agent in its own process (tests/integration/test_agent_bus.py,
benchmarks/bench_bus.py): one NeighbourBus serving one vehicle, publishing its state at a fixed
rate until its standard input closes or its time is up, reading its neighbours' rows at each
tick as an agent's law does, then printing per neighbour the samples received and lost and the
ages at those ticks (after the first `warmup_s`, default 2 s) as one JSON line.

    python tests/integration/agent_peer.py '{"network": {"key_prefix": "p", "agents": {"1":
        ["tcp/127.0.0.1:7451"], ...}, "supervisor": [...]}, "team": "t", "ids": [1, 2],
        "own": 2, "neighbours": [1], "rate_hz": 50, "seconds": 60}'
"""

from __future__ import annotations

import asyncio
import json
import sys
import time

import numpy as np

from gcs.agent.bus import NeighbourBus
from gcs.config.network_schema import AgentNetwork, NetworkConfig, SupervisorNetwork


def network_of(spec: dict) -> NetworkConfig:
    """{"key_prefix": str, "agents": {id: [endpoints]}, "supervisor": [endpoints]}."""
    agents = tuple(AgentNetwork(int(vid), tuple(listen)) for vid, listen in spec["agents"].items())
    return NetworkConfig(key_prefix=spec["key_prefix"], agents=agents,
                         supervisor=SupervisorNetwork(tuple(spec["supervisor"])))


async def main(spec: dict) -> None:
    bus = NeighbourBus(network_of(spec["network"]), spec["team"], spec["ids"], [spec["own"]],
                       spec["neighbours"])
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    loop.add_reader(sys.stdin.fileno(), stop.set)  # stdin readable: closed by the parent
    async with bus:
        print("agent_peer: ready", flush=True)
        start = time.monotonic()
        period, end = 1.0 / spec["rate_hz"], start + spec["seconds"]
        measure_from = start + spec.get("warmup_s", 2.0)
        neighbours = list(spec["neighbours"])
        ages: list[np.ndarray] = []
        k = 0
        while not stop.is_set() and time.monotonic() < end:
            t = time.monotonic()
            bus.publish(spec["own"], t, (k * 0.01, 1.0, 2.0), (0.5, 0.0, 0.0), (0.0, 0.0, 0.1),
                        (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            if t >= measure_from:
                ages.append(bus.rows(neighbours, t).age_s)
            k += 1
            try:
                async with asyncio.timeout(period - (time.monotonic() - t)):
                    await stop.wait()
            except TimeoutError:
                pass
        stats = bus.stats()
        table = np.array(ages).reshape(-1, len(neighbours)) * 1e3
        print(json.dumps({str(v): {"received": stats[v].received, "lost": stats[v].lost,
                                   "ages_ms": table[:, j].tolist()}
                          for j, v in enumerate(neighbours)}), flush=True)


if __name__ == "__main__":
    asyncio.run(main(json.loads(sys.argv[1])))
