"""The outputs of ``trackkit track``: tracks as Parquet, CSV and GeoJSON, the track table
(``tracks_summary.csv``, see ``report.track_table``), the track picture, GOSPA against time,
``results.json`` and one self-contained ``report.html`` that leads with the headline figures
(``report.track_words``) and an interactive map (``report.track_map``).

    rep = TrackReport(history, title="SolentAIS...", read=read_report, frame=reports.frame,
                      epoch=reports.epoch, truth=run.truth, gospa_c=500.0,
                      config={"virtual radar": {...}, "tracker": {...}},
                      background=run.truth.x, site=(0.0, 0.0), max_range=40e3)
    paths = write_track_report(rep, "out/")       # atomic, like report.files.write_report

Rows of ``tracks.parquet`` / ``tracks.csv``: one per live track per scan (tentative and
confirmed): ``id, scan, time`` (s from the epoch), ``time_utc`` (when the epoch is known;
a UTC timestamp in Parquet, ISO 8601 text with a ``Z`` in CSV), the state ``x, y, vx, vy``
(m, m/s, x east, y north in the local frame), the extra components by the names the
tracker's models give them (``turn_rate``, rad/s counter-clockwise, of the IMM's
coordinated-turn model; else ``state_4 ...``), the covariance diagonal ``var_x, var_y,
var_vx, var_vy`` (m^2, m^2/s^2; ``var_turn_rate`` ...), ``status``
("tentative" or "confirmed") and ``lat, lon`` (deg, WGS-84, when the frame is known: the
ground point of the 2-D track, see :func:`ground_geodetic`; an aircraft's x, y far from the
frame's origin are those of the point under it only to altitude x distance / earth radius,
600 m for 10 km up at 400 km, so its lat, lon are off by as much). With the smoothed
tracks (:mod:`trackkit.tracking.smoothing`, a Rauch-Tung-Striebel smoother over each track's
whole life), after those: ``x_smooth, y_smooth, vx_smooth, vy_smooth`` (and
``turn_rate_smooth`` ...), their variances
``var_x_smooth ...`` and ``lat_smooth, lon_smooth``, row for row. Floats
round-trip exactly in both files (Parquet is binary, the CSV writer prints the shortest
decimal that reads back as the same double).

``tracks.geojson`` (RFC 7946; needs the frame): a FeatureCollection with one LineString per
confirmed track (a Point for a track confirmed at a single scan), coordinates
``[lon, lat]`` of its confirmed positions in time order, properties ``id``, ``kind``
("track"), ``smoothed`` (false), ``start_s``, ``end_s``, ``start_utc``, ``end_utc``, ``points``
and ``times_s``; with the smoothed tracks, one more such feature per track of its smoothed
positions at the same times (``kind`` "smoothed track", ``smoothed`` true); and a Point for
the radar site (``kind`` "radar site") when there is one.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from numpy.typing import NDArray

from trackkit import __version__
from trackkit.eval.clear_mot import (
    classify_switches,
    clear_mot,
    clear_mot_summary,
    gospa_switching,
    id_scores,
    mota_steps,
)
from trackkit.eval.track_metrics import Frames, assign, gospa_steps, track_counts, track_summary
from trackkit.io.frames import EnuFrame, ground_geodetic
from trackkit.io.layouts import LAYOUTS
from trackkit.io.records import ReadReport
from trackkit.report.files import (
    REPORT_HTML,
    RESULTS_JSON,
    finite_or_none,
    write_atomically,
    write_json,
)
from trackkit.report.html import CSS, notes_and_figures
from trackkit.report.plots import save_figure
from trackkit.report.track_map import MAP_CSS, map_data, map_html
from trackkit.report.track_table import track_table
from trackkit.report.track_words import headline_figures, settings_in_words
from trackkit.tracking.history import TrackHistory
from trackkit.tracking.logic import TrackStatus
from trackkit.tracking.recorded import TrackingResult
from trackkit.tracking.smoothing import SmoothedTracks

__all__ = [
    "TRACK_FILES", "TrackReport", "history_table", "write_tracks_parquet", "write_tracks_csv",
    "tracks_geojson", "write_tracks_geojson", "track_figure", "gospa_figure",
    "track_metrics", "results_document", "render_track_html", "write_track_report",
    "write_skipped_csv", "track_table_html", "track_report",
]

Array = NDArray[np.float64]

TRACKS_PARQUET = "tracks.parquet"
TRACKS_CSV = "tracks.csv"
TRACKS_GEOJSON = "tracks.geojson"
TRACKS_PNG = "tracks.png"
GOSPA_PNG = "gospa.png"
SKIPPED_CSV = "skipped.csv"
TRACKS_SUMMARY_CSV = "tracks_summary.csv"
#: every file a track report may write; one of an earlier run that this run does not write
#: (no truth: no gospa.png) is removed, so the directory holds one consistent result
TRACK_FILES = (TRACKS_PARQUET, TRACKS_CSV, TRACKS_GEOJSON, TRACKS_PNG, GOSPA_PNG, SKIPPED_CSV,
               TRACKS_SUMMARY_CSV, REPORT_HTML, RESULTS_JSON)
#: what the report and the command say when no track reached confirmation
NO_TRACK_CONFIRMED = (
    "No track was confirmed: the track files hold no confirmed state (tentative ones only, "
    "if any), the GeoJSON no track, and the scores of confirmed tracks (RMSE, purity, "
    "delay) are n/a. A track is confirmed after a few hits; track more scans or check the "
    "detection probability and clutter options.")
_STATUS = {int(s): s.name.lower() for s in TrackStatus}
_STATE_NAMES = ("x", "y", "vx", "vy")
#: the units of the columns every history has
_UNITS = ("x", "y", "vx", "vy", "var_x", "var_y", "var_vx", "var_vy", "lat", "lon")
#: units of the extra state components a model names, and of their variances
_EXTRA_UNITS = {"turn_rate": ("rad/s", "rad^2/s^2")}


# --- the tables -------------------------------------------------------------------------------


def _utc(epoch: np.datetime64, t: Array) -> NDArray[np.datetime64]:
    return epoch.astype("datetime64[ns]") + np.round(np.asarray(t) * 1e9).astype(
        "timedelta64[ns]")


def _iso(t: NDArray[np.datetime64]) -> NDArray[np.str_]:
    return np.char.add(np.datetime_as_string(t, unit="ms"), "Z")


def history_table(history: TrackHistory, *, epoch: np.datetime64 | None = None,
                  frame: EnuFrame | None = None,
                  smoothed: SmoothedTracks | None = None) -> pa.Table:
    """The history as one row per track per scan, with the ``smoothed`` tracks' columns
    when given (see the module docstring); the schema metadata ``trackkit`` (JSON) holds the
    epoch and the frame's reference point."""
    h = history
    per_scan = np.diff(h.offsets)
    scan = np.repeat(np.arange(h.times.size, dtype=np.int64), per_scan)
    t = h.times[scan]
    n = h.mean.shape[1]
    names = _state_names(h, n)
    cols: dict[str, Any] = {"id": np.asarray(h.ids, np.int64), "scan": scan, "time": t}
    if epoch is not None:
        cols["time_utc"] = pa.array(_utc(epoch, t)).cast(pa.timestamp("ns", tz="UTC"))
    for k, name in enumerate(names):
        cols[name] = np.asarray(h.mean[:, k], float)
    for k, name in enumerate(names):
        cols[f"var_{name}"] = np.asarray(h.var[:, k], float)
    codes, row_code = np.unique(np.asarray(h.status, np.int64), return_inverse=True)
    named = np.array([_STATUS.get(int(c), str(int(c))) for c in codes], object)
    cols["status"] = pa.array(named[row_code.reshape(-1)], pa.string())
    if frame is not None:
        cols["lat"], cols["lon"] = ground_geodetic(frame, h.mean[:, 0], h.mean[:, 1])
    if smoothed is not None:
        cols.update(_smoothed_columns(smoothed, h.ids.size, frame, names))
    meta = {"epoch": None if epoch is None else str(epoch.astype("datetime64[ns]")),
            "frame": None if frame is None else [frame.lat0, frame.lon0, frame.alt0],
            "units": {"time": "s from epoch", "x": "m east", "y": "m north", "vx": "m/s",
                      "vy": "m/s", "var_x": "m^2", "var_y": "m^2", "var_vx": "m^2/s^2",
                      "var_vy": "m^2/s^2", "lat": "deg", "lon": "deg"}}
    meta["units"].update({k: u for name in names[4:] if name in _EXTRA_UNITS
                          for k, u in zip((name, f"var_{name}"), _EXTRA_UNITS[name],
                                          strict=True)})
    if smoothed is not None:
        meta["units"].update({f"{k}_smooth": u for k, u in list(meta["units"].items())
                              if k != "time" and (k in _UNITS or f"{k}_smooth" in cols)})
    table = pa.table({k: v if isinstance(v, pa.Array) else pa.array(v) for k, v in cols.items()})
    return table.replace_schema_metadata({"trackkit": json.dumps(meta)})


