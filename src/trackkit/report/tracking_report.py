"""The report of a multi-target Monte Carlo comparison , written atomically into one
directory like ``report.files.write_report``:

* ``results.json``: per tracker the time-averaged GOSPA (alpha = 2, p = 2) and its
  localisation, missed and false parts, OSPA (c, p), the mean number of confirmed tracks and
  the track summary (true targets confirmed and confirmed within N scans, false confirmed
  tracks and their rate per 100 scans, breaks, ID switches, mean time to confirm, purity,
  RMSE over the assigned target-track pairs, completeness) and the JPDA clusters approximated,
  with the ``units`` of every quantity. Only numbers that depend on the scenario and the seed,
  so equal seeds give byte-identical files; wall-clock times go to ``timings.json``.
* ``metrics.parquet``: one row per (tracker, scan): the Monte Carlo means of GOSPA, its parts,
  OSPA and the confirmed-track count, and the number of true targets present.
* ``xy.png``: one Monte Carlo run (run 0), one panel per tracker: the truths as lines, the
  confirmed tracks as lines labelled with their IDs, that run's plots faint.
* ``gospa.png``: mean GOSPA against time per tracker, and the mean number of confirmed tracks
  against the number of true targets.
* ``report.html``: one self-contained page (inline CSS, PNGs as data URIs, no scripts, no
  links): the scenario, the tables, the pictures, the notes and a short glossary.

    result, example = run_multitarget(scenario)          # trackkit.experiments.tracking_run
    paths = write_tracking_report(result, scenario, example, "trackkit-out/radar-crossing")
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from matplotlib.figure import Figure

from trackkit import __version__
from trackkit.eval.track_metrics import Frames
from trackkit.experiments.tracking_mc import TrackingResult
from trackkit.experiments.tracking_run import TrackingExample
from trackkit.report.files import (
    METRICS_PARQUET,
    REPORT_HTML,
    RESULTS_JSON,
    TIMINGS_JSON,
    TRACKKIT_FILES,
    finite_or_none,
    write_atomically,
    write_json,
)
from trackkit.report.glossary import code_spans
from trackkit.report.html import CSS, notes_and_figures
from trackkit.report.plots import distance_scale, finish_gospa_panels, gospa_panels, save_figure
from trackkit.scenario.multitarget import MultiTargetScenario, build_scene

__all__ = [
    "TRACKING_FILES", "TRACKING_GLOSSARY", "tracking_results_document",
    "tracking_timings_document", "tracking_metrics_table", "xy_figure", "gospa_figure",
    "render_tracking_html", "write_tracking_report",
]

XY_PNG = "xy.png"
GOSPA_PNG = "gospa.png"
#: The files the tracking report owns (an earlier run's not written again are removed).
TRACKING_FILES = (METRICS_PARQUET, XY_PNG, GOSPA_PNG, REPORT_HTML, TIMINGS_JSON, RESULTS_JSON)

#: per-tracker entries of results.json, in order, with their units (the table's rows too)
_TRACKER_UNITS: dict[str, str] = {
    "gospa": "m (mean over runs and scans of GOSPA, alpha = 2, p = 2)",
    "gospa_rms": "m (square root of the mean of GOSPA^2 = localisation + missed + false)",
    "gospa_localisation": "m^2 (mean over runs and scans; sum of d^2 over assigned pairs)",
    "gospa_missed": "m^2 (mean over runs and scans; c^2 / 2 per missed target)",
    "gospa_false": "m^2 (mean over runs and scans; c^2 / 2 per false track)",
    "ospa": "m (mean over runs and scans of OSPA at cut-off c and order ospa_p)",
    "confirmed_tracks": "tracks (mean over runs and scans of the confirmed tracks present)",
    "truths": "targets (total over all runs)",
    "truths_confirmed": "targets (total over all runs) with a track assigned at some scan",
    "confirmed_fraction": "fraction 0 to 1 of truths",
    "confirmed_within": "targets (total over all runs) confirmed within "
                        "confirm_within_s of their birth",
    "confirmed_within_fraction": "fraction 0 to 1 of truths",
    "mean_confirm_delay": "s (mean over the confirmed targets of first assigned time minus "
                          "birth time)",
    "tracks": "tracks (total over all runs of distinct confirmed track IDs)",
    "false_tracks": "tracks (total over all runs)",
    "false_tracks_per_100_scans": "tracks per 100 scans (false_tracks / (runs scans) x 100)",
    "false_track_fraction": "fraction 0 to 1 of tracks",
    "breaks": "events (total over all runs)",
    "truth_switches": "events (total over all runs; breaks included)",
    "id_switches": "events (total over all runs)",
    "mean_purity": "fraction 0 to 1 (mean over the tracks that are not false)",
    "rmse": "m (position, over all assigned target-track pairs of all runs and scans)",
    "completeness": "fraction 0 to 1 (assigned target-scans over target-scans)",
    "jpda_clusters_approximated": "clusters (total over all runs; 0 for GNN)",
}
_TOP_UNITS: dict[str, Any] = {
    "runs": "Monte Carlo runs",
    "scans": "scans per run",
    "duration_s": "s (first to last scan)",
    "scan_period_s": "s",
    "metrics": {
        "c_m": "m (cut-off of GOSPA, OSPA and the target-track assignment)",
        "ospa_p": "1",
        "gospa_p": "1",
        "gospa_alpha": "1",
        "confirm_within_scans": "scan periods",
        "confirm_within_s": "s",
    },
    "scene": {
        "pd": "1 (detection probability)",
        "clutter_per_scan": "false plots per scan (mean)",
        "q": "m^2/s^3 (the targets' process noise)",
        "targets": "targets in the scene",
    },
}
#: the summary table's rows: (key, label, format)
_ROWS: tuple[tuple[str, str, str], ...] = (
    ("gospa", "GOSPA mean [m]", ".1f"),
    ("gospa_rms", "GOSPA RMS [m]", ".1f"),
    ("gospa_localisation", "GOSPA localisation [m^2]", ".4g"),
    ("gospa_missed", "GOSPA missed [m^2]", ".4g"),
    ("gospa_false", "GOSPA false [m^2]", ".4g"),
    ("ospa", "OSPA mean [m]", ".1f"),
    ("confirmed_tracks", "confirmed tracks per scan", ".2f"),
    ("truths", "true targets", "d"),
    ("confirmed_fraction", "confirmed [%]", "%"),
    ("confirmed_within_fraction", "confirmed within N scans [%]", "%"),
    ("mean_confirm_delay", "mean time to confirm [s]", ".1f"),
    ("false_tracks", "false confirmed tracks", "d"),
    ("false_tracks_per_100_scans", "false tracks per 100 scans", ".2f"),
    ("breaks", "track breaks", "d"),
    ("id_switches", "ID switches", "d"),
    ("mean_purity", "track purity [%]", "%"),
    ("rmse", "RMSE, assigned pairs [m]", ".1f"),
    ("completeness", "completeness [%]", "%"),
    ("jpda_clusters_approximated", "JPDA clusters approximated", "d"),
)

#: The tracking report's glossary: ``(term, definition)`` pairs.
TRACKING_GLOSSARY: tuple[tuple[str, str], ...] = (
    ("GOSPA",
     "Generalised optimal sub-pattern assignment distance (alpha = 2, p = 2) between the true "
     "positions and the confirmed tracks' positions at one scan: "
     "`GOSPA^2 = sum of d^2 over assigned pairs + c^2/2 (missed targets) + c^2/2 (false "
     "tracks)`, a pair being assigned only if it is closer than the cut-off `c`. In metres; it "
     "adds up over targets, so it grows with their number. The mean is over runs and scans."),
    ("GOSPA parts",
     "Localisation (the sum of squared distances of the assigned pairs), missed (`c^2/2` per "
     "target without a track) and false (`c^2/2` per track without a target), in m^2: they "
     "add up to `GOSPA^2` at every scan and run, so their means add up to the square of "
     "`GOSPA RMS`."),
    ("OSPA",
     "Optimal sub-pattern assignment distance (cut-off `c`, order `p`): "
     "`OSPA^p = (min sum of min(d, c)^p + c^p |m - n|) / max(m, n)`, a per-target average in "
     "metres between 0 and `c` (0 when both sets are empty)."),
    ("Assignment",
     "The track counts and the RMSE assign true targets to confirmed tracks one-to-one at "
     "every scan by the optimal GOSPA assignment: a pair is assigned only if closer than `c`."),
    ("True targets confirmed",
     "Targets with a confirmed track assigned at some scan, out of all targets of all runs. "
     "Confirmed within N scans: assigned no later than N scan periods after the target's "
     "birth. Time to confirm: first assigned scan time minus birth time, averaged."),
    ("False confirmed tracks",
     "Confirmed tracks assigned to a target on less than half of their life; per 100 scans: "
     "their number over runs x scans, times 100."),
    ("Track breaks and ID switches",
     "A break: a target's track ends and the target is later assigned another track. An ID "
     "switch: a track's assigned target changes (the track moves from one target to "
     "another)."),
    ("Track purity",
     "Of a track that is not false: the fraction of its life assigned to the target it is "
     "assigned to most; averaged over those tracks."),
    ("RMSE, completeness",
     "RMSE: root mean square position error over all assigned target-track pairs. "
     "Completeness: assigned target-scans over all target-scans (1 = every target held at "
     "every scan)."),
    ("JPDA clusters approximated",
     "JPDA clusters too large for exact enumeration of the joint events, whose marginals came "
     "from loopy belief propagation instead."),
    ("Time per scan",
     "Wall-clock time of one tracker on one scan of one run, in `timings.json` (it varies "
     "from machine to machine, so it is kept out of `results.json`)."),
)


# ---------------------------------------------------------------------------------------------
# numbers
# ---------------------------------------------------------------------------------------------


def _scans(result: TrackingResult) -> int:
    return int(np.asarray(result.times).size)


def _tracker_entry(result: TrackingResult, name: str) -> dict[str, float | int]:
    tr = result.trackers[name]
    s = tr.summary
    parts = {k: float(np.mean(v)) for k, v in tr.gospa_parts.items()}
    total_scans = result.runs * _scans(result)
    entry: dict[str, float | int] = {
        "gospa": float(np.mean(tr.gospa)),
        "gospa_rms": math.sqrt(parts["localisation"] + parts["missed"] + parts["false"]),
        "gospa_localisation": parts["localisation"],
        "gospa_missed": parts["missed"],
        "gospa_false": parts["false"],
        "ospa": float(np.mean(tr.ospa)),
        "confirmed_tracks": float(np.mean(tr.confirmed)),
        "false_tracks_per_100_scans": 100.0 * s["false_tracks"] / total_scans,
        "jpda_clusters_approximated": int(tr.approximated),
    }
    for key in ("truths", "truths_confirmed", "confirmed_fraction", "confirmed_within",
                "confirmed_within_fraction", "mean_confirm_delay", "tracks", "false_tracks",
                "false_track_fraction", "breaks", "truth_switches", "id_switches",
                "mean_purity", "rmse", "completeness"):
        v = s[key]
        entry[key] = int(v) if isinstance(v, int | np.integer) else float(v)
    return {k: entry[k] for k in _TRACKER_UNITS}


def _period(result: TrackingResult) -> float:
    t = np.unique(np.asarray(result.times, dtype=float))
    return float(np.diff(t).min()) if t.size > 1 else math.nan


def tracking_results_document(result: TrackingResult, scenario: MultiTargetScenario,
                              scene=None) -> dict[str, Any]:
    """The ``results.json`` document (see the module doc); non-finite numbers as null.
    ``scene``: ``scenario``'s scene if already built."""
    scene = build_scene(scenario) if scene is None else scene
    times = np.asarray(result.times, dtype=float)
    s = scenario.scene
    doc: dict[str, Any] = {
        "scenario": scenario.name,
        "kind": "multi-target",
        "runs": int(result.runs),
        "seed": int(result.seed),
        "scans": _scans(result),
        "duration_s": float(times[-1] - times[0]) if times.size else 0.0,
        "scan_period_s": _period(result),
        "metrics": {
            "c_m": float(result.c),
            "ospa_p": float(scenario.report.ospa_p),
            "gospa_p": 2.0,
            "gospa_alpha": 2.0,
            "confirm_within_scans": float(scenario.report.confirm_within_scans),
            "confirm_within_s": float(result.within),
        },
        "scene": {"builder": s.builder, "pd": s.pd, "clutter_per_scan": s.clutter_per_scan,
                  "q": s.q, "targets": len(scene.targets)},
        "units": {**_TOP_UNITS, "trackers": dict(_TRACKER_UNITS)},
        "trackers": {name: _tracker_entry(result, name) for name in result.trackers},
    }
    return finite_or_none(doc)


