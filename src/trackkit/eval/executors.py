"""Where Monte Carlo chunks run: in this process, or on Dask workers (local or remote).

Each task is a list of blocks; results come back in task order. A Dask task whose worker dies
is re-run elsewhere (``retries``), so no runs are lost; if a task still fails, the whole
comparison fails rather than reporting a partial result.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["execute"]


def execute(
    fn: Callable[[Any, list[int]], list],
    scenario: Any,
    tasks: Sequence[list[int]],
    sizes: Sequence[int],
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> list[list]:
    """Run ``fn(scenario, task)`` for every task; ``sizes`` are the runs per task (progress)."""
    total = sum(sizes)
    if not workers and not scheduler:
        out, done = [], 0
        for task, size in zip(tasks, sizes, strict=True):
            out.append(fn(scenario, task))
            done += size
            if progress:
                progress(done, total)
        return out
    return _dask(fn, scenario, tasks, sizes, workers, scheduler, progress)


def _dask(fn, scenario, tasks, sizes, workers, scheduler, progress) -> list[list]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as err:  # pragma: no cover - dask is a dependency
        raise RuntimeError("--workers/--scheduler need dask.distributed installed") from err
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        s_future = client.scatter(scenario, broadcast=True)
        futures = [client.submit(fn, s_future, task, key=f"trackkit-{i}-{task[0]}",
                                 retries=3, pure=False)
                   for i, task in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list = [None] * len(futures)
        done, total = 0, sum(sizes)
        for fut in as_completed(futures):
            i = index[fut.key]
            results[i] = fut.result()
            done += sizes[i]
            if progress:
                progress(done, total)
        return results
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