def _smoothed_columns(sm: SmoothedTracks, rows: int, frame: EnuFrame | None,
                      state: list[str]) -> dict[str, Array]:
    """``x_smooth ...``, ``var_x_smooth ...`` and ``lat_smooth, lon_smooth`` of the smoothed
    components (named as the history's ``state`` components)."""
    if sm.mean.shape[0] != rows:
        raise ValueError(f"smoothed tracks have {sm.mean.shape[0]} rows; the history has "
                         f"{rows}: expected the smoothed tracks of this history")
    names = [state[k] if k < len(state) else f"state_{k}" for k in sm.dims.tolist()]
    cols = {f"{name}_smooth": np.asarray(sm.mean[:, i], float) for i, name in enumerate(names)}
    var = np.diagonal(sm.cov, axis1=-2, axis2=-1)
    cols.update({f"var_{name}_smooth": np.asarray(var[:, i], float)
                 for i, name in enumerate(names)})
    xy = _smoothed_xy(sm)
    if frame is not None and xy is not None:
        cols["lat_smooth"], cols["lon_smooth"] = ground_geodetic(frame, xy[:, 0], xy[:, 1])
    return cols


def _state_names(h: TrackHistory, n: int) -> list[str]:
    """The columns of the ``n`` state components: ``x, y, vx, vy``, then the history's
    ``extra_names`` (``state_4 ...`` for one it does not name)."""
    extra = tuple(h.extra_names)
    return [_STATE_NAMES[k] if k < 4 else extra[k - 4] if k - 4 < len(extra)
            else f"state_{k}" for k in range(n)]


def _smoothed_xy(sm: SmoothedTracks) -> Array | None:
    """The smoothed positions (N, 2), if the smoothed components include them."""
    at = {k: i for i, k in enumerate(sm.dims.tolist())}
    return sm.mean[:, [at[0], at[1]]] if 0 in at and 1 in at else None


def write_tracks_parquet(table: pa.Table, path: str | Path) -> Path:
    """Write :func:`history_table` as Parquet, dictionary-encoding the text columns only (a
    float column's dictionary, which pyarrow builds by default, finds few repeats: on the
    Solent tracks it made the file 21 % larger and the write 6 times slower)."""
    path = Path(path)
    text = [f.name for f in table.schema if pa.types.is_string(f.type)]
    pq.write_table(table, path, use_dictionary=text)
    return path