def tracking_timings_document(result: TrackingResult,
                              scenario: MultiTargetScenario) -> dict[str, Any]:
    """The ``timings.json`` document: tracking seconds per scan of each tracker."""
    return finite_or_none({
        "scenario": scenario.name, "runs": int(result.runs), "seed": int(result.seed),
        "units": {"seconds_per_scan": "s of tracking (all of a tracker's steps) per run and "
                                      "scan; simulation and metrics not included"},
        "seconds_per_scan": {name: float(t.seconds_per_scan)
                             for name, t in result.trackers.items()},
    })


def tracking_metrics_table(result: TrackingResult, scenario: MultiTargetScenario,
                           truths: np.ndarray | None = None) -> pa.Table:
    """Per-scan means over the runs, one row per (tracker, scan). Columns ``tracker, scan,
    time, truths, gospa, gospa_localisation, gospa_missed, gospa_false, ospa, confirmed``;
    units in the field metadata (``unit``), the settings in the schema metadata
    (``trackkit``, JSON). ``truths`` (the true targets present per scan, the same in every
    run) defaults to -1 where unknown."""
    S = _scans(result)
    names = list(result.trackers)
    k = len(names)
    truths = np.full(S, -1, np.int64) if truths is None else np.asarray(truths, np.int64)
    if truths.shape != (S,):
        raise ValueError(f"truths has shape {truths.shape}; expected ({S},), one per scan")

    def stack(get) -> np.ndarray:
        parts = [np.asarray(get(result.trackers[n]), dtype=np.float64).reshape(S)
                 for n in names]
        return np.concatenate(parts) if parts else np.empty(0)

    cols: dict[str, Any] = {
        "tracker": pa.array(np.repeat(names, S).tolist(), pa.string()),
        "scan": np.tile(np.arange(S, dtype=np.int64), k),
        "time": np.tile(np.asarray(result.times, dtype=np.float64), k),
        "truths": np.tile(truths, k),
        "gospa": stack(lambda t: t.gospa),
        "gospa_localisation": stack(lambda t: t.gospa_parts["localisation"]),
        "gospa_missed": stack(lambda t: t.gospa_parts["missed"]),
        "gospa_false": stack(lambda t: t.gospa_parts["false"]),
        "ospa": stack(lambda t: t.ospa),
        "confirmed": stack(lambda t: t.confirmed),
    }
    units = {"time": "s", "truths": "targets present", "gospa": "m",
             "gospa_localisation": "m^2", "gospa_missed": "m^2", "gospa_false": "m^2",
             "ospa": "m", "confirmed": "tracks (mean over runs)"}
    fields = []
    for name, values in cols.items():
        dtype = values.type if isinstance(values, pa.Array) else pa.from_numpy_dtype(values.dtype)
        unit = units.get(name)
        fields.append(pa.field(name, dtype, metadata={"unit": unit} if unit else None))
    meta = {"scenario": scenario.name, "kind": "multi-target", "runs": int(result.runs),
            "seed": int(result.seed), "scans": S, "c_m": float(result.c),
            "ospa_p": float(scenario.report.ospa_p), "gospa_p": 2.0, "gospa_alpha": 2.0}
    schema = pa.schema(fields, metadata={"trackkit": json.dumps(meta)})
    return pa.Table.from_arrays([pa.array(v) for v in cols.values()], schema=schema)


