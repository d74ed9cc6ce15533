"""The Stone Soup comparison of benchmarks/bench_recorded_stonesoup.py hands Stone Soup the
virtual radar's plots as measurements of the same points: Stone Soup's [bearing
counter-clockwise from east, range] against trackkit's [range, bearing clockwise from north],
at the radar's site, with the radar's noise."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2
from stonesoup.types.angle import Bearing
from stonesoup.types.array import StateVector
from stonesoup.types.detection import Detection
from stonesoup.types.state import State

from trackkit.eval.track_metrics import Frames
from trackkit.io import read_ais_csv, samples
from trackkit.sim.virtual_radar import VirtualRadar, virtual_radar

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_recorded_stonesoup.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_recorded_stonesoup", BENCH)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # the dataclasses look their module up
    spec.loader.exec_module(module)
    return module


bench = _bench()
SITE = (1500.0, -800.0)  # off the frame's origin, so the model's translation is exercised


def _radar_run(scans: int = 6, seed: int = 3):
    reports, _ = read_ais_csv(samples.path("solent-ais"))
    radar = VirtualRadar(site=SITE, period=3.0, sigma_range=20.0,
                         sigma_bearing=math.radians(0.5), pd=0.9, clutter=10.0,
                         max_range=40e3, min_range=50.0)
    return virtual_radar(reports, radar, seed, max_scans=scans)


def test_north_and_east_are_stonesoups_pi_over_2_and_0_and_range_comes_second():
    z = np.array([[1000.0, 0.0], [2000.0, math.pi / 2], [3000.0, math.pi], [4000.0, -3.0]])
    got = bench.to_stonesoup(z)
    assert np.allclose(got[:, 1], z[:, 0], rtol=0, atol=0)
    want = np.array([math.pi / 2, 0.0, -math.pi / 2, math.pi / 2 + 3.0 - 2 * math.pi])
    assert np.allclose(got[:, 0], want, rtol=0, atol=1e-15)


def test_stonesoups_model_of_an_object_is_trackkits_plot_converted():
    run = _radar_run()
    model = bench.measurement_model(run.sensor)
    assert np.allclose(model.covar(), np.diag([math.radians(0.5) ** 2, 20.0**2]), rtol=1e-15)
    p = run.truth.x
    state = np.zeros((p.shape[0], 4))
    state[:, :2] = p
    ours = bench.to_stonesoup(run.sensor.h(state))
    for k in range(p.shape[0]):
        theirs = model.function(State(StateVector([p[k, 0], 0.0, p[k, 1], 0.0])))
        assert math.isclose(float(theirs[1, 0]), ours[k, 1], rel_tol=1e-12)
        assert abs(math.remainder(float(theirs[0, 0]) - ours[k, 0], 2 * math.pi)) < 1e-12


def test_a_plot_inverted_by_stonesoups_model_lands_on_its_object_within_noise():
    run = _radar_run(scans=12)
    model = bench.measurement_model(run.sensor)
    scan_of = np.repeat(np.arange(len(run.scans)), np.diff(run.scans.offsets))
    z = bench.to_stonesoup(run.scans.z)
    d2 = []
    for i in np.flatnonzero(run.origin >= 0):
        s = scan_of[i]
        rows = slice(run.truth.offsets[s], run.truth.offsets[s + 1])
        truth = run.truth.x[rows][run.truth.ids[rows] == run.origin[i]][0]
        det = Detection(StateVector([Bearing(z[i, 0]), z[i, 1]]), measurement_model=model)
        x = model.inverse_function(det)
        err = np.array([float(x[0, 0]), float(x[2, 0])]) - truth
        # along-range and cross-range parts of the error, in units of their sigmas
        u = (truth - SITE) / np.hypot(*(truth - SITE))
        r = np.hypot(*(truth - SITE))
        along, across = err @ u, err @ np.array([-u[1], u[0]])
        d2.append((along / 20.0) ** 2 + (across / (r * math.radians(0.5))) ** 2)
    d2 = np.array(d2)
    assert d2.size > 200
    # chi-square with 2 degrees of freedom: no plot beyond its 1 - 1e-6 quantile, and the
    # mean within 4 standard errors (2 / sqrt(n)) of 2; a swapped axis, a bearing off by a
    # quarter turn or a missing site offset puts plots kilometres off
    assert d2.max() < chi2.ppf(1 - 1e-6, 2)
    assert abs(d2.mean() - 2.0) < 4 * 2.0 / math.sqrt(d2.size)


def test_every_plot_of_a_scan_becomes_one_detection_at_the_scans_time():
    run = _radar_run(scans=4)
    model = bench.measurement_model(run.sensor)
    scans = bench.stonesoup_scans(run.scans, model)
    assert [len(d) for _, d in scans] == np.diff(run.scans.offsets).tolist()
    for (t, dets), t_scan in zip(scans, run.scans.times, strict=True):
        assert (t - bench.T0).total_seconds() == t_scan
        assert all(d.timestamp == t and d.measurement_model is model for d in dets)


def test_the_truth_scored_as_tracks_is_one_clean_track_per_object():
    run = _radar_run(scans=6)
    s = bench.score(run.truth, run.truth, (0.0, 0.0), run.sensor.sigma_bearing, 500.0)
    assert s["gospa"] == s["gospa_switching"] == 0.0 and s["tracks_per_object"] == 1.0
    assert (s["breaks"], s["id_switches"], s["false_tracks"]) == (0, 0, 0)
    assert s["idf1"] == s["mota"] == 1.0
    d = bench.diagnose(run.truth, run.truth, run.scans.times, 500.0)
    assert set(d) >= {"duplicate", "coasting", "clutter", "breaks", "breaks_turning"}
    assert not any(d.values()), d


def _frames(rows: list[tuple[int, int, float, float]], steps: int):
    """Frames from (step, id, x, y) rows."""
    rows = sorted(rows)
    step = np.array([r[0] for r in rows])
    offsets = np.searchsorted(step, np.arange(steps + 1)).astype(np.int64)
    x = np.array([[r[2], r[3]] for r in rows])
    return Frames(offsets, x, np.array([r[1] for r in rows], np.int64))


def test_diagnose_tells_a_duplicate_a_coasting_track_clutter_and_a_break_apart():
    steps, times = 10, 3.0 * np.arange(10)
    truth = _frames([(s, 0, 100.0 * s, 0.0) for s in range(steps)]
                    + [(s, 1, 5000.0, 0.0) for s in range(8)], steps)  # object 1 ends at 7
    tracks = _frames(
        [(s, 10, 100.0 * s, 5.0) for s in range(4)]  # object 0, lost at scan 4 ...
        + [(s, 11, 100.0 * s, -5.0) for s in range(5, steps)]  # ... and a new track: a break
        + [(s, 12, 5030.0, 0.0) for s in range(steps)]  # object 1, coasting at 8 and 9
        + [(s, 13, 5060.0, 0.0) for s in (2, 3, 4)]  # a second track on object 1
        + [(s, 14, 20e3, 20e3) for s in (0, 1)], steps)  # far from everything
    d = bench.diagnose(tracks, truth, times, 500.0)
    # CLEAR-MOT counts the break as an ID switch too (object 0 matched to another track)
    assert d == {"duplicate": 3, "coasting": 2, "clutter": 2, "breaks": 1,
                 "breaks_unseen": 0, "breaks_still": 0, "breaks_turning": 0,
                 "breaks_near": 0, "id_switches": 1, "id_switches_near": 0}


def test_diagnose_counts_the_clear_mot_switches_and_those_beside_another_object():
    steps, times = 6, 3.0 * np.arange(6)
    # objects 0 and 1 are 30 m apart, 2 and 3 a kilometre; object 0's track is lost at scan 3
    # and a new one takes it on (a switch beside object 1), the tracks of 2 and 3 swap
    where = {0: (0.0, 0.0), 1: (30.0, 0.0), 2: (0.0, 5000.0), 3: (1000.0, 5000.0)}
    truth = _frames([(s, o, *xy) for s in range(steps) for o, xy in where.items()], steps)
    held = {10: (0, None), 14: (None, 0), 11: (1, 1), 12: (2, 3), 13: (3, 2)}
    tracks = _frames([(s, t, *where[pair[s >= 3]]) for s in range(steps)
                      for t, pair in held.items() if pair[s >= 3] is not None], steps)
    d = bench.diagnose(tracks, truth, times, 500.0)
    assert (d["id_switches"], d["id_switches_near"], d["breaks"], d["breaks_near"]) == (
        3, 1, 1, 1)
    # the score table's ID switches are the same CLEAR-MOT switches
    assert d["id_switches"] == bench.score(tracks, truth, (0.0, 0.0), 0.01, 500.0)[
        "id_switches"]


def test_both_trackers_run_on_the_same_plots_and_are_scored_alike():
    run = bench.compare("solent-ais", [bench.SETTINGS[0]], seed=0, max_scans=12,
                        log=lambda message: None)
    assert list(run["tracks"]) == ["trackkit", "pda-2-del3"]
    ss, (wall, cpu) = run["tracks"]["pda-2-del3"]
    assert ss.n_steps == run["truth"].n_steps == 12 and wall > 0 and cpu > 0
    # a confirmed Stone Soup track is present at every scan from confirmation to deletion
    steps = np.repeat(np.arange(ss.n_steps), ss.sizes)
    for tid in np.unique(ss.ids):
        at = steps[ss.ids == tid]
        assert np.array_equal(at, np.arange(at[0], at[-1] + 1)), tid
    scores = bench.evaluate(run)["scores"]
    for name in ("trackkit", "pda-2-del3"):
        assert scores[name]["completeness"] > 0.5, (name, scores[name])
