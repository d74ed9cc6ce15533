"""The interactive map of ``report.html``: the confirmed tracks coloured by id over the
reported positions (or plots), with zoom and pan, hover for a track's id, identity and times,
and a time slider; drawn on an HTML canvas by a few kilobytes of inline JavaScript from data
inlined in the page, so the page works with no network (no tile server, no script library)::

    data = map_data(history, table=track_table(history, ...), background=positions,
                    site=(0.0, 0.0), max_range=40e3, frame=frame, epoch=epoch)
    html = map_html(data)   # a <section> for the page body

The data are compact: positions in the local frame (m east, north) rounded to a grid of
``quantum`` m, each track thinned by the Douglas and Peucker (1973) algorithm to the points
that keep its path within ``tolerance`` m (about 1/4000 of the map's width, 10 m over a 40 km
harbour, below the radar's noise), then written as differences of integers; the background
as the distinct cells of a grid about 1/1000 of the map's width. Every text the page shows
(ids, identities) is set as text, never parsed as HTML.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from importlib.resources import files
from typing import Any

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray

from trackkit.io.frames import EnuFrame, ground_geodetic
from trackkit.tracking.history import TrackHistory
from trackkit.tracking.logic import TrackStatus

__all__ = ["map_data", "map_html", "simplify"]

Array = NDArray[np.float64]

#: matplotlib's tab10, as the PNG colours its tracks
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf")


def simplify(p: Array, tol: float) -> NDArray[np.int64]:
    """Indices of the points of the polyline ``p (n, 2)`` that the Douglas-Peucker algorithm
    keeps: every dropped point is within ``tol`` of the segment between the kept points
    around it; the first and last are always kept."""
    n = p.shape[0]
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        seg, rel = p[b] - p[a], p[a + 1:b] - p[a]
        length = float(np.hypot(*seg))
        d = (np.abs(seg[0] * rel[:, 1] - seg[1] * rel[:, 0]) / length if length > 0
             else np.hypot(rel[:, 0], rel[:, 1]))
        k = int(np.argmax(d))
        if d[k] > tol:
            keep[a + 1 + k] = True
            stack += [(a, a + 1 + k), (a + 1 + k, b)]
    return np.flatnonzero(keep)


def _deltas(v: NDArray[np.int64]) -> list[int]:
    return np.diff(v, prepend=0).tolist() if v.size else []


def _view(points: list[Array]) -> tuple[Array, float]:
    """Centre and width (m) of the central 99.8 % of the points (one wild report must not
    shrink the map)."""
    allp = np.concatenate(points) if points else np.zeros((0, 2))
    allp = allp[np.all(np.isfinite(allp), axis=1)]
    if not len(allp):
        return np.zeros(2), 1000.0
    lo, hi = np.percentile(allp, 0.1, axis=0), np.percentile(allp, 99.9, axis=0)
    return 0.5 * (lo + hi), max(float((hi - lo).max()) * 1.1, 100.0)


def _nice(x: float) -> float:
    """The number 1, 2 or 5 times a power of ten at or below ``x``."""
    e = 10.0 ** np.floor(np.log10(x))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * e <= x) * e)


def _geo_fit(frame: EnuFrame, centre: Array, width: float) -> list[list[float]]:
    """Least-squares quadratics lat, lon (deg) in x, y (km from ``centre``) over the map:
    the page's cursor readout (exact to about 1e-5 deg over a harbour)."""
    g = np.linspace(-width, width, 7)
    x, y = (a.ravel() for a in np.meshgrid(centre[0] + g, centre[1] + g))
    lat, lon = ground_geodetic(frame, x, y)
    u, v = (x - centre[0]) / 1e3, (y - centre[1]) / 1e3
    basis = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=1)
    return [np.linalg.lstsq(basis, z, rcond=None)[0].tolist() for z in (lat, lon)]


def _track_rows(history: TrackHistory) -> tuple[NDArray[np.int64], NDArray[np.int64], Array]:
    keep = np.flatnonzero(history.status == TrackStatus.CONFIRMED)
    scan = np.repeat(np.arange(history.times.size), np.diff(history.offsets))[keep]
    o = np.lexsort((scan, history.ids[keep]))
    return history.ids[keep][o], scan[o], history.mean[keep[o]][:, :2]


def _tracks(history: TrackHistory, table: pa.Table | None, tol: float,
            quantum: float) -> list[list[Any]]:
    """Per confirmed track ``[id, identity, first scan, scan steps, x steps, y steps]``
    (steps: differences of integers, positions in units of ``quantum`` m)."""
    ids, scan, p = _track_rows(history)
    who = {}
    if table is not None and table.num_rows:
        who = dict(zip(table["id"].to_pylist(), table["identity"].to_pylist(), strict=True))
    out = []
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]]) if ids.size else []
    ends = np.r_[starts[1:], ids.size] if ids.size else []
    for a, b in zip(list(starts), list(ends), strict=True):
        k = a + simplify(p[a:b], tol)
        q = np.round(p[k] / quantum).astype(np.int64)
        tid = int(ids[a])
        out.append([tid, who.get(tid) or "", int(scan[k[0]]), _deltas(scan[k])[1:],
                    _deltas(q[:, 0]), _deltas(q[:, 1])])
    return out


