"""A tracker run over a sequence of scans, and what it leaves: every live track at every
scan, stored flat (ragged per scan), ready for the multi-target metrics and for writing out.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from trackkit.eval.track_metrics import Frames
from trackkit.io.scans import Scan
from trackkit.tracking.logic import TrackStatus
from trackkit.tracking.tracker import Tracker, Tracks

Array = NDArray[np.float64]

__all__ = ["TrackHistory", "run_tracker"]


class TrackHistory(NamedTuple):
    """Scan s holds rows ``offsets[s]:offsets[s + 1]``: the tracks alive after it, with
    their ``ids``, ``status`` (``TrackStatus``), state ``mean (N, n)`` and covariance
    diagonal ``var (N, n)``. Per scan: ``times``, gated ``pairs``, tracks ``started`` and
    ``deleted``, and the JPDA clusters whose marginals were ``approximated``. ``cov (N, n,
    n)`` is the full covariance (what a smoother needs); ``hit (N,)`` whether the row's track
    was updated with a plot at that scan (a new track is, by its plot); either None in a
    history made without it. ``extra_names``: the names of the state's components after
    ``x, y, vx, vy`` (``Tracker.extra_names``; empty: not named)."""

    times: Array
    offsets: NDArray[np.int64]
    ids: NDArray[np.int64]
    status: NDArray[np.int8]
    mean: Array
    var: Array
    pairs: NDArray[np.int64]
    started: NDArray[np.int64]
    deleted: NDArray[np.int64]
    approximated: NDArray[np.int64]
    cov: Array | None = None
    hit: NDArray[np.bool_] | None = None
    extra_names: tuple[str, ...] = ()

    def confirmed(self, dims: tuple[int, ...] = (0, 1)) -> Frames:
        """The confirmed tracks per scan as ``Frames`` of the state components ``dims``
        (default the position), for OSPA, GOSPA and the track counts."""
        keep = self.status == TrackStatus.CONFIRMED
        scan = np.repeat(np.arange(self.times.size), np.diff(self.offsets))[keep]
        offsets = np.searchsorted(scan, np.arange(self.times.size + 1)).astype(np.int64)
        return Frames(offsets, self.mean[keep][:, list(dims)], self.ids[keep])


def run_tracker(tracker: Tracker, scans: Iterable[Scan], tracks: Tracks | None = None,
                progress: Callable[[int], None] | None = None) -> tuple[TrackHistory, Tracks]:
    """Step ``tracker`` through ``scans`` (from ``tracks``, default none at the first scan's
    time); returns the history and the tracks after the last scan. ``progress(s)`` is told
    each scan done."""
    rows: list[tuple] = []
    for s, scan in enumerate(scans):
        if tracks is None:
            tracks = tracker.init(float(scan.time))
        before = tracks.ids
        tracks = tracker.step(tracks, scan)
        est = tracker.estimate(tracks.belief)
        info = tracks.info
        rows.append((float(scan.time), tracks.ids, tracks.state.status, est.mean,
                     np.diagonal(est.cov, axis1=-2, axis2=-1), info.pairs, info.started.size,
                     info.deleted.size, info.approximated, est.cov,
                     _hits_now(before, info.hit, tracks.ids)))
        if progress is not None:
            progress(s + 1)
    if tracks is None:
        raise ValueError("scans is empty; expected at least one scan")
    n = np.asarray(rows[0][3]).shape[-1]
    sizes = [r[1].size for r in rows]
    history = TrackHistory(
        times=np.array([r[0] for r in rows]),
        offsets=np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        ids=np.concatenate([r[1] for r in rows]).astype(np.int64),
        status=np.concatenate([r[2] for r in rows]).astype(np.int8),
        mean=np.concatenate([r[3] for r in rows]).reshape(-1, n),
        var=np.concatenate([r[4] for r in rows]).reshape(-1, n),
        pairs=np.array([r[5] for r in rows], np.int64),
        started=np.array([r[6] for r in rows], np.int64),
        deleted=np.array([r[7] for r in rows], np.int64),
        approximated=np.array([r[8] for r in rows], np.int64),
        cov=np.concatenate([r[9] for r in rows]).reshape(-1, n, n),
        hit=np.concatenate([r[10] for r in rows]).astype(bool),
        extra_names=tracker.extra_names,
    )
    return history, tracks


def _hits_now(before: NDArray[np.int64], hit: NDArray[np.bool_],
              after: NDArray[np.int64]) -> NDArray[np.bool_]:
    """The step's hits (over the tracks ``before`` it) for the tracks ``after`` it: a
    surviving track keeps its hit, a new one was started by a plot."""
    out = np.ones(after.size, bool)
    if before.size:
        sorter = np.argsort(before, kind="stable")
        pos = np.minimum(np.searchsorted(before, after, sorter=sorter), before.size - 1)
        idx = sorter[pos]
        old = before[idx] == after
        out[old] = np.asarray(hit, bool)[idx[old]]
    return out