# ---------------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------------


def _by_id(f: Frames) -> list[tuple[int, np.ndarray]]:
    """The rows of each ID in step order: [(id, positions (k, 2)), ...] by ID."""
    ids = np.asarray(f.ids)
    if ids.size == 0:
        return []
    order = np.argsort(ids, kind="stable")  # rows are in step order already
    ids_s, xy = ids[order], np.asarray(f.x)[order, :2]
    starts = np.flatnonzero(np.r_[True, ids_s[1:] != ids_s[:-1]])
    ends = np.r_[starts[1:], ids_s.size]
    return [(int(ids_s[a]), xy[a:b]) for a, b in zip(starts, ends, strict=True)]


def _plot_positions(example: TrackingExample, scene) -> np.ndarray:
    """The run's plots as east-north positions (m) ``(N, 2)``."""
    from trackkit.models.sensors import RangeBearing
    from trackkit.tracking.initiate import convert_range_bearing

    scans = example.run.scans
    out = np.empty((len(scans.z), 2))
    sensor_of = np.repeat(np.asarray(scans.sensor), np.diff(scans.offsets))
    for j, sensor in enumerate(scene.sensors):
        rows = sensor_of == j
        if not rows.any():
            continue
        z = np.asarray(scans.z)[rows]
        out[rows] = (convert_range_bearing(z, sensor)[0] if isinstance(sensor, RangeBearing)
                     else z[:, :2])
    return out


