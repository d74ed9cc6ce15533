"""The track table of a ``trackkit track`` run: one row per confirmed track, what a person
reads first about it (``tracks_summary.csv``, and the table of ``report.html``)::

    table = track_table(history, truth=run.truth, c=500.0, object_ids=run.ids,
                        epoch=reports.epoch)

Columns: ``id``; ``identity``, the reporting identity (MMSI or ICAO 24-bit address) of the
object the track followed, and ``identity_share``, the fraction of the track's confirmed scans
on which the GOSPA assignment paired it with that object (empty and nan without a truth);
``start_s, end_s`` (s from the epoch) and ``start_utc, end_utc`` (ISO 8601 with ``Z``, when
the epoch is known) of its confirmed life; ``duration_s``; ``scans``; ``distance_m``,
the integral of its speed over its confirmed life, ``sum (|v_k| + |v_k+1|) / 2 (t_k+1 -
t_k)`` with ``v = (vx, vy)`` the filter's velocity (the path through the positions when the
state has none); ``mean_speed_m_s, max_speed_m_s``, of ``|v|`` over its confirmed scans;
``longest_coast_s``, the longest time it ran on prediction alone (from a scan that updated
it with a plot to a later scan without one; 0 for a track hit at every scan, nan when the
history does not record hits); and
``status`` at the end of the run: "tracking" (alive, hit at the last scan), "coasting" (alive,
not hit at the last scan; "alive" when the history does not record hits), "held" (lost,
kept unseen for a new track to continue it) or "deleted".

The identity is the object a track was assigned to most often, per scan, by the optimal
GOSPA assignment (Rahmathullah, Garcia-Fernandez and Svensson 2017) with cut-off ``c``, the
same pairing that scores the run; ties go to the object listed first.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pyarrow as pa
from numpy.typing import ArrayLike, NDArray

from trackkit.eval.track_metrics import Frames, assign, checked_assignment, dominant_truths
from trackkit.tracking.history import TrackHistory
from trackkit.tracking.logic import TrackStatus

__all__ = ["TRACK_TABLE_UNITS", "track_table"]

Array = NDArray[np.float64]

#: units of the numeric columns, for the page and the CSV's readers
TRACK_TABLE_UNITS = {"start_s": "s from epoch", "end_s": "s from epoch", "duration_s": "s",
                     "distance_m": "m", "mean_speed_m_s": "m/s", "max_speed_m_s": "m/s",
                     "longest_coast_s": "s"}


def _confirmed(history: TrackHistory) -> tuple[NDArray[np.int64], ...]:
    """Rows of the confirmed tracks sorted by id then scan, and their scans."""
    keep = np.flatnonzero(history.status == TrackStatus.CONFIRMED)
    scan = np.repeat(np.arange(history.times.size), np.diff(history.offsets))[keep]
    o = np.lexsort((scan, history.ids[keep]))
    return keep[o], scan[o]


def _groups(ids: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Start and end (exclusive) of each run of equal ``ids``."""
    if ids.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    return starts, np.r_[starts[1:], ids.size]


def _longest_coast(t: Array, hit: NDArray[np.bool_] | None,
                   starts: NDArray[np.int64]) -> Array:
    """Per group, max over its rows of t - t(last hit up to that row); a group's first row
    counts as a hit (a track is confirmed by a plot)."""
    if hit is None:
        return np.full(starts.size, np.nan)
    is_ref = hit.copy()
    is_ref[starts] = True
    # the row of the last hit: a running maximum never reaches back past a group's start,
    # which is itself a hit
    last_hit = np.maximum.accumulate(np.where(is_ref, np.arange(t.size), 0))
    return np.maximum.reduceat(t - t[last_hit], starts) if starts.size else np.zeros(0)


def _steps(t: Array, pos: Array, speed: Array, ids: NDArray[np.int64]) -> Array:
    """Distance from each row's previous one of the same track (0 at a track's first row):
    the trapezoid of the filter's speed over the interval, or the straight line between the
    positions when the state has no velocity. (The path through the filtered positions adds
    their jitter: a moored vessel would travel a kilometre an hour.)"""
    step = np.zeros(ids.size)
    if ids.size > 1:
        same = ids[1:] == ids[:-1]
        d = (0.5 * (speed[1:] + speed[:-1]) * np.diff(t) if np.all(np.isfinite(speed))
             else np.hypot(*(pos[1:] - pos[:-1]).T))
        step[1:] = np.where(same, d, 0.0)
    return step


