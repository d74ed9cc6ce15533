"""Multi-target metrics (trackkit.eval.track_metrics): OSPA, GOSPA and track-level counts.

* hand-computed cases (empty sets, all missed, all false, one pair inside and outside c);
* a brute-force textbook reference (minimum over every assignment) at p = 1, 2, 3, also for
  the component-splitting, enumeration and linear_sum_assignment paths of the kernel;
* properties (hypothesis): OSPA symmetric, <= c and a metric (triangle inequality); GOSPA
  parts add up to GOSPA^p; both invariant under permutations of the points;
* batching: a ragged batch of steps gives, bit for bit, the numbers of each step alone;
* oracles against Stone Soup 1.x: ``GOSPAMetric`` (distance and its localisation, missed and
  false parts, which it reports as p-th powers like ours) to 1e-9, and ``OSPAMetric`` at
  p = 1. Stone Soup's OSPA assigns by min(d, c) rather than min(d, c)^p, so at p = 2 it is
  not the textbook OSPA: it is checked here against the brute-force definition instead, and
  ``test_stone_soup_ospa_p2_differs_from_textbook`` shows a case where it is 51% high;
* track counts on scripted scenarios: a clean track, a late confirmation, a break, an ID swap
  between two crossing truths, a false track; and runs batched = runs alone.
"""

from __future__ import annotations

import datetime
import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import trackkit.eval.track_metrics as mt
from trackkit.eval.track_metrics import (
    Frames,
    TrackCounts,
    assign,
    frames,
    gospa,
    gospa_steps,
    ospa,
    ospa_steps,
    track_counts,
    track_summary,
)

# --------------------------------------------------------------------------------------------
# references
# --------------------------------------------------------------------------------------------


def _textbook_A(x: np.ndarray, y: np.ndarray, c: float, p: float) -> float:
    """min over all injective maps of the smaller set into the larger of sum min(d, c)^p."""
    if len(x) > len(y):
        x, y = y, x
    n, m = len(x), len(y)
    if n == 0:
        return 0.0
    D = np.minimum(np.linalg.norm(x[:, None] - y[None], axis=-1), c) ** p
    P = np.array(list(itertools.permutations(range(m), n)))
    return float(D[np.arange(n), P].sum(axis=1).min())


def textbook_gospa(x, y, c, p):
    A = _textbook_A(np.asarray(x, float), np.asarray(y, float), c, p)
    return (A + c**p / 2 * abs(len(x) - len(y))) ** (1 / p)


def textbook_ospa(x, y, c, p):
    n, m = len(x), len(y)
    if n == m == 0:
        return 0.0
    A = _textbook_A(np.asarray(x, float), np.asarray(y, float), c, p)
    return ((A + c**p * abs(n - m)) / max(n, m)) ** (1 / p)


def lsa_gospa(x, y, c, p):
    """GOSPA from one linear_sum_assignment on the full truncated matrix (for large sets)."""
    from scipy.optimize import linear_sum_assignment

    D = np.minimum(np.linalg.norm(x[:, None] - y[None], axis=-1), c) ** p
    r, k = linear_sum_assignment(D)
    return (D[r, k].sum() + c**p / 2 * abs(len(x) - len(y))) ** (1 / p)


def _clustered(rng, n, m, d=2, spread=6.0):
    return rng.uniform(0, spread, (n, d)), rng.uniform(0, spread, (m, d))


# --------------------------------------------------------------------------------------------
# hand-computed cases
# --------------------------------------------------------------------------------------------


def test_both_empty_is_zero():
    for f in (gospa, ospa):
        r = f(np.empty((0, 2)), np.empty((0, 2)), 5.0)
        assert r == (0.0, 0.0, 0.0, 0.0, 0)


def test_all_missed_and_all_false():
    x = np.array([[0.0, 0.0], [1.0, 1.0], [5.0, 5.0]])
    g = gospa(x, np.empty((0, 2)), c=2.0, p=2.0)  # GOSPA^2 = 3 c^2 / 2 = 6
    assert g.distance == pytest.approx(math.sqrt(6.0), rel=1e-15)
    assert (g.localisation, g.missed, g.false, g.assigned) == (0.0, 6.0, 0.0, 0)
    g = gospa(np.empty((0, 2)), x, c=2.0, p=2.0)
    assert (g.missed, g.false) == (0.0, 6.0)
    o = ospa(x, [], c=2.0, p=2.0)  # OSPA = c whenever one set is empty
    assert o.distance == pytest.approx(2.0, rel=1e-15) and o.missed == pytest.approx(4.0)
    o = ospa([], x, c=2.0, p=1.0)
    assert o.distance == pytest.approx(2.0, rel=1e-15) and o.false == pytest.approx(2.0)


