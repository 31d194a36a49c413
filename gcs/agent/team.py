"""Which part of the team an agent flies: its own vehicles, their graph neighbours, and the
sub-teams its flight and its law run over (pure).

An agent's law runs over its *law team*: its own vehicles and their graph neighbours, rows in
team-file order. Row i of the paper's law (23)-(24) reads vehicle i's own state and its
neighbours' positions, velocities and accelerations only (gcs/control/law.py), so the rows of
the agent's own vehicles are exactly the rows the whole team's law would compute; the
neighbours' rows are computed too and never sent anywhere.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from gcs.config import ConfigError, TeamConfig
from gcs.config.schema import GraphConfig

__all__ = ["AgentTeam", "sub_team"]


def sub_team(team: TeamConfig, ids: tuple[int, ...] | frozenset[int]) -> TeamConfig:
    """The team file restricted to the vehicles `ids` (team-file order) and the graph edges
    between them."""
    keep = set(ids)
    vehicles = tuple(v for v in team.vehicles if v.id in keep)
    edges = tuple(e for e in team.graph.edges if e.i in keep and e.j in keep)
    return dataclasses.replace(team, vehicles=vehicles, graph=GraphConfig(edges=edges))


@dataclass(frozen=True, slots=True)
class AgentTeam:
    """An agent's share of `team`: the vehicles it holds the links of (`own`)."""

    team: TeamConfig
    own: tuple[int, ...]

    def __post_init__(self) -> None:
        ids = self.team.ids()
        unknown = [vid for vid in self.own if vid not in ids]
        if unknown or not self.own:
            raise ConfigError(self.team.source_path, "vehicles",
                              f"agent vehicle ids {list(self.own)}: the team has {list(ids)}")
        if len(set(self.own)) != len(self.own):
            raise ConfigError(self.team.source_path, "vehicles",
                              f"agent vehicle ids {list(self.own)} repeat an id")
        object.__setattr__(self, "own", tuple(vid for vid in ids if vid in self.own))

    @property
    def neighbours(self) -> tuple[int, ...]:
        """The other vehicles some own vehicle has an edge to, in team-file order."""
        own = set(self.own)
        near = {e.j for e in self.team.graph.edges if e.i in own} | {
            e.i for e in self.team.graph.edges if e.j in own}
        return tuple(vid for vid in self.team.ids() if vid in near - own)

    @property
    def own_team(self) -> TeamConfig:
        """The team of the agent's links, mission machine, setpoints and records."""
        return sub_team(self.team, self.own)

    @property
    def law_team(self) -> TeamConfig:
        """The team its law runs over: own vehicles and their neighbours."""
        return sub_team(self.team, frozenset(self.own) | frozenset(self.neighbours))

    def rows(self) -> tuple[np.ndarray, np.ndarray]:
        """(own rows, neighbour rows) of the law team, each in the order of `own` /
        `neighbours`."""
        law_ids = self.law_team.ids()
        return (np.array([law_ids.index(v) for v in self.own], dtype=np.int64),
                np.array([law_ids.index(v) for v in self.neighbours], dtype=np.int64))