def xy_figure(example: TrackingExample, scenario: MultiTargetScenario,
              scene=None) -> Figure:
    """Plan view of one run, one panel per tracker: truths (black lines, circle at the
    start), confirmed tracks (coloured lines, ID at the track's end) and the run's plots
    (faint dots), framed on the truths."""
    scene = build_scene(scenario) if scene is None else scene
    names = list(example.histories)
    truths = _by_id(example.run.truth_positions)
    pts = np.concatenate([xy for _, xy in truths]) if truths else np.zeros((1, 2))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = 0.55 * max(float((hi - lo).max()), 1000.0)
    mid = 0.5 * (lo + hi)
    unit, s = distance_scale(2 * half)
    plots = _plot_positions(example, scene) * s
    ncols = min(len(names), 2)
    nrows = -(-len(names) // ncols)
    fig = Figure(figsize=(6.2 * ncols, 6.0 * nrows + 0.6), layout="constrained")
    many = len(truths) > 30
    for i, name in enumerate(names):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        ax.scatter(plots[:, 0], plots[:, 1], s=1.5, color="0.6", alpha=0.35, linewidths=0,
                   rasterized=True, label="plots (run 0)")
        for k, (_, xy) in enumerate(truths):
            ax.plot(xy[:, 0] * s, xy[:, 1] * s, color="black", lw=1.0 if many else 1.8,
                    label="truth" if k == 0 else None)
            ax.plot(xy[0, 0] * s, xy[0, 1] * s, "o", color="black", ms=2.5 if many else 4)
        tracks = _by_id(example.histories[name].confirmed())
        for k, (jid, xy) in enumerate(tracks):
            color = f"C{jid % 10}"
            ax.plot(xy[:, 0] * s, xy[:, 1] * s, color=color, lw=0.8 if many else 1.2,
                    label="confirmed tracks" if k == 0 else None)
            ax.annotate(str(jid), xy[-1] * s, fontsize=5 if many else 8, color=color,
                        xytext=(2, 2), textcoords="offset points", annotation_clip=True)
        ax.set_xlim((mid[0] - half) * s, (mid[0] + half) * s)
        ax.set_ylim((mid[1] - half) * s, (mid[1] + half) * s)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel(f"east [{unit}]")
        ax.set_ylabel(f"north [{unit}]")
        ax.set_title(f"{name}: {len(tracks)} confirmed tracks, {len(truths)} targets",
                     fontsize="medium")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small", markerscale=4)
    fig.suptitle(f"{scenario.name}: Monte Carlo run 0 (track IDs at the tracks' ends)",
                 fontsize="medium")
    return fig


def gospa_figure(result: TrackingResult, scenario: MultiTargetScenario,
                 truths: np.ndarray | None = None) -> Figure:
    """Mean GOSPA against time per tracker (top) and the mean number of confirmed tracks
    against the number of true targets (bottom)."""
    t = np.asarray(result.times, dtype=float)
    fig, top, bottom = gospa_panels(f"{scenario.name}: GOSPA (c = {result.c:g} m, p = 2, "
                                    f"alpha = 2), mean of {result.runs} runs")
    for i, (name, tr) in enumerate(result.trackers.items()):
        top.plot(t, tr.gospa, color=f"C{i}", lw=1.3,
                 label=f"{name} (mean {float(np.mean(tr.gospa)):.1f} m)")
        bottom.plot(t, tr.confirmed, color=f"C{i}", lw=1.2, label=name)
    if truths is not None:
        bottom.step(t, truths, where="post", color="black", ls="--", lw=1.0,
                    label="true targets")
    finish_gospa_panels(top, bottom)
    return fig


# ---------------------------------------------------------------------------------------------
# page
# ---------------------------------------------------------------------------------------------

_CAPTIONS = {
    "xy": "Monte Carlo run 0: the truths (black, circle at the start), each tracker's "
          "confirmed tracks (coloured, labelled with their IDs) and the run's radar plots "
          "(grey), in the radar's east-north frame.",
    "gospa": "GOSPA against time, mean over the runs (top), and the mean number of confirmed "
             "tracks against the number of true targets present (bottom).",
}


def _fmt(v: Any, spec: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if spec == "%":
        return f"{100 * v:.1f}"
    if spec == "d":
        return f"{int(v):d}"
    return format(v, spec)


def _summary_table(doc: Mapping[str, Any]) -> str:
    esc = html.escape
    names = list(doc["trackers"])
    head = "".join(f"<th>{esc(n)}</th>" for n in names)
    rows = []
    for key, label, spec in _ROWS:
        cells = "".join(f"<td>{_fmt(doc['trackers'][n][key], spec)}</td>" for n in names)
        rows.append(f"<tr><th>{esc(label)}</th>{cells}</tr>")
    m = doc["metrics"]
    caption = (f"Means over {doc['runs']} runs of {doc['scans']} scans; counts are totals "
               f"over all runs. c = {m['c_m']:g} m, OSPA p = {m['ospa_p']:g}, GOSPA p = 2, "
               f"alpha = 2; confirmed within N = {m['confirm_within_scans']:g} scans "
               f"({_fmt(m['confirm_within_s'], 'g')} s).")
    return (f'<table class="summary"><caption>{esc(caption)}</caption>'
            f"<thead><tr><th></th>{head}</tr></thead>\n<tbody>\n" + "\n".join(rows)
            + "\n</tbody></table>")


def _settings_table(scenario: MultiTargetScenario) -> str:
    esc = html.escape
    fields = ("filter", "q", "associator", "cost", "missed_distance", "logic", "alpha", "beta",
              "new_target_density", "confirm", "delete", "initiator", "v_std_mps",
              "v_max_mps", "margin_m", "p_gate", "pd", "clutter_density")
    specs = scenario.trackers
    used = [f for f in fields if any(getattr(t, f) is not None for t in specs)]
    head = "".join(f"<th>{esc(t.name)}</th>" for t in specs)
    rows = []
    for f in used:
        cells = "".join(f"<td>{esc('-' if getattr(t, f) is None else str(getattr(t, f)))}"
                        "</td>" for t in specs)
        rows.append(f"<tr><th>{esc(f)}</th>{cells}</tr>")
    return ('<table class="summary"><caption>Tracker settings (q in m^2/s^3; pd and clutter '
            "density: the scene's unless given).</caption>"
            f"<thead><tr><th></th>{head}</tr></thead>\n<tbody>\n" + "\n".join(rows)
            + "\n</tbody></table>")


def _glossary_html() -> str:
    items = [f"<dt>{html.escape(term)}</dt><dd>{code_spans(text)}</dd>"
             for term, text in TRACKING_GLOSSARY]
    return '<dl class="glossary">\n' + "\n".join(items) + "\n</dl>"


def render_tracking_html(doc: Mapping[str, Any], scenario: MultiTargetScenario,
                         images: Mapping[str, str | Path | bytes]) -> str:
    """The report page from the ``results.json`` document ``doc`` and ``images`` (figure
    name -> PNG path or bytes): self-contained, no scripts, no links."""
    esc = html.escape
    s = scenario.scene
    scene = (f"Scene {s.builder}: {doc['scene']['targets']} targets, pd = {s.pd:g}, "
             f"{s.clutter_per_scan:g} false plots per scan, targets' q = {s.q:g} m^2/s^3; "
             f"{doc['scans']} scans of {_fmt(doc['scan_period_s'], 'g')} s.")
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        '<head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>trackkit: {esc(scenario.name)}</title>",
        f"<style>{CSS}</style></head>",
        "<body>",
        f"<h1>{esc(scenario.name)}</h1>",
    ]
    if scenario.description:
        parts.append(f"<p>{esc(scenario.description)}</p>")
    parts.append(f'<p class="meta">{doc["runs"]} Monte Carlo runs, seed {doc["seed"]}. '
                 f"{esc(scene)} Generated by trackkit {esc(__version__)}.</p>")
    parts += ["<h2>Summary</h2>", _summary_table(doc), "<h2>Trackers</h2>",
              _settings_table(scenario)]
    parts += notes_and_figures(scenario.notes, images, _CAPTIONS)
    parts += ["<h2>Glossary</h2>", _glossary_html(), "</body>", "</html>", ""]
    return "\n".join(parts)


# ---------------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------------


def _write_all(result: TrackingResult, scenario: MultiTargetScenario,
               example: TrackingExample | None, folder: Path) -> dict[str, Path]:
    truths = None if example is None else np.asarray(example.run.truth.sizes, np.int64)
    scene = build_scene(scenario)
    written: dict[str, Path] = {"metrics": folder / METRICS_PARQUET}
    pq.write_table(tracking_metrics_table(result, scenario, truths), written["metrics"])
    images: dict[str, Path] = {}
    if example is not None:
        images["xy"] = save_figure(xy_figure(example, scenario, scene), folder / XY_PNG)
    images["gospa"] = save_figure(gospa_figure(result, scenario, truths), folder / GOSPA_PNG)
    written.update(images)
    doc = tracking_results_document(result, scenario, scene)
    written["html"] = folder / REPORT_HTML
    written["html"].write_text(render_tracking_html(doc, scenario, images), encoding="utf-8")
    written["timings"] = write_json(tracking_timings_document(result, scenario),
                                     folder / TIMINGS_JSON)
    written["results"] = write_json(doc, folder / RESULTS_JSON)
    return written


def write_tracking_report(result: TrackingResult, scenario: MultiTargetScenario,
                          example: TrackingExample | None, out: str | Path) -> dict[str, Path]:
    """Write the report files of a multi-target comparison into ``out`` atomically (see the
    module doc; as ``report.files.write_report``: a temporary directory inside ``out``,
    ``results.json`` moved into place last, nothing left behind on failure). Without an
    ``example`` there is no ``xy.png``. Returns name -> path (``metrics``, ``xy``,
    ``gospa``, ``html``, ``timings``, ``results``)."""
    return write_atomically(out, lambda folder: _write_all(result, scenario, example, folder),
                            (*TRACKKIT_FILES, *TRACKING_FILES))
