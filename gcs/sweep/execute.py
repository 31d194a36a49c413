"""Who flies the batches: local worker processes (every core by default) or a Ray cluster.

Both hand each batch to `gcs.sweep.work.fly_runs` and give its rows back as they finish, in
whatever order; a row depends on its run alone, so the table is the same whichever runs it.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Any

from gcs.sweep.study import Study
from gcs.sweep.work import fly_runs

Rows = list[dict[str, Any]]


def _warm_worker() -> None:
    from flightkit import jitcache

    jitcache.configure()
    from gcs.sim.warmup import compile_sim

    compile_sim(force=False)


def run_local(study: Study, batches: Sequence[list[int]], workers: int | None) -> Iterator[Rows]:
    """Fly the batches on `workers` processes (None: one per core); yields each batch's rows.
    At most two batches per worker are in flight, so an interrupt loses little."""
    count = workers or os.cpu_count() or 1
    if count == 1:
        for batch in batches:
            yield fly_runs(study, batch)
        return
    # forkserver: the workers start from a clean interpreter, not a copy of this one's threads
    context = multiprocessing.get_context("forkserver")
    pending = list(reversed(batches))
    with ProcessPoolExecutor(count, mp_context=context, initializer=_warm_worker) as pool:
        running: set[Future] = set()
        try:
            while pending or running:
                while pending and len(running) < 2 * count:
                    running.add(pool.submit(fly_runs, study, pending.pop()))
                finished, running = wait(running, return_when=FIRST_COMPLETED)
                for future in finished:
                    yield future.result()
        finally:
            for future in running:
                future.cancel()


def run_ray(study: Study, batches: Sequence[list[int]], address: str | None) -> Iterator[Rows]:
    """Fly the batches as Ray tasks on the cluster at `address` (None: start a local one)."""
    # Ray reports usage to its makers unless told not to; a ground station's tools do not.
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if _on_loopback(address):
        # Ray's switch for a one-machine cluster: every Ray process binds 127.0.0.1 (otherwise
        # Ray takes the machine's first network address, even for a cluster of one)
        os.environ.setdefault("RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER", "0")
    try:
        import ray
    except ImportError:
        raise RuntimeError("the ray executor needs Ray: pip install 'formation-gcs[ray]'") \
            from None
    started_here = not ray.is_initialized()
    if started_here:
        ray.init(address=address, include_dashboard=False, logging_level="ERROR",
                 log_to_driver=False)
    try:
        remote = ray.remote(_fly_on_ray)
        study_ref = ray.put(study)
        refs = [remote.remote(study_ref, batch) for batch in batches]
        while refs:
            done, refs = ray.wait(refs, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        if started_here:
            ray.shutdown()


def _fly_on_ray(study: Study, batch: list[int]) -> Rows:
    from flightkit import jitcache

    jitcache.configure()
    return fly_runs(study, batch)


def _on_loopback(address: str | None) -> bool:
    """Whether the cluster is this machine's alone: started here, or reached on loopback."""
    if address is None or address in ("auto", "local"):  # Ray's names for this machine's
        return True
    host = address.removeprefix("ray://").rsplit(":", 1)[0]
    return host.startswith("127.") or host == "localhost"