def write_tracks_csv(table: pa.Table, path: str | Path) -> Path:
    """Write :func:`history_table` as CSV (``time_utc`` as ISO 8601 text with ``Z``)."""
    path = Path(path)
    if "time_utc" in table.column_names:
        i = table.column_names.index("time_utc")
        ns = table.column(i).cast(pa.int64()).to_numpy().astype("datetime64[ns]")
        table = table.set_column(i, "time_utc", pa.array(_iso(ns).tolist(), pa.string()))
    _write_csv(table.replace_schema_metadata(None), path)
    return path


def _write_csv(table: pa.Table, path: Path) -> None:
    """CSV with a plain header line (pyarrow quotes every column name; ours need no quotes)
    and values quoted only where needed."""
    with open(path, "wb") as fh:
        fh.write((",".join(table.column_names) + "\n").encode("utf-8"))
        pacsv.write_csv(table, fh, pacsv.WriteOptions(include_header=False,
                                                      quoting_style="needed"))


def write_skipped_csv(read: ReadReport, path: str | Path) -> Path:
    """The skipped records: ``line, column, reason, value, expected`` (``line`` a CSV line,
    the header being line 1, or a Parquet row); a record skipped but not listed (beyond the
    reader's ``max_listed``) has its line only."""
    path = Path(path)
    listed = {b.line: b for b in read.bad}
    rows = []
    for line in read.skipped_lines.tolist():
        b = listed.get(int(line))
        rows.append((int(line), b.column, b.reason, b.value, b.expected) if b is not None
                    else (int(line), "", "(not listed)", "", ""))
    seen = {r[0] for r in rows}
    # a record that stopped the read (--on-bad stop) is listed without a skipped line
    rows += [(b.line, b.column, b.reason, b.value, b.expected) for b in read.bad
             if b.line not in seen]
    rows.sort(key=lambda r: r[0])
    unit = read.bad[0].unit if read.bad else "line"
    table = pa.table({unit: pa.array([r[0] for r in rows], pa.int64()),
                      "column": pa.array([r[1] for r in rows], pa.string()),
                      "reason": pa.array([r[2] for r in rows], pa.string()),
                      "value": pa.array([r[3] for r in rows], pa.string()),
                      "expected": pa.array([r[4] for r in rows], pa.string())})
    _write_csv(table, path)
    return path


# --- GeoJSON ----------------------------------------------------------------------------------


def _confirmed_rows(history: TrackHistory, xy: Array | None = None
                    ) -> tuple[NDArray[np.int64], Array, Array]:
    """Ids, times and positions (``xy (N, 2)`` per row, default the filtered ones) of the
    confirmed rows, sorted by id then time."""
    keep = history.status == TrackStatus.CONFIRMED
    scan = np.repeat(np.arange(history.times.size), np.diff(history.offsets))[keep]
    ids = history.ids[keep]
    o = np.lexsort((scan, ids))
    xy = history.mean[:, :2] if xy is None else xy
    return ids[o], history.times[scan[o]], xy[keep][o]


def tracks_geojson(history: TrackHistory, frame: EnuFrame, *,
                   epoch: np.datetime64 | None = None,
                   site: tuple[float, float] | None = None, digits: int = 7,
                   smoothed: SmoothedTracks | None = None) -> dict:
    """The confirmed tracks, and the ``smoothed`` ones when given, as a GeoJSON
    FeatureCollection (module docstring); coordinates rounded to ``digits`` decimals of a
    degree (7: about a centimetre)."""
    features = []
    if site is not None:
        slat, slon = ground_geodetic(frame, np.array([site[0]]), np.array([site[1]]))
        features.append({"type": "Feature", "properties": {"kind": "radar site"},
                         "geometry": {"type": "Point", "coordinates": [
                             round(float(slon[0]), digits), round(float(slat[0]), digits)]}})
    features += _track_features(history, frame, epoch, digits, None)
    xy = None if smoothed is None else _smoothed_xy(smoothed)
    if xy is not None:
        if xy.shape[0] != history.ids.size:
            raise ValueError(f"smoothed tracks have {xy.shape[0]} rows; the history has "
                             f"{history.ids.size}: expected the smoothed tracks of this history")
        features += _track_features(history, frame, epoch, digits, xy)
    return {"type": "FeatureCollection", "features": features}


def _track_features(history: TrackHistory, frame: EnuFrame, epoch: np.datetime64 | None,
                    digits: int, xy: Array | None) -> list[dict]:
    """One feature per confirmed track: of its filtered positions, or of ``xy`` (the
    smoothed ones, per history row)."""
    ids, t, p = _confirmed_rows(history, xy)
    lat, lon = ground_geodetic(frame, p[:, 0], p[:, 1])
    lon, lat = np.round(lon, digits), np.round(lat, digits)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]]) if ids.size else np.zeros(0, int)
    ends = np.r_[starts[1:], ids.size] if ids.size else starts
    features = []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        coords = np.stack([lon[a:b], lat[a:b]], axis=1).tolist()
        geometry = ({"type": "LineString", "coordinates": coords} if b - a > 1 else
                    {"type": "Point", "coordinates": coords[0]})
        props: dict[str, Any] = {"id": int(ids[a]),
                                 "kind": "track" if xy is None else "smoothed track",
                                 "smoothed": xy is not None, "start_s": float(t[a]),
                                 "end_s": float(t[b - 1]), "points": b - a}
        if epoch is not None:
            s0, e = _iso(_utc(epoch, np.array([t[a], t[b - 1]])))
            props["start_utc"], props["end_utc"] = str(s0), str(e)
        props["times_s"] = t[a:b].tolist()
        features.append({"type": "Feature", "properties": props, "geometry": geometry})
    return features


def write_tracks_geojson(doc: dict, path: str | Path) -> Path:
    """Write the GeoJSON document ``doc`` (from ``tracks_geojson``) to ``path`` as compact JSON
    (no nan: it is refused); returns the path."""
    path = Path(path)
    path.write_text(json.dumps(doc, separators=(",", ":"), allow_nan=False) + "\n",
                    encoding="utf-8")
    return path


