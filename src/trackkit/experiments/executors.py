"""Where Monte Carlo chunks run: in this process, or on Dask workers (local or remote).

Each task is a list of blocks; results come back in task order. A task reports its progress
as the runs it has done; on Dask the reports travel as worker events (``log_event``) to the
client, so the progress moves inside long tasks too. A Dask task whose worker dies is re-run
elsewhere (``retries``), so no runs are lost; if a task still fails, the whole comparison
fails rather than reporting a partial result.
"""

from __future__ import annotations

import logging
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["execute", "dask_client", "PROGRESS_TOPIC"]

#: The Dask event topic on which workers report the progress of their tasks.
PROGRESS_TOPIC = "trackkit-progress"

Task = list[int]
TaskFn = Callable[[Any, Task, Callable[[float], None] | None], list]


def execute(
    fn: TaskFn,
    scenario: Any,
    tasks: Iterable[Task],
    size_of: Callable[[Task], int],
    total: int,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Callable[[float, int], None] | None = None,
) -> list[list]:
    """Run ``fn(scenario, task, report)`` for every task, ``report(runs_done_in_task)``
    feeding ``progress(runs_done, total)``; ``size_of(task)`` is a task's runs."""
    if not workers and not scheduler:
        out: list[list] = []
        done = 0.0
        for task in tasks:
            report = None if progress is None else (lambda d, base=done: progress(base + d,
                                                                                  total))
            out.append(fn(scenario, task, report))
            done += size_of(task)
            if progress:
                progress(done, total)
        return out
    return _dask(fn, scenario, list(tasks), size_of, total, workers, scheduler, progress)


@contextmanager
def dask_client(workers: int | None, scheduler: str | None) -> Iterator[Any]:
    """A Dask client to the scheduler at ``scheduler``, or to a local cluster of ``workers``
    single-threaded worker processes; closed on exit, and a local cluster stopped."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as err:  # pragma: no cover - dask is a dependency
        raise RuntimeError("--workers/--scheduler need dask.distributed installed") from err
    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        # silence_logs: the scheduler's, nannies' and workers' own log lines (a heartbeat
        # that finds the scheduler gone while a Ctrl-C stops the cluster) are not the
        # user's business; a failed task reaches the client as its exception
        with _workers_ignore_ctrl_c():
            cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1,
                                   processes=True, dashboard_address=None,
                                   silence_logs=logging.CRITICAL)
        client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Start local worker processes with Ctrl-C ignored (the disposition they inherit): a
    terminal sends it to the whole process group, and this process, which handles it, stops
    the cluster; a worker that took it too would die with a traceback and its nanny warn."""
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: the signal is not ours to change
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _report_from_worker(key: str) -> Callable[[float], None]:
    def report(done: float) -> None:
        from dask.distributed import get_worker

        get_worker().log_event(PROGRESS_TOPIC, (key, float(done)))
    return report


def _on_worker(fn: TaskFn, scenario: Any, task: Task, key: str) -> list:
    return fn(scenario, task, _report_from_worker(key))


def _dask(fn, scenario, tasks, size_of, total, workers, scheduler, progress) -> list[list]:
    from dask.distributed import as_completed

    keys = [f"trackkit-{i}-{task[0]}" for i, task in enumerate(tasks)]
    partial: dict[str, float] = {}
    finished: dict[str, float] = {}
    lock = threading.Lock()

    last = [0.0]

    def tell() -> None:
        # the sum's order changes as tasks finish, so it can round a hair below the last
        # report: the bar never goes back
        if progress:
            last[0] = max(last[0], sum(finished.values())
                          + sum(v for k, v in partial.items() if k not in finished))
            progress(last[0], total)

    def on_event(event: tuple) -> None:
        _, (key, done) = event
        with lock:
            if key not in finished:  # a retried task starts again from 0: keep the maximum
                partial[key] = max(partial.get(key, 0.0), done)
                tell()

    with dask_client(workers, scheduler) as client:
        try:
            if progress:
                client.subscribe_topic(PROGRESS_TOPIC, on_event)
            s_future = client.scatter(scenario, broadcast=True)
            futures = [client.submit(_on_worker, fn, s_future, task, key, key=key, retries=3,
                                     pure=False)
                       for key, task in zip(keys, tasks, strict=True)]
            index = {f.key: i for i, f in enumerate(futures)}
            results: list = [None] * len(futures)
            for fut in as_completed(futures):
                i = index[fut.key]
                results[i] = fut.result()
                with lock:
                    finished[fut.key] = size_of(tasks[i])
                    tell()
            return results
        finally:
            if progress:
                client.unsubscribe_topic(PROGRESS_TOPIC)
