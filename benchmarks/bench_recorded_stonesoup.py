"""Recorded traffic through a virtual radar, tracked by trackkit and by Stone Soup on the same
plots, scored by the same metric code, in one process.

What is compared. ``trackkit track FILE --as-radar`` reads the AIS or ADS-B reports, makes the
plots a radar at the data's centre would have made of them (``sim.virtual_radar``: one scan
per period, range and nautical bearing with Gaussian noise, detection probability pd,
Poisson clutter) and tracks them; the reported positions at the scan times are the truth.
This script calls the same library function (``tracking.recorded.track_recording``) for a
seed, so trackkit's plots and tracks are exactly the command's, and hands the same plots to a
standard Stone Soup 1.9 tracker built from the same numbers (the input kind's profile,
``TRACK_PROFILES``): the radar's site, range and bearing noise, pd, clutter density
``clutter / ((max_range - min_range) 2 pi)`` per metre radian, gate probability 0.99 and the
velocity std of a new track; its one constant-velocity model takes the process noise q
(m^2/s^3) that trackkit's single-model tracker used (``SINGLE_MODEL_Q``: 0.05 for AIS, 100
for ADS-B), since trackkit's IMM now has a quiet mode (AIS q 0.0025) and a manoeuvring one
(0.5) that one model cannot be both of.

Stone Soup's tracker. A ``MultiTargetTracker`` with

* an EKF (``ExtendedKalmanPredictor``, ``ExtendedKalmanUpdater``) on a
  ``CombinedLinearGaussianTransitionModel`` of two ``ConstantVelocity(q)`` (state
  ``[x, vx, y, vy]``; the same Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]] per axis as trackkit's);
* a ``CartesianToBearingRange`` measurement model at the radar's site,
  ``noise_covar = diag(sigma_bearing^2, sigma_range^2)``. Stone Soup's measurement is
  ``[bearing, range]`` with the bearing counter-clockwise from the x (east) axis; trackkit's
  plot is ``[range, bearing]`` with the bearing clockwise from north, so a plot (r, b) becomes
  ``[Bearing(pi/2 - b), r]`` (``to_stonesoup``; checked in
  tests/tracking/test_recorded_stonesoup.py);
* ``GNNWith2DAssignment`` over a ``PDAHypothesiser`` (pd, clutter density, P_G = 0.99:
  trackkit's numbers) or a ``DistanceHypothesiser`` (``Mahalanobis``, missed distance
  sqrt(chi2.ppf(0.99, 2)) = 3.03: the same gate's edge);
* a ``MultiMeasurementInitiator`` (prior: velocity 0 with trackkit's velocity std, position
  from the plot through the model's inverse) with its own associator (the tracker's) and an
  inner ``UpdateTimeStepsDeleter(2)``: a tentative track survives one miss (one in ten plots
  is missing at pd 0.9) and is dropped at the second in a row;
* a deleter of confirmed tracks, time- or covariance-based.

The settings (``SETTINGS``), chosen to give Stone Soup its best chance rather than to tune it
to a file:

* ``pda-2-del3``: confirm on the second plot, delete after 3 missed scans. trackkit's SPRT
  score (alpha 0.01, beta 0.001, pd 0.9) confirms after two or three hits and deletes after
  about four misses in a row (each costs ln(1 - pd P_G) = -2.2 of the 6.9 the score may drop
  below its maximum); deleting after three and after five missed scans bracket it.
* ``pda-2-del5`` and ``pda-2-del10``: coast longer. Three misses in a row happen to a held
  object with probability (1 - pd)^3 = 1e-3 per scan, i.e. about once per track-hour at 3 s
  scans, a break each time; five (1e-5) make that rare, ten (30 s at 3 s scans) also carry
  a track across a vessel passing close by another. The price is coasting after a vessel's
  reports end and on false tracks.
* ``pda-3-del5``: confirm on the third plot: fewer false tracks from clutter and from the
  second plot of a clustered vessel, a scan later confirmation.
* ``pda-2-cov``: delete when the track's position variance ``var x + var y`` exceeds c^2,
  the GOSPA cut-off squared (500 m for AIS, 2 km for ADS-B): such a track can no longer be
  matched within the cut-off. A fixed threshold is range-dependent with a range-bearing
  radar (cross-range variance grows with range squared), the known weakness of this deleter.
* ``dist-2-del5``: the ``DistanceHypothesiser`` instead of the PDA one: GNN on Mahalanobis
  distance (a miss at the gate's edge), ignoring pd and the clutter density.

Scoring. Both trackers' confirmed tracks at every scan (Stone Soup's ``tracker.tracks``, each
holding its updated or predicted state at the scan; trackkit's ``TrackHistory.confirmed()``)
go to one function, ``score``, which calls trackkit's metric code (``gospa_steps``,
``track_counts``, ``track_summary`` as ``report.track_pages.track_metrics`` uses them), with
the profile's cut-off c; it is the one place to change the metrics. ``diagnose`` says what
each tracker got wrong where: confirmed track-scans matched to no object near another
object's track (duplicates on clustered vessels), after the object the track last held has
left the truth (coasting after its reports end, or out of range) or elsewhere (clutter); the
breaks after the object was out of the truth (a reporting gap longer than the radar bridges:
no plots), on a still object (under 0.5 m/s: moored, at anchor, drifting), on a turning
object (heading change over the 30 s before the break above 20 deg) and beside another
object (within 100 m); and the CLEAR-MOT ID switches of the score table with, of them,
those where another object was within 100 m of the switching one.

Timing. Wall and CPU time per scan of each tracker's scan loop, one after the other in one
process (trackkit: ``run_tracker`` from its first scan to its last, timed through the
progress callback; Stone Soup: ``next(tracker)`` per scan); reading the file and making the
plots are not timed. On a shared machine the CPU time is the steadier figure.

For each metric the best Stone Soup setting is kept ("Stone Soup at its best"); the script
prints one markdown table per file (the tables of docs/recorded-data.md and
benchmarks/RESULTS.md are its output). ``--save DIR`` keeps every tracker's confirmed tracks
and times; ``--rescore`` scores saved runs again without tracking (a change of metric code
costs seconds, not the eight minutes of CPU per Stone Soup setting on the whole Solent
file).

    python benchmarks/bench_recorded_stonesoup.py solent-ais opensky-adsb
    python benchmarks/bench_recorded_stonesoup.py FILE --max-scans 200 --settings pda-2-del3
    python benchmarks/bench_recorded_stonesoup.py FILE... --save runs/
    python benchmarks/bench_recorded_stonesoup.py runs/*.json --rescore

``--rescore`` merges runs of the same plots saved by several processes (``--settings`` split
between them, ``--save`` to different folders; ``--settings`` with no name runs trackkit
alone, so a new trackkit can be set beside Stone Soup runs kept from before, as long as the
plots are the same: the runs carry the plots' SHA-256).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from trackkit.eval.clear_mot import clear_mot, score_run
from trackkit.eval.track_metrics import Frames, assign
from trackkit.tracking.gating import GATE_PROBABILITY
from trackkit.tracking.recorded import (
    SINGLE_MODEL_Q,
    TrackingResult,
    TrackOptions,
    track_recording,
)

T0 = datetime(2000, 1, 1)  # Stone Soup wants datetimes: scan time t s is T0 + t
TURN_DEG = 20.0  # heading change over the TURN_WINDOW_S before a break that makes it a turn
TURN_WINDOW_S = 30.0
STILL_M_S = 0.5  # speed (m/s) under which an object is still: moored, at anchor or drifting
NEAR_M = 100.0  # another object this close (m) makes a break one "beside another object"


@dataclass(frozen=True)
class Setting:
    """One Stone Soup set-up: hypothesiser "pda" or "distance", the initiator's
    ``min_points``, and the deleter: missed scans (``UpdateTimeStepsDeleter``) or "cov"."""

    name: str
    hypothesiser: str
    min_points: int
    deleter: int | str


SETTINGS = (
    Setting("pda-2-del3", "pda", 2, 3),
    Setting("pda-2-del5", "pda", 2, 5),
    Setting("pda-2-del10", "pda", 2, 10),
    Setting("pda-3-del5", "pda", 3, 5),
    Setting("pda-2-cov", "pda", 2, "cov"),
    Setting("dist-2-del5", "distance", 2, 5),
)

#: the table's columns: (key in score's dict, heading, better is lower)
COLUMNS = (
    ("tracks_per_object", "tracks per object", True),
    ("breaks", "breaks", True),
    ("id_switches", "ID switches", True),
    ("id_switches_resolvable", "resolvable ID switches", True),
    ("idf1", "IDF1", False),
    ("mota", "MOTA", False),
    ("false_tracks", "false tracks", True),
    ("false_track_scans", "false track-scans", True),
    ("completeness", "completeness", False),
    ("gospa", "GOSPA (m)", True),
    ("gospa_switching", "GOSPA with switching (m)", True),
    ("ms_per_scan", "ms per scan", True),
    ("cpu_ms_per_scan", "CPU ms per scan", True),
)


# --- the plots and trackkit's tracks ------------------------------------------------------------


def run_trackkit(file: str, seed: int, max_scans: int | None
                 ) -> tuple[TrackingResult, tuple[float, float]]:
    """``trackkit track FILE --as-radar --seed SEED [--max-scans N]``, and the wall and CPU
    time per scan of its scan loop (ms). A warm-up run of 3 scans comes first, so that the
    compiled IMM kernels (``filters.imm_fast``: compiled on first use, or loaded from numba's
    cache) are ready before the measured loop."""
    track_recording(file, TrackOptions(as_radar=True, seed=seed, max_scans=3))
    marks: dict[str, float] = {}

    def progress(stage: str, done: float, total: float) -> None:
        if stage == "tracking":
            marks.setdefault("start", time.perf_counter())
            marks.setdefault("cpu_start", time.process_time())
            if done == total:
                marks["end"], marks["cpu_end"] = time.perf_counter(), time.process_time()

    result = track_recording(file, TrackOptions(as_radar=True, seed=seed, max_scans=max_scans),
                             progress=progress)
    n = len(result.scans)
    return result, (1e3 * (marks["end"] - marks["start"]) / n,
                    1e3 * (marks["cpu_end"] - marks["cpu_start"]) / n)


# --- the same plots for Stone Soup --------------------------------------------------------------


def measurement_model(sensor: Any) -> Any:
    """Stone Soup's model of a trackkit ``RangeBearing`` radar (state ``[x, vx, y, vy]``)."""
    from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
    from stonesoup.types.array import CovarianceMatrix, StateVector

    x0, y0 = (float(v) for v in sensor.origin)
    return CartesianToBearingRange(
        ndim_state=4, mapping=(0, 2),
        noise_covar=CovarianceMatrix(np.diag([sensor.sigma_bearing**2, sensor.sigma_range**2])),
        translation_offset=StateVector([x0, y0]))


