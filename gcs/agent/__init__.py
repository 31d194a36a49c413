"""One agent per vehicle: its share of the law over the neighbour bus, and the supervisor of a
team of agents (`gcs agent`, `gcs fly --agents`; docs/agents.md).

The bus, pure and sans-IO: `wire` (state samples as bytes), `control` (control messages as
JSON), `clocks` (a peer's clock offset), `table` (the latest sample per sender, per-edge
figures); its I/O: `session` (the Zenoh session and its keys), `bus` (NeighbourBus, an agent's
side) and `supervisor` (SupervisorBus). The agent: `team` (its share of the team), `neighbours`
(its law's rows), `runtime` (its flight and its watch of the team); the supervisor's sequence:
`supervise`; the records: `merge`; the command lines: `command`. Importing the package imports
none of them.
"""
