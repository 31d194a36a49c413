"""Benchmark of the per-tick graph work of `gcs fly`: one law step + the staleness rule + the
formation error, at n = 16, 64, 240 on grid graphs (row and column neighbours, as grid16.yaml).

Run: `.venv/bin/python -m benchmarks.bench_edges [--before REF] [--write docs/benchmarks.md]`.
Times the tick as the current tree runs it (the law on an edge list); with `--before REF` (a git
commit whose law still took the dense weight matrix, e.g. the parent of the edge-list change) it
also runs itself in a temporary worktree of REF and times the tick as that code ran it:
`law.adjacency = effective_adjacency(A, fresh)`, `stale_neighbour_counts(A, fresh)` and the
(n, n, 3) pair array of the formation error. Same state, graph and stale mask in both.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HEADING = "## The tick's graph work: edge list vs dense"
GRIDS = ((16, 4, 4), (64, 8, 8), (240, 15, 16))  # n, rows, columns


def grid_adjacency(rows: int, cols: int) -> np.ndarray:
    """Unit weights between row and column neighbours of a rows x cols grid, row-major."""
    n = rows * cols
    a = np.zeros((n, n))
    for r in range(rows):
        for c in range(cols):
            i = r * cols + c
            for j in ((i + 1) if c + 1 < cols else -1, (i + cols) if r + 1 < rows else -1):
                if j >= 0:
                    a[i, j] = a[j, i] = 1.0
    return a


def measure(root: Path, repeat_s: float) -> list[dict[str, float]]:
    """Per grid: median and best per-tick times [us] of each part of the tick, as the code under
    `root` runs it. The process imports `root`'s gcs: run from `root` (`python -m`), or, for
    --before, started with `root` first on PYTHONPATH (measure_before)."""
    import gcs

    if not Path(gcs.__file__).resolve().is_relative_to(root.resolve()):
        raise SystemExit(f"gcs is imported from {gcs.__file__}, not from {root}")
    return [time_grid(n, rows, cols, repeat_s) for n, rows, cols in GRIDS]


def time_grid(n: int, rows: int, cols: int, repeat_s: float) -> dict[str, float]:
    """Back-to-back ticks for `repeat_s` seconds on one grid (the same state every tick)."""
    from gcs.control.gains import PAPER_GAINS
    from gcs.control.geometry import rotation_from_rpy
    from gcs.control.law import TeamLaw, TeamMeasurement
    from gcs.fly import measure as fm

    try:
        from gcs import metrics
    except ImportError:  # an old checkout (--before)
        metrics = None

    dense = hasattr(fm, "effective_adjacency")
    a = grid_adjacency(rows, cols)
    rng = np.random.default_rng(n)
    offsets = np.ascontiguousarray(
        np.column_stack([np.arange(n) % cols * 4.0, np.arange(n) // cols * 4.0, np.zeros(n)]))
    p = np.ascontiguousarray(offsets + rng.normal(0.0, 0.3, (n, 3)) + [0.0, 0.0, 10.0])
    rot = np.stack([rotation_from_rpy(*t) for t in rng.normal(0.0, 0.05, (n, 3))])
    meas = TeamMeasurement(p, rng.normal(0.0, 0.2, (n, 3)), rng.normal(0.0, 0.2, (n, 3)),
                           rot, rng.normal(0.0, 0.1, (n, 3)))
    ref = np.zeros((4, 3))
    fresh = np.ones(n, dtype=bool)
    fresh[::7] = False  # a few stale vehicles, so the rule has work to do
    law = TeamLaw(PAPER_GAINS, a, offsets, np.full(n, 2.0), np.full((n, 3), 0.08))
    pair_offsets = offsets[:, None, :] - offsets[None, :, :]

    def staleness() -> None:
        if dense:
            law.adjacency = np.ascontiguousarray(fm.effective_adjacency(a, fresh))
            fm.stale_neighbour_counts(a, fresh)
        else:
            fm.drop_stale_neighbours(law.graph, fresh, law.active_graph.weight)

    def error() -> float:
        if dense:
            rel = p[:, None, :] - p[None, :, :] - pair_offsets
            return float(np.sqrt((rel * rel).sum(axis=2)).max())
        # the compiled pairwise maximum: gcs.fly.measure then, gcs.metrics since it moved
        where = fm if hasattr(fm, "formation_error_m") else metrics
        return where.formation_error_m(p, offsets)

    def step() -> None:
        law.step(meas, ref, 0.01, adapt=False)  # the same state every tick

    for _ in range(3):  # compile or load numba's cache
        staleness()
        error()
        step()
    times: dict[str, list[float]] = {"stale": [], "error": [], "law": [], "tick": []}
    deadline = time.perf_counter() + repeat_s
    while time.perf_counter() < deadline:
        t0 = time.perf_counter()
        staleness()
        t1 = time.perf_counter()
        step()
        t2 = time.perf_counter()
        error()
        t3 = time.perf_counter()
        times["stale"].append(t1 - t0)
        times["law"].append(t2 - t1)
        times["error"].append(t3 - t2)
        times["tick"].append(t3 - t0)
    row: dict[str, float] = {"n": n, "edges": int((a != 0).sum() // 2),
                             "ticks": len(times["tick"])}
    for key, values in times.items():
        row[f"{key}_median_us"] = 1e6 * statistics.median(values)
        row[f"{key}_best_us"] = 1e6 * min(values)
    return row


def measure_before(ref: str, repeat_s: float) -> list[dict[str, float]]:
    """`measure` in a temporary git worktree of `ref`: this file run by path (its folder, which
    holds no gcs, first on the import path) with the worktree next on PYTHONPATH, so that the
    child imports the worktree's gcs and this file's timing code."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), ref],
                       check=True, capture_output=True)
        try:
            proc = subprocess.run(
                [sys.executable, str(Path(__file__).resolve()), "--measure-root", str(tree),
                 "--seconds", str(repeat_s)], check=True, capture_output=True, text=True,
                env={**os.environ, "PYTHONPATH": str(tree)})
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                           check=True, capture_output=True)
    return json.loads(proc.stdout)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default=None, help="git commit of the dense law to compare")
    parser.add_argument("--seconds", type=float, default=3.0, help="timed per grid")
    parser.add_argument("--write", type=Path, default=None, help="update this markdown file")
    parser.add_argument("--measure-root", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure_root is not None:  # the child of --before: figures as JSON on stdout
        print(json.dumps(measure(args.measure_root, args.seconds)))
        return 0
    before = measure_before(args.before, args.seconds) if args.before else None
    after = measure(ROOT, args.seconds)
    load = os.getloadavg()[0]
    lines = [
        "",
        "One tick of `gcs fly`'s team computation on grid graphs (row and column neighbours, as "
        "`configs/grid16.yaml`; every 7th vehicle stale): the staleness rule with its stale "
        "counts, one `TeamLaw.step` (model-based u', u''), and the formation error (largest "
        "over all pairs), in microseconds, median over "
        f"{args.seconds:g} s of back-to-back ticks per grid (best in brackets for the total). "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, load average {load:.1f} (other work on the same cores: "
        "the medians of the dense n = 240 row vary by 2x between runs). Measured by "
        f"`python -m benchmarks.bench_edges{' --before ' + args.before if args.before else ''}`"
        + (f"; 'dense' is commit {args.before}, the law on the (n, n) weight matrix, the rule "
           "as `effective_adjacency` + `stale_neighbour_counts` and the error through the "
           "(n, n, 3) pair array." if before else "."),
        "",
    ]
    parts = ("stale", "law", "error")
    head = "| n | edges | pairs |"
    rule = "|---|---|---|"
    for variant in (["dense"] if before else []) + ["edge list"]:
        head += "".join(f" {variant}: {x} |" for x in ("staleness", "law step", "error",
                                                       "tick"))
        rule += "---|---|---|---|"
    lines += [head, rule]
    for k, row in enumerate(after):
        n = int(row["n"])
        cells = [str(n), str(int(row["edges"])), str(n * (n - 1) // 2)]
        for r in ([before[k]] if before else []) + [row]:
            cells += [f"{r[f'{key}_median_us']:.1f}" for key in parts]
            cells.append(f"{r['tick_median_us']:.1f} ({r['tick_best_us']:.1f})")
        lines.append("| " + " | ".join(cells) + " |")
        print(" ".join(cells), flush=True)
    lines += [
        "",
        "The graph enters the law as an edge list (`gcs.control.formation.EdgeList`, compressed "
        "rows built once from the weight matrix): s (21) and its derivatives s', s'' sum over "
        "row i's neighbours only, and the staleness rule rewrites the 2m edge weights in place "
        "(`gcs.fly.measure.drop_stale_neighbours`), so nothing n x n is allocated per tick. The "
        "formation error stays a maximum over all n (n - 1) / 2 pairs (its definition), computed "
        "by a compiled loop (`formation_error_m`) without the (n, n, 3) array; gcs fly takes it "
        "on log ticks only (every tick_rate / log_rate_hz ticks), so 'tick' here is a log "
        "tick. What remains of the law step is O(n + m): the attitude stage and the per-vehicle "
        "arrays, plus about 1.5 us per compiled call for numba to type the edge list (a named "
        "tuple) as an argument, which is why the edge-list law step is no faster at n = 16.",
    ]
    if args.write:
        from benchmarks.docsection import write_section  # not in the --before child

        write_section(args.write, HEADING, HEADING + "\n" + "\n".join(lines) + "\n")
        print(f"updated {args.write}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