# --- metrics ----------------------------------------------------------------------------------


def track_metrics(history: TrackHistory, truth: Frames | None, c: float, p: float = 2.0, *,
                  site: tuple[float, float] | None = None, sigma_bearing: float | None = None
                  ) -> dict[str, Any]:
    """Counts of the tracks and, with a truth, GOSPA (cut-off ``c`` m, order ``p``) of the
    confirmed positions per scan, the track-level counts of ``track_counts`` and the
    identity scores of ``eval.clear_mot`` (``identity``; ID switches between objects the
    radar resolves need its ``site`` and bearing noise ``sigma_bearing``, rad).

    ``gospa.mean`` is the mean over scans of GOSPA (m); ``localisation``, ``missed`` and
    ``false`` are the means over scans of its additive parts (p-th powers, m^p), so that
    ``rms = (localisation + missed + false)^(1/p)``; ``missed_per_scan`` and
    ``false_per_scan`` are the mean numbers of objects left unassigned and of confirmed
    tracks assigned to none. Keys that start with ``_`` are for the figures and the track
    table, not written: the per-scan series and ``_assignment``, the rows of the GOSPA
    assignment (``eval.track_metrics.assign``) that every score here is computed from."""
    conf = history.confirmed()
    ids_conf = np.unique(conf.ids)
    out: dict[str, Any] = {
        "scans": int(history.times.size),
        "tracks_started": int(np.unique(history.ids).size),
        "tracks_confirmed": int(ids_conf.size),
        "mean_confirmed_per_scan": float(conf.sizes.mean()) if conf.n_steps else 0.0,
    }
    if truth is None:
        return out
    ab = assign(truth, conf, c, p)  # one solve serves every score below and the track table
    g = gospa_steps(truth, conf, c, p, assignment=ab)
    half = c**p / 2
    out["gospa"] = {
        "c": float(c), "p": float(p), "mean": float(np.mean(g.distance)),
        "rms": float(np.mean(g.distance**p) ** (1 / p)),
        "localisation": float(np.mean(g.localisation)), "missed": float(np.mean(g.missed)),
        "false": float(np.mean(g.false)),
        "missed_per_scan": float(np.mean(g.missed) / half),
        "false_per_scan": float(np.mean(g.false) / half),
        "objects_per_scan": float(truth.sizes.mean()),
    }
    period = float(np.median(np.diff(history.times))) if history.times.size > 1 else 0.0
    counts = track_counts(truth, conf, c, p=p, times=history.times, within=5 * period,
                          assignment=ab)
    summary = track_summary(counts)
    out["tracks"] = {k: (v if isinstance(v, int) else float(v)) for k, v in summary.items()}
    out["tracks"]["confirmed_within_s"] = 5 * period
    out["_gospa_steps"] = g  # for the figure; not written
    out["_assignment"] = ab  # for the track table; not written
    out.update(_identity(truth, conf, c, p, site, sigma_bearing, ab))
    return out


def _identity(truth: Frames, conf: Frames, c: float, p: float,
              site: tuple[float, float] | None, sigma_bearing: float | None,
              assignment: tuple[NDArray[np.int64], NDArray[np.int64]]) -> dict[str, Any]:
    """CLEAR-MOT, IDF1 and GOSPA with switching (``identity``) and their per-scan series
    (``_identity_steps``, not written). The CLEAR-MOT and IDF1 threshold is the GOSPA
    cut-off c: a track farther than c from an object is neither assigned to it by GOSPA
    nor matched to it here. The switching penalty is c too (gospa_switching: a full switch
    then costs as much as a missed object plus a false track)."""
    cm = clear_mot(truth, conf, c)
    s = clear_mot_summary(cm)
    ids = id_scores(truth, conf, c)
    gs = gospa_switching(truth, conf, c, p, switching_penalty=c, assignment=assignment)
    resolvable: int | None = None
    res_steps = None
    if site is not None and sigma_bearing is not None:
        sw = classify_switches(cm.switch_step, cm.switch_truth, truth, site, sigma_bearing)
        resolvable = sw.resolvable
        res_steps = np.bincount(cm.switch_step[sw.mask], minlength=truth.n_steps)
    ident = {"threshold_m": float(c), "mota": s["mota"], "motp_m": s["motp"],
             "id_switches": s["switches"], "id_switches_resolvable": resolvable,
             "track_transfers": s["transfers"], "fragmentations": s["fragmentations"],
             "idf1": ids.idf1, "idp": ids.idp, "idr": ids.idr,
             "gospa_switching_mean": float(np.mean(gs.distance)) if gs.distance.size else None,
             "switching_penalty_m": float(c), "switches": float(np.sum(gs.switches))}
    steps = {"mota": mota_steps(cm), "id_switches": cm.switches,
             "id_switches_resolvable": res_steps, "fragmentations": cm.fragmentations,
             "idtp": ids.idtp_steps, "gospa_switching": gs.distance, "switches": gs.switches}
    return {"identity": ident, "_identity_steps": steps}


# --- figures ----------------------------------------------------------------------------------