def _identities(history: TrackHistory, truth: Frames, c: float, p: float,
                track_ids: NDArray[np.int64], life: NDArray[np.int64],
                object_ids: Sequence[str] | None,
                assignment: tuple[ArrayLike, ArrayLike] | None) -> tuple[list[str], Array]:
    """Per track (``track_ids``, sorted), the object it was assigned to most often and the
    share of its ``life`` (confirmed scans) assigned to that object."""
    conf = history.confirmed()
    truth_rows, track_rows = (assign(truth, conf, c, p) if assignment is None
                              else checked_assignment(assignment, truth, conf))
    names = [""] * track_ids.size
    share = np.full(track_ids.size, np.nan)
    trk = np.searchsorted(track_ids, conf.ids[track_rows])
    tracks, codes, n = dominant_truths(trk, np.asarray(truth.ids)[truth_rows])
    for k, code, count in zip(tracks.tolist(), codes.tolist(), n.tolist(), strict=True):
        names[k] = str(object_ids[code]) if object_ids is not None else str(code)
        share[k] = count / life[k]
    return names, share


def _status(history: TrackHistory, last_row: NDArray[np.int64],
            last_scan: NDArray[np.int64]) -> list[str]:
    alive = last_scan == history.times.size - 1
    if history.hit is None:
        return np.where(alive, "alive", "deleted").tolist()
    hit = np.asarray(history.hit, bool)[last_row]
    status = np.where(alive, np.where(hit, "tracking", "coasting"), "deleted")
    end = slice(history.offsets[-2], history.offsets[-1]) if history.times.size else slice(0)
    lost = history.ids[end][history.status[end] == TrackStatus.LOST]
    return np.where(np.isin(history.ids[last_row], lost), "held", status).tolist()


def track_table(history: TrackHistory, *, truth: Frames | None = None, c: float = 500.0,
                p: float = 2.0, object_ids: Sequence[str] | None = None,
                epoch: np.datetime64 | None = None,
                assignment: tuple[ArrayLike, ArrayLike] | None = None) -> pa.Table:
    """One row per confirmed track (module docstring), sorted by id.

    With a ``truth`` (per scan the objects' positions, ``ids`` their codes), each track's
    identity is ``object_ids[code]`` of the object assigned to it on most of its scans
    (the code itself without ``object_ids``). ``assignment``: the rows ``(i, j)`` that
    ``eval.track_metrics.assign(truth, history.confirmed(), c, p)`` returned, when the caller
    has them (``report.track_pages.track_metrics`` keeps them as ``_assignment``)."""
    rows, scan = _confirmed(history)
    ids = history.ids[rows]
    t = history.times[scan]
    pos = history.mean[rows][:, :2]
    starts, ends = _groups(ids)
    speed = (np.hypot(history.mean[rows, 2], history.mean[rows, 3])
             if history.mean.shape[1] >= 4 else np.full(ids.size, np.nan))
    step = _steps(t, pos, speed, ids)
    life = ends - starts
    hit = None if history.hit is None else np.asarray(history.hit, bool)[rows]
    track_ids = ids[starts]
    cols: dict[str, object] = {"id": track_ids}
    if truth is not None:
        names, share = _identities(history, truth, c, p, track_ids, life, object_ids,
                                   assignment)
    else:
        names, share = [""] * starts.size, np.full(starts.size, np.nan)
    cols["identity"] = pa.array(names, pa.string())
    cols["identity_share"] = share
    cols["start_s"], cols["end_s"] = t[starts], t[ends - 1]
    if epoch is not None:
        for name, tt in (("start_utc", t[starts]), ("end_utc", t[ends - 1])):
            utc = epoch.astype("datetime64[ns]") + np.round(tt * 1e9).astype("timedelta64[ns]")
            cols[name] = pa.array(np.char.add(np.datetime_as_string(utc, unit="s"), "Z")
                                  .tolist(), pa.string())
    cols["duration_s"] = t[ends - 1] - t[starts]
    cols["scans"] = life.astype(np.int64)
    reduce = starts.size > 0
    cols["distance_m"] = np.add.reduceat(step, starts) if reduce else np.zeros(0)
    cols["mean_speed_m_s"] = np.add.reduceat(speed, starts) / life if reduce else np.zeros(0)
    cols["max_speed_m_s"] = np.maximum.reduceat(speed, starts) if reduce else np.zeros(0)
    cols["longest_coast_s"] = _longest_coast(t, hit, starts)
    cols["status"] = pa.array(_status(history, rows[ends - 1], scan[ends - 1]), pa.string())
    return pa.table({k: v if isinstance(v, pa.Array) else pa.array(v) for k, v in cols.items()})
