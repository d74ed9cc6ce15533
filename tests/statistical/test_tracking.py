"""The multi-target tracker on the issue's scenes, with fixed seeds (issue 11, item 2).

radar-clutter: 10 aircraft (two 90 degree turns, three that leave early), a range-bearing
surveillance radar with pd = 0.9 and 20 false plots per scan. 20 runs x 101 scans: 200 true
targets and 2 020 scans, so "at least 95% confirmed within 5 scans" is judged on 200 births
(a true rate of 0.90 would pass with probability below 1%: binomial, one-sided) and "below 1
false confirmed track per 100 scans" on 2 020 scans (a true rate of 2 per 100 scans would
pass with probability below 0.1%: Poisson, one-sided).

radar-crossing: three craft that cross and then run 180 m apart; GNN against JPDA by mean
GOSPA (c = 500 m, p = 2), 40 runs.
"""

from __future__ import annotations

import numpy as np
import pytest

import trackkit as tk
from trackkit.eval.multitarget import gospa_steps, track_counts, track_summary
from trackkit.sim.multitarget import radar_clutter, radar_crossing, simulate_scene
from trackkit.tracking import GNN, JPDA, ScoreLogic, SinglePoint, Tracker
from trackkit.tracking.history import run_tracker

pytestmark = pytest.mark.slow

C = 500.0  # metres: the GOSPA and assignment cut-off


def tracker(scene, associator, q: float) -> Tracker:
    """EKF, constant velocity, single-point initiation and the SPRT score logic with a 1%
    false-confirmation and 0.1% false-deletion probability (Wald), new targets expected at
    the scene's birth rate."""
    sensor, lam = scene.sensors[0], scene.clutter_density[0]
    logic = ScoreLogic.from_sprt(alpha=1e-2, beta=1e-3, pd=0.9, clutter_density=lam,
                                 new_target_density=4e-7)
    return Tracker(tk.filters.EKF(), tk.models.ConstantVelocity(dim=2, q=q), sensor, pd=0.9,
                   clutter_density=lam, associator=associator, logic=logic,
                   initiator=SinglePoint(v_std=100.0))


def evaluate(scene, associator, runs: int, seed: int, q: float):
    data = simulate_scene(scene, runs, seed)
    trk = tracker(scene, associator, q)
    counts, gospa, scans = [], [], 0
    for run in data:
        history, _ = run_tracker(trk, run.scans)
        period = float(np.diff(history.times).min())
        tracks = history.confirmed()
        counts.append(track_counts(run.truth_positions, tracks, C, times=history.times,
                                   within=5 * period))
        gospa.append(gospa_steps(run.truth_positions, tracks, C).distance)
        scans += history.times.size
    total = type(counts[0])(*(np.concatenate(f) for f in zip(*counts, strict=True)))
    return track_summary(total), float(np.mean(np.concatenate(gospa))), scans


@pytest.fixture(scope="module")
def clutter():
    scene = radar_clutter()
    return {name: evaluate(scene, a, runs=20, seed=2026, q=10.0)
            for name, a in (("GNN", GNN()), ("JPDA", JPDA()))}


@pytest.mark.parametrize("name", ["GNN", "JPDA"])
def test_radar_clutter_confirms_95_percent_within_5_scans(clutter, name):
    summary, _, _ = clutter[name]
    assert summary["truths"] == 200
    assert summary["confirmed_within_fraction"] >= 0.95, summary


@pytest.mark.parametrize("name", ["GNN", "JPDA"])
def test_radar_clutter_false_tracks_below_1_per_100_scans(clutter, name):
    summary, _, scans = clutter[name]
    assert scans == 20 * 101
    assert 100 * summary["false_tracks"] / scans < 1.0, summary


@pytest.fixture(scope="module")
def crossing():
    scene = radar_crossing()
    return {name: evaluate(scene, a, runs=40, seed=2027, q=1.0)
            for name, a in (("GNN", GNN()), ("JPDA", JPDA()))}


def test_radar_crossing_both_trackers_hold_all_three_targets(crossing):
    for name, (summary, _, _) in crossing.items():
        assert summary["confirmed_fraction"] == 1.0, name
        assert summary["completeness"] > 0.8, (name, summary["completeness"])


@pytest.mark.xfail(strict=True, reason=(
    "JPDA's mean GOSPA is above GNN's on radar-crossing (measured here: 114.0 against 107.1 "
    "m, 40 runs): while the craft run 180 m apart (2-4 cross-range sigmas) the JPDA means "
    "coalesce and its tracks swap more often (68 against 49 ID switches); completeness is "
    "equal (0.954). A coalescence-avoiding JPDA variant is left for later"))
def test_radar_crossing_jpda_no_worse_than_gnn(crossing):
    assert crossing["JPDA"][1] <= crossing["GNN"][1], (crossing["JPDA"][1],
                                                       crossing["GNN"][1])