def _background(points: Array | None, cell: float) -> list[list[int]]:
    """The distinct grid cells (``cell`` m) of the points, sorted, as steps."""
    if points is None or not len(points):
        return [[], []]
    pts = np.asarray(points, float)[:, :2]
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    g = np.unique(np.round(pts / cell).astype(np.int64), axis=0)
    return [_deltas(g[:, 0]), _deltas(g[:, 1])]


def map_data(history: TrackHistory, *, table: pa.Table | None = None,
             background: Array | None = None, site: tuple[float, float] | None = None,
             max_range: float | None = None, frame: EnuFrame | None = None,
             epoch: np.datetime64 | None = None, identity_label: str = "identity",
             background_label: str = "reported positions") -> dict[str, Any]:
    """What the map draws, JSON-ready (module docstring); ``table`` (``track_table``) gives
    each track's identity, named ``identity_label`` ("MMSI", "ICAO") in the hover."""
    _, _, p = _track_rows(history)
    pts = [p] + ([np.asarray(background, float)[:, :2]] if background is not None else [])
    centre, width = _view(pts)
    tol = _nice(width / 4000)
    quantum = tol / 2
    cell = _nice(width / 1000)
    return {
        "quantum": quantum, "cell": cell, "tolerance": tol,
        "centre": np.round(centre, 1).tolist(), "width": round(width, 1),
        "times": np.round(history.times, 3).tolist(),
        "epoch_ms": None if epoch is None else
        int(epoch.astype("datetime64[ms]").astype(np.int64)),
        "tracks": _tracks(history, table, tol, quantum),
        "background": _background(background, cell), "background_label": background_label,
        "site": None if site is None else [float(site[0]), float(site[1])],
        "max_range": None if max_range is None else float(max_range),
        "geo": None if frame is None else _geo_fit(frame, centre, width),
        "identity_label": identity_label, "palette": list(PALETTE),
    }


def _json_for_script(data: Mapping[str, Any]) -> str:
    """JSON safe inside a ``<script>`` element: no ``<``, ``>`` or ``&`` left to end it."""
    text = json.dumps(data, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def _script() -> str:
    """The map's JavaScript (``track_map.js`` beside this module); a ``</`` in it would end
    the script element."""
    text = files("trackkit.report").joinpath("track_map.js").read_text(encoding="utf-8")
    if "</" in text:
        raise AssertionError("track_map.js holds '</', which would end its script element")
    return text


def _legend(data: Mapping[str, Any]) -> str:
    site = "; triangle: the radar" if data.get("site") is not None else ""
    return site + (", dashed: its range" if site and data.get("max_range") else "")


def map_html(data: Mapping[str, Any]) -> str:
    """The map section: canvas, controls, the data and the script, all inline."""
    return "\n".join([
        '<section id="tk-map" class="tk-map">',
        '<div class="tk-map-controls">',
        '<button type="button" id="tk-play" aria-label="play">&#9654;</button>',
        '<input type="range" id="tk-time" min="0" max="0" value="0" step="1" '
        'aria-label="time">',
        '<span id="tk-time-label"></span>',
        '<label>show <select id="tk-mode"><option value="upto">tracks up to the time'
        '</option><option value="recent">the last 10 minutes</option><option value="all">'
        "whole tracks</option></select></label>",
        '<button type="button" id="tk-reset">reset view</button>',
        "</div>",
        '<div class="tk-map-frame"><canvas id="tk-canvas" width="1000" height="640">'
        "The map needs a browser with JavaScript; the pictures below show the same tracks."
        '</canvas><div id="tk-tip" class="tk-tip" hidden></div>'
        '<div id="tk-readout" class="tk-readout"></div></div>',
        '<p class="tk-help">Drag to pan, scroll (or the + and - keys) to zoom, double-click '
        "to reset; hover a track for its id, identity and times. Grey: the "
        f'<span id="tk-bg-label"></span>{_legend(data)}.</p>',
        f'<script type="application/json" id="tk-map-data">{_json_for_script(data)}</script>',
        f"<script>{_script()}</script>",
        "</section>",
    ])


MAP_CSS = """
.tk-map { margin: 1em 0; }
.tk-map-controls { display: flex; gap: 0.6em; align-items: center; flex-wrap: wrap;
                   font-size: 0.9em; margin-bottom: 0.4em; }
.tk-map-controls input[type=range] { flex: 1 1 300px; }
#tk-time-label { font-variant-numeric: tabular-nums; min-width: 12em; }
.tk-map-frame { position: relative; border: 1px solid #ccc; background: #fbfbfb; }
.tk-map-frame canvas { display: block; width: 100%; height: 640px; cursor: grab;
                       touch-action: none; }
.tk-tip { position: absolute; pointer-events: none; background: rgba(255,255,255,0.95);
          border: 1px solid #888; padding: 0.3em 0.5em; font-size: 0.85em;
          white-space: pre; box-shadow: 0 1px 3px rgba(0,0,0,0.2); }
.tk-readout { position: absolute; right: 0.4em; bottom: 0.3em; font-size: 0.8em;
              color: #555; font-variant-numeric: tabular-nums; pointer-events: none; }
.tk-help { color: #555; font-size: 0.85em; margin-top: 0.3em; }
"""
