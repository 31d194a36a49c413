"""Formation data of the law: communication graph (adjacency, edge list, Laplacian,
connectivity), offsets theta_i and the reference velocity v_r(t) with its derivatives.

Graphs are undirected with symmetric weights a_ij = a_ji >= 0 (Assumption 2); vehicles are
indexed 0..n-1 in team order. The compiled law reads the graph as an `EdgeList` (built once from
the weight matrix), so a tick costs O(n + m) for m edges, not O(n^2).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np
from numba import njit


class EdgeList(NamedTuple):
    """The weight matrix by rows, as compiled code reads it (compressed sparse rows).

    Row i's entries are e = row_start[i] .. row_start[i + 1] - 1, each naming a neighbour
    j = neighbour[e] (ascending within the row) and its weight a_ij = weight[e]; an undirected
    edge {i, j} is stored twice, as (i, j) in row i and (j, i) in row j. For n vehicles and m
    edges: row_start (n + 1,) int64, neighbour and weight (2m,) int64 and float64, contiguous.
    """

    row_start: np.ndarray
    neighbour: np.ndarray
    weight: np.ndarray


def edge_list(adjacency: np.ndarray) -> EdgeList:
    """The nonzero entries of a weight matrix (n, n) by rows; for any square matrix (the
    rows need not be symmetric: a vehicle's own view of its neighbourhood is one row)."""
    a = np.asarray(adjacency, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise ValueError(f"adjacency: expected a square (n, n) matrix, got shape {a.shape}")
    n = a.shape[0]
    rows, cols = np.nonzero(a)  # row-major: each row's columns ascending
    row_start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=row_start[1:])
    return EdgeList(row_start, np.ascontiguousarray(cols, dtype=np.int64),
                    np.ascontiguousarray(a[rows, cols]))


def adjacency_from_edges(n: int, edges: Iterable[tuple[int, int, float]]) -> np.ndarray:
    """Symmetric weight matrix (n, n) from undirected edges (i, j, weight) on indices 0..n-1."""
    adjacency = np.zeros((n, n))
    for i, j, weight in edges:
        if i == j:
            raise ValueError(f"edge ({i}, {j}): self loop")
        if not 0 <= i < n or not 0 <= j < n:
            raise ValueError(f"edge ({i}, {j}): index outside 0..{n - 1}")
        if not weight > 0.0:
            raise ValueError(f"edge ({i}, {j}): weight must be > 0, got {weight}")
        adjacency[i, j] = adjacency[j, i] = weight
    return adjacency


def laplacian(adjacency: np.ndarray) -> np.ndarray:
    """L = D - A."""
    return np.diag(adjacency.sum(axis=1)) - adjacency


def unreachable(adjacency: np.ndarray, start: int = 0) -> list[int]:
    """Indices that cannot be reached from `start` (empty list: the graph is connected)."""
    n = adjacency.shape[0]
    seen = {start}
    frontier = [start]
    while frontier:
        i = frontier.pop()
        for j in np.flatnonzero(adjacency[i] > 0.0):
            if int(j) not in seen:
                seen.add(int(j))
                frontier.append(int(j))
    return [i for i in range(n) if i not in seen]


def is_connected(adjacency: np.ndarray) -> bool:
    """Undirected connectivity; equivalently the Laplacian's second eigenvalue is positive."""
    return adjacency.shape[0] > 0 and not unreachable(adjacency)


def pair_offsets(offsets_m: np.ndarray) -> np.ndarray:
    """theta_ij = theta_i - theta_j, (n, n, 3)."""
    return offsets_m[:, None, :] - offsets_m[None, :, :]


@njit(cache=True)
def reference_velocity(
    t_s: float, constant: np.ndarray, amplitude: np.ndarray, omega: np.ndarray, phase: np.ndarray
) -> np.ndarray:
    """v_r(t) and its first three derivatives, (4, 3) [m/s, m/s^2, m/s^3, m/s^4], world ENU.

    Per axis k: v_r,k(t) = constant[k] + sum_m amplitude[k,m] cos(omega[k,m] t + phase[k,m]).
    """
    out = np.zeros((4, 3))
    for k in range(3):
        out[0, k] = constant[k]
        for m in range(amplitude.shape[1]):
            a = amplitude[k, m]
            w = omega[k, m]
            arg = w * t_s + phase[k, m]
            c = np.cos(arg)
            s = np.sin(arg)
            out[0, k] += a * c
            out[1, k] -= a * w * s
            out[2, k] -= a * w * w * c
            out[3, k] += a * w * w * w * s
    return out


@njit(cache=True)
def reference_velocity_series(
    t_s: np.ndarray, constant: np.ndarray, amplitude: np.ndarray, omega: np.ndarray,
    phase: np.ndarray
) -> np.ndarray:
    """v_r at each instant of `t_s`, (T, 3): row k is reference_velocity(t_s[k], ...)[0]."""
    out = np.empty((t_s.size, 3))
    for k in range(t_s.size):
        out[k] = reference_velocity(t_s[k], constant, amplitude, omega, phase)[0]
    return out
