"""The multi-target trackers on the bundled scenes, run as `trackkit run` runs them
(the bundled files, 100 runs each at their seed).

radar-clutter: 10 aircraft (two 90 degree turns, three that leave early), a range-bearing
surveillance radar with pd = 0.9 and 20 false plots per scan; 100 runs x 101 scans, so "at
least 95% confirmed within 5 scans" is judged on 1 000 births (a true rate of 0.93 would pass
with probability below 1%: binomial, one-sided) and "below 1 false confirmed track per 100
scans" on 10 100 scans (a true rate of 1.3 per 100 scans would pass with probability below
1%: Poisson, one-sided).

radar-crossing: three craft that cross and then run 180 m apart; GNN against JPDA by mean
GOSPA (c = 500 m, p = 2), 100 runs.
"""

from __future__ import annotations

import pytest

from trackkit.experiments.tracking_run import run_multitarget
from trackkit.scenario.multitarget import load_multitarget

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def clutter():
    result, _ = run_multitarget(load_multitarget("radar-clutter"))
    return result


@pytest.fixture(scope="module")
def crossing():
    result, _ = run_multitarget(load_multitarget("radar-crossing"))
    return result


def test_radar_clutter_gnn_confirms_95_percent_within_5_scans(clutter):
    summary = clutter.trackers["GNN"].summary
    assert summary["truths"] == 1000
    assert summary["confirmed_within_fraction"] >= 0.95, summary


@pytest.mark.xfail(strict=True, reason=(
    "JPDA confirms 93.8% of the aircraft within 5 scans of birth on radar-clutter (100 "
    "runs; GNN 96.4%): its hits are weighed by association probabilities, so a track in "
    "clutter reaches the score threshold a little later"))
def test_radar_clutter_jpda_confirms_95_percent_within_5_scans(clutter):
    summary = clutter.trackers["JPDA"].summary
    assert summary["confirmed_within_fraction"] >= 0.95, summary


@pytest.mark.parametrize("name", ["GNN", "JPDA"])
def test_radar_clutter_false_tracks_below_1_per_100_scans(clutter, name):
    summary = clutter.trackers[name].summary
    scans = clutter.runs * clutter.times.size
    assert scans == 100 * 101
    assert 100 * summary["false_tracks"] / scans < 1.0, summary


def test_radar_crossing_both_trackers_hold_all_three_targets(crossing):
    for name, r in crossing.trackers.items():
        assert r.summary["confirmed_fraction"] == 1.0, name
        assert r.summary["completeness"] > 0.8, (name, r.summary["completeness"])


@pytest.mark.xfail(strict=True, reason=(
    "JPDA's mean GOSPA is above GNN's on radar-crossing (117.5 against 108.5 m, 100 runs): "
    "while the craft run 180 m apart (2-4 cross-range sigmas) the JPDA means coalesce and its "
    "tracks swap more often; JPDA* (113.0 m) closes half the gap, not all of it. The premise "
    "does not hold for craft this close: GNN's GOSPA is lower at pd 0.7 and 0.9 with 20-100 "
    "false plots per scan (7-25%), and with exact enumeration of every cluster (118.4 m); "
    "see the scene's notes"))
def test_radar_crossing_jpda_no_worse_than_gnn(crossing):
    assert crossing.trackers["JPDA"].mean_gospa <= crossing.trackers["GNN"].mean_gospa


def test_radar_crossing_jpda_star_coalesces_less_than_jpda(crossing):
    # JPDA* prunes the joint events a swap would make more likely: fewer ID switches (184
    # against 237 measured) and a lower mean GOSPA (113.0 against 117.5 m) than JPDA
    star, plain = crossing.trackers["JPDA*"], crossing.trackers["JPDA"]
    assert star.summary["id_switches"] < plain.summary["id_switches"]
    assert star.mean_gospa < plain.mean_gospa