def test_one_pair_inside_and_outside_c():
    x, y = [[0.0, 0.0]], [[3.0, 4.0]]  # d = 5
    g = gospa(x, y, c=10.0, p=2.0)
    assert g == (5.0, 25.0, 0.0, 0.0, 1)
    assert ospa(x, y, c=10.0, p=1.0) == (5.0, 5.0, 0.0, 0.0, 1)
    g = gospa(x, y, c=4.0, p=2.0)  # outside c: one missed and one false, c^2 / 2 each
    assert g == (4.0, 0.0, 8.0, 8.0, 0)
    o = ospa(x, y, c=4.0, p=2.0)  # OSPA counts a truncated pair as localisation, at c
    assert o == (4.0, 16.0, 0.0, 0.0, 0)
    g = gospa(x, y, c=5.0, p=1.0)  # exactly at c: not assigned (d < c is required)
    assert g.assigned == 0 and g.distance == pytest.approx(5.0)


def test_two_truths_three_estimates_by_hand():
    x = [[0.0], [10.0]]
    y = [[1.0], [10.5], [30.0]]  # pairs 0-1 (1), 10-10.5 (0.5); 30 is false
    g = gospa(x, y, c=3.0, p=2.0)
    assert g.localisation == pytest.approx(1.25) and g.false == pytest.approx(4.5)
    assert g.distance == pytest.approx(math.sqrt(5.75)) and g.assigned == 2
    o = ospa(x, y, c=3.0, p=1.0)  # (1 + 0.5 + 3) / 3
    assert o.distance == pytest.approx(1.5) and o.false == pytest.approx(1.0)


# --------------------------------------------------------------------------------------------
# against the textbook definition
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("p", [1.0, 2.0, 3.0])
def test_equals_textbook_on_random_small_sets(p):
    rng = np.random.default_rng(int(p))
    for _ in range(150):
        n, m = rng.integers(0, 6, 2)
        x, y = _clustered(rng, n, m)
        assert gospa(x, y, 2.0, p).distance == pytest.approx(
            textbook_gospa(x, y, 2.0, p), rel=1e-12, abs=1e-12
        )
        assert ospa(x, y, 2.0, p).distance == pytest.approx(
            textbook_ospa(x, y, 2.0, p), rel=1e-12, abs=1e-12
        )


@pytest.mark.parametrize("max_perms", [0, 720])
def test_component_solvers_agree_with_textbook(monkeypatch, max_perms):
    """Components solved by enumeration (default) and by linear_sum_assignment (forced)."""
    monkeypatch.setattr(mt, "_MAX_PERMS", max_perms)
    mt._perms.cache_clear()
    rng = np.random.default_rng(7)
    try:
        for _ in range(60):
            n, m = rng.integers(2, 7, 2)
            x, y = _clustered(rng, n, m, spread=4.0)
            for p in (1.0, 2.0):
                assert gospa(x, y, 2.5, p).distance == pytest.approx(
                    textbook_gospa(x, y, 2.5, p), rel=1e-12
                )
    finally:
        mt._perms.cache_clear()


@pytest.mark.parametrize("c", [50.0, 400.0, 1e5])
def test_large_step_matches_full_assignment(c):
    """Large steps (own broadcast pass; sparse -> components, dense -> one assignment)."""
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 2000, (120, 2))
    y = np.vstack([x[:100] + rng.normal(0, 30, (100, 2)), rng.uniform(0, 2000, (30, 2))])
    for p in (1.0, 2.0):
        assert gospa(x, y, c, p).distance == pytest.approx(lsa_gospa(x, y, c, p), rel=1e-12)


# --------------------------------------------------------------------------------------------
# properties
# --------------------------------------------------------------------------------------------

_pt = st.tuples(st.floats(-5, 5), st.floats(-5, 5))
_set = st.lists(_pt, min_size=0, max_size=5).map(lambda v: np.array(v, float).reshape(-1, 2))
_c = st.floats(0.5, 8.0)
_p = st.sampled_from([1.0, 1.5, 2.0, 3.0])


