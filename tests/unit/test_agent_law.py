"""An agent's share of the law: its law team, and its own rows equal to the whole team's."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from gcs.agent.neighbours import NeighbourRows
from gcs.agent.table import Rows
from gcs.agent.team import AgentTeam
from gcs.config import ConfigError, load_team
from gcs.control.formation import reference_velocity
from gcs.control.law import TeamMeasurement
from gcs.fly.measure import TeamSample, drop_stale_neighbours
from gcs.fly.setup import FlyOptions, prepare
from gcs.fly.tick import build_law, law_arrays

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def grid16():
    return load_team(ROOT / "configs" / "grid16.yaml")


def test_an_agent_knows_its_neighbours_from_the_graph(grid16):
    a = AgentTeam(grid16, (6,))
    assert a.neighbours == (2, 5, 7, 10)
    assert a.law_team.ids() == (2, 5, 6, 7, 10)
    own, nb = a.rows()
    assert own.tolist() == [2] and nb.tolist() == [0, 1, 3, 4]
    both = AgentTeam(grid16, (7, 6))  # given in any order, kept in team order
    assert both.own == (6, 7) and both.neighbours == (2, 3, 5, 8, 10, 11)
    assert len(both.own_team.graph.edges) == 1  # the edge 6-7 between its own vehicles


@pytest.mark.parametrize("ids", [(17,), (), (3, 3)])
def test_an_agent_of_vehicles_the_team_has_not_is_refused(grid16, ids):
    with pytest.raises(ConfigError, match="agent vehicle ids"):
        AgentTeam(grid16, ids)


class Exact:
    """Neighbour states as the whole team has them, taken now (a bus with no delay)."""

    def __init__(self, ids, meas: TeamMeasurement, taken_s: float) -> None:
        self.index = {vid: k for k, vid in enumerate(ids)}
        self.meas = meas
        self.taken_s = taken_s
        self.published: list[int] = []

    def publish(self, vehicle_id, *_args) -> None:
        self.published.append(vehicle_id)

    def rows(self, ids, now_s) -> Rows:
        r = [self.index[v] for v in ids]
        k = len(r)
        taken = np.full(k, self.taken_s)
        return Rows(tuple(ids), self.meas.position_m[r], self.meas.velocity_mps[r],
                    self.meas.acceleration_mps2[r], np.tile([1.0, 0, 0, 0], (k, 1)),
                    np.zeros((k, 3)), taken, taken.copy(), now_s - taken,
                    np.ones(k, dtype=bool))


def measurement(team, rng) -> TeamMeasurement:
    n = team.n
    angles = rng.normal(0.0, 0.1, (n, 3))
    rot = np.empty((n, 3, 3))
    for i, (r, p, y) in enumerate(angles):
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        rot[i] = np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                           [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                           [-sp, cp * sr, cp * cr]])
    return TeamMeasurement(team.initial_positions_enu_m() + rng.normal(0, 0.5, (n, 3)),
                           rng.normal(0, 0.5, (n, 3)), rng.normal(0, 0.5, (n, 3)), rot,
                           rng.normal(0, 0.3, (n, 3)))


@pytest.mark.parametrize("own", [(6,), (1,), (6, 7), (16,)])
def test_the_agents_own_rows_are_the_whole_teams_rows(grid16, own):
    # GIVEN the whole team's law and an agent's law over its own vehicles and neighbours,
    # both from gcs fly's set-up, the agent's neighbour rows read exactly as the team has them
    team = grid16
    setup = prepare(team, FlyOptions(out_dir=Path("unused"), mode="rates"))
    whole, _, _ = build_law(setup)
    agent = AgentTeam(setup.team, own)
    part, _, _ = build_law(dataclasses.replace(setup, team=agent.law_team))
    ref_arrays, _ = law_arrays(team)
    rng = np.random.default_rng(7)
    idx = [team.index_of(v) for v in own]
    dt = 0.01
    for k in range(50):
        meas = measurement(team, rng)
        rows = NeighbourRows(agent, Exact(team.ids(), meas, k * dt), stale_after_s=0.1)
        fresh = np.ones(team.n, dtype=bool)
        drop_stale_neighbours(whole.graph, fresh, whole.active_graph.weight)
        drop_stale_neighbours(part.graph, rows.fresh(fresh[idx], k * dt), part.active_graph.weight)
        own_meas = TeamMeasurement(*(a[idx] for a in meas))
        ref = reference_velocity(k * dt, *ref_arrays)
        # WHEN both step, the agent's over the rows NeighbourRows assembles
        c_whole = whole.step(meas, ref, dt)
        c_part = rows.own(part.step(rows.measurement(own_meas, None), ref, dt))
        # THEN the agent's commands and estimates are the whole team's rows, step after step
        np.testing.assert_allclose(c_part.rate_cmd_radps, c_whole.rate_cmd_radps[idx],
                                   rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(c_part.thrust_n, c_whole.thrust_n[idx], rtol=1e-12)
        np.testing.assert_allclose(c_part.mass_estimate_kg, c_whole.mass_estimate_kg[idx],
                                   rtol=1e-12)
    np.testing.assert_allclose(part.mhat[rows.own_rows], whole.mhat[idx], rtol=1e-12)


def test_a_stale_or_unheard_neighbour_is_out_of_the_law_and_its_row_stays_finite(grid16):
    team = grid16
    agent = AgentTeam(team, (6,))
    rng = np.random.default_rng(3)
    meas = measurement(team, rng)
    src = Exact(team.ids(), meas, taken_s=0.0)
    rows = NeighbourRows(agent, src, stale_after_s=0.1)
    # neighbour 5 is 0.2 s old, neighbour 7 never heard (NaN, -inf), neighbour 10 stamped
    # 0.05 s in the future (within the bound), then 0.15 s (a clock that disagrees)
    state = src.rows(agent.neighbours, 0.2)
    state.taken_local_s[:] = 0.15
    state.taken_local_s[1] = 0.0
    state.position_enu_m[2] = np.nan
    state.taken_local_s[2] = -np.inf
    state.finite[2] = False
    state.taken_local_s[3] = 0.25
    src.rows = lambda ids, now_s: state
    fresh = rows.fresh(np.ones(1, dtype=bool), now_s=0.2)
    assert fresh.tolist() == [True, False, True, False, True]  # law team 2, 5, 6, 7, 10
    state.taken_local_s[3] = 0.35
    assert rows.fresh(np.ones(1, dtype=bool), now_s=0.2).tolist() == [True, False, True,
                                                                        False, False]
    state.taken_local_s[3] = 0.15
    idx = [team.index_of(6)]
    m = rows.measurement(TeamMeasurement(*(a[idx] for a in meas)), act_s=0.25)
    assert np.isfinite(m.position_m).all() and np.isfinite(m.velocity_mps).all()
    # the fresh neighbours were predicted to the act time (0.1 s ahead of their samples)
    v2 = meas.velocity_mps[team.index_of(2)]
    a2 = meas.acceleration_mps2[team.index_of(2)]
    np.testing.assert_allclose(m.position_m[0], meas.position_m[team.index_of(2)]
                               + 0.1 * v2 + 0.005 * a2)


def test_without_prediction_neighbours_are_carried_to_the_own_samples_instant(grid16):
    # GIVEN an agent whose own sample was taken at 0.22 s and neighbours' samples of 0.20 s
    # (a tick older: they crossed the bus after their agents' ticks) and one of 0.25 s
    team = grid16
    agent = AgentTeam(team, (6,))
    meas = measurement(team, np.random.default_rng(5))
    src = Exact(team.ids(), meas, taken_s=0.20)
    state = src.rows(agent.neighbours, 0.23)
    state.taken_local_s[3] = 0.25
    src.rows = lambda ids, now_s: state
    rows = NeighbourRows(agent, src, stale_after_s=0.1)
    rows.fresh(np.ones(1, dtype=bool), now_s=0.23)
    idx = [team.index_of(6)]
    own = TeamMeasurement(*(a[idx] for a in meas))
    m = rows.measurement(own, None, own_taken_s=np.array([0.22]))
    # THEN each older neighbour stands where its velocity and acceleration carry it in 0.02 s,
    # the newer one where it was (never carried backward), and the own row is untouched
    for row, vid in zip(rows.neighbour_rows, agent.neighbours, strict=True):
        j = team.index_of(vid)
        h = 0.0 if vid == agent.neighbours[3] else 0.02
        np.testing.assert_allclose(m.position_m[row], meas.position_m[j]
                                   + h * meas.velocity_mps[j]
                                   + 0.5 * h * h * meas.acceleration_mps2[j], rtol=1e-12)
        np.testing.assert_allclose(m.velocity_mps[row], meas.velocity_mps[j]
                                   + h * meas.acceleration_mps2[j], rtol=1e-12)
    np.testing.assert_array_equal(m.position_m[rows.own_rows], own.position_m)
    # AND without an own instant (nothing taken yet) they are used as received
    m0 = rows.measurement(own, None)
    np.testing.assert_array_equal(m0.position_m[rows.neighbour_rows],
                                  state.position_enu_m)


def test_the_tick_publishes_each_own_vehicle_with_a_finite_sample(grid16):
    agent = AgentTeam(grid16, (6, 7))
    src = Exact(grid16.ids(), measurement(grid16, np.random.default_rng(1)), 0.0)
    rows = NeighbourRows(agent, src, stale_after_s=0.1)
    n = 2
    sample = TeamSample(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)),
                        np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.zeros(n),
                        np.zeros(n), np.array([True, False]), np.zeros(n), np.zeros(n),
                        np.zeros(n), np.zeros(n))
    rows.publish(sample)
    assert src.published == [6]
