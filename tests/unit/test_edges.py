"""The law on an edge list equals the paper's dense sums over a_ij: (21), (23), (24), u' and u''
of spec 2.9, the staleness rule and the formation error, on random weighted graphs."""

from __future__ import annotations

import numpy as np
import pytest

from gcs.control.derivatives import force_derivatives
from gcs.control.formation import edge_list
from gcs.control.gains import PAPER_GAINS
from gcs.control.law import TeamLaw, TeamMeasurement, position_stage
from gcs.fly.measure import drop_stale_neighbours
from gcs.metrics import formation_error_m

G = PAPER_GAINS
E3 = np.array([0.0, 0.0, 1.0])


def random_graph(rng: np.random.Generator, n: int, density: float, isolated: int) -> np.ndarray:
    """A symmetric weight matrix (n, n), zero diagonal, weights in [0.2, 3), the last
    `isolated` vehicles without any edge."""
    upper = np.triu(rng.uniform(0.2, 3.0, (n, n)) * (rng.random((n, n)) < density), k=1)
    a = upper + upper.T
    if isolated:
        a[n - isolated:, :] = 0.0
        a[:, n - isolated:] = 0.0
    return a


def random_state(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    rot = np.empty((n, 3, 3))
    for i in range(n):
        q, r = np.linalg.qr(np.eye(3) + 0.2 * rng.normal(size=(3, 3)))
        q = q @ np.diag(np.sign(np.diag(r)))
        rot[i] = q if np.linalg.det(q) > 0 else -q
    return {
        "p": rng.normal(0.0, 3.0, (n, 3)), "v": rng.normal(0.0, 0.7, (n, 3)),
        "acc": rng.normal(0.0, 0.5, (n, 3)), "rot": rot, "w": rng.normal(0.0, 0.3, (n, 3)),
        "theta": rng.normal(0.0, 2.0, (n, 3)), "mhat": rng.uniform(0.5, 4.0, n),
        "ref": rng.normal(0.0, 0.2, (4, 3)),
    }


def sat(x):
    return G.sigma_a * np.tanh(x / G.sigma_a)


def dsat(x):
    return 1.0 - np.tanh(x / G.sigma_a) ** 2


def ddsat(x):
    return -2.0 / G.sigma_a * np.tanh(x / G.sigma_a) * dsat(x)


def laplacian_sum(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """sum_j a_ij (x_i - x_j) per row, over all n x n pairs (the dense form)."""
    return np.einsum("ij,ijk->ik", a, x[:, None, :] - x[None, :, :])


def dense_law(a: np.ndarray, st: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The adaptive law and its derivatives from the paper's formulas, dense in a_ij."""
    sig, g, am, ap = G.sigma_a, G.gravity_mps2, G.alpha_m, G.alpha_p
    p, v, acc, rot, w, th, mhat, ref = (st[k] for k in
                                        ("p", "v", "acc", "rot", "w", "theta", "mhat", "ref"))
    ve = v - ref[0]
    s = G.c_p * laplacian_sum(a, p - th) + ve  # (21)
    phi = 2.0 + sat(v).sum(axis=1) / (3.0 * sig)
    kappa = am * mhat / phi
    acmd = -ap * (sat(s) + sat(ve)) + g * E3 + ref[1]  # (23)
    u = kappa[:, None] * acmd
    t_n = np.linalg.norm(u, axis=1)  # (12)
    re3 = rot[:, :, 2]
    zeta = dsat(v)
    mhat_d = (-g * dsat(v[:, 2]) * mhat / (3.0 * sig * phi)
              + t_n * (zeta * re3).sum(axis=1) / (3.0 * sig * am))  # (24), sign of spec 2.3
    # spec 2.9: first derivatives along the loop, v' = acc measured
    ve_d = acc - ref[1]
    s_d = G.c_p * laplacian_sum(a, v) + ve_d
    phi_d = (zeta * acc).sum(axis=1) / (3.0 * sig)
    kap_d = am * (mhat_d / phi - mhat * phi_d / phi**2)
    a_d = -ap * (dsat(s) * s_d + dsat(ve) * ve_d) + ref[2]
    u_d = kap_d[:, None] * acmd + kappa[:, None] * a_d
    # v'' = (1/kappa) (T' R e3 + T R (omega x e3))
    t_d = (u * u_d).sum(axis=1) / t_n
    rwe3 = rot[:, :, 0] * w[:, 1:2] - rot[:, :, 1] * w[:, 0:1]
    v_dd = (t_d[:, None] * re3 + t_n[:, None] * rwe3) / kappa[:, None]
    zeta_d = ddsat(v) * acc
    phi_dd = (ddsat(v) * acc**2 + dsat(v) * v_dd).sum(axis=1) / (3.0 * sig)
    mhat_dd = (-(g / (3.0 * sig)) * (zeta_d[:, 2] * mhat / phi + zeta[:, 2] * mhat_d / phi
                                     - zeta[:, 2] * mhat * phi_d / phi**2)
               + (t_d * (zeta * re3).sum(axis=1) + t_n * (zeta_d * re3).sum(axis=1)
                  + t_n * (zeta * rwe3).sum(axis=1)) / (3.0 * sig * am))
    kap_dd = am * (mhat_dd / phi - 2.0 * mhat_d * phi_d / phi**2 - mhat * phi_dd / phi**2
                   + 2.0 * mhat * phi_d**2 / phi**3)
    ve_dd = v_dd - ref[2]
    s_dd = G.c_p * laplacian_sum(a, acc) + ve_dd
    a_dd = -ap * (ddsat(s) * s_d**2 + dsat(s) * s_dd + ddsat(ve) * ve_d**2
                  + dsat(ve) * ve_dd) + ref[3]
    u_dd = kap_dd[:, None] * acmd + 2.0 * kap_d[:, None] * a_d + kappa[:, None] * a_dd
    return {"u": u, "a": acmd, "s": s, "ve": ve, "phi": phi, "kappa": kappa, "thrust": t_n,
            "mhat_rate": mhat_d, "du": u_d, "ddu": u_dd}


CASES = [  # (n, edge density, isolated vehicles, seed)
    (1, 0.0, 0, 1), (2, 1.0, 0, 2), (2, 1.0, 2, 3), (7, 0.5, 1, 4), (30, 0.15, 3, 5),
    (64, 0.06, 0, 6),
]


@pytest.mark.parametrize(("n", "density", "isolated", "seed"), CASES)
@pytest.mark.parametrize("stale_fraction", [0.0, 0.3])
def test_the_edge_list_law_equals_the_dense_sums(n, density, isolated, seed, stale_fraction):
    # GIVEN a random weighted symmetric graph, a random team state and a random stale mask
    rng = np.random.default_rng(seed)
    a = random_graph(rng, n, density, isolated)
    st = random_state(rng, n)
    fresh = rng.random(n) >= stale_fraction
    graph = edge_list(a)
    weight = np.full_like(graph.weight, np.nan)
    # WHEN the staleness rule is applied to the edge list and the law evaluated on it
    stale = drop_stale_neighbours(graph, fresh, weight)
    active = graph._replace(weight=weight)
    stage = position_stage(
        st["p"], st["v"], st["rot"], st["mhat"], st["mhat"], active, st["theta"], st["ref"], G,
        True)
    u, acmd, s, ve, ph, kappa, t_n, mhat_rate = stage
    meas = TeamMeasurement(st["p"], st["v"], st["acc"], st["rot"], st["w"])
    du, ddu = force_derivatives(meas, stage, st["mhat"], 1.0 / kappa, active, st["ref"], G, True)
    # THEN every output is the dense formula's with row i keeping a_ij only for fresh j
    ref = dense_law(a * fresh[None, :], st)
    got = {"u": u, "a": acmd, "s": s, "ve": ve, "phi": ph, "kappa": kappa, "thrust": t_n,
           "mhat_rate": mhat_rate, "du": du, "ddu": ddu}
    for name, value in got.items():
        np.testing.assert_allclose(value, ref[name], rtol=1e-11, atol=1e-11, err_msg=name)
    # AND the stale counts are the dense ones: neighbours j (a_ij != 0) that are stale
    np.testing.assert_array_equal(stale, ((a != 0.0) & ~fresh[None, :]).sum(axis=1))
    # AND the configured graph keeps its weights (a fresh tick restores them)
    np.testing.assert_array_equal(graph.weight, a[a != 0.0])


def test_edge_list_rows_of_a_grid_with_an_isolated_vehicle_and_of_one_vehicle():
    # GIVEN a 2 x 2 grid (0-1, 0-2, 1-3, 2-3) plus vehicle 4 without edges
    a = np.zeros((5, 5))
    for i, j, wt in ((0, 1, 1.0), (0, 2, 2.0), (1, 3, 0.5), (2, 3, 1.5)):
        a[i, j] = a[j, i] = wt
    g = edge_list(a)
    # THEN each edge is stored in both rows, ascending, and row 4 is empty
    np.testing.assert_array_equal(g.row_start, [0, 2, 4, 6, 8, 8])
    np.testing.assert_array_equal(g.neighbour, [1, 2, 0, 3, 0, 3, 1, 2])
    np.testing.assert_array_equal(g.weight, [1.0, 2.0, 1.0, 0.5, 2.0, 1.5, 0.5, 1.5])
    assert g.row_start.dtype == np.int64 and g.neighbour.dtype == np.int64
    # AND one vehicle has one empty row
    one = edge_list(np.zeros((1, 1)))
    assert one.row_start.tolist() == [0, 0] and one.neighbour.size == 0 == one.weight.size
    with pytest.raises(ValueError, match=r"adjacency: expected a square \(n, n\) matrix, got "
                                         r"shape \(2, 3\)"):
        edge_list(np.zeros((2, 3)))


def test_team_law_steps_on_its_active_weights():
    # GIVEN a team law on a random graph and the same law built on the effective weights
    rng = np.random.default_rng(7)
    n = 12
    a = random_graph(rng, n, 0.3, 1)
    st = random_state(rng, n)
    fresh = rng.random(n) >= 0.3
    meas = TeamMeasurement(st["p"], st["v"], st["acc"], st["rot"], st["w"])

    def law(adjacency):
        return TeamLaw(G, adjacency, st["theta"], st["mhat"], np.full((n, 3), 0.08))

    flown = law(a)
    # WHEN the stale neighbours are dropped in place between ticks
    drop_stale_neighbours(flown.graph, fresh, flown.active_graph.weight)
    got = flown.step(meas, st["ref"], 0.01)
    want = law(a * fresh[None, :]).step(meas, st["ref"], 0.01)
    # THEN it flies exactly as a law configured with a_ij fresh[j]
    np.testing.assert_array_equal(got.rate_cmd_radps, want.rate_cmd_radps)
    np.testing.assert_array_equal(got.torque_nm, want.torque_nm)
    np.testing.assert_array_equal(got.thrust_n, want.thrust_n)


@pytest.mark.parametrize("n", [1, 2, 5, 40])
def test_formation_error_is_the_largest_pair_error(n):
    # GIVEN positions and offsets
    rng = np.random.default_rng(n)
    p, theta = rng.normal(0.0, 3.0, (2, n, 3))
    # WHEN the compiled kernel takes the formation error
    got = formation_error_m(p, theta)
    # THEN it is max over all pairs of |p_i - p_j - (theta_i - theta_j)|, as the dense form
    rel = p[:, None, :] - p[None, :, :] - (theta[:, None, :] - theta[None, :, :])
    assert got == float(np.sqrt((rel * rel).sum(axis=2)).max())
    # AND an unknown position makes it unknown
    p[n - 1, 1] = np.nan
    assert np.isnan(formation_error_m(p, theta))