def to_stonesoup(z: NDArray[np.float64]) -> NDArray[np.float64]:
    """trackkit plots ``(N, 2)`` of [range, nautical bearing (clockwise from north)] as Stone
    Soup measurements [bearing counter-clockwise from east, range] (bearing in (-pi, pi])."""
    b = np.pi / 2 - z[:, 1]
    return np.stack([np.arctan2(np.sin(b), np.cos(b)), z[:, 0]], axis=-1)


def stonesoup_scans(scans: Any, model: Any) -> list[tuple[datetime, set]]:
    """Every scan as ``(time, set of Detection)``, the detector Stone Soup's tracker reads."""
    from stonesoup.types.angle import Bearing
    from stonesoup.types.array import StateVector
    from stonesoup.types.detection import Detection

    out = []
    for s in range(len(scans)):
        t = T0 + timedelta(seconds=float(scans.times[s]))
        z = to_stonesoup(scans.z[scans.offsets[s]:scans.offsets[s + 1]])
        out.append((t, {Detection(StateVector([Bearing(b), r]), timestamp=t,
                                  measurement_model=model) for b, r in z.tolist()}))
    return out


# --- Stone Soup's tracker -----------------------------------------------------------------------


# Stone Soup's one constant-velocity model must cover quiet and manoeuvring motion alike: it
# takes SINGLE_MODEL_Q, not the quiet mode's q of trackkit's IMM (with which one model would
# lose every manoeuvre)


