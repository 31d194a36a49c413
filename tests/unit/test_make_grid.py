"""configs/grid240.yaml is what benchmarks/make_grid.py writes, and a valid team: 240 vehicles,
the 15 x 16 grid graph's 449 edges, one shared GCS port; a shared port refuses more vehicles
than one MAVLink network has sysids."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.make_grid import grid_edges, team_text
from gcs.config import load_team

ROOT = Path(__file__).resolve().parents[2]


def test_grid240_is_the_generators_output_and_loads() -> None:
    path = ROOT / "configs" / "grid240.yaml"
    assert path.read_text() == team_text(15, 16, 14550)
    team = load_team(path)
    assert team.n == 240
    assert len(team.graph.edges) == 449
    assert {v.link.local_port for v in team.vehicles} == {14550}
    assert sorted(v.sysid for v in team.vehicles) == list(range(1, 241))


def test_grid_edges_are_row_and_column_neighbours() -> None:
    assert grid_edges(2, 3) == [(1, 2), (1, 4), (2, 3), (2, 5), (3, 6), (4, 5), (5, 6)]
    assert len(grid_edges(15, 16)) == 15 * 15 + 14 * 16


def test_a_team_holds_at_most_254_vehicles() -> None:
    with pytest.raises(SystemExit, match="sysids 1-254"):
        team_text(16, 16, 14550)
    assert "sysid: 254" in team_text(2, 127, None)


@pytest.mark.parametrize("rows, cols", [(4, 4), (6, 10), (8, 8), (15, 16)])
def test_without_a_shared_port_no_gcs_port_is_a_vehicles_port(rows, cols, tmp_path) -> None:
    path = tmp_path / "grid.yaml"
    path.write_text(team_text(rows, cols, None))
    team = load_team(path)
    gcs = [v.link.local_port for v in team.vehicles]
    vehicles = {v.link.remote_port for v in team.vehicles}
    assert len(set(gcs)) == team.n and not set(gcs) & vehicles
    assert min(gcs) == 14640 or min(gcs) == max(vehicles) + 1