@settings(max_examples=100, deadline=None)
@given(_set, _set, _c, _p)
def test_ospa_symmetric_bounded_and_decomposes(x, y, c, p):
    a, b = ospa(x, y, c, p), ospa(y, x, c, p)
    assert a.distance == pytest.approx(b.distance, rel=1e-12, abs=1e-12)
    assert (a.missed, a.false) == pytest.approx((b.false, b.missed), rel=1e-12, abs=1e-12)
    assert 0 <= a.distance <= c * (1 + 1e-12)
    total = a.localisation + a.missed + a.false
    assert a.distance**p == pytest.approx(total, rel=1e-12, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(_set, _set, _set, _c, _p)
def test_ospa_and_gospa_triangle_inequality(x, y, z, c, p):
    for f in (ospa, gospa):
        xz, xy, yz = (f(a, b, c, p).distance for a, b in ((x, z), (x, y), (y, z)))
        assert xz <= xy + yz + 1e-9


@settings(max_examples=100, deadline=None)
@given(_set, _set, _c, _p)
def test_gospa_parts_add_up_and_count(x, y, c, p):
    g = gospa(x, y, c, p)
    assert g.distance**p == pytest.approx(
        g.localisation + g.missed + g.false, rel=1e-12, abs=1e-12
    )
    assert g.missed == pytest.approx(c**p / 2 * (len(x) - g.assigned), rel=1e-15)
    assert g.false == pytest.approx(c**p / 2 * (len(y) - g.assigned), rel=1e-15)
    assert g.localisation <= g.assigned * c**p * (1 + 1e-12)
    r = gospa(y, x, c, p)
    assert r.distance == pytest.approx(g.distance, rel=1e-12, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(_set, _set, _c, _p, st.randoms(use_true_random=False))
def test_permutation_invariance(x, y, c, p, rnd):
    px = x[rnd.sample(range(len(x)), len(x))] if len(x) else x
    py = y[rnd.sample(range(len(y)), len(y))] if len(y) else y
    for f in (ospa, gospa):
        a, b = f(x, y, c, p), f(px, py, c, p)
        assert a.distance == pytest.approx(b.distance, rel=1e-12, abs=1e-12)
        assert a.localisation == pytest.approx(b.localisation, rel=1e-12, abs=1e-12)
        assert (a.missed, a.false, a.assigned) == pytest.approx(
            (b.missed, b.false, b.assigned)
        )


# --------------------------------------------------------------------------------------------
# batching and the input format
# --------------------------------------------------------------------------------------------


def _random_frames(rng, S, lam_x=3, lam_y=4, big_every=0):
    n, m = rng.poisson(lam_x, S), rng.poisson(lam_y, S)
    if big_every:
        n[::big_every], m[::big_every] = 80, 90  # n m >= _BIG: the broadcast path
    xs = [rng.uniform(0, 10, (k, 2)) for k in n]
    ys = [rng.uniform(0, 10, (k, 2)) for k in m]
    return xs, ys


def test_batch_is_bitwise_each_step_alone_and_chunk_independent(monkeypatch):
    rng = np.random.default_rng(11)
    xs, ys = _random_frames(rng, 60, big_every=17)
    X, Y = frames(xs), frames(ys)
    for fn, f1 in ((gospa_steps, gospa), (ospa_steps, ospa)):
        r = fn(X, Y, 2.0, 2.0)
        assert r.distance.shape == (60,)
        for s in range(60):
            one = f1(xs[s], ys[s], 2.0, 2.0)
            assert tuple(v[s] for v in r) == tuple(one), s
        # tiny chunks of small steps: same bits
        monkeypatch.setattr(mt, "_PAIR_CHUNK", 7)
        r2 = fn(X, Y, 2.0, 2.0)
        monkeypatch.undo()
        for a, b in zip(r, r2, strict=True):
            np.testing.assert_array_equal(a, b)


def test_steps_equal_textbook_per_step():
    rng = np.random.default_rng(5)
    xs, ys = _random_frames(rng, 40)
    g = gospa_steps(frames(xs), frames(ys), 1.5, 1.0)
    o = ospa_steps(frames(xs), frames(ys), 1.5, 2.0)
    for s in range(40):
        assert g.distance[s] == pytest.approx(textbook_gospa(xs[s], ys[s], 1.5, 1.0), rel=1e-12)
        assert o.distance[s] == pytest.approx(
            textbook_ospa(xs[s], ys[s], 1.5, 2.0), rel=1e-12, abs=1e-15
        )


def test_frames_builds_ragged_arrays_and_assign_pairs_rows():
    f = frames([[[0.0, 0.0], [1.0, 0.0]], [], [[2.0, 2.0]]], ids=[[4, 5], [], [4]])
    np.testing.assert_array_equal(f.offsets, [0, 2, 2, 3])
    assert f.x.shape == (3, 2) and f.ids.tolist() == [4, 5, 4] and f.n_steps == 3
    t = frames([[[0.1, 0.0]], [[5.0, 5.0]], [[2.0, 2.5], [9.0, 9.0]]])
    i, j = assign(f, t, c=1.0)
    assert i.tolist() == [0, 2] and j.tolist() == [0, 2]


def test_bad_input_names_the_argument():
    x = frames([[[0.0, 0.0]]])
    with pytest.raises(ValueError, match="c = 0.0"):
        gospa_steps(x, x, 0.0)
    with pytest.raises(ValueError, match="c = -1.0"):
        ospa([[0.0]], [[1.0]], -1.0)
    with pytest.raises(ValueError, match="p = 0.5"):
        gospa([[0.0]], [[1.0]], 1.0, p=0.5)
    with pytest.raises(ValueError, match="p = inf"):
        ospa([[0.0]], [[1.0]], 1.0, p=math.inf)
    with pytest.raises(ValueError, match="dimension 2 .* 3"):
        gospa_steps(x, frames([[[0.0, 0.0, 0.0]]]), 1.0)
    with pytest.raises(ValueError, match="1 steps and estimates 2"):
        gospa_steps(x, frames([[[0.0, 0.0]], []]), 1.0)
    with pytest.raises(ValueError, match="truth.offsets"):
        gospa_steps(Frames(np.array([0, 2]), np.zeros((1, 2))), x, 1.0)
    with pytest.raises(ValueError, match="truth.x has shape"):
        gospa_steps(Frames(np.array([0, 1]), np.zeros(1)), x, 1.0)
    with pytest.raises(ValueError, match="non-finite"):
        gospa([[np.nan, 0.0]], [[0.0, 0.0]], 1.0)
    with pytest.raises(ValueError, match="truth.ids is None"):
        track_counts(x, x, 1.0)
    xi = frames([[[0.0, 0.0], [1.0, 1.0]]], ids=[[3, 3]])
    with pytest.raises(ValueError, match="truth.ids repeat"):
        track_counts(xi, frames([[[0.0, 0.0]]], ids=[[1]]), 1.0)
    ok = frames([[[0.0, 0.0]]], ids=[[1]])
    with pytest.raises(ValueError, match="run_offsets"):
        track_counts(ok, ok, 1.0, run_offsets=[0, 2])
    with pytest.raises(ValueError, match="times has shape"):
        track_counts(ok, ok, 1.0, times=[0.0, 1.0])
    with pytest.raises(ValueError, match="min_assigned = 0"):
        track_counts(ok, ok, 1.0, min_assigned=0)
    with pytest.raises(ValueError, match=r"points\[1\] has shape"):
        frames([[[0.0, 0.0]], [0.0, 1.0]])


# --------------------------------------------------------------------------------------------
# oracles: Stone Soup
# --------------------------------------------------------------------------------------------

_T0 = datetime.datetime(2024, 1, 1)


def _states(pts):
    from stonesoup.types.state import State

    return [State(np.asarray(v, float).reshape(-1, 1), timestamp=_T0) for v in pts]


@pytest.mark.parametrize("p", [1.0, 2.0])
def test_gospa_equals_stone_soup(p):
    from stonesoup.metricgenerator.ospametric import GOSPAMetric

    rng = np.random.default_rng(int(10 * p))
    ss = GOSPAMetric(c=2.0, p=p)
    for _ in range(120):
        n, m = rng.integers(0, 8, 2)
        if n + m == 0:  # Stone Soup needs a state to take the time from
            continue
        x, y = _clustered(rng, n, m, d=rng.integers(1, 4))
        ref = ss.compute_gospa_metric(_states(y), _states(x))[0].value
        g = gospa(x, y, 2.0, p)
        for key in ("distance", "localisation", "missed", "false"):
            assert getattr(g, key) == pytest.approx(ref[key], rel=1e-9, abs=1e-12), key


def test_ospa_equals_stone_soup_at_p1():
    from stonesoup.metricgenerator.ospametric import OSPAMetric

    rng = np.random.default_rng(21)
    ss = OSPAMetric(c=2.0, p=1.0)
    for _ in range(120):
        n, m = rng.integers(0, 8, 2)
        if n + m == 0:
            continue
        x, y = _clustered(rng, n, m)
        ref = ss.compute_OSPA_distance(_states(y), _states(x)).value
        assert ospa(x, y, 2.0, 1.0).distance == pytest.approx(ref, rel=1e-9, abs=1e-12)


def test_stone_soup_ospa_p2_differs_from_textbook():
    """Stone Soup's OSPA pairs by min(d, c), then raises to p: at p = 2 it pairs the two
    coincident points and leaves a 5 m pair, where the textbook (min of sum d^2) pairs
    three short ones: sqrt(25 / 3) = 2.89 against sqrt(11 / 3) = 1.91."""
    from stonesoup.metricgenerator.ospametric import OSPAMetric

    x = np.array([[3.0, 3.0], [4.0, 3.0], [2.0, 1.0]])
    y = np.array([[0.0, 0.0], [2.0, 1.0], [3.0, 3.0]])
    ours = ospa(x, y, c=10.0, p=2.0).distance
    assert ours == pytest.approx(textbook_ospa(x, y, 10.0, 2.0), rel=1e-14)
    assert ours == pytest.approx(math.sqrt(11 / 3), rel=1e-14)
    ss = OSPAMetric(c=10.0, p=2.0).compute_OSPA_distance(_states(y), _states(x)).value
    assert ss == pytest.approx(math.sqrt(25 / 3), rel=1e-12)
    assert ss / ours - 1 > 0.5
    # at p = 1 the two agree on the same sets
    ss1 = OSPAMetric(c=10.0, p=1.0).compute_OSPA_distance(_states(y), _states(x)).value
    assert ospa(x, y, c=10.0, p=1.0).distance == pytest.approx(ss1, rel=1e-12)


# --------------------------------------------------------------------------------------------
# track counts on scripted scenarios
# --------------------------------------------------------------------------------------------


def _scenario(K: int, truths: dict, tracks: dict) -> tuple[Frames, Frames]:
    """``truths[id] = f(k)`` giving a position (x, y) or None when absent; same for tracks."""

    def build(objs):
        pts, ids = [], []
        for k in range(K):
            here = [(i, f(k)) for i, f in objs.items() if f(k) is not None]
            pts.append(np.array([v for _, v in here], float).reshape(-1, 2))
            ids.append([i for i, _ in here])
        return frames(pts, ids, dim=2)

    return build(truths), build(tracks)


def _on(lo, hi, f):
    return lambda k: f(k) if lo <= k <= hi else None


def _counts(r, i=0):
    return {k: (v[i].item() if hasattr(v[i], "item") else v[i]) for k, v in r._asdict().items()}


def test_clean_track_with_late_confirmation():
    truth = {1: lambda k: (10.0 * k, 0.0)}
    tracks = {7: _on(3, 9, lambda k: (10.0 * k + 1.0, 0.0))}
    X, Y = _scenario(10, truth, tracks)
    r = _counts(track_counts(X, Y, c=5.0, times=5.0 * np.arange(10)))
    assert r == {
        "truths": 1, "truths_confirmed": 1, "confirmed_within": 1, "confirm_delay": 15.0,
        "truth_steps": 10,
        "assigned_steps": 7, "tracks": 1, "false_tracks": 0, "track_steps": 7,
        "purity": 1.0, "breaks": 0, "truth_switches": 0, "id_switches": 0, "sq_error": 7.0,
    }  # fmt: skip
    # confirmed 15 s after birth: within 15 s, not within 14.9 s
    assert track_counts(X, Y, c=5.0, times=5.0 * np.arange(10), within=15.0).confirmed_within[0]
    assert not track_counts(X, Y, c=5.0, times=5.0 * np.arange(10),
                            within=14.9).confirmed_within[0]
    s = track_summary(track_counts(X, Y, c=5.0))
    assert s["mean_confirm_delay"] == 3.0 and s["rmse"] == 1.0
    assert s["completeness"] == 0.7 and s["mean_purity"] == 1.0


def test_confirmation_delay_counts_from_birth():
    truth = {1: _on(4, 9, lambda k: (0.0, 10.0 * k))}
    tracks = {2: _on(6, 9, lambda k: (0.0, 10.0 * k))}
    X, Y = _scenario(10, truth, tracks)
    r = track_counts(X, Y, c=5.0)
    assert r.confirm_delay.tolist() == [2.0] and r.truth_steps.tolist() == [6]


def test_track_break():
    truth = {1: lambda k: (10.0 * k, 0.0)}
    tracks = {3: _on(1, 8, lambda k: (10.0 * k, 1.0)), 4: _on(12, 19, lambda k: (10.0 * k, 2.0))}
    X, Y = _scenario(20, truth, tracks)
    r = _counts(track_counts(X, Y, c=5.0))
    assert (r["breaks"], r["truth_switches"], r["id_switches"]) == (1, 1, 0)
    assert (r["tracks"], r["false_tracks"], r["purity"]) == (2, 0, 2.0)
    assert r["sq_error"] == 8 * 1.0 + 8 * 4.0 and r["confirm_delay"] == 1.0


def test_id_swap_between_crossing_truths():
    truth = {1: lambda k: (10.0 * k, 0.0), 2: lambda k: (90.0 - 10.0 * k, 0.0)}
    # the tracks bounce off each other where the truths cross, between steps 4 and 5
    tracks = {
        10: lambda k: (10.0 * k + 1.0 if k <= 4 else 91.0 - 10.0 * k, 0.0),
        20: lambda k: (89.0 - 10.0 * k if k <= 4 else 10.0 * k - 1.0, 0.0),
    }
    X, Y = _scenario(10, truth, tracks)
    r = _counts(track_counts(X, Y, c=5.0))
    assert (r["id_switches"], r["truth_switches"], r["breaks"]) == (2, 2, 0)
    assert r["purity"] == pytest.approx(1.0)  # each track: 5 of 10 steps on its dominant
    assert r["assigned_steps"] == 20 and r["false_tracks"] == 0


def test_false_track_and_dominant_truth():
    truth = {1: lambda k: (10.0 * k, 0.0), 2: _on(0, 5, lambda k: (500.0, 0.0))}
    tracks = {
        1: lambda k: (10.0 * k, 0.5),
        9: _on(0, 7, lambda k: (500.0, 1.0) if k <= 2 else (1000.0, 1000.0)),  # 3 of 8
        5: _on(0, 5, lambda k: (500.0, 2.0) if k <= 2 else (2000.0, 0.0)),  # 0 of 6
    }
    X, Y = _scenario(10, truth, tracks)
    # tracks 9 and 5 both pass truth 2 at steps 0-2; the nearer, 9, is assigned there
    r = track_counts(X, Y, c=5.0)
    assert r.tracks.tolist() == [3]
    assert r.false_tracks.tolist() == [2]  # 9 (3 of 8) and 5 (0 of 6)
    assert r.purity.tolist() == [1.0]
    r = track_counts(X, Y, c=5.0, min_assigned=0.3)  # 3 of 8 >= 0.3: only 5 is false
    assert r.false_tracks.tolist() == [1] and r.purity.tolist() == [1.0 + 3 / 8]


def _concat(fs: list[Frames]) -> Frames:
    """Runs laid one after another (the Monte Carlo engine's layout)."""
    steps = [(f.x[f.offsets[k] : f.offsets[k + 1]], f.ids[f.offsets[k] : f.offsets[k + 1]])
             for f in fs for k in range(f.n_steps)]  # fmt: skip
    return frames([x for x, _ in steps], [i for _, i in steps], dim=2)


def test_runs_batched_equal_runs_alone():
    scen = [
        _scenario(10, {1: lambda k: (10.0 * k, 0.0)}, {1: _on(2, 9, lambda k: (10.0 * k, 1.0))}),
        _scenario(
            6,
            {1: lambda k: (0.0, 5.0 * k), 3: lambda k: (50.0, 0.0)},
            {1: lambda k: (0.0, 5.0 * k + 0.5), 2: _on(1, 3, lambda k: (50.0, 0.5))},
        ),
        _scenario(4, {}, {4: lambda k: (0.0, 0.0)}),
    ]
    X, Y = _concat([s[0] for s in scen]), _concat([s[1] for s in scen])
    both = track_counts(X, Y, c=2.0, run_offsets=[0, 10, 16, 20])
    for i, (x, y) in enumerate(scen):
        alone = track_counts(x, y, c=2.0)
        for name, a, b in zip(both._fields, both, alone, strict=True):
            assert a[i] == b[0], name
    assert both.truths.tolist() == [1, 2, 0] and both.false_tracks.tolist() == [0, 0, 1]
    assert both.confirm_delay.tolist() == [2.0, 1.0, 0.0]
    s = track_summary(both)
    assert s["truths"] == 3 and s["tracks"] == 4 and s["false_track_fraction"] == 0.25


def _reference_counts(truth: Frames, tracks: Frames, c: float, run_offsets, min_assigned,
                      within: float = math.inf):
    """The definitions of ``track_counts`` written out with dicts, run by run."""
    I, J = assign(truth, tracks, c)
    pair = dict(zip(I.tolist(), J.tolist(), strict=True))
    out = []
    for r in range(len(run_offsets) - 1):
        birth, first, life, last, on, combo = {}, {}, {}, {}, {}, {}
        tseq, jseq = {}, {}
        n = {"truth_steps": 0, "assigned_steps": 0, "track_steps": 0, "sq_error": 0.0}
        for s in range(run_offsets[r], run_offsets[r + 1]):
            k = s - run_offsets[r]
            for i in range(truth.offsets[s], truth.offsets[s + 1]):
                t = int(truth.ids[i])
                birth.setdefault(t, k)
                n["truth_steps"] += 1
                if i in pair:
                    j = pair[i]
                    tr = int(tracks.ids[j])
                    first.setdefault(t, k)
                    on[tr] = on.get(tr, 0) + 1
                    combo[tr, t] = combo.get((tr, t), 0) + 1
                    tseq.setdefault(t, []).append((k, tr))
                    jseq.setdefault(tr, []).append((k, t))
                    n["assigned_steps"] += 1
                    n["sq_error"] += float(np.sum((truth.x[i] - tracks.x[j]) ** 2))
            for j in range(tracks.offsets[s], tracks.offsets[s + 1]):
                tr = int(tracks.ids[j])
                life[tr] = life.get(tr, 0) + 1
                last[tr] = k
                n["track_steps"] += 1
        false = {tr for tr in life if on.get(tr, 0) < min_assigned * life[tr]}
        switches = breaks = 0
        for seq in tseq.values():
            for (_, a), (k, b) in itertools.pairwise(seq):
                if a != b:
                    switches += 1
                    breaks += last[a] < k
        n.update(
            truths=len(birth),
            truths_confirmed=len(first),
            confirmed_within=sum(first[t] - birth[t] <= within for t in first),
            confirm_delay=float(sum(first[t] - birth[t] for t in first)),
            tracks=len(life),
            false_tracks=len(false),
            purity=sum(
                max(v for (tr2, _), v in combo.items() if tr2 == tr) / life[tr]
                for tr in life
                if tr not in false
            ),
            breaks=breaks,
            truth_switches=switches,
            id_switches=sum(
                a != b for seq in jseq.values() for (_, a), (_, b) in itertools.pairwise(seq)
            ),
        )
        out.append(n)
    return out


def test_track_counts_equal_reference_on_random_runs():
    """Random IDs and positions in a small box: many switches, breaks and false tracks."""
    rng = np.random.default_rng(9)
    xs, xi, ys, yi, ro = [], [], [], [], [0]
    for _ in range(12):
        K = int(rng.integers(1, 15))
        for _ in range(K):
            t = rng.choice(6, rng.integers(0, 6), replace=False)
            j = rng.choice(9, rng.integers(0, 8), replace=False)
            xs.append(rng.uniform(0, 10, (t.size, 2)))
            ys.append(rng.uniform(0, 10, (j.size, 2)))
            xi.append(t)
            yi.append(j)
        ro.append(ro[-1] + K)
    X, Y = frames(xs, xi, dim=2), frames(ys, yi, dim=2)
    for frac, within in ((0.5, math.inf), (0.2, 3.0)):
        got = track_counts(X, Y, c=3.0, run_offsets=ro, min_assigned=frac, within=within)
        ref = _reference_counts(X, Y, 3.0, ro, frac, within)
        for r, want in enumerate(ref):
            for name in TrackCounts._fields:
                assert getattr(got, name)[r] == pytest.approx(want[name], rel=1e-12), (r, name)
    assert got.breaks.sum() > 0 and got.id_switches.sum() > 0 and got.false_tracks.sum() > 0


def test_empty_batches_keep_dtypes():
    e = frames([], dim=2)
    g = gospa_steps(e, e, 1.0)
    assert g.distance.dtype == g.localisation.dtype == np.float64 and g.assigned.size == 0
    ei = frames([[], []], ids=[[], []], dim=2)
    r = track_counts(ei, ei, 1.0)
    assert r.sq_error.dtype == r.purity.dtype == np.float64 and r.truths.tolist() == [0]
    assert math.isnan(track_summary(r)["rmse"])


def test_pairs_within_equals_brute_force_on_small_and_large_steps():
    """Steps below and above the broadcast size (80 x 80 points) in one batch: every pair
    closer than c, sorted by truth row then estimate row, with its squared distance."""
    rng = np.random.default_rng(4)
    sizes = [(3, 4), (80, 80), (0, 5), (6, 0), (2, 9), (70, 90), (5, 5)]
    X = frames([rng.uniform(0, 10, (n, 2)) for n, _ in sizes], dim=2)
    Y = frames([rng.uniform(0, 10, (m, 2)) for _, m in sizes], dim=2)
    I, J, d2 = mt.pairs_within(X, Y, 1.5)
    want = []
    for s in range(len(sizes)):
        for i in range(X.offsets[s], X.offsets[s + 1]):
            for j in range(Y.offsets[s], Y.offsets[s + 1]):
                d = float(np.sum((X.x[i] - Y.x[j]) ** 2))
                if d < 1.5**2:
                    want.append((i, j, d))
    assert list(zip(I.tolist(), J.tolist(), strict=True)) == [(i, j) for i, j, _ in want]
    np.testing.assert_allclose(d2, [d for *_, d in want], rtol=1e-15)


def test_solve_partial_maximum_cardinality_and_refusals():
    """With cp above min(a, b) max(cost), two pairs beat one cheaper pair; with cp small the
    cheaper single pair wins (the GOSPA trade-off); a cost at cp is refused."""
    I, J, cost = np.array([0, 0, 1]), np.array([0, 1, 0]), np.array([0.1, 0.9, 0.9])
    i, j, _ = mt.solve_partial(I, J, cost, 10.0)
    assert sorted(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 1), (1, 0)]
    i, j, _ = mt.solve_partial(I, J, cost, 1.0)
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == [(0, 0)]
    with pytest.raises(ValueError, match="cost has values >= cp"):
        mt.solve_partial(I, J, cost, 0.9)
    with pytest.raises(ValueError, match="expected one"):
        mt.solve_partial(I, J[:2], cost, 10.0)


def test_track_counts_with_a_given_assignment_are_the_same():
    rng = np.random.default_rng(2)
    X = frames([rng.uniform(0, 10, (5, 2)) for _ in range(20)], [rng.permutation(5)] * 20)
    Y = frames([rng.uniform(0, 10, (6, 2)) for _ in range(20)], [rng.permutation(6)] * 20)
    a = track_counts(X, Y, 3.0)
    b = track_counts(X, Y, 3.0, assignment=assign(X, Y, 3.0))
    for name in TrackCounts._fields:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def _random_pair(seed: int, d: int) -> tuple[Frames, Frames]:
    """Truth and estimates with IDs over 30 steps of random sizes (some empty), clustered so
    that components of several points form, and two large steps (n m >= 4096) that go
    through the kernel's broadcast pass."""
    rng = np.random.default_rng(seed)
    n = rng.integers(0, 9, 30)
    m = rng.integers(0, 11, 30)
    n[[4, 17]], m[[4, 17]] = (70, 90), (80, 60)
    xs = [rng.uniform(0, 12, (k, d)) for k in n]
    ys = [x[: min(k, len(x))] + rng.normal(0, 0.6, (min(k, len(x)), d)) for x, k in zip(
        xs, m, strict=True)]
    ys = [np.concatenate([y, rng.uniform(0, 12, (k - len(y), d))]) for y, k in zip(
        ys, m, strict=True)]
    return (frames(xs, [rng.permutation(k) for k in n], dim=d),
            frames(ys, [rng.permutation(k) for k in m], dim=d))


@pytest.mark.parametrize(("seed", "d", "p"), [(0, 2, 2.0), (1, 2, 1.0), (2, 3, 3.0),
                                              (3, 2, 1.5)])
def test_given_assignment_gives_the_same_bits(seed, d, p):
    """gospa_steps and track_counts with the assignment passed equal them without, bit for
    bit, whatever the order the rows are given in."""
    X, Y = _random_pair(seed, d)
    c = 1.5
    ab = assign(X, Y, c, p)
    assert ab[0].size > 100
    o = np.random.default_rng(seed).permutation(ab[0].size)
    plain = gospa_steps(X, Y, c, p)
    for rows in (ab, (ab[0][o], ab[1][o])):
        for name, a, b in zip(plain._fields, plain, gospa_steps(X, Y, c, p, assignment=rows),
                              strict=True):
            np.testing.assert_array_equal(a, b, err_msg=name)
            assert a.dtype == b.dtype, name
        counts = track_counts(X, Y, c, p=p, assignment=rows)
        for name, a, b in zip(TrackCounts._fields, track_counts(X, Y, c, p=p), counts,
                              strict=True):
            np.testing.assert_array_equal(a, b, err_msg=name)


def test_given_assignment_is_checked():
    X, Y = _random_pair(0, 2)
    I, J = assign(X, Y, 1.5)
    with pytest.raises(ValueError, match="different steps"):
        gospa_steps(X, Y, 1.5, assignment=(I, np.roll(J, 1)))
    with pytest.raises(ValueError, match="outside"):
        track_counts(X, Y, 1.5, assignment=(I, J + Y.offsets[-1]))
    with pytest.raises(ValueError, match="expected integers"):
        gospa_steps(X, Y, 1.5, assignment=(I, J[:-1]))
    with pytest.raises(ValueError, match="expected the rows"):
        gospa_steps(X, Y, 1.5, assignment=(I,))


def test_dominant_truths_equal_a_count_per_track():
    """Per track, the truth of most pairs, the lowest on a tie, against a dictionary count;
    the number of pairs is that of the dominant truth."""
    rng = np.random.default_rng(9)
    track = rng.integers(0, 40, 3000) * 3 + 5
    truth = rng.integers(0, 6, 3000) + 100
    got = mt.dominant_truths(track, truth)
    want: dict[int, dict[int, int]] = {}
    for a, b in zip(track.tolist(), truth.tolist(), strict=True):
        want.setdefault(a, {}).setdefault(b, 0)
        want[a][b] += 1
    rows = [(a, *max(sorted(want[a].items()), key=lambda kv: kv[1])) for a in sorted(want)]
    assert [tuple(r) for r in zip(*(g.tolist() for g in got), strict=True)] == rows
    ties = sum(list(want[a].values()).count(n) > 1 for a, _, n in rows)
    assert ties > 0  # the tie rule was exercised
    empty = mt.dominant_truths(np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert all(e.size == 0 for e in empty)
    with pytest.raises(ValueError, match="expected integers"):
        mt.dominant_truths(track, truth[:-1])