def track_figure(history: TrackHistory, *, background: Array | None = None,
                 background_label: str = "reported positions",
                 site: tuple[float, float] | None = None, max_range: float | None = None,
                 title: str = "") -> Figure:
    """Plan view in ENU km: ``background`` points (the reported positions or the plots) in
    grey, every confirmed track as a coloured line, the radar site and its range ring."""
    fig = Figure(figsize=(8.0, 7.5), layout="constrained")
    ax = fig.add_subplot()
    km = 1e-3
    pts = []
    if background is not None and len(background):
        bg = np.asarray(background, float)
        if bg.shape[0] > 200_000:  # enough to show the traffic; a PNG cannot show more
            bg = bg[np.linspace(0, bg.shape[0] - 1, 200_000).astype(int)]
        ax.scatter(bg[:, 0] * km, bg[:, 1] * km, s=1.0, c="0.7", lw=0, rasterized=True)
        # a legend entry with a visible marker (a 1-point dot would not show)
        ax.plot([], [], "o", color="0.7", ms=4, label=background_label)
        pts.append(bg)
    ids, _, p = _confirmed_rows(history)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]]) if ids.size else np.zeros(0, int)
    ends = np.r_[starts[1:], ids.size] if ids.size else starts
    # one collection, not a plot call per track: hundreds of tracks draw in one pass
    segs = [p[a:b] * km for a, b in zip(starts.tolist(), ends.tolist(), strict=True)]
    ax.add_collection(LineCollection(segs, colors=[f"C{k % 10}" for k in range(len(segs))],
                                     linewidths=1.0))
    if segs:
        ax.plot([], [], color="C0", lw=1.0, label="confirmed tracks")
    if ids.size:
        pts.append(p)
    if site is not None:
        ax.plot(site[0] * km, site[1] * km, "k^", ms=7, label="radar")
        if max_range is not None:
            a = np.linspace(0, 2 * np.pi, 361)
            ax.plot((site[0] + max_range * np.sin(a)) * km, (site[1] + max_range * np.cos(a)) * km,
                    color="0.4", lw=0.8, ls="--", label="max range")
    if pts:
        allp = np.concatenate(pts)
        allp = allp[np.all(np.isfinite(allp), axis=1)]
        if len(allp):
            # the central 99.8 % of the points: one wild report must not shrink the picture
            lo = np.percentile(allp, 0.1, axis=0)
            hi = np.percentile(allp, 99.9, axis=0)
            half = 0.55 * max(float((hi - lo).max()), 1.0)
            mid = 0.5 * (lo + hi)
            ax.set_xlim((mid[0] - half) * km, (mid[0] + half) * km)
            ax.set_ylim((mid[1] - half) * km, (mid[1] + half) * km)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("east [km]")
    ax.set_ylabel("north [km]")
    n_tracks = int(np.unique(ids).size)
    ax.set_title(f"{title}: {n_tracks} confirmed tracks" if title else
                 f"{n_tracks} confirmed tracks", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncols=4, fontsize="small",
              frameon=False)
    return fig


def gospa_figure(times: Array, g: Any, truth_sizes: NDArray[np.int64],
                 track_sizes: NDArray[np.int64], c: float, *,
                 epoch: np.datetime64 | None = None) -> Figure:
    """GOSPA (m) against time, and below it the objects in range, the confirmed tracks and
    the pairs assigned within the cut-off (missed = objects - assigned, false = tracks -
    assigned)."""
    t = np.asarray(times, float)
    t_min = (t - t[0]) / 60.0 if t.size else t
    fig = Figure(figsize=(8.5, 6.0), layout="constrained")
    a1, a2 = fig.subplots(2, 1, sharex=True)
    a1.plot(t_min, g.distance, color="C0", lw=1.0, label="GOSPA")
    a1.axhline(float(np.mean(g.distance)), color="C0", ls="--", lw=0.8,
               label=f"mean {np.mean(g.distance):.4g} m")
    a1.set_ylabel("GOSPA [m]")
    a1.set_title(f"GOSPA against the reported positions (c = {c:g} m, p = 2)",
                 fontsize="medium")
    a1.grid(True, alpha=0.3)
    a1.legend(fontsize="small")
    a2.plot(t_min, truth_sizes, color="black", lw=1.0, label="objects in range")
    a2.plot(t_min, track_sizes, color="C1", lw=1.0, label="confirmed tracks")
    a2.plot(t_min, g.assigned, color="C2", lw=1.0, label="assigned (within c)")
    a2.set_ylabel("count")
    start = f" from {np.datetime_as_string(_utc(epoch, t[:1])[0], unit='s')}Z" if (
        epoch is not None and t.size) else ""
    a2.set_xlabel(f"time [min]{start}")
    a2.grid(True, alpha=0.3)
    a2.legend(fontsize="small")
    return fig


# --- the report -------------------------------------------------------------------------------


@dataclass
class TrackReport:
    """Everything the track report shows. ``config`` maps a section title ("virtual radar",
    "tracker") to label -> value (text or numbers, shown as given); ``background`` are the
    points drawn under the tracks (``background_label`` names them); ``notes`` are printed
    in the page; ``smoothed`` tracks go beside the filtered ones in the track files."""

    history: TrackHistory
    title: str
    source: str = ""
    fmt: str = ""
    read: ReadReport | None = None
    epoch: np.datetime64 | None = None
    frame: EnuFrame | None = None
    truth: Frames | None = None
    gospa_c: float = 500.0
    config: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    background: Array | None = None
    background_label: str = "reported positions"
    site: tuple[float, float] | None = None
    max_range: float | None = None
    notes: Sequence[str] = ()
    smoothed: SmoothedTracks | None = None
    #: the reporting identity (MMSI, ICAO address) of each object code of ``truth.ids``
    object_ids: Sequence[str] | None = None


def track_report(result: TrackingResult) -> TrackReport:
    """The report of a ``track_recording`` result, as ``trackkit track`` writes it."""
    rec, read = result.recording, result.read
    return TrackReport(result.history, title=rec.path.name, source=str(rec.path), fmt=rec.kind,
                       read=read, epoch=read.epoch, frame=result.frame, truth=result.truth,
                       gospa_c=rec.settings.gospa_c, config=result.config,
                       background=result.background, background_label=result.background_label,
                       site=result.site, max_range=result.max_range, notes=result.notes,
                       object_ids=result.object_ids, smoothed=result.smoothed)


