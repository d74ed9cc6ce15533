"""Identity-aware scores (trackkit.eval.clear_mot) against the implementations people use:

* CLEAR-MOT and the ID measures against py-motmetrics' ``MOTAccumulator`` fed the same
  Euclidean distances (nan at or beyond the threshold), on random scenes with births, deaths,
  crossings, missed steps, track breaks, track swaps and false tracks: totals (MOTA, MOTP,
  IDSW, transfers, fragmentations, IDTP, IDF1, IDP, IDR) and every step's events, to 1e-12;
* GOSPA with the switching penalty against Stone Soup's ``GOSPAMetric(switching_penalty=...)``
  on the same kind of scenes, every time step's distance and parts, to 1e-9 relative;
* the resolvable-switch rule on hand-computed cases and against a per-event loop;
* ``score_run`` against the functions it gathers, and the errors a caller can make.
"""

from __future__ import annotations

import datetime
import math

import numpy as np
import pytest

from trackkit.eval.clear_mot import (
    classify_switches,
    clear_mot,
    clear_mot_summary,
    gospa_switching,
    id_scores,
    mota_steps,
    score_run,
)
from trackkit.eval.track_metrics import Frames, assign, frames, gospa_steps

C = 2.0  # threshold (and GOSPA cut-off) of the random scenes


