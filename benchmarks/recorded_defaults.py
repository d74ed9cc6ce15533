"""The defaults of ``trackkit track --as-radar`` against the previous ones, on whole recordings.

Each recording (the Solent AIS file, 85 min, and the OpenSky ADS-B file, 6 min) is turned into
radar plots by the virtual radar of its profile (``TRACK_PROFILES``), once per seed, and the
same plots are tracked by

- ``old``: the first defaults, built explicitly here: a constant-velocity EKF (q 0.05
  m^2/s^3 for AIS), single-point initiation and Wald's SPRT thresholds (alpha 0.01, beta
  0.001: deleted at the third missed scan);
- ``previous`` (AIS): today's with one process noise for both of the IMM's models (0.05)
  and a 30 min hold, the defaults before the IMM had a quiet and a manoeuvring mode;
- ``new, no hold``: today's without holding lost tracks (a track is deleted after a few
  missed scans), what it buys;
- ``new``: today's ``TRACK_PROFILES`` (the IMM of a quiet constant-velocity model and a
  manoeuvring coordinated-turn one, two-point initiation, a lost track held unseen for a
  new one to continue);
- ``new, --misses 3`` (AIS): today's, shown coasting three missed scans rather than two;

Every run is scored by one function, ``score(history, run, c) -> {name: value}`` (by default
:func:`track_scores`: the figures of ``trackkit.eval.clear_mot.score_run``, and the mean
purity of the tracks cut into 5-minute pieces, :func:`pieces`); another
is given as ``--scorer module:function`` with the same signature, and its names become the
table's columns. The table gives the mean and the standard deviation over the seeds of each
figure, and the wall time of a run's tracking.

    python benchmarks/recorded_defaults.py [--solent FILE] [--opensky FILE] [--seeds 0-9]
        [--max-scans N] [--scorer module:function] [--only ais|opensky]

The files default to ``shared/data`` beside the repository (as the tests find them).
"""

from __future__ import annotations

import argparse
import importlib
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from trackkit import io as tio
from trackkit.eval.clear_mot import score_run
from trackkit.eval.track_metrics import Frames
from trackkit.sim.virtual_radar import VirtualRadar, VirtualRadarRun, virtual_radar
from trackkit.tracking.history import TrackHistory, run_tracker
from trackkit.tracking.recorded import (
    SINGLE_MODEL_Q,
    TRACK_PROFILES,
    TrackProfile,
    build_tracker,
    profile_radar,
)

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
Scorer = Callable[[TrackHistory, VirtualRadarRun, float], dict[str, float]]


def profiles(kind: str) -> dict[str, TrackProfile]:
    """The settings compared: the first and the previous defaults, today's without the hold
    and today's, on the same radar (and for AIS today's coasting a scan longer)."""
    new = TRACK_PROFILES[kind]
    old = replace(new, q=SINGLE_MODEL_Q[kind], turn_q=None, turn_std_deg=None, manoeuvre_q=None,
                  misses=None, v_max=None, hold=None, rejoin=None)
    out = {"old": old}
    if new.manoeuvre_q is not None:
        out["previous"] = replace(new, q=SINGLE_MODEL_Q[kind], manoeuvre_q=None, hold=1800.0)
    out |= {"new, no hold": replace(new, hold=None, rejoin=None), "new": new}
    if new.regain:
        out["new, --misses 3"] = replace(new, misses=3.0)
    return out


#: the figures of ``trackkit.eval.clear_mot.score_run`` the table shows, with their labels
FIGURES = {"tracks_per_object": "tracks per object", "breaks": "breaks",
           "id_switches": "ID switches", "id_switches_resolvable": "resolvable ID switches",
           "fragmentations": "fragmentations", "idf1": "IDF1", "mota": "MOTA",
           "gospa": "GOSPA (m)", "gospa_switching": "GOSPA with switching (m)",
           "completeness": "completeness", "false_tracks": "false tracks",
           "false_track_scans": "false track-scans", "mean_purity": "mean purity",
           "rmse": "RMSE (m)"}


#: the length of the pieces the tracks are cut into for purity at equal length (s)
PIECE = 300.0


def track_scores(history: TrackHistory, run: VirtualRadarRun, c: float) -> dict[str, float]:
    """The figures of one run as ``trackkit track`` reports them (``score_run``: CLEAR-MOT
    ID switches, those between objects the radar resolves, IDF1, MOTA, GOSPA with and
    without the switching penalty c, the track counts), and the mean purity of the tracks
    cut into pieces of ``PIECE`` seconds (``pieces``)."""
    tracks, site, sb = history.confirmed(), tuple(run.radar.site), run.radar.sigma_bearing
    got = score_run(tracks, run.truth, site, sb, c)
    cut = score_run(pieces(tracks, round(PIECE / run.radar.period)), run.truth, site, sb, c)
    return {**{label: got[key] for key, label in FIGURES.items()},
            "mean purity, 5 min pieces": cut["mean_purity"],
            "mean track life (scans)": float(np.mean(np.unique(tracks.ids,
                                                               return_counts=True)[1]))}