def stonesoup_tracker(setting: Setting, result: TrackingResult, detector: list) -> Any:
    """The ``MultiTargetTracker`` of ``setting`` with the run's radar and tracker numbers."""
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.deleter.error import CovarianceBasedDeleter
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import ExtendedKalmanPredictor
    from stonesoup.tracker.simple import MultiTargetTracker
    from stonesoup.types.array import CovarianceMatrix, StateVector
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import ExtendedKalmanUpdater

    s = result.recording.settings
    model = measurement_model(result.sensor)
    cv = ConstantVelocity(SINGLE_MODEL_Q.get(result.recording.kind, s.q))
    predictor = ExtendedKalmanPredictor(CombinedLinearGaussianTransitionModel([cv, cv]))
    updater = ExtendedKalmanUpdater(model)
    if setting.hypothesiser == "pda":
        density = max(s.clutter, 0.1) / ((s.max_range - s.min_range) * 2 * math.pi)
        hyp = PDAHypothesiser(predictor, updater, clutter_spatial_density=density,
                              prob_detect=s.pd, prob_gate=GATE_PROBABILITY)
    else:
        hyp = DistanceHypothesiser(predictor, updater, measure=Mahalanobis(),
                                   missed_distance=math.sqrt(chi2.ppf(GATE_PROBABILITY, 2)))
    associator = GNNWith2DAssignment(hyp)
    prior = GaussianState(StateVector([0.0, 0.0, 0.0, 0.0]),
                          CovarianceMatrix(np.diag([0.0, s.v_std**2, 0.0, s.v_std**2])))
    initiator = MultiMeasurementInitiator(
        prior_state=prior, measurement_model=model, deleter=UpdateTimeStepsDeleter(2),
        data_associator=associator, updater=updater, min_points=setting.min_points)
    deleter = (CovarianceBasedDeleter(covar_trace_thresh=s.gospa_c**2, mapping=[0, 2])
               if setting.deleter == "cov" else UpdateTimeStepsDeleter(setting.deleter))
    return MultiTargetTracker(initiator=initiator, deleter=deleter, detector=detector,
                              data_associator=associator, updater=updater)