def scene(seed: int, steps: int = 30, objects: int = 9) -> tuple[Frames, Frames]:
    """Truth and tracks of a random scene in a 12 x 12 box: objects born and dying at random
    steps, moving straight (so that some cross); a track per object, with noise (now and then
    beyond the threshold), missed steps, new IDs (breaks), swaps of IDs between two objects
    and false tracks that live a few steps."""
    rng = np.random.default_rng(seed)
    birth = rng.integers(0, steps // 2, objects)
    death = np.minimum(birth + rng.integers(steps // 3, steps + 1, objects), steps)
    x0 = rng.uniform(0, 12, (objects, 2))
    v = rng.normal(0, 0.35, (objects, 2))
    label = np.arange(objects) + 100  # each object's current track ID
    fresh = iter(range(1000, 100000))
    false_ids = {}  # false track ID -> (position, steps left)
    tx, tid, yx, yid = [], [], [], []
    for k in range(steps):
        alive = np.flatnonzero((birth <= k) & (k < death))
        if alive.size > 1 and rng.random() < 0.25:  # swap two objects' track IDs
            a, b = rng.choice(alive, 2, replace=False)
            label[a], label[b] = label[b], label[a]
        for a in alive[rng.random(alive.size) < 0.06]:  # a break: a new track ID
            label[a] = next(fresh)
        pos = x0[alive] + v[alive] * k
        tx.append(pos)
        tid.append(alive + 7 * (alive % 3))  # IDs not in the objects' order of index
        seen = alive[rng.random(alive.size) < 0.85]
        noise = rng.normal(0, 0.5, (seen.size, 2)) * np.where(rng.random(seen.size) < 0.1,
                                                               5.0, 1.0)[:, None]
        pts, ids = [x0[seen] + v[seen] * k + noise], [label[seen]]
        for _ in range(rng.poisson(1.0)):
            false_ids[next(fresh)] = (rng.uniform(0, 12, 2), int(rng.integers(1, 5)))
        for f, (p, left) in list(false_ids.items()):
            pts.append(p[None] + rng.normal(0, 0.2, (1, 2)))
            ids.append(np.array([f]))
            false_ids[f] = (p, left - 1)
            if left <= 1:
                del false_ids[f]
        p, i = np.concatenate(pts), np.concatenate(ids)
        o = rng.permutation(len(i))  # tracks in no particular order
        yx.append(p[o])
        yid.append(i[o])
    return frames(tx, tid, dim=2), frames(yx, yid, dim=2)


def step_slices(f: Frames, k: int) -> tuple[np.ndarray, np.ndarray]:
    a, b = f.offsets[k], f.offsets[k + 1]
    return f.x[a:b], f.ids[a:b]


# --- py-motmetrics ----------------------------------------------------------------------------


def motmetrics_run(truth: Frames, tracks: Frames, c: float):
    """py-motmetrics' accumulator and summary on Euclidean distances, nan where d >= c; the
    object IDs go in ascending order (its carry-over favours the first object listed)."""
    mm = pytest.importorskip("motmetrics")
    acc = mm.MOTAccumulator(auto_id=False)
    for k in range(truth.n_steps):
        x, oid = step_slices(truth, k)
        y, hid = step_slices(tracks, k)
        o = np.argsort(oid)
        x, oid = x[o], oid[o]
        d = np.linalg.norm(x[:, None, :] - y[None, :, :], axis=-1)
        d[d >= c] = np.nan
        acc.update(oid, hid, d, frameid=k)
    names = ["num_objects", "num_predictions", "num_matches", "num_misses",
             "num_false_positives", "num_switches", "num_transfer", "num_fragmentations",
             "mota", "motp", "idtp", "idfp", "idfn", "idf1", "idp", "idr"]
    summary = mm.metrics.create().compute(acc, metrics=names, name="run")
    return acc.mot_events, {n: float(summary[n].iloc[0]) for n in names}


@pytest.mark.parametrize("seed", range(8))
def test_clear_mot_and_id_measures_equal_motmetrics(seed):
    truth, tracks = scene(seed)
    events, ref = motmetrics_run(truth, tracks, C)
    cm = clear_mot(truth, tracks, C)
    s = clear_mot_summary(cm)
    ids = id_scores(truth, tracks, C)
    assert s["switches"] > 0 and s["fragmentations"] > 0 and s["false_positives"] > 0
    for ours, theirs in [("objects", "num_objects"), ("predictions", "num_predictions"),
                         ("misses", "num_misses"),
                         ("false_positives", "num_false_positives"),
                         ("switches", "num_switches"), ("transfers", "num_transfer"),
                         ("fragmentations", "num_fragmentations")]:
        assert s[ours] == ref[theirs], ours
    # motmetrics' num_matches excludes switches; ours counts every matched pair
    assert s["matches"] == ref["num_matches"] + ref["num_switches"]
    for ours, theirs in [(s["mota"], "mota"), (s["motp"], "motp"), (ids.idf1, "idf1"),
                         (ids.idp, "idp"), (ids.idr, "idr")]:
        assert ours == pytest.approx(ref[theirs], rel=1e-12, abs=1e-12), theirs
    assert (ids.idtp, ids.idfp, ids.idfn) == (ref["idtp"], ref["idfp"], ref["idfn"])
    # every step's events
    typ = events["Type"].to_numpy()
    fid = events.index.get_level_values("FrameId").to_numpy()
    per = {t: np.bincount(fid[typ == t], minlength=truth.n_steps)
           for t in ("MATCH", "SWITCH", "MISS", "FP", "TRANSFER")}
    np.testing.assert_array_equal(cm.switches, per["SWITCH"])
    np.testing.assert_array_equal(cm.matches, per["MATCH"] + per["SWITCH"])
    np.testing.assert_array_equal(cm.misses, per["MISS"])
    np.testing.assert_array_equal(cm.false_positives, per["FP"])
    np.testing.assert_array_equal(cm.transfers, per["TRANSFER"])
    hit = np.isin(typ, ["MATCH", "SWITCH"])
    dsum = np.bincount(fid[hit], weights=events["D"].to_numpy()[hit], minlength=truth.n_steps)
    np.testing.assert_allclose(cm.distance, dsum, rtol=1e-12, atol=0)
    sw = typ == "SWITCH"
    np.testing.assert_array_equal(cm.switch_step, fid[sw])
    np.testing.assert_array_equal(cm.switch_truth, events["OId"].to_numpy()[sw].astype(int))
    assert ids.idtp_steps.sum() == ids.idtp


def test_the_counts_had_the_events_to_check():
    """The random scenes hold every kind of event the oracle test compares."""
    tot = {"switches": 0, "transfers": 0, "fragmentations": 0, "misses": 0}
    for seed in range(8):
        s = clear_mot_summary(clear_mot(*scene(seed), C))
        for k in tot:
            tot[k] += s[k]
    assert min(tot.values()) >= 10, tot


def test_mota_of_each_step_adds_up_to_the_run():
    truth, tracks = scene(3)
    cm = clear_mot(truth, tracks, C)
    m = mota_steps(cm)
    gt = cm.objects
    ok = gt > 0
    total = 1 - np.sum((1 - m[ok]) * gt[ok]) / gt.sum()
    assert total == pytest.approx(clear_mot_summary(cm)["mota"], rel=1e-12)
    assert np.all(np.isnan(m[~ok]))


def test_hand_case_carry_over_switch_fragmentation():
    """Two objects, tracks 1 and 2. Step 1: track 1 drifts nearer object B, but the
    carry-over keeps it on A (no switch, although a least-cost assignment would swap);
    step 2: track 1 leaves A (miss), step 3: A is taken by track 2 while B is missed:
    a switch of A (from 1 to 2), a transfer of 2 and a fragmentation of A."""
    A0, B0 = [0.0, 0.0], [3.0, 0.0]
    truth = frames([[A0, B0]] * 4, [[10, 20]] * 4)
    tracks = frames([[[0.1, 0], [3.1, 0]], [[1.6, 0], [2.0, 0]], [[5.0, 5.0], [3.0, 0.1]],
                     [[0.2, 0.0]]], [[1, 2], [1, 2], [1, 2], [2]])
    cm = clear_mot(truth, tracks, 2.0)
    np.testing.assert_array_equal(cm.matches, [2, 2, 1, 1])
    np.testing.assert_array_equal(cm.switches, [0, 0, 0, 1])
    np.testing.assert_array_equal(cm.transfers, [0, 0, 0, 1])
    np.testing.assert_array_equal(cm.fragmentations, [0, 0, 1, 0])
    np.testing.assert_array_equal(cm.switch_truth, [10])
    assert cm.distance[1] == pytest.approx(1.6 + 1.0)
    s = clear_mot_summary(cm)
    assert s["mota"] == pytest.approx(1 - (2 + 1 + 1) / 8)


@pytest.mark.parametrize(("a", "keeper"), [(10, 10), (30, 20)])
def test_hand_case_two_objects_last_matched_to_one_track(a, keeper):
    """Track 1 follows object a, then (a absent) object 20; at step 2, a is back and both
    are within the threshold of track 1 and were last matched to it: the lower ID keeps it,
    as in py-motmetrics with the objects listed in ascending order. At step 3 the keeper
    meets a new track 2 (an ID switch of the keeper), the other object track 1 again."""
    A, B = [-5.0, 0.0], [5.0, 0.0]
    truth = frames([[[0, 0], [1.5, 0]], [[1.5, 0]], [[0, 0], [1.5, 0]], [A, B]],
                   [[a, 20], [20], [a, 20], [a, 20]])
    k, other = (A, B) if keeper == a else (B, A)
    tracks = frames([[[0, 0]], [[1.5, 0]], [[0.75, 0]], [k, other]], [[1], [1], [1], [2, 1]])
    cm = clear_mot(truth, tracks, 2.0)
    assert cm.matches.tolist() == [1, 1, 1, 2] and cm.misses.tolist() == [1, 0, 1, 0]
    assert cm.transfers.tolist() == [0, 1, 0, 0] and cm.distance[2] == 0.75
    assert cm.switch_step.tolist() == [3] and cm.switch_truth.tolist() == [keeper]
    events, ref = motmetrics_run(truth, tracks, 2.0)
    assert events[events["Type"] == "MATCH"].loc[2]["OId"].tolist() == [keeper]
    assert events[events["Type"] == "SWITCH"]["OId"].tolist() == [keeper]
    assert clear_mot_summary(cm)["transfers"] == ref["num_transfer"]


# --- Stone Soup's GOSPA with switching --------------------------------------------------------


def stone_soup_gospa(truth: Frames, tracks: Frames, c: float, p: float, gamma: float):
    """Stone Soup's GOSPAMetric with switching_penalty on the same paths: its metric per time
    step (the steps where a truth or a track is present)."""
    pytest.importorskip("stonesoup")
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
    from stonesoup.types.state import State
    from stonesoup.types.track import Track

    t0 = datetime.datetime(2024, 1, 1)

    def paths(f: Frames, make_path, make_state):
        out = {}
        for k in range(f.n_steps):
            x, ids = step_slices(f, k)
            for xi, i in zip(x, ids, strict=True):
                out.setdefault(int(i), make_path()).append(
                    make_state(xi.reshape(2, 1), timestamp=t0 + datetime.timedelta(seconds=k)))
        return list(out.values())

    gt = paths(truth, GroundTruthPath, GroundTruthState)
    tr = paths(tracks, Track, State)
    g = GOSPAMetric(c=c, p=p, switching_penalty=gamma)
    metric = g.compute_over_time(*g.extract_states(tr, True), *g.extract_states(gt, True))
    return {int((m.timestamp - t0).total_seconds()): m.value for m in metric.value}


@pytest.mark.parametrize(("seed", "p", "gamma"), [(0, 2.0, 2.0), (1, 2.0, 0.7), (2, 1.0, 2.0),
                                                  (3, 2.0, 0.0), (4, 3.0, 1.5)])
def test_gospa_switching_equals_stone_soup(seed, p, gamma):
    truth, tracks = scene(seed, steps=25, objects=7)
    ref = stone_soup_gospa(truth, tracks, C, p, gamma)
    ours = gospa_switching(truth, tracks, C, p, switching_penalty=gamma)
    present = np.flatnonzero(truth.sizes + tracks.sizes > 0)
    assert sorted(ref) == present.tolist()
    half = 0
    for k in present.tolist():
        r = ref[k]
        for name in ("distance", "localisation", "missed", "false", "switching"):
            assert getattr(ours, name)[k] == pytest.approx(r[name], rel=1e-9, abs=1e-12), (
                k, name)
        half += ours.switches[k] % 1 != 0
    assert ours.switches.sum() >= 3 and half >= 1  # full and half switches were checked
    plain = gospa_steps(truth, tracks, C, p)
    np.testing.assert_allclose(ours.gospa, plain.distance, rtol=1e-12)


def test_gospa_switching_hand_case():
    """One object: track 1, then no track (half), then track 2 (half), then track 1 (full);
    a second object first unassigned, then assigned (its first assignment: no cost)."""
    truth = frames([[[0, 0], [9, 9]]] * 4, [[1, 2]] * 4)
    tracks = frames([[[0, 0]], [], [[0, 0], [9, 9]], [[0, 0]]], [[1], [], [2, 5], [1]], dim=2)
    g = gospa_switching(truth, tracks, 1.0, 2.0, switching_penalty=3.0)
    np.testing.assert_array_equal(g.switches, [0, 0.5, 0.5, 1.5])
    np.testing.assert_allclose(g.switching, 3.0 * np.sqrt([0, 0.5, 0.5, 1.5]))
    np.testing.assert_allclose(g.distance**2, g.gospa**2 + 9.0 * g.switches)


def test_gospa_switching_with_no_object_in_any_scan():
    """No truth at all (nothing in the radar's range): every track is false, no switch."""
    truth = frames([[], []], [[], []], dim=2)
    tracks = frames([[[0, 0]], []], [[4], []], dim=2)
    g = gospa_switching(truth, tracks, 2.0, 2.0)
    np.testing.assert_array_equal(g.switches, [0, 0])
    np.testing.assert_allclose(g.distance, [np.sqrt(2.0), 0.0])


# --- resolvable switches ----------------------------------------------------------------------


SB = 0.5**7  # rad; at 1024 m three cross-range sigmas are 24 m exactly


def test_resolvable_hand_cases():
    """Object 7 at 1024 m east of the site: resolvable when the nearest other object is more
    than 24 m away; at 2048 m the limit is 48 m; a lone object is resolvable; the site need
    not be the origin."""
    truth = frames([[[1024, 0], [1024, 24.0]],  # 24 m: not farther than 24 m
                    [[1024, 0], [1024, 24.5]],  # resolvable
                    [[2048, 0], [2048, 40.0]],  # 40 m < 48 m: not resolvable
                    [[2048, 0]],  # alone
                    [[1124, -50], [1124, -20]]],  # site (100, -50): 30 m > 24 m
                   [[7, 8], [8, 7], [7, 3], [7], [7, 9]])
    ev = classify_switches([0, 1, 2, 3], [7, 7, 7, 7], truth, (0.0, 0.0), SB)
    np.testing.assert_array_equal(ev.mask, [False, True, False, True])
    assert (ev.total, ev.resolvable) == (4, 2)
    ev = classify_switches([4, 4], [7, 9], truth, (100.0, -50.0), SB)
    np.testing.assert_array_equal(ev.mask, [True, True])
    none = classify_switches([], [], truth, (0.0, 0.0), SB)
    assert (none.total, none.resolvable, none.mask.size) == (0, 0, 0)


def test_resolvable_equals_a_loop_over_events():
    truth, tracks = scene(5)
    cm = clear_mot(truth, tracks, C)
    site, sb = (-20.0, 5.0), 0.05
    ev = classify_switches(cm.switch_step, cm.switch_truth, truth, site, sb)
    want = []
    for k, a in zip(cm.switch_step.tolist(), cm.switch_truth.tolist(), strict=True):
        x, ids = step_slices(truth, k)
        xa = x[ids == a][0]
        others = np.linalg.norm(x[ids != a] - xa, axis=1)
        want.append(bool(np.all(others > 3 * np.hypot(*(xa - site)) * sb)))
    assert ev.mask.tolist() == want and 0 < sum(want) < len(want)


# --- score_run and errors ---------------------------------------------------------------------


def test_score_run_gathers_the_scores():
    truth, tracks = scene(6)
    r = score_run(tracks, truth, (0.0, 0.0), 0.01, C)
    cm = clear_mot_summary(clear_mot(truth, tracks, C))
    ids = id_scores(truth, tracks, C)
    g = gospa_switching(truth, tracks, C)
    assert r["id_switches"] == cm["switches"] and r["mota"] == cm["mota"]
    assert r["idf1"] == ids.idf1 and r["fragmentations"] == cm["fragmentations"]
    assert r["gospa_switching"] == pytest.approx(float(np.mean(g.distance)), rel=1e-15)
    assert r["gospa"] == pytest.approx(float(np.mean(gospa_steps(truth, tracks, C).distance)),
                                       rel=1e-12)
    assert r["gospa_switching"] > r["gospa"]
    assert r["false_track_scans"] == int(np.sum(tracks.sizes - gospa_steps(truth, tracks,
                                                                            C).assigned))
    assert 0 <= r["id_switches_resolvable"] <= r["id_switches"]
    assert math.isnan(score_run(tracks, truth, None, None, C)["id_switches_resolvable"])


def test_empty_and_trackless_runs():
    truth, _ = scene(1)
    none = frames([[] for _ in range(truth.n_steps)], [[] for _ in range(truth.n_steps)],
                  dim=2)
    s = clear_mot_summary(clear_mot(truth, none, C))
    assert s["misses"] == s["objects"] and s["mota"] == 0.0 and math.isnan(s["motp"])
    assert id_scores(truth, none, C).idf1 == 0.0
    r = score_run(none, truth, (0.0, 0.0), 0.01, C)
    assert r["id_switches"] == 0 and r["tracks"] == 0


@pytest.mark.parametrize(("kw", "message"), [
    (dict(c=0.0), "c = 0.0"),
    (dict(ids=False), "truth.ids is None"),
    (dict(repeat=True), "truth.ids repeat an ID"),
])
def test_errors_name_the_argument(kw, message):
    truth, tracks = scene(0, steps=5)
    c = kw.get("c", C)
    if kw.get("ids") is False:
        truth = Frames(truth.offsets, truth.x)
    if kw.get("repeat"):
        ids = truth.ids.copy()
        ids[1] = ids[0]
        truth = Frames(truth.offsets, truth.x, ids)
    with pytest.raises(ValueError, match=message):
        clear_mot(truth, tracks, c)


def test_a_switch_of_an_absent_truth_is_refused():
    truth, _ = scene(0, steps=5)
    with pytest.raises(ValueError, match="truth 12345 is not in the truth at step 2"):
        classify_switches([2], [12345], truth, (0.0, 0.0), SB)


@pytest.mark.parametrize(("seed", "p"), [(7, 2.0), (8, 1.0), (9, 3.0)])
def test_gospa_switching_with_a_given_assignment_is_the_same(seed, p):
    """Passing the GOSPA assignment gives every array bit for bit."""
    truth, tracks = scene(seed, steps=40, objects=12)
    ab = assign(truth, tracks, C, p)
    a = gospa_switching(truth, tracks, C, p, switching_penalty=1.3)
    b = gospa_switching(truth, tracks, C, p, switching_penalty=1.3, assignment=ab)
    for name, x, y in zip(a._fields, a, b, strict=True):
        np.testing.assert_array_equal(x, y, err_msg=name)
    assert np.sum(a.switches) > 0
    with pytest.raises(ValueError, match="expected an order"):
        gospa_switching(truth, tracks, C, 0.5, assignment=ab)