def _input_document(read: ReadReport | None, source: str, fmt: str) -> dict[str, Any]:
    if read is None:
        return {"file": source, "format": fmt}
    return {"file": read.path, "format": fmt, "layout": read.layout or None,
            "records_read": read.rows_read,
            "records_kept": read.rows_kept, "records_skipped": read.n_skipped,
            "skipped_by_reason": dict(read.skipped), "duplicates_dropped": read.duplicates,
            "out_of_order_sorted": read.out_of_order, "not_given": dict(read.not_given),
            "set_missing": {k: dict(v) for k, v in read.set_missing.items()},
            "epoch_utc": None if read.epoch is None else
            str(read.epoch.astype("datetime64[ms]")) + "Z"}


def results_document(rep: TrackReport, metrics: Mapping[str, Any]) -> dict[str, Any]:
    """``results.json``: the input account, the configuration, the track counts and GOSPA."""
    doc = {"title": rep.title, "input": _input_document(rep.read, rep.source, rep.fmt),
           "config": {k: dict(v) for k, v in rep.config.items()},
           "results": {k: v for k, v in metrics.items() if not k.startswith("_")},
           "notes": list(rep.notes), "trackkit": __version__}
    return finite_or_none(doc)


def _fmt(v: Any) -> str:
    if v is None:  # a score of no tracks (an RMSE over no assigned track)
        return "n/a"
    if isinstance(v, float):
        return "n/a" if not math.isfinite(v) else f"{v:.6g}"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_fmt(x)}" for k, x in v.items()) or "none"
    return str(v)


def _table(rows: Sequence[tuple[str, Any]], caption: str = "") -> str:
    esc = html.escape
    body = "\n".join(f"<tr><th>{esc(str(k))}</th><td>{esc(_fmt(v))}</td></tr>" for k, v in rows)
    cap = f"<caption>{esc(caption)}</caption>\n" if caption else ""
    return f'<table class="summary">\n{cap}<tbody>\n{body}\n</tbody>\n</table>'


_TRACK_LABELS = (
    ("truths", "objects in range at some scan"),
    ("truths_confirmed", "objects ever tracked"),
    ("confirmed_fraction", "fraction of objects tracked"),
    ("confirmed_within_fraction", "fraction tracked within 5 scans of appearing"),
    ("mean_confirm_delay", "mean delay to a track (s)"),
    ("completeness", "completeness (object-scans with a track)"),
    ("tracks", "confirmed tracks"),
    ("false_tracks", "false tracks (unassigned most of their life)"),
    ("breaks", "track breaks (object picked up again by a new track)"),
    ("truth_switches", "track changes of an object (breaks included)"),
    ("id_switches", "ID switches (a track moving to another object)"),
    ("mean_purity", "mean purity"),
    ("rmse", "position RMSE of assigned tracks (m)"),
)


_PAGE_CSS = """
.lead { font-size: 1.05em; }
.headline { display: flex; flex-wrap: wrap; gap: 0.8em; margin: 1em 0; }
.headline > div { flex: 1 1 170px; border: 1px solid #ddd; border-radius: 4px;
                padding: 0.5em 0.8em; background: #fafafa; }
.headline .value { font-size: 1.6em; font-weight: 600; font-variant-numeric: tabular-nums; }
.headline .label { font-weight: 600; }
.headline .what { color: #555; font-size: 0.8em; }
.track-table-wrap { max-height: 32em; overflow: auto; border: 1px solid #eee; }
table.tracks { border-collapse: collapse; font-size: 0.85em; width: 100%; }
table.tracks th { position: sticky; top: 0; background: #f4f4f4; text-align: left; }
table.tracks th, table.tracks td { border-bottom: 1px solid #eee; padding: 0.2em 0.6em; }
table.tracks td { white-space: nowrap; }
table.tracks td.num { text-align: right; font-variant-numeric: tabular-nums; }
@media print { .tk-map, .track-table-wrap { max-height: none; overflow: visible; }
               .tk-map { display: none; } }
"""

#: the track table's columns on the page: (column, heading, scale, digits)
_TABLE_COLUMNS = (("id", "track", None, 0), ("identity", "identity", None, 0),
                  ("start_utc", "start (UTC)", None, 0), ("end_utc", "end (UTC)", None, 0),
                  ("duration_s", "duration (min)", 1 / 60, 1),
                  ("distance_m", "distance (km)", 1e-3, 2),
                  ("mean_speed_m_s", "mean speed (kn)", 3600 / 1852, 1),
                  ("max_speed_m_s", "max speed (kn)", 3600 / 1852, 1),
                  ("longest_coast_s", "longest coast (s)", 1.0, 0), ("status", "status", None, 0))
_IDENTITY = {"ais": "MMSI", "opensky": "ICAO"}


def _headline_html(rep: TrackReport, metrics: Mapping[str, Any]) -> list[str]:
    esc = html.escape
    cards = [f'<div><div class="label">{esc(label)}</div><div class="value">{esc(value)}</div>'
             f'<div class="what">{esc(what)}</div></div>'
             for label, value, what in headline_figures(metrics, rep.history.times, rep.fmt)]
    return ['<div class="headline">', *cards, "</div>"]


def _lead(rep: TrackReport, metrics: Mapping[str, Any]) -> str:
    t = rep.history.times
    minutes = (t[-1] - t[0]) / 60 if t.size > 1 else 0.0
    start = ""
    if rep.epoch is not None and t.size:
        start = " from " + str(np.datetime_as_string(_utc(rep.epoch, t[:1])[0], unit="s")) + " UTC"
    how = (f"through a virtual radar; scored against the {rep.background_label}"
           if rep.truth is not None else f"from its {rep.background_label}")
    return (f'<p class="lead">{metrics["tracks_confirmed"]:,} confirmed tracks in '
            f"{metrics['scans']:,} scans ({minutes:.1f} min{html.escape(start)}) of "
            f"{html.escape(Path(rep.source).name or rep.title)}, {html.escape(how)}.</p>")