def run_stonesoup(setting: Setting, result: TrackingResult
                  ) -> tuple[Frames, tuple[float, float]]:
    """Stone Soup's confirmed tracks at every scan of ``result``'s plots (positions, ids), and
    its wall and CPU time per scan (ms)."""
    detector = stonesoup_scans(result.scans, measurement_model(result.sensor))
    tracker = iter(stonesoup_tracker(setting, result, detector))
    # keyed by Stone Soup's own track ID (a UUID): Python's id() of a deleted track may be
    # reused by a new one, and keeping every track alive would hold all their states
    ids: dict[str, int] = {}
    sizes, rows, spent, cpu = [], [], 0.0, 0.0
    for _ in range(len(detector)):
        t0, c0 = time.perf_counter(), time.process_time()
        _, tracks = next(tracker)
        spent += time.perf_counter() - t0
        cpu += time.process_time() - c0
        sizes.append(len(tracks))
        for tr in tracks:
            sv = tr.state_vector
            rows.append((ids.setdefault(tr.id, len(ids)), float(sv[0, 0]), float(sv[2, 0])))
    arr = np.array(rows, dtype=float).reshape(-1, 3)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    n = len(detector)
    return (Frames(offsets, arr[:, 1:], arr[:, 0].astype(np.int64)),
            (1e3 * spent / n, 1e3 * cpu / n))


# --- one scoring function for both --------------------------------------------------------------


def score(confirmed: Frames, truth: Frames, site: tuple[float, float], sigma_bearing: float,
          c: float) -> dict[str, float]:
    """The figures of one run's confirmed tracks against the truth, with trackkit's metric
    code as ``trackkit track`` reports them (``eval.clear_mot.score_run``: cut-off, CLEAR-MOT
    threshold and switching penalty c, order 2; ID switches between objects the radar at
    ``site`` with bearing noise ``sigma_bearing`` rad resolves)."""
    return {k: float(v) for k, v in score_run(confirmed, truth, site, sigma_bearing, c).items()}


