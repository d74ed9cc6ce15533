"""The batched association (every small cluster's joint events at once) against the
one-cluster-at-a-time path it stands in for: the same numbers, bit for bit, and the
thresholds where it takes over."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from trackkit.tracking import association
from trackkit.tracking.association import (
    Costs,
    clusters,
    gnn_assign,
    jpda_probabilities,
    loglik_costs,
)
from trackkit.tracking.gating import gate, predict_measurement

from .scenes import scene

# (tracks, side of the square, clutter): spread out (clusters of 1 to 3 tracks) to crowded
# (clusters of tens of tracks, past BATCH_MAX_TRACKS and BATCH_MAX_EVENTS)
SCENES = [(400, 20000.0, 40.0), (300, 4000.0, 60.0), (120, 1200.0, 30.0), (60, 400.0, 10.0)]


def _gate(seed: int, T: int, side: float, clutter: float):
    rng = np.random.default_rng(seed)
    sc = scene(rng, T, side=side, clutter=clutter, pd=0.8)
    mp = predict_measurement(sc.predicted, sc.sensor)
    return gate(mp.zhat, mp.S, sc.z, 0.99), sc


def _events(g, tracks) -> int:
    """Joint events of the cluster of ``tracks``, by brute force over every choice."""
    options = [[-1, *g.det[g.track == t].tolist()] for t in tracks]
    n = 0
    for choice in itertools.product(*options):
        used = [d for d in choice if d >= 0]
        n += len(used) == len(set(used))
    return n


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(("T", "side", "clutter"), SCENES)
@pytest.mark.parametrize("star", [False, True])
def test_jpda_batched_equals_one_cluster_at_a_time(seed, T, side, clutter, star, monkeypatch):
    g, sc = _gate(seed, T, side, clutter)
    fast = jpda_probabilities(g, sc.pd, sc.clutter_density, star=star)
    monkeypatch.setattr(association, "BATCH_MAX_EVENTS", 0)  # every cluster on its own
    ref = jpda_probabilities(g, sc.pd, sc.clutter_density, star=star)
    np.testing.assert_array_equal(fast.beta, ref.beta)
    np.testing.assert_array_equal(fast.beta0, ref.beta0)
    np.testing.assert_array_equal(fast.approximated, ref.approximated)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(("T", "side", "clutter"), SCENES)
def test_gnn_batched_equals_one_cluster_at_a_time(seed, T, side, clutter, monkeypatch):
    g, sc = _gate(seed, T, side, clutter)
    costs = loglik_costs(g, sc.pd, sc.clutter_density)
    fast = gnn_assign(g, costs, method="clusters")
    sparse = gnn_assign(g, costs, method="sparse")
    monkeypatch.setattr(association, "BATCH_MAX_EVENTS", 0)
    ref = gnn_assign(g, costs, method="clusters")
    np.testing.assert_array_equal(fast.det, ref.det)
    np.testing.assert_array_equal(fast.unassigned, ref.unassigned)
    assert fast.cost == ref.cost
    np.testing.assert_array_equal(fast.det, sparse.det)


def test_gnn_exact_ties_are_left_to_linear_sum_assignment(monkeypatch):
    """Integer costs tie often: the batched path must hand each tied cluster on, so the
    assignment is linear_sum_assignment's."""
    g, _ = _gate(3, 300, 4000.0, 60.0)
    rng = np.random.default_rng(0)
    costs = Costs(rng.integers(0, 3, g.size).astype(float), np.full(g.n_tracks, 2.0))
    fast = gnn_assign(g, costs, method="clusters")
    lay = association._layout(g, clusters(g))
    cm = costs.pair[lay.pairs]
    solved = association._gnn_batched(lay, cm, costs.miss, np.full(g.n_tracks, -1))
    assert 0 < solved.sum() < solved.size  # some clusters tie, some do not
    monkeypatch.setattr(association, "BATCH_MAX_EVENTS", 0)
    np.testing.assert_array_equal(fast.det, gnn_assign(g, costs, method="clusters").det)


