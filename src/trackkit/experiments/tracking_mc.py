"""Monte Carlo of multi-target trackers on a simulated scene: simulate, track, evaluate.

Run r of a scene is simulated from ``run_rng(seed, r)`` alone (``sim.scene``), every
tracker sees the same plots, and each run is evaluated on its own: GOSPA and OSPA per scan
(against the true positions, cut-off ``c``) and the track-level counts
(``eval.track_metrics.track_counts``). Runs go in fixed blocks to an executor (in-process or
Dask, as the single-target engine); per-run numbers are kept and reduced in run order, so a
result is bit-identical whatever the chunking and the executor, on one machine.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from trackkit.eval.track_metrics import (
    TrackCounts,
    gospa_steps,
    ospa_steps,
    track_counts,
    track_summary,
)
from trackkit.sim.scene import Scene, simulate_scene
from trackkit.tracking.history import run_tracker
from trackkit.tracking.tracker import Tracker

Array = NDArray[np.float64]

__all__ = ["TrackerResult", "TrackingResult", "run_tracking"]


@dataclass
class _RunNumbers:
    """One run of one tracker: per scan GOSPA (distance and the three parts, p-th powers),
    OSPA, the number of confirmed tracks; the run's track counts; its tracking time."""

    gospa: Array  # (S, 4) distance, localisation, missed, false
    ospa: Array  # (S,)
    confirmed: NDArray[np.int64]  # (S,)
    counts: TrackCounts
    approximated: int
    seconds: float


@dataclass
class TrackerResult:
    """One tracker over all runs: per-scan means over runs of GOSPA (and its parts), OSPA and
    the confirmed-track count; the track summary (``track_summary`` of the summed counts);
    JPDA clusters approximated; wall seconds per scan."""

    name: str
    gospa: Array
    gospa_parts: dict[str, Array]
    ospa: Array
    confirmed: Array
    summary: dict[str, float]
    approximated: int
    seconds_per_scan: float

    @property
    def mean_gospa(self) -> float:
        return float(np.mean(self.gospa))


@dataclass
class TrackingResult:
    runs: int
    seed: int
    times: Array  # (S,) scan times
    c: float
    within: float
    trackers: dict[str, TrackerResult]


def _one_run(run, tracker: Tracker, c: float, ospa_p: float, within: float) -> _RunNumbers:
    t0 = time.perf_counter()
    history, _ = run_tracker(tracker, run.scans)
    seconds = time.perf_counter() - t0
    tracks = history.confirmed()
    truth = run.truth_positions
    g = gospa_steps(truth, tracks, c)
    return _RunNumbers(
        gospa=np.stack([g.distance, g.localisation, g.missed, g.false], axis=1),
        ospa=ospa_steps(truth, tracks, c, ospa_p).distance,
        confirmed=np.diff(tracks.offsets),
        counts=track_counts(truth, tracks, c, times=history.times, within=within),
        approximated=int(history.approximated.sum()),
        seconds=seconds,
    )


def track_block(scene: Scene, trackers: dict[str, Tracker], runs: Sequence[int], seed: int,
                c: float, ospa_p: float, within: float,
                progress: Callable[[float], None] | None = None
                ) -> dict[str, list[_RunNumbers]]:
    """Simulate runs ``runs`` and evaluate every tracker on each (one executor task);
    ``progress`` is told the runs done."""
    out: dict[str, list[_RunNumbers]] = {name: [] for name in trackers}
    for i, run in enumerate(simulate_scene(scene, list(runs), seed)):
        for name, tracker in trackers.items():
            out[name].append(_one_run(run, tracker, c, ospa_p, within))
        if progress is not None:
            progress(i + 1)
    return out


def _task(job: tuple, blocks: list[int], progress: Callable[[float], None] | None) -> list:
    scene, trackers, runs, block, seed, c, ospa_p, within = job
    parts = []
    done = 0
    for b in blocks:
        ids = range(b * block, min(runs, (b + 1) * block))
        tell = None if progress is None else (lambda k, d=done: progress(d + k))
        parts.append((b, track_block(scene, trackers, ids, seed, c, ospa_p, within, tell)))
        done += len(ids)
    return parts


def run_tracking(scene: Scene, trackers: dict[str, Tracker], runs: int, seed: int,
                 c: float = 500.0, within: float = np.inf, block: int = 10,
                 workers: int | None = None, scheduler: str | None = None,
                 progress: Callable[[float, int], None] | None = None,
                 ospa_p: float = 1.0) -> TrackingResult:
    """Every tracker of ``trackers`` on runs 0..runs-1 of ``scene``: GOSPA (c, p = 2) and
    OSPA (c, ``ospa_p``) per scan, track counts (a truth counts as confirmed within
    ``within`` seconds of its birth), in blocks of ``block`` runs on an executor."""
    from trackkit.experiments.executors import execute

    if not trackers:
        raise ValueError("trackers is empty; expected at least one named tracker")
    if runs < 1 or block < 1:
        raise ValueError(f"runs = {runs}, block = {block}; expected both >= 1")
    nblocks = -(-runs // block)
    job = (scene, trackers, runs, block, seed, c, ospa_p, within)
    tasks = [[b] for b in range(nblocks)]
    size = {b: min(runs, (b + 1) * block) - b * block for b in range(nblocks)}
    chunks = execute(_task, job, tasks, lambda t: sum(size[b] for b in t), runs,
                     workers=workers, scheduler=scheduler, progress=progress)
    parts = sorted((p for chunk in chunks for p in chunk), key=lambda p: p[0])
    times = np.asarray(scene.scan_times()[0], dtype=float)
    results = {}
    for name in trackers:
        per_run = [r for _, d in parts for r in d[name]]
        g = np.stack([r.gospa for r in per_run])  # (R, S, 4), summed in run order
        counts = TrackCounts(*(np.concatenate(f) for f in
                               zip(*(r.counts for r in per_run), strict=True)))
        scans = sum(r.gospa.shape[0] for r in per_run)
        results[name] = TrackerResult(
            name=name,
            gospa=g[:, :, 0].mean(0),
            gospa_parts={k: g[:, :, i].mean(0) for i, k in
                         enumerate(("localisation", "missed", "false"), start=1)},
            ospa=np.stack([r.ospa for r in per_run]).mean(0),
            confirmed=np.stack([r.confirmed for r in per_run]).mean(0),
            summary=track_summary(counts),
            approximated=sum(r.approximated for r in per_run),
            seconds_per_scan=sum(r.seconds for r in per_run) / scans,
        )
    return TrackingResult(runs, seed, times, c, within, results)