# --- what went wrong where ----------------------------------------------------------------------


def _unassigned_kinds(truth: Frames, tracks: Frames, I: NDArray, J: NDArray, c: float
                      ) -> dict[str, int]:
    """The confirmed track-scans matched to no object: near (< c) an object another track
    holds (duplicate), after the object the track last held left the truth (coasting), or
    elsewhere (clutter)."""
    S = truth.n_steps
    ys = np.repeat(np.arange(S), tracks.sizes)
    xs = np.repeat(np.arange(S), truth.sizes)
    held = np.full(tracks.x.shape[0], -1, np.int64)
    held[J] = truth.ids[I]
    last: dict[int, int] = {}  # track id -> truth id it held last
    present = {s: set(truth.ids[truth.offsets[s]:truth.offsets[s + 1]].tolist())
               for s in range(S)}
    kinds = {"duplicate": 0, "coasting": 0, "clutter": 0}
    for r in np.argsort(ys, kind="stable").tolist():
        tid, s = int(tracks.ids[r]), int(ys[r])
        if held[r] >= 0:
            last[tid] = int(held[r])
            continue
        if tid in last and last[tid] not in present[s]:
            kinds["coasting"] += 1
            continue
        d = np.hypot(*(truth.x[xs == s] - tracks.x[r]).T) if present[s] else np.array([])
        kinds["duplicate" if d.size and d.min() < c else "clutter"] += 1
    return kinds


def _break_kinds(truth: Frames, tracks: Frames, I: NDArray, J: NDArray,
                 times: NDArray) -> dict[str, int]:
    """The breaks (an object's track changing while the previous track is gone) and, of
    them, those where the object was out of the truth since its last assigned scan (a gap
    in its reports longer than the radar bridges, or out of range: no plots), those on a
    still object (moving under
    ``STILL_M_S``), on a turn (heading change above ``TURN_DEG`` over the ``TURN_WINDOW_S``
    before) and beside another object (within ``NEAR_M``)."""
    S = truth.n_steps
    xs = np.repeat(np.arange(S), truth.sizes)
    ys = np.repeat(np.arange(S), tracks.sizes)
    track_last = dict(zip(tracks.ids.tolist(), ys.tolist(), strict=True))  # the last wins
    pos = {(o, s): truth.x[i] for i, (o, s) in enumerate(zip(truth.ids.tolist(), xs.tolist(),
                                                              strict=True))}
    lag = max(int(round(TURN_WINDOW_S / np.median(np.diff(times)))), 2) if S > 1 else 2
    out = {"breaks": 0, "breaks_unseen": 0, "breaks_still": 0, "breaks_turning": 0,
           "breaks_near": 0}
    prev_obj, prev_track, prev_s = -1, -1, -1
    for k in np.lexsort((xs[I], truth.ids[I])).tolist():
        obj, s, tid = int(truth.ids[I[k]]), int(xs[I[k]]), int(tracks.ids[J[k]])
        if obj == prev_obj and tid != prev_track and track_last[prev_track] < s:
            out["breaks"] += 1
            out["breaks_unseen"] += any((obj, k) not in pos for k in range(prev_s + 1, s))
            before = pos.get((obj, s - lag))  # unknown (not still) if it was unseen then
            out["breaks_still"] += bool(before is not None and np.hypot(
                *(pos[(obj, s)] - before)) < STILL_M_S * (times[s] - times[s - lag]))
            out["breaks_turning"] += _turning(pos, obj, s, lag)
            others = truth.x[truth.offsets[s]:truth.offsets[s + 1]]
            d = np.sort(np.hypot(*(others - pos[(obj, s)]).T))
            out["breaks_near"] += bool(d.size > 1 and d[1] < NEAR_M)
        prev_obj, prev_track, prev_s = obj, tid, s
    return out