def _cell(v: Any, scale: float | None, digits: int) -> str:
    if scale is None:
        return f"<td>{html.escape('' if v is None else str(v))}</td>"
    ok = v is not None and math.isfinite(v)
    return f'<td class="num">{f"{v * scale:,.{digits}f}" if ok else "n/a"}</td>'


def track_table_html(table: pa.Table, kind: str = "") -> str:
    """The track table (``track_table``) as an HTML table, every text escaped."""
    esc = html.escape
    cols = [c for c in _TABLE_COLUMNS if c[0] in table.column_names]
    if table.num_rows and not any(table["identity"].to_pylist()):
        cols = [c for c in cols if c[0] != "identity"]
    label = _IDENTITY.get(kind, "identity")
    head = "".join(f"<th>{esc(label if c[0] == 'identity' else c[1])}</th>" for c in cols)
    data = {c[0]: table[c[0]].to_pylist() for c in cols}
    rows = ["<tr>" + "".join(_cell(data[c][i], s, d) for c, _, s, d in cols) + "</tr>"
            for i in range(table.num_rows)]
    return "\n".join(['<div class="track-table-wrap"><table class="tracks">',
                      f"<thead><tr>{head}</tr></thead><tbody>", *rows,
                      "</tbody></table></div>"])


def _results_html(metrics: Mapping[str, Any]) -> list[str]:
    """The run's counts, GOSPA and the track-level counts in full."""
    parts = [_table([("scans", metrics["scans"]), ("tracks started", metrics["tracks_started"]),
                     ("tracks confirmed", metrics["tracks_confirmed"]),
                     ("mean confirmed tracks per scan", metrics["mean_confirmed_per_scan"])])]
    g = metrics.get("gospa")
    if g is None:
        return parts + ["<p>No truth: GOSPA and the track-level counts need reported "
                        "positions (AIS or ADS-B with --as-radar).</p>"]
    c = g["c"]
    parts.append(_table([
        ("mean GOSPA (m)", g["mean"]), ("RMS GOSPA (m)", g["rms"]),
        ("localisation part, mean (m^2)", g["localisation"]),
        ("missed part, mean (m^2)", g["missed"]), ("false part, mean (m^2)", g["false"]),
        ("objects in range per scan", g["objects_per_scan"]),
        ("missed objects per scan", g["missed_per_scan"]),
        ("false tracks per scan", g["false_per_scan"]),
    ], caption=f"GOSPA of the confirmed tracks against the reported positions, per scan, "
               f"c = {c:g} m, p = 2, alpha = 2: GOSPA^2 = localisation + missed + false, "
               f"a missed object or a false track costing c^2/2."))
    tr = metrics.get("tracks", {})
    parts.append(_table([(label, tr[k]) for k, label in _TRACK_LABELS if k in tr],
                        caption=f"Track-level counts: objects and confirmed tracks paired "
                                f"per scan by the GOSPA assignment (within {c:g} m)."))
    return parts + _other_metrics(metrics)


_SHOWN = {"scans", "tracks_started", "tracks_confirmed", "mean_confirmed_per_scan", "gospa",
          "tracks"}


def _other_metrics(metrics: Mapping[str, Any]) -> list[str]:
    """Any further figure of ``track_metrics`` (a number or text, alone or in a section);
    series (lists) are in results.json only."""
    def plain(v: Any) -> bool:
        return v is None or isinstance(v, int | float | str | np.generic)

    extra = {k: v for k, v in metrics.items() if k not in _SHOWN and not k.startswith("_")}
    parts = []
    alone = [(k.replace("_", " "), v) for k, v in extra.items() if plain(v)]
    if alone:
        parts.append(_table(alone))
    for k, v in extra.items():
        rows = ([(a.replace("_", " "), b) for a, b in v.items() if plain(b)]
                if isinstance(v, Mapping) else [])
        if rows:
            parts.append(_table(rows, caption=k.replace("_", " ")))
    return parts


def _input_html(rep: TrackReport) -> list[str]:
    esc = html.escape
    inp = _input_document(rep.read, rep.source, rep.fmt)
    labels = {"file": "file", "format": "format", "records_read": "records read",
              "records_kept": "records kept", "records_skipped": "records skipped",
              "skipped_by_reason": "skipped, by reason",
              "duplicates_dropped": "exact duplicates dropped",
              "out_of_order_sorted": "records out of time order (sorted)",
              "not_given": "optional fields not given (kept as nan)", "epoch_utc": "t = 0 at",
              "layout": "layout recognised"}
    if inp.get("layout"):
        inp["layout"] = _layout_title(inp["layout"])
    missing = inp.pop("set_missing", None)
    parts = ["<h2>Input</h2>", _table([(labels.get(k, k), v) for k, v in inp.items()
                                      if v is not None])]
    if missing:
        parts.append(_table([(f"{name}: {reason}", n) for name, why in missing.items()
                             for reason, n in sorted(why.items(), key=lambda kv: -kv[1])],
                            caption="optional fields set missing (kept as nan), by field "
                                    "and reason"))
    if rep.read is not None and rep.read.out_of_order:
        parts.append(f"<p>{rep.read.out_of_order} records were out of time order in the file; "
                     "they were sorted by time before tracking.</p>")
    if rep.read is not None and rep.read.bad:
        shown = rep.read.bad[:20]
        parts.append(f"<p>First {len(shown)} of {rep.read.n_skipped} skipped records "
                     f"(all in {SKIPPED_CSV}):</p>\n<ul>")
        parts += [f"<li><code>{esc(str(b))}</code></li>" for b in shown]
        parts.append("</ul>")
    return parts