def pieces(tracks: Frames, n: int) -> Frames:
    """The tracks cut into pieces of ``n`` scans from each track's first scan, a new ID per
    piece: the same positions, only shorter lives. A track's purity (the share of its life
    on its dominant object) falls with its life, since one swap costs all the rest of it, so
    the mean purity of trackers whose tracks live for different times is compared at one
    length."""
    step = np.repeat(np.arange(tracks.n_steps), tracks.sizes)
    ids = np.asarray(tracks.ids, np.int64)
    order = np.lexsort((step, ids))
    first = np.empty_like(step)
    head = np.r_[True, ids[order][1:] != ids[order][:-1]]
    first[order] = step[order][head][np.cumsum(head) - 1]
    return tracks._replace(ids=ids * (tracks.n_steps // n + 1) + (step - first) // n)


def run_once(reports: Any, s: TrackProfile, vr: VirtualRadar, seed: int,
             max_scans: int | None) -> tuple[TrackHistory, VirtualRadarRun, float]:
    """The radar's plots for ``seed`` tracked with the settings ``s``; the wall time (s) of
    the tracking."""
    run = virtual_radar(reports, vr, seed, max_scans=max_scans)
    tracker, _ = build_tracker(run.sensor, s, max(vr.clutter, 0.1) / vr.volume, "gnn", "ekf")
    t0 = time.perf_counter()
    history, _ = run_tracker(tracker, run.scans)
    return history, run, time.perf_counter() - t0


def compare(kind: str, reports: Any, seeds: list[int], score: Scorer,
            max_scans: int | None) -> dict[str, dict[str, list[float]]]:
    """Per setting, per figure, the values over the seeds (and ``wall (s)``)."""
    out: dict[str, dict[str, list[float]]] = {}
    for name, s in profiles(kind).items():
        vr = profile_radar(s)  # at the data's median position, as trackkit track
        rows: dict[str, list[float]] = {}
        for seed in seeds:
            history, run, wall = run_once(reports, s, vr, seed, max_scans)
            for key, value in {**score(history, run, float(s.gospa_c)),
                               "wall (s)": wall}.items():
                rows.setdefault(key, []).append(float(value))
        out[name] = rows
    return out


def table(title: str, results: dict[str, dict[str, list[float]]]) -> str:
    """A markdown table: a row per figure, mean ± std over the seeds per setting."""
    names = list(results)
    keys = list(results[names[0]])
    lines = [f"### {title}", "", "| figure | " + " | ".join(names) + " |",
             "|---|" + "---|" * len(names)]
    for key in keys:
        cells = []
        for name in names:
            v = np.asarray(results[name][key])
            cells.append(f"{_g(v.mean())} ± {_g(v.std(ddof=1) if v.size > 1 else 0.0)}")
        lines.append(f"| {key} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _g(x: float) -> str:
    return f"{x:.3g}" if abs(x) < 1000 else f"{x:.0f}"


def _seeds(text: str) -> list[int]:
    a, sep, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if sep else [int(v) for v in text.split(",")]


def _scorer(text: str | None) -> Scorer:
    if not text:
        return track_scores
    module, _, name = text.partition(":")
    return getattr(importlib.import_module(module), name)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--solent", type=Path, default=DATA / "SolentAIS_20160112_130211.csv")
    ap.add_argument("--opensky", type=Path, default=DATA / "OpenSky_Plane_States.csv")
    ap.add_argument("--seeds", default="0-9", help="e.g. 0-9 or 100,101")
    ap.add_argument("--max-scans", type=int, default=None)
    ap.add_argument("--scorer", default=None, help="module:function (default track_scores)")
    ap.add_argument("--only", choices=("ais", "opensky"), default=None)
    args = ap.parse_args()
    seeds, score = _seeds(args.seeds), _scorer(args.scorer)
    print(f"seeds {seeds[0]}..{seeds[-1]} ({len(seeds)}), mean ± std over seeds\n")
    for kind, path, read in (("ais", args.solent, tio.read_ais_csv),
                             ("opensky", args.opensky, tio.read_opensky_csv)):
        if args.only not in (None, kind):
            continue
        reports, _ = read(path)
        results = compare(kind, reports, seeds, score, args.max_scans)
        print(table(f"{path.name} ({kind})", results), "\n", flush=True)


if __name__ == "__main__":
    main()