def _turning(pos: dict, obj: int, s: int, lag: int) -> bool:
    """Whether the object's heading changed by more than ``TURN_DEG`` between the first and
    second halves of the ``lag`` scans before ``s`` (a still object has no heading)."""
    a, m, b = (pos.get((obj, k)) for k in (s - lag, s - lag // 2, s))
    if a is None or m is None or b is None:
        return False
    if np.hypot(*(m - a)) < 1.0 or np.hypot(*(b - m)) < 1.0:
        return False
    h1, h2 = (math.atan2(*(q - p)[::-1]) for p, q in ((a, m), (m, b)))
    return abs(math.degrees(math.remainder(h2 - h1, 2 * math.pi))) > TURN_DEG


def _near_switches(truth: Frames, tracks: Frames, c: float) -> dict[str, int]:
    """The CLEAR-MOT ID switches (``clear_mot``, threshold c: an object matched to another
    track than its last, as the score table counts them) and, of them, those where another
    object is within ``NEAR_M`` of the switching one at the switch: vessels moored or moving
    together, which a radar cannot tell apart far out."""
    cm = clear_mot(truth, tracks, c)
    near = 0
    for s, obj in zip(cm.switch_step.tolist(), cm.switch_truth.tolist(), strict=True):
        here = slice(int(truth.offsets[s]), int(truth.offsets[s + 1]))
        ids, x = truth.ids[here], truth.x[here, :2]
        d = np.hypot(*(x[ids != obj] - x[ids == obj][0]).T)
        near += bool(d.size and d.min() < NEAR_M)
    return {"id_switches": int(cm.switch_step.size), "id_switches_near": near}


def diagnose(confirmed: Frames, truth: Frames, times: NDArray[np.float64], c: float
             ) -> dict[str, int]:
    """Where a tracker went wrong: its unmatched track-scans by kind, and its breaks by
    where they happened."""
    I, J = assign(truth, confirmed, c, 2.0)
    return {**_unassigned_kinds(truth, confirmed, I, J, c),
            **_break_kinds(truth, confirmed, I, J, times),
            **_near_switches(truth, confirmed, c)}


# --- the table ----------------------------------------------------------------------------------


def _fmt(key: str, v: float) -> str:
    if math.isnan(v):
        return "-"  # not measured (a run saved before CPU time was), or no denominator
    if key in ("breaks", "id_switches", "id_switches_resolvable", "false_tracks",
               "false_track_scans"):
        return f"{int(v)}"
    if key in ("mean_purity", "completeness", "idf1", "mota"):
        return f"{v:.3f}"
    return f"{v:.1f}" if "ms_per_scan" not in key or v >= 10 else f"{v:.2f}"


def _ratio(r: dict[str, float], ours: dict[str, float]) -> str:
    """Wall and CPU time per scan of ``r`` over trackkit's."""
    wall, cpu = (r[k] / ours[k] for k in ("ms_per_scan", "cpu_ms_per_scan"))
    return ", ".join("-" if math.isnan(v) else f"{v:.0f}x" for v in (wall, cpu))


def best_of(rows: dict[str, dict[str, float]]) -> dict[str, tuple[float, str]]:
    """Per metric, Stone Soup's best value over the settings and the setting that gave it."""
    best = {}
    for key, _, lower in COLUMNS:
        known = [n for n in rows if not math.isnan(rows[n][key])] or list(rows)
        name = (min if lower else max)(known, key=lambda n: rows[n][key])
        best[key] = (rows[name][key], name)
    return best


def table(title: str, ours: dict[str, float], theirs: dict[str, dict[str, float]]) -> str:
    """The markdown table of one file: trackkit, every Stone Soup setting, Stone Soup at its
    best (per metric, with the setting), and the speed ratio Stone Soup / trackkit."""
    head = ("| tracker, setting | " + " | ".join(h for _, h, _ in COLUMNS)
            + " | speed ratio (wall, CPU) |")
    lines = [f"### {title}", "", head, "|---" * (len(COLUMNS) + 2) + "|"]

    def row(name: str, r: dict[str, float]) -> str:
        cells = [_fmt(k, r[k]) for k, _, _ in COLUMNS]
        return f"| {name} | " + " | ".join(cells) + f" | {_ratio(r, ours)} |"

    lines.append(row("trackkit", ours).replace(f" | {_ratio(ours, ours)} |", " | 1 |"))
    for name, r in theirs.items():
        lines.append(row(f"Stone Soup {name}", r))
    if not theirs:
        return "\n".join(lines)
    best = best_of(theirs)
    cells = [f"{_fmt(k, best[k][0])} ({best[k][1]})" for k, _, _ in COLUMNS]
    fastest = {k: best[k][0] for k in ("ms_per_scan", "cpu_ms_per_scan")}
    lines.append("| **Stone Soup at its best** | " + " | ".join(cells)
                 + f" | {_ratio(fastest, ours)} |")
    return "\n".join(lines)


def diagnosis_table(title: str, diags: dict[str, dict[str, int]]) -> str:
    """Unmatched confirmed track-scans by kind, breaks by where they happened and the
    CLEAR-MOT ID switches beside another object, per tracker."""
    lines = [f"#### {title}: where the tracks went wrong", "",
             "| tracker, setting | duplicate track-scans | coasting track-scans "
             "| clutter track-scans | breaks | after the object was unseen | on a still "
             "object | on a turn | beside another object | ID switches (CLEAR-MOT) | with "
             "another object within 100 m |", "|---" * 11 + "|"]
    keys = ("duplicate", "coasting", "clutter", "breaks", "breaks_unseen", "breaks_still",
            "breaks_turning", "breaks_near", "id_switches", "id_switches_near")
    for name, d in diags.items():
        lines.append(f"| {name} | " + " | ".join(str(d[k]) for k in keys) + " |")
    return "\n".join(lines)


# --- main ---------------------------------------------------------------------------------------


def compare(file: str, settings: Sequence[Setting], seed: int, max_scans: int | None,
            log: Any = print, save_to: Path | None = None) -> dict[str, Any]:
    """trackkit and every Stone Soup setting on one file's plots: the truth, each tracker's
    confirmed tracks (``Frames``) and its ms per scan, and what the run was (saved to
    ``save_to`` after each tracker, so that a long run stopped keeps what it has done)."""
    result, ms = run_trackkit(file, seed, max_scans)
    times = result.history.times
    log(f"{file}: {len(times)} scans, {result.plots} plots, trackkit {ms[0]:.2f} ms/scan "
        f"({ms[1]:.2f} CPU)")
    run = {"file": file, "scans": len(times), "plots": result.plots, "seed": seed,
           "plots_sha256": hashlib.sha256(result.scans.z.tobytes()).hexdigest(),
           "cutoff_m": float(result.recording.settings.gospa_c), "times": times,
           "site": [float(v) for v in result.site],
           "sigma_bearing": float(result.sensor.sigma_bearing),
           "truth": result.truth, "tracks": {"trackkit": (result.history.confirmed(), ms)}}
    if save_to is not None:
        save(run, save_to)
    for st in settings:
        run["tracks"][st.name] = run_stonesoup(st, result)
        wall, cpu = run["tracks"][st.name][1]
        log(f"  Stone Soup {st.name}: {wall:.1f} ms/scan ({cpu:.1f} CPU)")
        if save_to is not None:
            save(run, save_to)
    return run


def evaluate(run: dict[str, Any]) -> dict[str, Any]:
    """Every tracker of a ``compare`` run scored and diagnosed by the same functions."""
    c, times, truth = run["cutoff_m"], run["times"], run["truth"]
    scores, diags = {}, {}
    for name, (frames, (wall, cpu)) in run["tracks"].items():
        scores[name] = {**score(frames, truth, tuple(run["site"]), run["sigma_bearing"], c),
                        "ms_per_scan": wall,
                        "cpu_ms_per_scan": cpu}
        label = name if name == "trackkit" else f"Stone Soup {name}"
        diags[label] = diagnose(frames, truth, times, c)
    return {"scores": scores, "diagnosis": diags}


def save(run: dict[str, Any], path: Path) -> None:
    """A ``compare`` run as one .npz (arrays) and its .json (the rest), for ``load``."""
    arrays = {"times": run["times"],
              **{f"truth_{k}": v for k, v in run["truth"]._asdict().items()}}
    for n, (f, _) in enumerate(run["tracks"].values()):
        arrays.update({f"tracks{n}_{k}": v for k, v in f._asdict().items()})
    np.savez_compressed(path.with_suffix(".npz"), **arrays)
    meta = {k: run[k] for k in ("file", "scans", "plots", "seed", "plots_sha256", "cutoff_m",
                                "site", "sigma_bearing")}
    meta["ms_per_scan"] = {name: ms for name, (_, ms) in run["tracks"].items()}
    path.with_suffix(".json").write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")


def load(path: Path) -> dict[str, Any]:
    """A run written by ``save``."""
    meta = json.loads(path.with_suffix(".json").read_text(encoding="utf-8"))
    a = np.load(path.with_suffix(".npz"))

    def frames(prefix: str) -> Frames:
        return Frames(a[f"{prefix}_offsets"], a[f"{prefix}_x"], a[f"{prefix}_ids"])

    tracks = {name: (frames(f"tracks{n}"), tuple(ms))
              for n, (name, ms) in enumerate(meta.pop("ms_per_scan").items())}
    return {**meta, "times": a["times"], "truth": frames("truth"), "tracks": tracks}


def merge(runs: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Saved runs of the same plots (Stone Soup's settings run in separate processes, or
    trackkit run again) as one run, in the order of ``SETTINGS``; trackkit's from the
    first. Runs of different plots (another seed, length, or radar code) stay apart."""
    merged: dict[tuple, dict[str, Any]] = {}
    for run in runs:
        key = (Path(run["file"]).name, run["seed"], run["scans"], run.get("plots_sha256"))
        same = [k for k in merged if k[:3] == key[:3] and None in (k[3], key[3])]
        key = same[0] if same else key  # a run saved without the hash: the same plots
        if key not in merged:
            merged[key] = run
            continue
        for name, tracks in run["tracks"].items():
            merged[key]["tracks"].setdefault(name, tracks)
    order = ["trackkit"] + [st.name for st in SETTINGS]
    for run in merged.values():
        run["tracks"] = {n: run["tracks"][n] for n in order if n in run["tracks"]}
    return list(merged.values())


def render(run: dict[str, Any], ev: dict[str, Any]) -> str:
    """The markdown of one file's comparison."""
    ours = ev["scores"]["trackkit"]
    theirs = {k: v for k, v in ev["scores"].items() if k != "trackkit"}
    title = (f"{Path(run['file']).name}: {run['scans']} scans, {run['plots']} plots, "
             f"{int(ours['objects'])} objects, seed {run['seed']}, GOSPA cut-off "
             f"{run['cutoff_m']:g} m")
    diagnosis = diagnosis_table(Path(run["file"]).name, ev["diagnosis"])
    return table(title, ours, theirs) + "\n\n" + diagnosis


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="+", help="AIS or OpenSky files, or bundled sample names; "
                    "with --rescore, runs saved by --save (their .json)")
    ap.add_argument("--seed", type=int, default=0, help="the virtual radar's seed")
    ap.add_argument("--max-scans", type=int, default=None, help="only the first N scans")
    ap.add_argument("--settings", nargs="*", default=[s.name for s in SETTINGS],
                    choices=[s.name for s in SETTINGS], help="Stone Soup settings to run")
    ap.add_argument("--save", type=Path, default=None,
                    help="write each run's tracks to this folder (FILE-STEM.npz and .json)")
    ap.add_argument("--rescore", action="store_true",
                    help="score runs saved by --save again, without tracking")
    args = ap.parse_args(argv)
    chosen = [s for s in SETTINGS if s.name in args.settings]
    if args.rescore:
        for run in merge([load(Path(f)) for f in args.files]):
            print("\n" + render(run, evaluate(run)) + "\n", flush=True)
        return
    for file in args.files:
        if args.save is not None:
            args.save.mkdir(parents=True, exist_ok=True)
        run = compare(file, chosen, args.seed, args.max_scans,
                      log=lambda m: print(m, flush=True),
                      save_to=None if args.save is None else args.save / Path(file).stem)
        print("\n" + render(run, evaluate(run)) + "\n", flush=True)


if __name__ == "__main__":
    main()