def _layout_title(name: str) -> str:
    """``NOAA MarineCadastre ... (noaa)``: the layout recognised, in words and by name."""
    known = LAYOUTS.get(name)
    return f"{known.title} ({name})" if known is not None else name


def _map_section(rep: TrackReport, table: pa.Table | None) -> list[str]:
    data = map_data(rep.history, table=table, background=rep.background, site=rep.site,
                    max_range=rep.max_range, frame=rep.frame, epoch=rep.epoch,
                    identity_label=_IDENTITY.get(rep.fmt, "identity"),
                    background_label=rep.background_label)
    return ["<h2>Map</h2>", map_html(data)]


def render_track_html(rep: TrackReport, metrics: Mapping[str, Any],
                      images: Mapping[str, Path | bytes], table: pa.Table | None = None) -> str:
    """The self-contained report page: the headline figures and the interactive map first,
    then the track table (``table``, from ``track_table``), the settings in words, the
    results in full, the input, the pictures for print and the settings as raw keys. CSS,
    script, data and PNGs are inline: it opens with no network."""
    esc = html.escape
    parts = ["<!DOCTYPE html>", '<html lang="en">', '<head><meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             f"<title>trackkit track: {esc(rep.title)}</title>",
             f"<style>{CSS}{_PAGE_CSS}{MAP_CSS}</style></head>", "<body>",
             f"<h1>{esc(rep.title)}</h1>",
             f'<p class="meta">Tracks from {esc(rep.source)} ({esc(rep.fmt)}). Generated by '
             f"trackkit {__version__}.</p>", _lead(rep, metrics)]
    parts += _headline_html(rep, metrics)
    if metrics["tracks_confirmed"] == 0:
        parts.append(f"<p>{esc(NO_TRACK_CONFIRMED)}</p>")
    parts += _map_section(rep, table)
    if table is not None:
        who = ("; the identity is the reporting identity of the object the track was paired "
               "with on most of its scans" if any(table["identity"].to_pylist()) else "")
        parts += [f"<h2>Tracks</h2>\n<p>One row per confirmed track (also in "
                  f"{TRACKS_SUMMARY_CSV}, in SI units){who}.</p>",
                  track_table_html(table, rep.fmt)]
    parts.append("<h2>Settings</h2>")
    parts += [f"<h3>{esc(title)}</h3>\n<p>{esc(text)}</p>"
              for title, text in settings_in_words(rep.config)]
    parts += ["<h2>Results in full</h2>", *_results_html(metrics), *_input_html(rep)]
    captions = {"tracks": "Confirmed tracks (coloured) over the "
                          f"{rep.background_label} (grey), east and north in km.",
                "gospa": "GOSPA against time; below, the objects in range, the confirmed "
                         "tracks and the pairs within the cut-off."}
    parts += notes_and_figures(list(rep.notes), images, captions)
    if rep.config:
        parts.append("<h2>Settings as in results.json</h2>")
        parts += [_table(list(values.items()), caption=section)
                  for section, values in rep.config.items()]
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


def _write_all(rep: TrackReport, folder: Path) -> dict[str, Path]:
    sigma_deg = rep.config.get("virtual radar", {}).get("sigma_bearing_deg")
    metrics = track_metrics(rep.history, rep.truth, rep.gospa_c, site=rep.site,
                            sigma_bearing=None if sigma_deg is None else math.radians(sigma_deg))
    table = history_table(rep.history, epoch=rep.epoch, frame=rep.frame,
                          smoothed=rep.smoothed)
    summary = track_table(rep.history, truth=rep.truth, c=rep.gospa_c,
                          object_ids=rep.object_ids, epoch=rep.epoch,
                          assignment=metrics.get("_assignment"))
    out = {"parquet": write_tracks_parquet(table, folder / TRACKS_PARQUET),
           "csv": write_tracks_csv(table, folder / TRACKS_CSV)}
    out["summary"] = folder / TRACKS_SUMMARY_CSV
    _write_csv(summary, out["summary"])
    if rep.frame is not None:
        out["geojson"] = write_tracks_geojson(
            tracks_geojson(rep.history, rep.frame, epoch=rep.epoch, site=rep.site,
                           smoothed=rep.smoothed),
            folder / TRACKS_GEOJSON)
    if rep.read is not None and (rep.read.n_skipped or rep.read.bad):
        out["skipped"] = write_skipped_csv(rep.read, folder / SKIPPED_CSV)
    images: dict[str, Path] = {}
    images["tracks"] = save_figure(track_figure(rep.history, background=rep.background,
                                          background_label=rep.background_label,
                                          site=rep.site, max_range=rep.max_range,
                                          title=rep.title), folder / TRACKS_PNG)
    g = metrics.get("_gospa_steps")
    if g is not None and rep.truth is not None:
        images["gospa"] = save_figure(gospa_figure(rep.history.times, g, rep.truth.sizes,
                                             rep.history.confirmed().sizes, rep.gospa_c,
                                             epoch=rep.epoch), folder / GOSPA_PNG)
    out.update({f"{k}_png": v for k, v in images.items()})
    out["html"] = folder / REPORT_HTML
    out["html"].write_text(render_track_html(rep, metrics, images, summary), encoding="utf-8")
    doc = results_document(rep, metrics)
    out["results"] = write_json(doc, folder / RESULTS_JSON)
    return out


def write_track_report(rep: TrackReport, out_dir: str | Path) -> dict[str, Path]:
    """Write every file of the track report into ``out_dir``, all or nothing: into a
    temporary directory inside ``out_dir`` first, then moved into place under an
    ``INCOMPLETE`` marker, ``results.json`` last (as ``report.files.write_report``). Track
    files of an earlier run that this one does not write are removed; other files are left
    alone. Returns name -> path."""
    return write_atomically(out_dir, lambda folder: _write_all(rep, folder), TRACK_FILES)