@pytest.mark.parametrize("cap", [3, 8, 40])
def test_batched_takes_the_clusters_within_the_thresholds(cap, monkeypatch):
    """A cluster is batched exactly when it has at most BATCH_MAX_TRACKS tracks and at most
    BATCH_MAX_EVENTS joint events (counted here by brute force), and the marginals are the
    same on either side."""
    g, sc = _gate(1, 120, 1200.0, 30.0)
    cl = clusters(g)
    lay = association._layout(g, cl)
    monkeypatch.setattr(association, "BATCH_MAX_EVENTS", cap)
    monkeypatch.setattr(association, "BATCH_MAX_TRACKS", 4)
    ev = association._joint_events(lay, np.zeros(lay.pairs.size), cap)
    nt = np.diff(lay.t_bounds)
    counts = np.array([_events(g, lay.tracks[a:b]) if n <= 4 else -1 for a, b, n in
                       zip(lay.t_bounds[:-1], lay.t_bounds[1:], nt, strict=True)])
    expect = (nt <= 4) & (counts <= cap)
    np.testing.assert_array_equal(ev.batched, expect)
    assert expect.any() and not expect.all()
    np.testing.assert_array_equal(np.bincount(ev.cluster, minlength=nt.size)[expect],
                                  counts[expect])
    fast = jpda_probabilities(g, sc.pd, sc.clutter_density)
    monkeypatch.setattr(association, "BATCH_MAX_EVENTS", 0)
    ref = jpda_probabilities(g, sc.pd, sc.clutter_density)
    np.testing.assert_array_equal(fast.beta, ref.beta)
    np.testing.assert_array_equal(fast.beta0, ref.beta0)


@pytest.mark.parametrize("max_events", [4, 30])
def test_jpda_max_events_below_the_batch_cap_still_decides_the_fallback(max_events,
                                                                        monkeypatch):
    """With max_events under BATCH_MAX_EVENTS the batched path stops at max_events, so the
    clusters sent to loopy belief propagation are the one-at-a-time path's."""
    g, sc = _gate(2, 120, 1200.0, 30.0)
    fast = jpda_probabilities(g, sc.pd, sc.clutter_density, max_events=max_events)
    assert fast.approximated.any()
    monkeypatch.setattr(association, "BATCH_MAX_EVENTS", 0)
    ref = jpda_probabilities(g, sc.pd, sc.clutter_density, max_events=max_events)
    np.testing.assert_array_equal(fast.approximated, ref.approximated)
    np.testing.assert_array_equal(fast.beta, ref.beta)
    np.testing.assert_array_equal(fast.beta0, ref.beta0)


def test_joint_events_match_enumerate_event_for_event():
    """Each batched cluster's events, in order, with their weights: those ``_enumerate``
    builds (its marginals from them equal the batched ones above)."""
    g, sc = _gate(0, 300, 4000.0, 60.0)
    lay = association._layout(g, clusters(g))
    lr = association._log_ratio(g, sc.pd, sc.clutter_density, None)[lay.pairs]
    ev = association._joint_events(lay, lr, 10_000)
    k = int(np.argmax(np.diff(lay.t_bounds) * ev.batched))  # the largest batched cluster
    mine = ev.cluster == k
    p0, p1 = lay.p_bounds[k], lay.p_bounds[k + 1]
    nt = lay.t_bounds[k + 1] - lay.t_bounds[k]
    assert nt >= 3
    # rebuild the reference's events exactly as _enumerate does
    lt, ld, w = lay.local_track[p0:p1], lay.local_det[p0:p1], lr[p0:p1]
    evs, logw = [[-1] * nt], [0.0]
    for i in range(nt):
        ext, ext_w = [], []
        for e, lw in zip(evs, logw, strict=True):
            for d, wi in zip(ld[lt == i], w[lt == i], strict=True):
                if d not in e:
                    ext.append(e[:i] + [int(d)] + e[i + 1:])
                    ext_w.append(lw + wi)
        evs, logw = evs + ext, logw + ext_w
    np.testing.assert_array_equal(ev.det[mine][:, :nt], np.array(evs))
    np.testing.assert_array_equal(ev.logw[mine], np.array(logw))
