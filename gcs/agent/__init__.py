"""One agent per vehicle: its share of the law over the neighbour bus, and the supervisor of
a team of agents (`gcs agent`, `gcs fly --agents`; docs/agents.md)."""
